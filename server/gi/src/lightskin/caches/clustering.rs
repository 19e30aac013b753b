//! Steps 2–4: per voxel, the samples' normals binned in a cube-map normal container, the bin
//! with the largest area turned into a cache until none is left, and caches floating off the
//! surface snapped onto their closest sample.

use super::*;

/// Cells per cube-face side of the normal container (step 2). A cell at a face centre spans the
/// widest angle, whose half-diagonal is at most √2/N radians; N > √2/θ keeps every bin inside a
/// θ-cone around its centre, so the bin chosen in step 3 always contributes samples.
pub(super) fn normal_resolution(theta: f32) -> u32 {
    ((std::f32::consts::SQRT_2 / theta).floor() as u32)
        .saturating_add(1)
        .clamp(1, 16384)
}

/// Cube-map bin of a unit normal: face (±X, ±Y, ±Z) then an N×N grid on that face.
pub(super) fn normal_bin(n: Vec3, res: u32) -> u32 {
    let a = n.abs();
    let (face, u, v, major) = if a.x >= a.y && a.x >= a.z {
        (u32::from(n.x < 0.0), n.y, n.z, a.x)
    } else if a.y >= a.z {
        (2 + u32::from(n.y < 0.0), n.z, n.x, a.y)
    } else {
        (4 + u32::from(n.z < 0.0), n.x, n.y, a.z)
    };
    let cell = |c: f32| (((c / major + 1.0) * 0.5 * res as f32) as u32).min(res - 1);
    (face * res + cell(v)) * res + cell(u)
}

/// Centre direction of a [`normal_bin`] cell.
pub(super) fn normal_bin_centre(bin: u32, res: u32) -> Vec3 {
    let face = bin / (res * res);
    let within = bin % (res * res);
    let coord = |i: u32| (i as f32 + 0.5) / res as f32 * 2.0 - 1.0;
    let (v, u) = (coord(within / res), coord(within % res));
    let sign = if face.is_multiple_of(2) { 1.0 } else { -1.0 };
    match face / 2 {
        0 => Vec3::new(sign, u, v),
        1 => Vec3::new(v, sign, u),
        _ => Vec3::new(u, v, sign),
    }
    .normalize()
}

/// Steps 2–4 for every voxel. Returns the caches, their member samples (each cache's
/// `first..first + count`) and how many caches were snapped.
pub(super) fn cluster(
    samples: &[Sample],
    voxel_order: &[u32],
    voxels: &[(u32, u32)],
    setup: &Setup,
    progress: &mut dyn FnMut(Progress),
) -> (Vec<Proto>, Vec<u32>, u64) {
    let per_voxel = par_map_chunked(voxels.len(), "clustering", progress, |v| {
        let (start, end) = voxels[v];
        cluster_voxel(
            samples,
            &voxel_order[start as usize..end as usize],
            v as u32,
            setup,
        )
    });
    let mut protos = Vec::new();
    let mut members = Vec::with_capacity(samples.len());
    let mut snapped = 0;
    for (voxel_protos, voxel_members, voxel_snapped) in per_voxel {
        let base = members.len() as u32;
        protos.extend(voxel_protos.into_iter().map(|p| Proto {
            first: p.first + base,
            ..p
        }));
        members.extend_from_slice(&voxel_members);
        snapped += voxel_snapped;
    }
    (protos, members, snapped)
}

/// Steps 2–4 for one voxel's samples.
pub(super) fn cluster_voxel(
    samples: &[Sample],
    voxel_samples: &[u32],
    voxel: u32,
    setup: &Setup,
) -> (Vec<Proto>, Vec<u32>, u64) {
    let res = setup.normal_bins;
    let cos = setup.cos_theta;
    // Step 2: the normal container, kept as (bin, sample) pairs sorted by bin.
    let mut remaining: Vec<(u32, u32)> = voxel_samples
        .iter()
        .map(|&s| (normal_bin(samples[s as usize].normal, res), s))
        .collect();
    remaining.sort_unstable();

    let mut protos = Vec::new();
    let mut members = Vec::new();
    let mut snapped = 0;
    while !remaining.is_empty() {
        // Step 3: the bin representing the largest surface (lowest bin id on ties).
        let mut best = (remaining[0].0, f64::NEG_INFINITY);
        let mut run_start = 0;
        for i in 1..=remaining.len() {
            if i == remaining.len() || remaining[i].0 != remaining[run_start].0 {
                let area: f64 = remaining[run_start..i]
                    .iter()
                    .map(|&(_, s)| f64::from(samples[s as usize].area))
                    .sum();
                if area > best.1 {
                    best = (remaining[run_start].0, area);
                }
                run_start = i;
            }
        }
        let centre = normal_bin_centre(best.0, res);
        // Samples deviating less than theta_eps from the bin centre; the bin's own samples
        // always count, which only matters when theta_eps is below the container resolution.
        let around_centre =
            |&(bin, s): &(u32, u32)| bin == best.0 || samples[s as usize].normal.dot(centre) > cos;

        let mut normal_sum = DVec3::ZERO;
        for entry in remaining.iter().filter(|e| around_centre(e)) {
            let s = &samples[entry.1 as usize];
            normal_sum += s.normal.as_dvec3() * f64::from(s.area);
        }
        let mut normal = normal_sum.as_vec3().try_normalize().unwrap_or(centre);
        // The cache represents (and removes) those samples that are also within theta_eps of
        // the averaged normal, so every sample ends up within theta_eps of its cache. For
        // normals inside a θ-cone the weighted mean always has one such sample: if all had
        // n·m̂ <= cos θ, then |m| = Σ wᵢ nᵢ·m̂ <= cos θ < Σ wᵢ nᵢ·c <= |m|.
        let mut taken: Vec<u32> = remaining
            .iter()
            .filter(|e| around_centre(e) && samples[e.1 as usize].normal.dot(normal) > cos)
            .map(|e| e.1)
            .collect();
        if taken.is_empty() {
            // Only reachable through the bin fallback above: take the best-aligned sample.
            let closest = remaining
                .iter()
                .filter(|e| around_centre(e))
                .max_by(|a, b| {
                    let da = samples[a.1 as usize].normal.dot(normal);
                    let db = samples[b.1 as usize].normal.dot(normal);
                    da.total_cmp(&db).then(b.1.cmp(&a.1))
                })
                .map_or(remaining[0].1, |e| e.1);
            normal = samples[closest as usize].normal;
            taken.push(closest);
        }
        taken.sort_unstable();

        let (mut position, area) = weighted_position(samples, &taken);
        if let Some(p) = snap(samples, &taken, position, setup.d_eps) {
            position = p;
            snapped += 1;
        }
        protos.push(Proto {
            position,
            normal,
            area,
            voxel,
            first: members.len() as u32,
            count: taken.len() as u32,
        });
        members.extend_from_slice(&taken);
        remaining.retain(|e| taken.binary_search(&e.1).is_err());
    }
    (protos, members, snapped)
}

/// Area-weighted mean position of samples, and their total area.
pub(super) fn weighted_position(samples: &[Sample], ids: &[u32]) -> (Vec3, f64) {
    let mut sum = DVec3::ZERO;
    let mut area = 0.0;
    for &s in ids {
        let s = &samples[s as usize];
        let a = f64::from(s.area);
        sum += s.position.as_dvec3() * a;
        area += a;
    }
    ((sum / area).as_vec3(), area)
}

/// Step 4: an averaged position can float off a curved or bent surface. It counts as floating
/// when it lies off the tangent plane of its closest sample by more than a small fraction of
/// d_eps; then the cache moves onto that sample.
pub(super) fn snap(samples: &[Sample], ids: &[u32], position: Vec3, d_eps: f32) -> Option<Vec3> {
    let closest = ids.iter().copied().min_by(|&a, &b| {
        let da = samples[a as usize].position.distance_squared(position);
        let db = samples[b as usize].position.distance_squared(position);
        da.total_cmp(&db).then(a.cmp(&b))
    })?;
    let s = &samples[closest as usize];
    let off_plane = (position - s.position).dot(s.normal).abs();
    (off_plane > FLOATING_TOLERANCE * d_eps).then_some(s.position)
}

// ---------------------------------------------------------------------------------------------
// Step 5: joining caches across voxels
// ---------------------------------------------------------------------------------------------
