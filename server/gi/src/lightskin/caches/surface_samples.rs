//! Step 1: the surfaces sampled at a spacing of at most d_eps/4 (triangles bisected until
//! small enough) and the samples binned into voxels of edge d_eps/2.

use super::*;

/// Splits a triangle by longest-edge bisection until no piece has an edge longer than
/// `spacing`, calling `emit(centroid, area)` per piece, and returns the piece count (stopping
/// early once it passes `budget`). Bisection keeps pieces well shaped (the smallest angle at
/// most halves) and needs only O(area/spacing² + perimeter/spacing) pieces even for slivers,
/// and every surface point lies within `spacing` (the piece's longest edge) of its piece's
/// centroid sample.
pub(super) fn bisect(
    corners: [Vec3; 3],
    area: f64,
    spacing: f32,
    budget: u64,
    stack: &mut Vec<([Vec3; 3], u32)>,
    emit: &mut impl FnMut(Vec3, f64),
) -> u64 {
    let spacing2 = spacing * spacing;
    let mut pieces = 0u64;
    stack.clear();
    stack.push((corners, 0));
    while let Some(([a, b, c], depth)) = stack.pop() {
        let edges = [
            (b - a).length_squared(),
            (c - b).length_squared(),
            (a - c).length_squared(),
        ];
        let longest = if edges[0] >= edges[1] && edges[0] >= edges[2] {
            0
        } else if edges[1] >= edges[2] {
            1
        } else {
            2
        };
        if edges[longest] <= spacing2 || depth >= MAX_BISECTION_DEPTH {
            emit((a + b + c) / 3.0, area / f64::from(depth).exp2());
            pieces += 1;
            if pieces > budget {
                return pieces;
            }
            continue;
        }
        // Rotate so the longest edge runs from p to q, with r opposite.
        let (p, q, r) = match longest {
            0 => (a, b, c),
            1 => (b, c, a),
            _ => (c, a, b),
        };
        let m = (p + q) * 0.5;
        stack.push(([m, q, r], depth + 1));
        stack.push(([p, m, r], depth + 1));
    }
    pieces
}

/// Step 1: area-weighted surface samples with geometric triangle normals (flat per triangle, so
/// a sample's normal is exactly the surface normal at the sample; vertex normals may be smoothed
/// across creases that the caches should respect). Returns the samples and the number of
/// triangles without area.
pub(super) fn sample_surfaces(
    scene: &Scene,
    d_eps: f32,
    progress: &mut dyn FnMut(Progress),
) -> Result<(Vec<Sample>, u64), CacheError> {
    let spacing = d_eps * SAMPLE_SPACING;
    let triangles = scene.triangle_count();
    let blocks = triangles.div_ceil(TRIANGLE_BLOCK);
    let block_range = |b: usize| b * TRIANGLE_BLOCK..((b + 1) * TRIANGLE_BLOCK).min(triangles);

    // Count first so that memory is only committed once the total is known to be sane.
    let counts = par_map_chunked(blocks, "counting samples", progress, |b| {
        let mut stack = Vec::new();
        let mut count = 0u64;
        for t in block_range(b) {
            if let Some((_, corners)) = triangle_normal(scene, t) {
                count += bisect(
                    corners,
                    0.0,
                    spacing,
                    MAX_SAMPLES,
                    &mut stack,
                    &mut |_, _| {},
                );
                if count > MAX_SAMPLES {
                    break;
                }
            }
        }
        count
    });
    let total = counts
        .iter()
        .try_fold(0u64, |s, &c| s.checked_add(c).filter(|&s| s <= MAX_SAMPLES));
    let Some(total) = total else {
        return Err(CacheError::TooManySamples { d_eps });
    };

    let models = triangle_models(scene);
    let per_block = par_map_chunked(blocks, "sampling", progress, |b| {
        let mut stack = Vec::new();
        let mut out = Vec::new();
        let mut degenerate = 0u64;
        for t in block_range(b) {
            let Some((normal, corners)) = triangle_normal(scene, t) else {
                degenerate += 1;
                continue;
            };
            let material = scene.vertices[triangle(scene, t)[0] as usize].material;
            let area = triangle_area(scene, t);
            bisect(corners, area, spacing, u64::MAX, &mut stack, &mut |p, a| {
                out.push(Sample {
                    position: p,
                    normal,
                    // Keep every weight positive so weighted means never divide by zero.
                    area: (a as f32).max(f32::MIN_POSITIVE),
                    material,
                    model: models[t],
                })
            });
        }
        (out, degenerate)
    });
    let mut samples = Vec::with_capacity(total as usize);
    let mut degenerate = 0;
    for (block, d) in per_block {
        samples.extend_from_slice(&block);
        degenerate += d;
    }
    Ok((samples, degenerate))
}

/// Step 1: bins samples into voxels of edge `h`, one set of voxels per model (so the voxels,
/// and the caches made of them, come model by model). Returns the sample indices ordered by
/// voxel and each voxel's range in that order. Sorting by (model, voxel, sample) instead of
/// filling a hash map gives a deterministic voxel order for free.
pub(super) fn voxelise(
    samples: &[Sample],
    h: f32,
    progress: &mut dyn FnMut(Progress),
) -> (Vec<u32>, Vec<(u32, u32)>) {
    let n = samples.len() as u64;
    progress(Progress {
        step: "voxelising",
        done: 0,
        total: n,
    });
    let h = f64::from(h);
    let mut keyed: Vec<((u32, [i64; 3]), u32)> = samples
        .par_iter()
        .enumerate()
        .map(|(i, s)| {
            let p = s.position.as_dvec3() / h;
            // Saturating float-to-int casts keep absurd coordinates from wrapping.
            let key = [p.x.floor() as i64, p.y.floor() as i64, p.z.floor() as i64];
            ((s.model, key), i as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    let mut voxels = Vec::new();
    let mut start = 0;
    for i in 1..=keyed.len() {
        if i == keyed.len() || keyed[i].0 != keyed[start].0 {
            voxels.push((start as u32, i as u32));
            start = i;
        }
    }
    progress(Progress {
        step: "voxelising",
        done: n,
        total: n,
    });
    (keyed.into_iter().map(|(_, i)| i).collect(), voxels)
}

// ---------------------------------------------------------------------------------------------
// Steps 2–4: normal containers, clustering, snapping
// ---------------------------------------------------------------------------------------------
