//! The few numbers of a scene that precomputation keys, size estimates and test settings read.

use crate::scene::Scene;

/// What the keys and size estimates of every precomputation read of a scene, summed once
/// when the scene is added (requests are checked against them per message).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneFacts {
    /// Total area of the scene's triangles, in square scene units.
    pub surface_area: f64,
    /// Radius of the scene's bounding sphere.
    pub radius: f32,
    pub triangles: u64,
    /// Size of the scene's bounding box.
    pub extent: glam::Vec3,
    /// Whether it has emissive triangles (an RSM face more where emitters light a frame).
    pub emitters: bool,
}

impl SceneFacts {
    pub fn of(scene: &Scene) -> Self {
        Self {
            surface_area: super::triangles::surface_area(scene),
            radius: scene.bounds.radius(),
            triangles: scene.triangle_count() as u64,
            extent: scene.bounds.max - scene.bounds.min,
            emitters: crate::scene::emitters::has_emitters(scene),
        }
    }
}
