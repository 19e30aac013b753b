//! Emissive surfaces as virtual lights (issue 33 part 4): points on the scene's emissive
//! triangles drawn by power, each a diffusely emitting disk with its share of the emitted flux,
//! which the RSM-based methods light with as they light with RSM texels (seed 004's VALs,
//! seed 003's VPLs: both are diffuse emitters of a flux over an area).
//!
//! A sample emits from the side of its triangle that the triangle's vertex normals face (glTF's
//! front): a lamp modelled as a closed box, as exported lamps usually are, sends its light out
//! of the box, where its walls' inner sides, two-sided, would send as much again through the
//! walls (the VALs' light is not occluded by emitters, which cast no shadows in any method).
//! The path-traced reference meets an emitter's back only where it is open (a bare quad), so
//! a bare two-sided emitter's back is light these samples leave out.
//!
//! A triangle of area A and radiance L sends πLA from its front. Sample k picks triangle t
//! with probability p_t = P_t / ΣP (P_t its luminance power) and a point uniform in it; it
//! carries flux π L_t A_t / (N p_t) over the disk area A_t / (N p_t), so the expected flux of
//! each triangle is exactly its πLA.

use crate::environment::luminance;
use crate::halton::halton;
use crate::{material::Material, Scene};
use glam::Vec3;
use std::f32::consts::PI;

/// One emitter sample: a diffuse emitter of `flux` from `position` on the side `normal` faces,
/// standing for `area` of surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EmitterSample {
    pub position: Vec3,
    pub normal: Vec3,
    pub flux: Vec3,
    pub area: f32,
}

/// Whether the scene has a triangle of non-zero area whose material emits.
pub fn has_emitters(scene: &Scene) -> bool {
    !emissive_triangles(scene).is_empty()
}

/// (corners, unit normal on the side its vertex normals face, area, radiance, luminance power)
/// of each emissive triangle of non-zero area.
fn emissive_triangles(scene: &Scene) -> Vec<([Vec3; 3], Vec3, f32, Vec3, f64)> {
    scene
        .material_ranges
        .iter()
        .filter(|r| scene.materials[r.material as usize].is_emissive())
        .flat_map(|r| {
            let first = r.first_index as usize;
            scene.indices[first..first + r.index_count as usize].chunks_exact(3)
        })
        .filter_map(|t| {
            let corner = |i: u32| Vec3::from(scene.vertices[i as usize].position);
            let p = [corner(t[0]), corner(t[1]), corner(t[2])];
            let cross = (p[1] - p[0]).cross(p[2] - p[0]);
            let area = 0.5 * cross.length();
            let vertex = |i: u32| &scene.vertices[i as usize];
            let material: &Material = &scene.materials[vertex(t[0]).material as usize];
            let radiance = Vec3::from(material.emissive);
            let power = f64::from(luminance(radiance.to_array())) * f64::from(area);
            let shading: Vec3 = t.iter().map(|&i| Vec3::from(vertex(i).normal)).sum();
            let geometric = cross / (2.0 * area);
            let front = if shading.dot(geometric) < 0.0 {
                -geometric
            } else {
                geometric
            };
            (area > 0.0 && power > 0.0 && power.is_finite())
                .then_some((p, front, area, radiance, power))
        })
        .collect()
}

/// `count` samples of the scene's emitters (see the module doc); empty without emitters.
pub fn sample(scene: &Scene, count: usize) -> Vec<EmitterSample> {
    let triangles = emissive_triangles(scene);
    let total: f64 = triangles.iter().map(|t| t.4).sum();
    if triangles.is_empty() || count == 0 || total <= 0.0 {
        return Vec::new();
    }
    let mut cumulative = Vec::with_capacity(triangles.len());
    let mut running = 0.0f64;
    for t in &triangles {
        running += t.4;
        cumulative.push(running / total);
    }
    let n = count as f64;
    (0..count as u32)
        .map(|k| {
            // The first coordinate, (k + ½)/N, picks the triangle: stratified by power.
            let u = (f64::from(k) + 0.5) / n;
            let index = cumulative
                .partition_point(|&c| c < u)
                .min(triangles.len() - 1);
            let (p, normal, area, radiance, power) = triangles[index];
            let probability = power / total;
            // Uniform in the triangle (square-root warp), by Halton points: the same scene gives
            // the same samples every frame.
            let (a, b) = (halton(k + 1, 2), halton(k + 1, 3));
            let s = a.sqrt();
            let position = p[0] * (1.0 - s) + p[1] * (s * (1.0 - b)) + p[2] * (s * b);
            let share = (f64::from(area) / (n * probability)) as f32;
            EmitterSample {
                position,
                normal,
                flux: radiance * PI * share,
                area: share,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Material, Vertex};

    /// Two emissive quads of different radiance and size, and a plain one.
    fn scene() -> Scene {
        let mut vertices = Vec::new();
        let mut indices = Vec::new();
        let mut quad = |origin: Vec3, size: f32, material: u32| {
            let base = vertices.len() as u32;
            for (x, z) in [(0.0, 0.0), (size, 0.0), (size, size), (0.0, size)] {
                vertices.push(Vertex {
                    position: (origin + Vec3::new(x, 0.0, z)).to_array(),
                    normal: [0.0, 1.0, 0.0],
                    uv: [0.0; 2],
                    material,
                });
            }
            indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        };
        quad(Vec3::ZERO, 1.0, 0);
        quad(Vec3::new(2.0, 1.0, 0.0), 0.5, 1);
        quad(Vec3::new(0.0, -1.0, 0.0), 3.0, 2);
        let materials = vec![
            Material {
                emissive: [2.0, 1.0, 0.5],
                ..Material::default()
            },
            Material {
                emissive: [8.0, 8.0, 8.0],
                ..Material::default()
            },
            Material::default(),
        ];
        Scene::new(
            "emitters",
            vertices,
            indices,
            materials,
            vec![],
            vec![],
            vec![],
        )
        .expect("scene")
    }

    /// Each emissive quad gets its πLA of flux in the samples (up to the stratification of
    /// N), all from its front, and the points lie on the emitters.
    #[test]
    fn samples_carry_each_emitters_flux_from_its_front() {
        let scene = scene();
        assert!(has_emitters(&scene));
        let samples = sample(&scene, 4096);
        assert_eq!(samples.len(), 4096);
        let emitted = |in_quad: &dyn Fn(Vec3) -> bool, up: bool| -> Vec3 {
            samples
                .iter()
                .filter(|s| in_quad(s.position) && (s.normal.y > 0.0) == up)
                .map(|s| s.flux)
                .sum()
        };
        let first = |p: Vec3| p.y.abs() < 1e-6 && p.x <= 1.0 + 1e-6 && p.z <= 1.0 + 1e-6;
        let second = |p: Vec3| (p.y - 1.0).abs() < 1e-6 && p.x >= 2.0 - 1e-6;
        let a = emitted(&first, true);
        let want_a = Vec3::new(2.0, 1.0, 0.5) * PI;
        assert!(
            (a - want_a).abs().max_element() < 0.02 * want_a.x,
            "{a} vs {want_a}"
        );
        let b = emitted(&second, true);
        let want_b = Vec3::splat(8.0 * 0.25 * PI);
        assert!(
            (b - want_b).abs().max_element() < 0.02 * want_b.x,
            "{b} vs {want_b}"
        );
        assert_eq!(emitted(&first, false) + emitted(&second, false), Vec3::ZERO);
        assert!(samples
            .iter()
            .all(|s| first(s.position) || second(s.position)));
        assert!(samples.iter().all(|s| (s.normal.y - 1.0).abs() < 1e-6));
        // The areas add up to both quads.
        let area: f32 = samples.iter().map(|s| s.area).sum();
        assert!((area - 1.25).abs() < 0.02, "{area}");
    }

    #[test]
    fn a_scene_without_emitters_has_no_samples() {
        let mut scene = scene();
        for m in &mut scene.materials {
            m.emissive = [0.0; 3];
        }
        assert!(!has_emitters(&scene));
        assert!(sample(&scene, 64).is_empty());
    }
}
