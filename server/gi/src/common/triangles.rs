//! A scene's triangles as the methods' precomputations read them: corners, areas and the
//! geometric normal (surface samples of the precomputations).

use crate::scene::Scene;
use glam::Vec3;

/// The vertex indices of triangle `t`.
pub fn triangle(scene: &Scene, t: usize) -> [u32; 3] {
    [
        scene.indices[3 * t],
        scene.indices[3 * t + 1],
        scene.indices[3 * t + 2],
    ]
}

/// The area of triangle `t`, in double precision (areas of large scenes are summed).
pub fn triangle_area(scene: &Scene, t: usize) -> f64 {
    let [a, b, c] = triangle(scene, t).map(|i| Vec3::from(scene.vertices[i as usize].position));
    let (a, b, c) = (a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
    0.5 * (b - a).cross(c - a).length()
}

/// Total triangle area, summed sequentially so the result does not depend on thread count.
pub fn surface_area(scene: &Scene) -> f64 {
    (0..scene.triangle_count())
        .map(|t| triangle_area(scene, t))
        .sum()
}

/// Geometric normal of a triangle, flipped to agree with its vertex normals when those say
/// otherwise (assets whose winding disagrees with their shading normals). `None` without area.
pub fn triangle_normal(scene: &Scene, t: usize) -> Option<(Vec3, [Vec3; 3])> {
    let idx = triangle(scene, t);
    let corners = idx.map(|i| Vec3::from(scene.vertices[i as usize].position));
    let n = (corners[1] - corners[0])
        .cross(corners[2] - corners[0])
        .try_normalize()?;
    let shading: Vec3 = idx
        .iter()
        .map(|&i| Vec3::from(scene.vertices[i as usize].normal))
        .sum();
    Some((if shading.dot(n) < 0.0 { -n } else { n }, corners))
}
