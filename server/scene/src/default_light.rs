//! Defaults for scenes that bring no light or camera of their own.

use super::{Aabb, Scene};
use glam::Vec3;
use lightcast_protocol::{Camera, Light, LightKind};

/// Vertical field of view used when the scene has no camera.
pub const DEFAULT_FOV_Y_DEGREES: f32 = 45.0;

/// Illuminance of the default sun and at the centre of a default emitter-derived spot (lux).
/// Exposure is automatic by default, so only ratios between lights matter.
const DEFAULT_ILLUMINANCE: f32 = 10.0;

/// The light a scene is rendered with when the user names none: the file's first
/// KHR_lights_punctual light; else a spot light standing in for the scene's emissive surfaces
/// (a glTF lamp is usually modelled as emissive geometry); else a sun from above and behind
/// the default camera's shoulder.
pub fn default_light(scene: &Scene) -> Light {
    if let Some(light) = scene.lights.first() {
        return light.clone();
    }
    if let Some(light) = emitter_spot(scene) {
        return light;
    }
    Light {
        kind: LightKind::Directional,
        position: scene.bounds.center().into(),
        direction: Vec3::new(-0.35, -0.85, -0.4).normalize().into(),
        color: [1.0, 0.96, 0.9],
        intensity: DEFAULT_ILLUMINANCE,
        inner_cone: 0.0,
        outer_cone: 0.0,
    }
}

/// The lights a scene is rendered with when the user names none: every KHR_lights_punctual
/// light of its file, the first `max` of them; else the one [`default_light`].
pub fn default_lights(scene: &Scene, max: usize) -> Vec<Light> {
    if scene.lights.is_empty() {
        vec![default_light(scene)]
    } else {
        scene.lights.iter().take(max.max(1)).cloned().collect()
    }
}

/// The scene's default light when it stands in for the scene's emissive surfaces (the scene
/// says its light does, or it has no punctual light of its own and some emissive
/// triangles): a render with that light and its emitters both would count their light twice.
pub fn emitter_stand_in(scene: &Scene) -> Option<Light> {
    if scene.lights_stand_in_for_emitters {
        scene.lights.first().cloned()
    } else if scene.lights.is_empty() {
        emitter_spot(scene)
    } else {
        None
    }
}

/// Whether emissive surfaces light a render (`render.gi.emitters`): as `asked`, else on
/// unless the scene's `stand_in` for them ([`emitter_stand_in`]) is among the render's
/// lights (they would be counted twice).
pub fn emitters_for(asked: Option<bool>, stand_in: Option<&Light>, lights: &[Light]) -> bool {
    asked.unwrap_or_else(|| stand_in.is_none_or(|s| !lights.contains(s)))
}

/// A wide spot light at the area-weighted centroid of the emissive triangles, aimed at the
/// scene centre (straight down when the emitter sits at the centre).
fn emitter_spot(scene: &Scene) -> Option<Light> {
    let mut area_sum = 0.0f32;
    let mut centroid = Vec3::ZERO;
    let mut radiance = Vec3::ZERO;
    for range in &scene.material_ranges {
        let material = &scene.materials[range.material as usize];
        if !material.is_emissive() {
            continue;
        }
        let start = range.first_index as usize;
        let end = start + range.index_count as usize;
        for tri in scene.indices[start..end].chunks_exact(3) {
            let p =
                [tri[0], tri[1], tri[2]].map(|i| Vec3::from(scene.vertices[i as usize].position));
            let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
            area_sum += area;
            centroid += area * (p[0] + p[1] + p[2]) / 3.0;
            radiance += area * Vec3::from(material.emissive);
        }
    }
    if area_sum <= 0.0 {
        return None;
    }
    let position = centroid / area_sum;
    let to_center = scene.bounds.center() - position;
    let direction = if to_center.length() > 1e-3 * scene.bounds.radius().max(1e-6) {
        to_center.normalize()
    } else {
        Vec3::NEG_Y
    };
    let distance = to_center.length().max(0.1 * scene.bounds.radius());
    let color = (radiance / radiance.max_element().max(1e-6)).into();
    Some(Light {
        kind: LightKind::Spot,
        position: position.into(),
        direction: direction.into(),
        color,
        intensity: DEFAULT_ILLUMINANCE * distance * distance,
        inner_cone: 60f32.to_radians(),
        outer_cone: 80f32.to_radians(),
    })
}

/// The camera a scene is rendered with when the user names none: the file's first camera,
/// else one in front of the bounds (+Z, slightly raised) that fits the bounding sphere.
pub fn default_camera(scene: &Scene) -> Camera {
    if let Some(camera) = scene.cameras.first() {
        return camera.clone();
    }
    framing_camera(&scene.bounds, DEFAULT_FOV_Y_DEGREES)
}

/// A camera looking at the bounds' centre from +Z (glTF's "front"), raised a little, at the
/// distance where the bounding sphere just fits the vertical field of view.
pub fn framing_camera(bounds: &Aabb, fov_y_degrees: f32) -> Camera {
    let center = bounds.center();
    let radius = bounds.radius().max(1e-3);
    let half_fov = (fov_y_degrees.to_radians() * 0.5).max(1e-3);
    let distance = radius / half_fov.sin();
    let from = Vec3::new(0.0, 0.2, 1.0).normalize();
    Camera {
        position: (center + from * distance).into(),
        target: center.into(),
        fov_y_degrees,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Material, Vertex};

    fn quad_scene(emissive: bool) -> Scene {
        let material = Material {
            emissive: if emissive { [5.0, 5.0, 4.0] } else { [0.0; 3] },
            ..Material::default()
        };
        let floor = Material::default();
        let v = |p: [f32; 3], m: u32| Vertex {
            position: p,
            normal: [0.0, -1.0, 0.0],
            uv: [0.0; 2],
            material: m,
        };
        let vertices = vec![
            v([-0.1, 2.0, -0.1], 0),
            v([0.1, 2.0, -0.1], 0),
            v([0.1, 2.0, 0.1], 0),
            v([-1.0, 0.0, -1.0], 1),
            v([1.0, 0.0, -1.0], 1),
            v([1.0, 0.0, 1.0], 1),
        ];
        Scene::new(
            "q",
            vertices,
            vec![0, 1, 2, 3, 4, 5],
            vec![material, floor],
            vec![],
            vec![],
            vec![],
        )
        .expect("valid")
    }

    #[test]
    fn emissive_geometry_becomes_a_spot_light_aimed_at_the_scene() {
        let light = default_light(&quad_scene(true));
        assert_eq!(light.kind, LightKind::Spot);
        assert!((light.position[1] - 2.0).abs() < 1e-5);
        let dir = Vec3::from(light.direction);
        assert!(dir.y < -0.9, "spot should point down, got {dir}");
        assert_eq!(light.color[0], 1.0);
        assert!(light.color[2] < 1.0);
    }

    #[test]
    fn no_emitter_gives_a_sun_and_framing_camera_sees_the_bounds() {
        let scene = quad_scene(false);
        assert_eq!(default_light(&scene).kind, LightKind::Directional);
        let camera = default_camera(&scene);
        let to_target = Vec3::from(camera.target) - Vec3::from(camera.position);
        let distance = to_target.length();
        let half_fov = (camera.fov_y_degrees.to_radians() * 0.5).sin();
        assert!((distance * half_fov - scene.bounds.radius()).abs() < 1e-4);
        assert!(camera.position[2] > scene.bounds.max.z);
    }

    /// Every light of the file is a default, the first `max` of them; a scene without one gets
    /// its single stand-in or sun.
    #[test]
    fn default_lights_are_the_files_lights_up_to_the_limit() {
        let mut scene = quad_scene(true);
        assert_eq!(default_lights(&scene, 16), vec![default_light(&scene)]);
        let light = |i: usize| Light {
            kind: LightKind::Point,
            position: [i as f32, 1.0, 0.0],
            direction: [0.0, -1.0, 0.0],
            color: [1.0; 3],
            intensity: 1.0,
            inner_cone: 0.0,
            outer_cone: 0.0,
        };
        scene.lights = (0..20).map(light).collect();
        assert_eq!(default_lights(&scene, 16), scene.lights[..16].to_vec());
        assert_eq!(default_lights(&scene, 5), scene.lights[..5].to_vec());
        assert_eq!(default_lights(&scene, 0).len(), 1);
    }

    /// Emitters are on by default unless the scene's stand-in for them is among the lights
    /// (alone or beside others); other lights alone leave them on.
    #[test]
    fn emitters_are_off_only_under_the_stand_in_alone() {
        let scene = quad_scene(true);
        let stand_in = emitter_stand_in(&scene).expect("a stand-in");
        let other = Light {
            intensity: 3.0,
            ..stand_in.clone()
        };
        let s = Some(&stand_in);
        assert!(!emitters_for(None, s, std::slice::from_ref(&stand_in)));
        assert!(emitters_for(None, s, std::slice::from_ref(&other)));
        assert!(!emitters_for(None, s, &[other.clone(), stand_in.clone()]));
        assert!(emitters_for(None, s, &[other.clone(), other]));
        assert!(emitters_for(Some(true), s, std::slice::from_ref(&stand_in)));
        assert!(emitters_for(None, None, std::slice::from_ref(&stand_in)));
    }
}
