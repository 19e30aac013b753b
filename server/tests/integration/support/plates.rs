//! Two plates facing each other under a point light, and the light one reflects onto the
//! other by numerical integration: the truth the reference and the RSM-based methods' glossy
//! senders are checked against.

use super::{brdf, floor_corners, plain_material, quad};
use glam::Vec3;
use lightcast_protocol::{Camera, Light, LightKind};
use lightcast_server::gi::params::Senders;
use lightcast_server::scene::Scene;

pub fn point_light(position: Vec3, intensity: f32) -> Light {
    Light {
        kind: LightKind::Point,
        position: position.to_array(),
        direction: [0.0, -1.0, 0.0],
        color: [1.0; 3],
        intensity,
        inner_cone: 0.0,
        outer_cone: 0.0,
    }
}

/// Plate A (floor, y = 0, 2×2, facing up) under plate B (y = 1, 2×2, facing down), a point
/// light between them, the camera looking down at A from under B. With one bounce A's
/// indirect light is the light B reflects onto it.
pub struct Plates {
    pub scene: Scene,
    pub camera: Camera,
    pub light: Light,
}

pub fn plates() -> Plates {
    plates_in(1)
}

/// [`plates`] with each plate made of `cells`² squares: methods that light a mesh's vertices
/// (LightSkin's caches, eq. 8–9) see the middle of a plate, not only its corners.
pub fn plates_in(cells: u32) -> Plates {
    let (mut vertices, mut indices) = (Vec::new(), Vec::new());
    let half = 1.0 / cells as f32;
    for i in 0..cells {
        for j in 0..cells {
            let (cx, cz) = (
                -1.0 + (2 * i + 1) as f32 * half,
                -1.0 + (2 * j + 1) as f32 * half,
            );
            quad(
                &mut vertices,
                &mut indices,
                floor_corners(cx, cz, 0.0, half),
                0,
            );
            let mut top = floor_corners(cx, cz, 1.0, half);
            top.reverse();
            quad(&mut vertices, &mut indices, top, 1);
        }
    }
    let materials = vec![
        plain_material([0.8, 0.7, 0.6], 0.0, 1.0),
        plain_material([0.3, 0.6, 0.9], 0.0, 0.5),
    ];
    Plates {
        scene: super::scene(vertices, indices, materials),
        camera: Camera {
            position: [0.05, 0.9, 0.1],
            target: [0.0, 0.0, 0.0],
            fov_y_degrees: 60.0,
        },
        light: point_light(Vec3::new(0.2, 0.55, -0.1), 1.0),
    }
}

/// One-bounce indirect radiance leaving `x` on plate A towards `eye`: the integral over plate
/// B of f_A · L_B · G, with L_B = f_B · E_B from the point light, by the midpoint rule; f_B is
/// the whole BRDF or, with diffuse `senders`, its diffuse lobe.
pub fn plates_indirect(p: &Plates, x: Vec3, eye: Vec3, cells: u32, senders: Senders) -> Vec3 {
    let (floor, ceiling) = (&p.scene.materials[0], &p.scene.materials[1]);
    let (n_a, n_b) = (Vec3::Y, Vec3::NEG_Y);
    let light = Vec3::from(p.light.position);
    let to_eye = (eye - x).normalize();
    let cell = 2.0 / cells as f32;
    let mut sum = Vec3::ZERO;
    for i in 0..cells {
        for j in 0..cells {
            let y = Vec3::new(
                -1.0 + (i as f32 + 0.5) * cell,
                1.0,
                -1.0 + (j as f32 + 0.5) * cell,
            );
            let d = y - x;
            let r2 = d.length_squared();
            let w = d / r2.sqrt();
            let (cos_x, cos_y) = (n_a.dot(w), n_b.dot(-w));
            let to_light = light - y;
            let d_l2 = to_light.length_squared();
            let to_light = to_light / d_l2.sqrt();
            let e_b = p.light.intensity * n_b.dot(to_light).max(0.0) / d_l2;
            let f_b = match senders {
                Senders::Full => brdf(ceiling, n_b, to_light, -w),
                Senders::Diffuse => ceiling.brdf().eval_diffuse(n_b, to_light, -w),
            };
            let l_b = f_b * e_b;
            sum += brdf(floor, n_a, w, to_eye) * l_b * cos_x.max(0.0) * cos_y.max(0.0) / r2;
        }
    }
    sum * cell * cell
}

/// The plates (of `cells`² squares each) with a glossy ceiling (roughness 0.5, half metal): a
/// fifth or more of the floor's light is the ceiling's glossy reflection.
pub fn glossy_plates(cells: u32) -> Plates {
    let p = plates_in(cells);
    let mut materials = p.scene.materials.clone();
    materials[1].metallic = 0.5;
    Plates {
        scene: super::scene(p.scene.vertices, p.scene.indices, materials),
        ..p
    }
}
