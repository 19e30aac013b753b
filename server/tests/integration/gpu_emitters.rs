//! Emissive surfaces as lights in every method (issue 33 part 4) on lavapipe: an open floor
//! under a downward-facing emissive panel, lit by nothing else (its one punctual light has
//! intensity 0). The reference's indirect light there is the panel's light on the floor;
//! every real-time method must find it from `emitters` alone (the RSM methods through the
//! emitter face of `passes::rsm::EmitterFace`), within 15 %, and none without. Measured
//! (mean over the frame): `lightskin`/`brsm` −3.4 %, `clustered` +0.8 %, `rsm_gather` +0.4 %,
//! `surfels` +12.5 %. On the same floor as two triangles `lightskin`/`brsm` were 63 % dark:
//! their caches are kept per vertex, and an 8 m triangle's corners are far from the light.

use super::support::{self, directional, floor_corners, plain_material, quad};
use glam::Vec3;
use lightcast_protocol::Camera;
use lightcast_server::gi::{self, GiMethod, GiParams};
use lightcast_server::renderer::{RenderSettings, Renderer};
use lightcast_server::scene::{Material, Scene};

/// An 8 m floor (albedo 0.6, in 0.5 m tiles: LightSkin keeps its caches per vertex) and a
/// 1 m panel 1.5 m above it facing down, emitting (4, 3.5, 3) per steradian; the camera looks
/// down at the floor below the panel from beside it.
fn panel_over_a_floor() -> (Scene, Camera) {
    let (mut vertices, mut indices) = (Vec::new(), Vec::new());
    for i in 0..16 {
        for j in 0..16 {
            let centre = |k: i32| -3.75 + 0.5 * k as f32;
            quad(
                &mut vertices,
                &mut indices,
                floor_corners(centre(i), centre(j), 0.0, 0.25),
                0,
            );
        }
    }
    let mut panel = floor_corners(0.0, 0.0, 1.5, 0.5);
    panel.reverse();
    quad(&mut vertices, &mut indices, panel, 1);
    let materials = vec![
        plain_material([0.6; 3], 0.0, 1.0),
        Material {
            emissive: [4.0, 3.5, 3.0],
            ..plain_material([0.5; 3], 0.0, 1.0)
        },
    ];
    let camera = Camera {
        position: [0.0, 1.2, 1.8],
        target: [0.0, 0.0, 0.0],
        fov_y_degrees: 50.0,
    };
    (support::scene(vertices, indices, materials), camera)
}

/// Mean indirect light of one frame of `gi` with `emitters`.
fn mean_indirect(renderer: &mut Renderer, camera: &Camera, mut gi: GiParams, on: bool) -> Vec3 {
    gi.set("emitters", on);
    let settings = RenderSettings {
        gi,
        ..support::settings(
            32,
            24,
            camera.clone(),
            directional(Vec3::new(0.2, -1.0, 0.1), 0.0),
        )
    };
    support::precompute(renderer, &settings.gi);
    let frame = renderer.render(&settings).expect("render");
    let indirect = frame.indirect.expect("captured");
    indirect
        .iter()
        .fold(Vec3::ZERO, |s, p| s + Vec3::new(p[0], p[1], p[2]))
        / indirect.len() as f32
}

#[test]
fn every_method_lights_from_emissive_surfaces_alone() {
    let (scene, camera) = panel_over_a_floor();
    let methods: Vec<GiMethod> = gi::methods()
        .filter(|&m| gi::lights_from_emitters(m) && m != gi::reference::REFERENCE)
        .collect();
    let mut renderer = Renderer::new(support::gpu(), scene.clone());
    support::set_bvh(&mut renderer);
    let mut reference = GiParams::new(gi::reference::REFERENCE);
    reference.set("spp", 256);
    let truth = mean_indirect(&mut renderer, &camera, reference, true);
    assert!(
        truth.min_element() > 0.0,
        "the panel lights the floor: {truth}"
    );
    let mut failed = Vec::new();
    for method in methods {
        let small = support::small(method, &scene);
        let lit = mean_indirect(&mut renderer, &camera, small.clone(), true);
        let dark = mean_indirect(&mut renderer, &camera, small, false);
        let rel = (lit - truth) / truth;
        eprintln!("{method}: {lit} vs reference {truth} ({rel}); emitters off: {dark}");
        assert!(
            dark.max_element() < 1e-3 * truth.max_element(),
            "{method} without emitters: {dark}"
        );
        if rel.abs().max_element() >= 0.15 {
            failed.push(format!("{method}: {lit} vs {truth}"));
        }
    }
    // An RSM of 512² holds more texels than an emitter face's 256² samples: they fill its
    // first rows, and the methods light from them alike.
    for method in [gi::clustered::CLUSTERED, gi::rsm_gather::RSM_GATHER] {
        let mut large = support::small(method, &scene);
        large.set("rsm_size", 512);
        let lit = mean_indirect(&mut renderer, &camera, large, true);
        let rel = (lit - truth) / truth;
        eprintln!("{method} at rsm_size 512: {lit} ({rel})");
        if rel.abs().max_element() >= 0.15 {
            failed.push(format!("{method} at rsm_size 512: {lit} vs {truth}"));
        }
    }
    assert!(failed.is_empty(), "{failed:?}");
}
