//! The sampling pattern of reflective shadow maps (Dachsbacher & Stamminger 2005, §3.2) and the
//! CPU reference of the gather (`shaders/rsm_gather/gather.wgsl`).
//!
//! Every pixel x projects to the RSM texel (s, t) and gathers the pixel lights at
//! (s + r_max·ξ1·sin 2πξ2, t + r_max·ξ1·cos 2πξ2) for a fixed set of (ξ1, ξ2), the same for
//! every pixel. With ξ1 uniform the samples' density over the disk falls as 1/r: the texels
//! near (s, t), which light x most, are drawn most often. The paper compensates by weighting
//! each sample with ξ1² and normalising; that weight is not the inverse of this density, so
//! its sum is biased towards the far texels. The density of r = r_max·ξ1, θ = 2πξ2 over the
//! disk is p = 1/(2π·r_max·r) per texel, so here sample i weighs 1/(N·p) = 2π·r_max²·ξ1/N
//! texels: the sum estimates, without bias, the light of every texel within r_max of (s, t)
//! (LightSkin's sum over all texels, restricted to the disk). Texels beyond r_max, and every
//! occluder between a texel and x, are what the method leaves out.
//!
//! (ξ1, ξ2) are the Halton points of bases 2 and 3 (from index 1): stratified, so a few hundred
//! samples cover the disk evenly. A pixel whose projection lies outside the light's frustum
//! (a surface beside a spot light's cone, or behind it) gathers around the nearest point of
//! the map, clamped to its border: the paper does not say what such pixels do, and they still
//! receive light from the lit texels near that border.

use crate::gi::common::halton::halton;
use crate::gi::common::vpl::{vpl_light, VplLight};
use crate::passes::rsm::{emitter_samples, GlossySender};
use crate::scene::brdf::Brdf;
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec2, Vec3, Vec4Swizzles};
use std::f32::consts::TAU;

/// One sample of the pattern. Mirrors `GatherSample` in `shaders/rsm_gather/gather.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GatherSample {
    /// ξ1·(sin 2πξ2, cos 2πξ2): the offset in units of r_max.
    pub offset: [f32; 2],
    /// 2π·ξ1/N: the texels it stands for, in units of r_max².
    pub weight: f32,
    pub pad0: f32,
}

/// The pattern of `n` samples.
pub fn pattern(n: u32) -> Vec<GatherSample> {
    (1..=n)
        .map(|i| {
            let (xi1, xi2) = (halton(i, 2), halton(i, 3));
            let (sin, cos) = (TAU * xi2).sin_cos();
            GatherSample {
                offset: [xi1 * sin, xi1 * cos],
                weight: TAU * xi1 / n as f32,
                pad0: 0.0,
            }
        })
        .collect()
}

/// Where a point projects in a face of `size`² texels with `view_proj`: its continuous texel
/// coordinates, and whether it lies inside the face's frustum.
pub fn project(view_proj: &Mat4, size: u32, x: Vec3) -> (Vec2, bool) {
    let clip = *view_proj * x.extend(1.0);
    let size = size as f32;
    if clip.w <= 0.0 {
        // Behind a perspective face: the nearest point of the map lies on its border in the
        // direction the point projects towards.
        let d = clip.xy().normalize_or_zero() * Vec2::new(1.0, -1.0);
        let uv = (Vec2::splat(0.5) + d * 2.0).clamp(Vec2::ZERO, Vec2::ONE);
        return (uv * size, false);
    }
    let ndc = clip.xy() / clip.w;
    let inside = ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0;
    let uv = Vec2::new(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5).clamp(Vec2::ZERO, Vec2::ONE);
    (uv * size, inside)
}

/// The face (of `faces`, side by side in the atlas) whose frustum holds a point, with its
/// texel coordinates within that face, else the first face at the nearest point of its border:
/// what the `gather-samples` view's probe shows.
pub fn gather_centre(faces: &[Mat4], size: u32, x: Vec3) -> (usize, Vec2) {
    let mut first = None;
    for (f, view_proj) in faces.iter().enumerate() {
        let (st, inside) = project(view_proj, size, x);
        if inside {
            return (f, st);
        }
        first.get_or_insert((f, st));
    }
    first.unwrap_or((0, Vec2::ZERO))
}

/// An RSM atlas as read back: `faces` squares of `size`² side by side, per texel RGBA
/// position (w = 1 where a surface is), normal and flux with disk area.
pub struct RsmAtlas<'a> {
    pub size: u32,
    pub faces: u32,
    pub position: &'a [[f32; 4]],
    pub normal: &'a [[f32; 4]],
    pub flux_area: &'a [[f32; 4]],
    /// [`GlossySender::decode`] reads these.
    pub glossy: &'a [[u32; 4]],
}

/// The row-major atlas texels (`faces` faces of `size`² side by side) that `samples` reach
/// from `centre` in face `face` at `radius` texels, each with its weight in texels; samples off
/// the face are left out.
pub fn sample_texels(
    samples: &[GatherSample],
    size: u32,
    faces: u32,
    face: usize,
    centre: Vec2,
    radius: f32,
) -> Vec<(usize, f32)> {
    let side = size as f32;
    let atlas_width = (size * faces) as usize;
    samples
        .iter()
        .filter_map(|s| {
            let p = centre + radius * Vec2::from(s.offset);
            if p.x < 0.0 || p.y < 0.0 || p.x >= side || p.y >= side {
                return None;
            }
            let texel = p.y as usize * atlas_width + face * size as usize + p.x as usize;
            Some((texel, s.weight * radius * radius))
        })
        .collect()
}

/// The `light` of the atlas face that holds the emitters' samples (`passes::rsm::EmitterFace`):
/// it has no projection, so a pixel gathers it whole ([`emitter_texels`]).
pub const EMITTER_FACE: u32 = u32::MAX;

/// The texels of emitter face `face`, whose first `filled` texels hold samples, that a pixel
/// gathers with `count` samples: every (filled/count)-th, each standing for that many (all of
/// them, each for one, when there are no more than `count`). The emitter samples are
/// stratified by power in their order (`scene::emitters::sample`), so an even subset of them
/// is a stratified subset of the emitters; every pixel reads the same one, so the light they
/// give has no noise between pixels.
pub fn emitter_texels(
    count: u32,
    filled: u32,
    size: u32,
    faces: u32,
    face: usize,
) -> Vec<(usize, f32)> {
    let texels = u64::from(filled);
    let m = u64::from(count).min(texels).max(1);
    let atlas_width = (size * faces) as usize;
    (0..m)
        .map(|i| {
            // As gather.wgsl computes it in u32: ⌊i·texels/m⌋ = i·q + ⌊i·r/m⌋.
            let k = i * (texels / m) + (i * (texels % m)) / m;
            let (x, y) = (
                (k % u64::from(size)) as usize,
                (k / u64::from(size)) as usize,
            );
            (
                y * atlas_width + face * size as usize + x,
                (texels as f64 / m as f64) as f32,
            )
        })
        .collect()
}

/// The faces of each light: runs of `faces` (each face's light and view-projection, in atlas
/// order) with the same light, each with the atlas index of its first face.
pub fn light_runs(faces: &[(u32, Mat4)]) -> impl Iterator<Item = (usize, Vec<Mat4>)> + '_ {
    faces.chunk_by(|a, b| a.0 == b.0).scan(0, |start, run| {
        let first = *start;
        *start += run.len();
        Some((first, run.iter().map(|(_, m)| *m).collect()))
    })
}

/// The gathered light at surface point `x` (unit normal `n`, BRDF `s`) seen from `viewer`:
/// for each face of each light, Σ over the samples of weight × the pixel light's L
/// (`vpl_light`) of the texel each reaches around where `x` projects in that face (its nearest
/// border point where `x` lies outside). A spot or directional light has one face; a point
/// light's six faces see disjoint surfaces, so all six are gathered from: a wall lit from the
/// floor below the light gathers from the floor's face (gathering only the face that holds
/// `x`, the first version left a point light's indirect light 80 % dark in the Cornell box,
/// `bench/results/lavapipe-three-lights-errors.md`). `faces`: each atlas face's light and
/// view-projection; a face of light [`EMITTER_FACE`] is gathered whole ([`emitter_texels`]).
#[allow(clippy::too_many_arguments)]
pub fn gather(
    rsm: &RsmAtlas,
    faces: &[(u32, Mat4)],
    samples: &[GatherSample],
    radius_fraction: f32,
    x: Vec3,
    n: Vec3,
    viewer: Vec3,
    s: &Brdf,
) -> Vec3 {
    let v = (viewer - x).normalize();
    let radius = radius_fraction * rsm.size as f32;
    light_runs(faces)
        .flat_map(|(first, run)| {
            if faces[first].0 == EMITTER_FACE {
                let filled = emitter_samples(rsm.size);
                return emitter_texels(samples.len() as u32, filled, rsm.size, rsm.faces, first);
            }
            run.iter()
                .enumerate()
                .flat_map(|(f, view_proj)| {
                    let (centre, _) = project(view_proj, rsm.size, x);
                    sample_texels(samples, rsm.size, rsm.faces, first + f, centre, radius)
                })
                .collect::<Vec<_>>()
        })
        .filter(|&(i, _)| rsm.position[i][3] != 0.0)
        .map(|(i, weight)| {
            let [fr, fg, fb, area] = rsm.flux_area[i];
            let light = VplLight {
                position: Vec3::from_slice(&rsm.position[i][..3]),
                normal: Vec3::from_slice(&rsm.normal[i][..3]),
                flux: Vec3::new(fr, fg, fb),
                glossy: GlossySender::decode(rsm.glossy[i]),
                area,
                footprint: area * weight,
            };
            vpl_light(&light, x, n, v, s) * weight
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The weights estimate the number of texels in the disk: Σ weight over the samples is
    /// π·r_max² (in units of r_max²: π) up to the Halton points' discrepancy (3/N), and the
    /// offsets lie in the unit disk.
    #[test]
    fn weights_sum_to_the_disk_area() {
        for n in [100, 400, 1600] {
            let p = pattern(n);
            let sum: f32 = p.iter().map(|s| s.weight).sum();
            let error = (sum / std::f32::consts::PI - 1.0).abs();
            assert!(error < 3.0 / n as f32, "{n}: {sum}");
            assert!(p.iter().all(|s| Vec2::from(s.offset).length() < 1.0));
        }
    }

    /// Over a map of equal texels, the weighted count of texels reached is the disk's area in
    /// texels (the estimator is unbiased for a constant), within the pattern's stratification.
    #[test]
    fn a_uniform_map_gathers_the_disk_area() {
        let samples = pattern(400);
        let (size, radius) = (256, 40.0);
        let texels = sample_texels(&samples, size, 1, 0, Vec2::splat(128.0), radius);
        let total: f32 = texels.iter().map(|t| t.1).sum();
        let disk = std::f32::consts::PI * radius * radius;
        assert!((total / disk - 1.0).abs() < 0.01, "{total} vs {disk}");
        // Near a corner only the quarter of the disk on the map is gathered.
        let corner: f32 = sample_texels(&samples, size, 1, 0, Vec2::ZERO, radius)
            .iter()
            .map(|t| t.1)
            .sum();
        assert!(
            (corner / (disk / 4.0) - 1.0).abs() < 0.1,
            "{corner} vs {}",
            disk / 4.0
        );
    }

    /// A point inside the frustum projects to its texel; the second face of an atlas is found
    /// and offset; a point behind a perspective face lands on its border.
    #[test]
    fn points_project_to_their_face() {
        let ortho = Mat4::orthographic_rh(-1.0, 1.0, -1.0, 1.0, 0.0, 10.0)
            * Mat4::look_to_rh(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z, Vec3::Y);
        let (st, inside) = project(&ortho, 100, Vec3::new(0.5, 0.5, 0.0));
        assert!(inside);
        assert!((st - Vec2::new(75.0, 25.0)).length() < 1e-3, "{st}");
        let (st, inside) = project(&ortho, 100, Vec3::new(3.0, 0.0, 0.0));
        assert!(!inside);
        assert_eq!(st.x, 100.0);
        let far_left = Mat4::from_translation(Vec3::new(100.0, 0.0, 0.0));
        let (face, st) = gather_centre(&[ortho * far_left, ortho], 100, Vec3::new(-0.5, 0.0, 0.0));
        assert_eq!(face, 1);
        assert!((st - Vec2::new(25.0, 50.0)).length() < 1e-3, "{st}");
        let spot = Mat4::perspective_rh(1.0, 1.0, 0.1, 10.0)
            * Mat4::look_to_rh(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y);
        let (st, inside) = project(&spot, 64, Vec3::new(1.0, 0.0, 1.0));
        assert!(!inside);
        assert_eq!(st, Vec2::new(64.0, 32.0));
    }
}
