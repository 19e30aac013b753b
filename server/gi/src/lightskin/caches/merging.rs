//! Step 5: similar caches from neighbouring voxels joined.

use super::*;

/// A cache after step 5.
#[derive(Clone, Copy, Debug)]
pub(super) struct Joined {
    pub position: Vec3,
    pub normal: Vec3,
    pub model: u32,
}

/// Step 5: caches from different voxels closer than d_eps/4 whose normals differ by less than
/// theta_eps/2 are joined (area-weighted position and normal). Larger caches absorb smaller
/// ones first, so the order (and the result) is fixed. A join is skipped if it would leave any
/// member sample more than theta_eps from the joined normal. Returns the joined caches, the
/// joined cache of every sample and how many joins had to be snapped (step 4 again).
pub(super) fn merge(
    protos: &[Proto],
    members: &[u32],
    samples: &[Sample],
    setup: &Setup,
    progress: &mut dyn FnMut(Progress),
) -> (Vec<Joined>, Vec<u32>, u64) {
    let n = protos.len();
    progress(Progress {
        step: "merging",
        done: 0,
        total: n as u64,
    });
    let positions: Vec<Vec3> = protos.iter().map(|p| p.position).collect();
    let tree = KdTree::new(&positions);
    let radius = setup.d_eps * MERGE_DISTANCE;
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.par_sort_unstable_by(|&a, &b| {
        protos[b as usize]
            .area
            .total_cmp(&protos[a as usize].area)
            .then(a.cmp(&b))
    });
    let member_ids = |p: &Proto| &members[p.first as usize..(p.first + p.count) as usize];
    // A proto's samples share its voxel, and so its model.
    let model = |p: &Proto| samples[members[p.first as usize] as usize].model;

    let mut taken = vec![false; n];
    // (anchor, group) in anchor order of processing; sorted by anchor afterwards.
    let mut groups: Vec<(u32, Vec<u32>)> = Vec::with_capacity(n);
    let mut candidates = Vec::new();
    for (done, &i) in order.iter().enumerate() {
        if done > 0 && done.is_multiple_of(CHUNK) {
            progress(Progress {
                step: "merging",
                done: done as u64,
                total: n as u64,
            });
        }
        if taken[i as usize] {
            continue;
        }
        taken[i as usize] = true;
        let anchor = &protos[i as usize];
        candidates.clear();
        tree.within(anchor.position, radius * radius, &mut |j| {
            let other = &protos[j as usize];
            if !taken[j as usize]
                && other.voxel != anchor.voxel
                && model(other) == model(anchor)
                && other.normal.dot(anchor.normal) > setup.cos_half_theta
            {
                candidates.push(j);
            }
        });
        candidates.sort_unstable();
        let mut group = vec![i];
        let mut normal_sum = anchor.normal.as_dvec3() * anchor.area;
        for &j in &candidates {
            let other = &protos[j as usize];
            let Some(normal) = (normal_sum + other.normal.as_dvec3() * other.area)
                .as_vec3()
                .try_normalize()
            else {
                continue;
            };
            let keeps_samples = group
                .iter()
                .chain(std::iter::once(&j))
                .flat_map(|&g| member_ids(&protos[g as usize]))
                .all(|&s| samples[s as usize].normal.dot(normal) > setup.cos_theta);
            if keeps_samples {
                group.push(j);
                taken[j as usize] = true;
                normal_sum += other.normal.as_dvec3() * other.area;
            }
        }
        groups.push((i, group));
    }
    groups.sort_unstable_by_key(|g| g.0);

    let mut owner = vec![u32::MAX; samples.len()];
    let mut snapped = 0;
    let joined = groups
        .iter()
        .enumerate()
        .map(|(index, (_, group))| {
            for &g in group {
                for &s in member_ids(&protos[g as usize]) {
                    owner[s as usize] = index as u32;
                }
            }
            let first = &protos[group[0] as usize];
            if group.len() == 1 {
                return Joined {
                    position: first.position,
                    normal: first.normal,
                    model: model(first),
                };
            }
            let (mut position_sum, mut normal_sum, mut area) = (DVec3::ZERO, DVec3::ZERO, 0.0);
            for &g in group {
                let p = &protos[g as usize];
                position_sum += p.position.as_dvec3() * p.area;
                normal_sum += p.normal.as_dvec3() * p.area;
                area += p.area;
            }
            let mut position = (position_sum / area).as_vec3();
            let all_members: Vec<u32> = group
                .iter()
                .flat_map(|&g| member_ids(&protos[g as usize]).iter().copied())
                .collect();
            if let Some(p) = snap(samples, &all_members, position, setup.d_eps) {
                position = p;
                snapped += 1;
            }
            Joined {
                position,
                normal: normal_sum.as_vec3().try_normalize().unwrap_or(first.normal),
                model: model(first),
            }
        })
        .collect();
    progress(Progress {
        step: "merging",
        done: n as u64,
        total: n as u64,
    });
    (joined, owner, snapped)
}

// ---------------------------------------------------------------------------------------------
// Voronoi areas, materials, per-vertex neighbours
// ---------------------------------------------------------------------------------------------
