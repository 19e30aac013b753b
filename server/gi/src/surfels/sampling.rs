//! Surfels (seed 001, "Surfel Placement"): n_S small discs of equal area a = A/n_S spread over
//! every triangle in proportion to its area, so that together they stand for the whole surface
//! (the senders of light transport, eq. 1–3) and the hierarchy above them sums whole areas.
//!
//! 1. Triangles are put in spatial (Morton) order first: the scene's own order is by material,
//!    and small triangles accumulated into one surfel must lie next to each other.
//! 2. Surfel i goes to the triangle whose span of the running area sum holds (i + ½)·a: a
//!    triangle of area A_t gets ⌊A_t/a⌋ or ⌈A_t/a⌉ surfels, and a run of triangles smaller
//!    than a shares one, which is the paper's accumulation of small triangles.
//! 3. Within its triangle a surfel sits at Halton point i + 1 (bases 2 and 3) under an
//!    area-preserving map, so the surfels of one triangle are stratified (the paper's Fig. 3
//!    prefers Halton to random points).
//! 4. A few Jacobi steps of repulsion between neighbours along each surfel's tangent plane even
//!    out the spacing; a surfel never leaves its own triangle, so the counts and areas above
//!    stay exact.
//!
//! The output is the same whatever the thread count: chunks are concatenated in order and
//! every step reads only the previous step's positions.

use crate::gi::common::halton::halton;
use crate::gi::common::triangles::{triangle_area, triangle_normal};
use crate::gi::precompute::Progress;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;

/// Relaxation steps (the paper gives none). On two squares of 1,024 surfels each, 8 steps
/// bring the variation of nearest-neighbour distances from 34 % to 8 % and the closest pair
/// from 0.1 to 0.6 hexagonal spacings (the test below).
pub const RELAX_STEPS: u32 = 8;
/// Surfels per parallel chunk, with a progress report and a cancellation check after each.
const CHUNK: usize = 4096;

/// One surfel: a disc of the set's [`Surfels::area`] on triangle `triangle`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surfel {
    /// Scene units.
    pub position: Vec3,
    /// Unit geometric normal of its triangle, on the side of the vertex normals.
    pub normal: Vec3,
    /// Texture coordinates at `position`, for the material's base colour.
    pub uv: Vec2,
    /// Index of its triangle in the scene's index list.
    pub triangle: u32,
    pub material: u32,
}

/// The surfels of a scene.
#[derive(Clone, Debug)]
pub struct Surfels {
    pub surfels: Vec<Surfel>,
    /// Area of every surfel, a = A/n_S, in square scene units.
    pub area: f64,
    /// A, the scene's triangle area (zero-area triangles get no surfel).
    pub total_area: f64,
}

/// Why a scene got no surfels.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SamplingError {
    #[error("the scene has no triangle with an area")]
    NoArea,
    #[error("at least one surfel is needed")]
    NoSurfels,
    #[error("cancelled: the scene was deleted, or nobody waits for the set any more")]
    Cancelled,
}

/// A triangle that can hold surfels.
struct Face {
    triangle: u32,
    corners: [Vec3; 3],
    normal: Vec3,
    area: f64,
}

/// `count` surfels over `scene`, relaxed by `relax_steps` steps.
pub fn sample(
    scene: &Scene,
    count: u32,
    relax_steps: u32,
    progress: &mut dyn FnMut(Progress),
    cancelled: &dyn Fn() -> bool,
) -> Result<Surfels, SamplingError> {
    if count == 0 {
        return Err(SamplingError::NoSurfels);
    }
    let faces = faces_in_morton_order(scene);
    let total_area: f64 = faces.iter().map(|f| f.area).sum();
    if !(total_area > 0.0 && total_area.is_finite()) {
        return Err(SamplingError::NoArea);
    }
    let area = total_area / f64::from(count);
    // Running sums in the same sequential order as `total_area`, so the last equals it.
    let ends: Vec<f64> = faces
        .iter()
        .scan(0.0, |sum, f| {
            *sum += f.area;
            Some(*sum)
        })
        .collect();
    let mut surfels = Vec::with_capacity(count as usize);
    for start in (0..count as usize).step_by(CHUNK) {
        if cancelled() {
            return Err(SamplingError::Cancelled);
        }
        let end = (start + CHUNK).min(count as usize);
        let chunk: Vec<Surfel> = (start..end)
            .into_par_iter()
            .map(|i| {
                let target = (i as f64 + 0.5) * area;
                // The first face whose running sum passes the target (rounding can leave the
                // last target a hair above the total: clamp to the last face).
                let f = ends.partition_point(|&e| e <= target).min(faces.len() - 1);
                place(scene, &faces[f], i as u32)
            })
            .collect();
        surfels.extend(chunk);
        progress(Progress {
            step: "surfels",
            done: end as u64,
            total: u64::from(count),
        });
    }
    let spacing = hexagonal_spacing(area);
    let faces_by_triangle: HashMap<u32, &Face> = faces.iter().map(|f| (f.triangle, f)).collect();
    for step in 0..relax_steps {
        if cancelled() {
            return Err(SamplingError::Cancelled);
        }
        surfels = relax(scene, &surfels, &faces_by_triangle, spacing);
        progress(Progress {
            step: "relaxing",
            done: u64::from(step + 1),
            total: u64::from(relax_steps),
        });
    }
    Ok(Surfels {
        surfels,
        area,
        total_area,
    })
}

/// Distance between neighbours of a hexagonal packing with one surfel per area `a`.
fn hexagonal_spacing(area: f64) -> f32 {
    (2.0 * area / 3f64.sqrt()).sqrt() as f32
}

/// The triangles with an area, sorted by the Morton code of their centroid within the scene's
/// bounds (index as tie-break).
fn faces_in_morton_order(scene: &Scene) -> Vec<Face> {
    let bounds = scene.bounds;
    // Cubic cells (one scale for every axis), so that a run of codes is a compact region
    // rather than a sliver along the shortest axis.
    let size = (bounds.max - bounds.min)
        .max_element()
        .max(f32::MIN_POSITIVE);
    let mut faces: Vec<(u32, Face)> = (0..scene.triangle_count())
        .into_par_iter()
        .filter_map(|t| {
            let area = triangle_area(scene, t);
            let (normal, corners) = triangle_normal(scene, t)?;
            if !(area > 0.0 && area.is_finite()) {
                return None;
            }
            let centroid = (corners[0] + corners[1] + corners[2]) / 3.0;
            let cell = ((centroid - bounds.min) / size * 1023.0)
                .clamp(Vec3::ZERO, Vec3::splat(1023.0))
                .as_uvec3();
            let face = Face {
                triangle: t as u32,
                corners,
                normal,
                area,
            };
            Some((morton(cell.x, cell.y, cell.z), face))
        })
        .collect();
    faces.sort_by_key(|(code, f)| (*code, f.triangle));
    faces.into_iter().map(|(_, f)| f).collect()
}

/// 30-bit Morton code of three 10-bit coordinates.
fn morton(x: u32, y: u32, z: u32) -> u32 {
    fn spread(mut v: u32) -> u32 {
        v &= 0x3ff;
        v = (v | (v << 16)) & 0x0300_00ff;
        v = (v | (v << 8)) & 0x0300_f00f;
        v = (v | (v << 4)) & 0x030c_30c3;
        (v | (v << 2)) & 0x0924_9249
    }
    spread(x) | (spread(y) << 1) | (spread(z) << 2)
}

/// Surfel `i` on `face` at Halton point i + 1, mapped uniformly by area onto the triangle
/// (Shirley's square-to-triangle map: b₀ = 1 − √u, b₁ = v·√u).
fn place(scene: &Scene, face: &Face, i: u32) -> Surfel {
    let (u, v) = (halton(i + 1, 2), halton(i + 1, 3));
    let su = u.sqrt();
    let b = [1.0 - su, v * su, (1.0 - v) * su];
    surfel_at(scene, face, b)
}

/// The surfel at barycentric coordinates `b` of `face`.
fn surfel_at(scene: &Scene, face: &Face, b: [f32; 3]) -> Surfel {
    let [a, bb, c] = face.corners;
    let idx = [0, 1, 2].map(|k| scene.indices[3 * face.triangle as usize + k] as usize);
    let uv = idx
        .iter()
        .zip(b)
        .map(|(&i, w)| Vec2::from(scene.vertices[i].uv) * w)
        .sum();
    Surfel {
        position: a * b[0] + bb * b[1] + c * b[2],
        normal: face.normal,
        uv,
        triangle: face.triangle,
        material: scene.vertices[idx[0]].material,
    }
}

/// One Jacobi step: each surfel moves away from neighbours closer than `spacing` that face
/// the same way (never across the two sides of a thin wall), along its tangent plane, by at
/// most half the spacing, and back onto its own triangle.
fn relax(
    scene: &Scene,
    surfels: &[Surfel],
    faces: &HashMap<u32, &Face>,
    spacing: f32,
) -> Vec<Surfel> {
    let cell_of = |p: Vec3| (p / spacing).floor().as_ivec3();
    let mut grid: HashMap<glam::IVec3, Vec<u32>> = HashMap::new();
    for (i, s) in surfels.iter().enumerate() {
        grid.entry(cell_of(s.position)).or_default().push(i as u32);
    }
    surfels
        .par_iter()
        .enumerate()
        .map(|(i, s)| {
            let home = cell_of(s.position);
            let mut push = Vec3::ZERO;
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let Some(others) = grid.get(&(home + glam::IVec3::new(dx, dy, dz))) else {
                            continue;
                        };
                        for &j in others {
                            let o = &surfels[j as usize];
                            let d = s.position.distance(o.position);
                            if j as usize != i
                                && d < spacing
                                && d > 0.0
                                && s.normal.dot(o.normal) > 0.5
                            {
                                push += 0.5 * (spacing - d) * (s.position - o.position) / d;
                            }
                        }
                    }
                }
            }
            let push = (push - push.dot(s.normal) * s.normal).clamp_length_max(0.5 * spacing);
            let Some(face) = faces.get(&s.triangle) else {
                return *s;
            };
            surfel_at(
                scene,
                face,
                closest_barycentric(s.position + push, face.corners),
            )
        })
        .collect()
}

/// Barycentric coordinates of the point of triangle `t` closest to `p` (Ericson, "Real-Time
/// Collision Detection", 5.1.5).
fn closest_barycentric(p: Vec3, t: [Vec3; 3]) -> [f32; 3] {
    let [a, b, c] = t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    [1.0 - v - w, v, w]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::surfels::test_scenes::quads;
    use crate::scene::procedural;

    fn square(x0: f32, z0: f32, side: f32, y: f32) -> [Vec3; 4] {
        [
            Vec3::new(x0, y, z0 + side),
            Vec3::new(x0 + side, y, z0 + side),
            Vec3::new(x0 + side, y, z0),
            Vec3::new(x0, y, z0),
        ]
    }

    fn none() -> impl FnMut(Progress) {
        |_| {}
    }

    #[test]
    fn surfels_cover_exactly_the_scene_area() {
        let scene = procedural::cornell_box();
        let area = crate::gi::common::triangles::surface_area(&scene);
        let s = sample(&scene, 5000, RELAX_STEPS, &mut none(), &|| false).expect("surfels");
        assert_eq!(s.surfels.len(), 5000);
        assert!(
            ((s.total_area - area) / area).abs() < 1e-12,
            "{} vs {area}",
            s.total_area
        );
        let summed: f64 = s.surfels.iter().map(|_| s.area).sum();
        assert!(((summed - area) / area).abs() < 1e-12, "{summed} vs {area}");
    }

    #[test]
    fn triangles_get_surfels_in_proportion_to_their_area() {
        // Two quads of areas 1 and 3, not coplanar.
        let scene = quads(&[
            square(0.0, 0.0, 1.0, 0.0),
            [
                Vec3::new(3.0, 0.0, 0.0),
                Vec3::new(3.0, 0.0, 3f32.sqrt()),
                Vec3::new(3.0, 3f32.sqrt(), 3f32.sqrt()),
                Vec3::new(3.0, 3f32.sqrt(), 0.0),
            ],
        ]);
        let s = sample(&scene, 1000, 0, &mut none(), &|| false).expect("surfels");
        let on_first = s.surfels.iter().filter(|s| s.triangle < 2).count();
        assert_eq!(on_first, 250);
        assert_eq!(s.surfels.len() - on_first, 750);
    }

    #[test]
    fn small_triangles_are_accumulated_until_they_make_a_surfel() {
        // 100 × 10 squares of side 0.01 in a row: 2,000 triangles of a twentieth of a surfel.
        let squares: Vec<[Vec3; 4]> = (0..1000)
            .map(|k| square((k % 100) as f32 * 0.01, (k / 100) as f32 * 0.01, 0.01, 0.0))
            .collect();
        let scene = quads(&squares);
        let s = sample(&scene, 100, 0, &mut none(), &|| false).expect("surfels");
        let mut triangles: Vec<u32> = s.surfels.iter().map(|s| s.triangle).collect();
        triangles.sort_unstable();
        triangles.dedup();
        assert_eq!(triangles.len(), 100, "no triangle holds two surfels");
        // In Morton order every run of 20 triangles holds exactly one surfel.
        let order: Vec<u32> = faces_in_morton_order(&scene)
            .iter()
            .map(|f| f.triangle)
            .collect();
        for run in order.chunks(20) {
            let held = run.iter().filter(|t| triangles.contains(t)).count();
            assert_eq!(held, 1, "run {run:?}");
        }
        // The triangles one surfel stands for lie closer together in Morton order than in
        // the scene's own order (rows of squares).
        let centroid = |t: u32| {
            let q = t as usize / 2;
            Vec3::new((q % 100) as f32 * 0.01, 0.0, (q / 100) as f32 * 0.01)
        };
        let mean_diameter = |order: &[u32]| {
            let runs = order.chunks(20);
            let count = runs.len() as f32;
            runs.map(|run| {
                run.iter()
                    .flat_map(|&a| run.iter().map(move |&b| centroid(a).distance(centroid(b))))
                    .fold(0.0, f32::max)
            })
            .sum::<f32>()
                / count
        };
        let by_index: Vec<u32> = (0..2000).collect();
        let (morton, rows) = (mean_diameter(&order), mean_diameter(&by_index));
        eprintln!("mean diameter of a surfel's triangles: Morton {morton}, index order {rows}");
        assert!(morton < 0.8 * rows, "Morton {morton} vs rows {rows}");
    }

    #[test]
    fn relaxation_evens_out_spacing_and_keeps_surfels_on_their_triangles() {
        let scene = quads(&[square(0.0, 0.0, 1.0, 0.0), square(0.0, 0.0, 1.0, 0.5)]);
        let nearest = |s: &Surfels| -> Vec<f32> {
            s.surfels
                .iter()
                .map(|a| {
                    s.surfels
                        .iter()
                        .filter(|b| b.normal.dot(a.normal) > 0.5 && b.position != a.position)
                        .map(|b| a.position.distance(b.position))
                        .fold(f32::INFINITY, f32::min)
                })
                .collect()
        };
        let spread = |d: &[f32]| {
            let mean = d.iter().sum::<f32>() / d.len() as f32;
            let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / d.len() as f32;
            (
                d.iter().copied().fold(f32::INFINITY, f32::min),
                var.sqrt() / mean,
            )
        };
        let raw = sample(&scene, 2048, 0, &mut none(), &|| false).expect("surfels");
        let relaxed = sample(&scene, 2048, RELAX_STEPS, &mut none(), &|| false).expect("surfels");
        let (raw_min, raw_cv) = spread(&nearest(&raw));
        let (min, cv) = spread(&nearest(&relaxed));
        eprintln!("nearest-neighbour distance: min {raw_min} → {min}, variation {raw_cv} → {cv}");
        assert!(min > raw_min, "closest pair {raw_min} → {min}");
        assert!(cv < 0.75 * raw_cv, "variation {raw_cv} → {cv}");
        for (s, r) in relaxed.surfels.iter().zip(&raw.surfels) {
            assert_eq!(s.triangle, r.triangle, "surfels stay on their triangle");
            let corners = triangle_normal(&scene, s.triangle as usize)
                .expect("face")
                .1;
            let b = closest_barycentric(s.position, corners);
            let on = corners[0] * b[0] + corners[1] * b[1] + corners[2] * b[2];
            assert!(on.distance(s.position) < 1e-5, "{s:?} is off its triangle");
            // Both squares' uv run 0..1 over x and z.
            assert!((s.uv.x - s.position.x).abs() < 1e-4, "{s:?}");
        }
    }

    #[test]
    fn sampling_is_deterministic_and_reports_progress_and_cancellation() {
        let scene = procedural::cornell_box();
        let mut steps = Vec::new();
        let a = sample(&scene, 9000, 2, &mut |p| steps.push(p), &|| false).expect("surfels");
        let b = sample(&scene, 9000, 2, &mut none(), &|| false).expect("surfels");
        assert_eq!(a.surfels, b.surfels);
        assert_eq!(
            steps.iter().filter(|p| p.step == "surfels").count(),
            3,
            "one report per chunk of {CHUNK}"
        );
        assert_eq!(
            steps.last().map(|p| (p.step, p.done, p.total)),
            Some(("relaxing", 2, 2))
        );
        assert_eq!(
            sample(&scene, 9000, 2, &mut none(), &|| true).err(),
            Some(SamplingError::Cancelled)
        );
        assert_eq!(
            sample(&scene, 0, 2, &mut none(), &|| false).err(),
            Some(SamplingError::NoSurfels)
        );
    }

    #[test]
    fn closest_points_on_a_triangle_are_found_in_every_region() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let cases = [
            (Vec3::new(0.2, 0.2, 1.0), [0.6, 0.2, 0.2]),
            (Vec3::new(-1.0, -1.0, 0.0), [1.0, 0.0, 0.0]),
            (Vec3::new(2.0, -0.5, 0.0), [0.0, 1.0, 0.0]),
            (Vec3::new(0.5, -1.0, 0.0), [0.5, 0.5, 0.0]),
            (Vec3::new(1.0, 1.0, 0.0), [0.0, 0.5, 0.5]),
            (Vec3::new(-1.0, 0.5, 0.0), [0.5, 0.0, 0.5]),
        ];
        for (p, expected) in cases {
            let b = closest_barycentric(p, t);
            for k in 0..3 {
                assert!(
                    (b[k] - expected[k]).abs() < 1e-6,
                    "{p}: {b:?} vs {expected:?}"
                );
            }
        }
    }
}
