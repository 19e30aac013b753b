//! Scale invariance of every GI method served (issue 10): the Cornell box scaled by s (vertex
//! positions, camera, light position; spot/point intensity in candela times s², so the
//! irradiance I/d² on every surface is unchanged) must render the same picture as the unscaled
//! box. Radiance is invariant under a uniform change of length unit, so any difference comes
//! from an absolute length hidden in a constant: ε_p of eq. 6 multiplied by a VAL area, a
//! floor of squared distances in metres, a fixed shadow bias. Every registered method runs at
//! its small setting, held to the tolerance its table states (`Testing`).

use crate::support::*;
use glam::Vec3;
use lightcast_protocol::{Camera, Light, LightKind};
use lightcast_server::gi::{self, GiParams};
use lightcast_server::renderer::{Frame, Renderer};
use lightcast_server::scene::{procedural, Scene};

const W: u32 = 96;
const H: u32 = 72;
/// A centimetre-unit file read as metres would be 100× too large, a 2 km street in
/// kilometres 1000× too small; these bracket both, in the direction each constant breaks.
const SCALES: [f32; 2] = [0.01, 1000.0];

fn scaled_light(light: &Light, s: f32) -> Light {
    let intensity = match light.kind {
        LightKind::Directional => light.intensity,
        // Candela: E = I / d², and d grows by s.
        LightKind::Spot | LightKind::Point => light.intensity * s * s,
    };
    Light {
        position: light.position.map(|c| c * s),
        intensity,
        ..light.clone()
    }
}

fn scaled_camera(camera: &Camera, s: f32) -> Camera {
    Camera {
        position: camera.position.map(|c| c * s),
        target: camera.target.map(|c| c * s),
        ..camera.clone()
    }
}

/// The scene with every length multiplied by `s`; materials (albedo, emitted radiance) keep.
fn scaled(scene: &Scene, s: f32) -> Scene {
    let mut vertices = scene.vertices.clone();
    for v in &mut vertices {
        v.position = v.position.map(|c| c * s);
    }
    let mut scaled = Scene::new(
        scene.name.clone(),
        vertices,
        scene.indices.clone(),
        scene.materials.clone(),
        scene.textures.clone(),
        scene.lights.iter().map(|l| scaled_light(l, s)).collect(),
        scene.cameras.iter().map(|c| scaled_camera(c, s)).collect(),
    )
    .expect("a scaled valid scene is valid");
    // Its nodes too (their translations are lengths): the same bottom levels of the BVH.
    let (up, down) = (
        glam::Mat4::from_scale(glam::Vec3::splat(s)),
        glam::Mat4::from_scale(glam::Vec3::splat(1.0 / s)),
    );
    let nodes = scene
        .nodes
        .iter()
        .map(|n| lightcast_server::scene::nodes::Node {
            local: n.local.map(|l| lightcast_server::scene::nodes::Transform {
                translation: l.translation * s,
                ..l
            }),
            rest_world: up * n.rest_world * down,
            ..n.clone()
        })
        .collect();
    scaled
        .set_nodes(nodes, scene.animations.clone())
        .expect("the same hierarchy");
    scaled
}

/// One frame per registered method at its small setting for `scene` lit by `light` and seen by
/// `camera`, after the method's precomputation.
fn render_methods(scene: &Scene, camera: &Camera, light: &Light) -> Vec<(GiParams, Frame)> {
    let mut renderer = Renderer::new(gpu(), scene.clone());
    gi::methods()
        .map(|method| {
            let mut s = settings(W, H, camera.clone(), light.clone());
            s.gi = small(method, scene);
            precompute(&mut renderer, &s.gi);
            let frame = renderer.render(&s).expect("render");
            (s.gi, frame)
        })
        .collect()
}

/// A buffer's name, as rendered and as wanted.
type Compared<'a> = (&'static str, &'a [[f32; 4]], &'a [[f32; 4]]);

/// The buffers a frame of `method` is compared by: the HDR image, and the indirect light of a
/// method that has any.
fn buffers<'a>(method: gi::GiMethod, frame: &'a Frame, want: &'a Frame) -> Vec<Compared<'a>> {
    let captured = |b: &'a Option<Vec<[f32; 4]>>| b.as_deref().expect("captured");
    let mut out = vec![("hdr", captured(&frame.hdr), captured(&want.hdr))];
    if method != gi::none::NONE {
        out.push((
            "indirect",
            captured(&frame.indirect),
            captured(&want.indirect),
        ));
    }
    out
}

#[test]
fn cornell_box_scaled_by_a_hundredth_and_a_thousand_renders_the_same_for_every_method() {
    let base = procedural::cornell_box();
    let (camera, light) = (base.cameras[0].clone(), base.lights[0].clone());
    assert_eq!(light.kind, LightKind::Spot);
    let unscaled = render_methods(&base, &camera, &light);
    // The unscaled renders must have something to compare: GI lights what the spot does not.
    for (gi, frame) in unscaled
        .iter()
        .filter(|(gi, _)| gi.method != gi::none::NONE)
    {
        let indirect = frame.indirect.as_ref().expect("captured");
        let lit = indirect
            .iter()
            .filter(|c| Vec3::new(c[0], c[1], c[2]).max_element() > 0.0)
            .count();
        assert!(lit > (W * H / 2) as usize, "{} lit {lit} pixels", gi.method);
    }

    let mut failures = Vec::new();
    for s in SCALES {
        let scene = scaled(&base, s);
        let frames = render_methods(&scene, &scaled_camera(&camera, s), &scaled_light(&light, s));
        for ((gi, frame), (_, want)) in frames.iter().zip(&unscaled) {
            let tolerance = gi::table(gi.method).testing.scale_tolerance;
            for (name, got, want) in buffers(gi.method, frame, want) {
                let error = relative_mae(got, want);
                eprintln!("×{s} {} {name}: relative MAE {error:.5}", gi.method);
                // NaN fails too.
                if error.is_nan() || error > tolerance {
                    failures.push(format!(
                        "×{s} {} {name}: {error:.5} > {tolerance}",
                        gi.method
                    ));
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "relative MAE above tolerance: {failures:?}"
    );
}

/// Scaling by a power of two is exact in floating point, so a method free of length
/// constants renders the very same pixels: every method whose table says so
/// (`exact_at_powers_of_two`; the others derive something by rounding from lengths and are
/// held to the test above instead).
#[test]
fn power_of_two_scales_give_identical_pixels_where_the_method_says_so() {
    let base = procedural::cornell_box();
    let (camera, light) = (base.cameras[0].clone(), base.lights[0].clone());
    let unscaled = render_methods(&base, &camera, &light);
    let exact = |gi: &GiParams| gi::table(gi.method).testing.exact_at_powers_of_two;
    assert!(unscaled.iter().any(|(gi, _)| exact(gi)));
    for s in [1.0 / 128.0, 1024.0] {
        let scene = scaled(&base, s);
        let frames = render_methods(&scene, &scaled_camera(&camera, s), &scaled_light(&light, s));
        for ((gi, frame), (_, want)) in frames
            .iter()
            .zip(&unscaled)
            .filter(|((gi, _), _)| exact(gi))
        {
            for (name, got, want) in buffers(gi.method, frame, want) {
                assert!(
                    got == want,
                    "×{s} {} {name}: relative MAE {}",
                    gi.method,
                    relative_mae(got, want)
                );
            }
        }
    }
}
