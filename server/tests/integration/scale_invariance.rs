//! Scale invariance of every GI method served (issue 10): the Cornell box scaled by s (vertex
//! positions, camera, light position; spot/point intensity in candela times s², so the
//! irradiance I/d² on every surface is unchanged) must render the same picture as the unscaled
//! box. Radiance is invariant under a uniform change of length unit, so any difference comes
//! from an absolute length hidden in a constant: ε_p of eq. 6 multiplied by a VAL area, a
//! floor of squared distances in metres, a fixed shadow bias.

use crate::support::*;
use glam::Vec3;
use lightcast_protocol::{Camera, Light, LightKind};
use lightcast_server::gi::lightskin::caches::{precompute, CacheParams};
use lightcast_server::gi::lightskin::LightSkin;
use lightcast_server::gi::GiParams;
use lightcast_server::renderer::{Frame, Renderer};
use lightcast_server::scene::{procedural, Scene};

const W: u32 = 96;
const H: u32 = 72;
/// A centimetre-unit file read as metres would be 100× too large, a 2 km street in
/// kilometres 1000× too small; these bracket both, in the direction each constant breaks.
const SCALES: [f32; 2] = [0.01, 1000.0];
/// Relative mean absolute difference allowed between a scaled and the unscaled render, for
/// the HDR image and for the indirect buffer alone. Scaling a position by 0.01 or 1000 rounds
/// it (neither is a power of two), so rasterisation, shadow-map depths and the cache
/// distribution see coordinates perturbed by ~1 ulp. Measured on lavapipe: at most 0.05 % for
/// every method and buffer; before ε_p of eq. 6 and the distance floors were made relative,
/// LightSkin's indirect buffer was off by 2.9 % (×1000: ε_p·A_l outweighed the form factors)
/// and 17 % (×0.01: the 1 cm floors), so 0.5 % separates the two with room for drivers.
const TOLERANCE: f32 = 0.005;
/// The same for the path-traced reference: its 8 samples per pixel follow equal random
/// numbers at every scale, but a coordinate rounded differently can flip a ray's hit, and
/// that path then carries a different 8-sample estimate. Measured on lavapipe: 0.9 % (×0.01)
/// and 0.65 % (×1000) on the indirect buffer; at power-of-two scales, where no rounding
/// differs, it is exactly 0 (see the next test), so no length constant is left in it.
const REFERENCE_TOLERANCE: f32 = 0.02;

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
    Scene::new(
        scene.name.clone(),
        vertices,
        scene.indices.clone(),
        scene.materials.clone(),
        scene.textures.clone(),
        scene.lights.iter().map(|l| scaled_light(l, s)).collect(),
        scene.cameras.iter().map(|c| scaled_camera(c, s)).collect(),
    )
    .expect("a scaled valid scene is valid")
}

/// `none`, `lightskin`, `brsm` (with proxy occlusion) and the path-traced `reference` (two
/// bounces). BRSM draws from uniform importance:
/// eq. 11 clamps the squared VAL–view-sample distance to at least 1 in scene units, as the
/// paper writes it, so its sampling pdf (not the expectation, which the 1/(N·P) weights keep)
/// depends on the unit: with eq. 11's importance the BRSM buffers differed by 1.4 % (×0.01) and
/// 1.6 % (×1000), and by 0.02 % with the clamp removed. Uniform importance still runs the
/// whole BRSM path (cumulative sums, selection, weighted cache lighting) scale for scale.
fn methods() -> [GiParams; 5] {
    let gi = |method| {
        GiParams::new(method)
            .with("rsm_size", 64)
            .with("view_samples", 256)
            .with("val_count", 1024)
            .with("jitter", 0.5)
            .with(
                "uniform_importance",
                method == lightcast_server::gi::lightskin::BRSM,
            )
            .with("occlusion", true)
    };
    [
        GiParams::new(lightcast_server::gi::none::NONE),
        gi(lightcast_server::gi::lightskin::LIGHTSKIN),
        gi(lightcast_server::gi::lightskin::BRSM),
        // The same random numbers at every scale (the seed and sample indices are equal), so
        // paths differ only where a rounded coordinate flips a hit; two bounces test the ray
        // offsets of the second surface too.
        GiParams::new(lightcast_server::gi::reference::REFERENCE)
            .with("bounces", 2)
            .with("spp", 8),
        // Δx and the blur distance are in units of the scene's extent, and a VPL's disk area
        // bounds its form factor: no length constant.
        GiParams::new(lightcast_server::gi::clustered::CLUSTERED)
            .with("rsm_size", 64)
            .with("vpl_count", 1024),
    ]
}

/// One frame per method of [`methods`] for `scene` lit by `light` and seen by `camera`, with
/// the scene's light caches at their default parameters.
fn render_methods(scene: &Scene, camera: &Camera, light: &Light) -> (f32, Vec<Frame>) {
    let params = CacheParams::for_scene(scene);
    let caches = precompute(scene, &params, &mut |_| {}).expect("caches");
    let mut renderer = Renderer::new(gpu(), scene.clone());
    renderer
        .gi::<LightSkin>()
        .expect("LightSkin is registered")
        .set_caches(&caches)
        .expect("caches fit the scene");
    set_bvh(&mut renderer);
    let frames = methods()
        .into_iter()
        .map(|gi| {
            let mut s = settings(W, H, camera.clone(), light.clone());
            s.gi = gi;
            renderer.render(&s).expect("render")
        })
        .collect();
    (params.d_eps, frames)
}

/// Σ|a − b| / Σ|b| over the RGB of every pixel.
fn relative_mae(a: &[[f32; 4]], b: &[[f32; 4]]) -> f32 {
    assert_eq!(a.len(), b.len());
    let (mut diff, mut total) = (0.0f64, 0.0f64);
    for (p, q) in a.iter().zip(b) {
        for c in 0..3 {
            diff += f64::from((p[c] - q[c]).abs());
            total += f64::from(q[c].abs());
        }
    }
    (diff / total.max(f64::MIN_POSITIVE)) as f32
}

#[test]
fn cornell_box_scaled_by_a_hundredth_and_a_thousand_renders_the_same_for_every_method() {
    let base = procedural::cornell_box();
    let (camera, light) = (base.cameras[0].clone(), base.lights[0].clone());
    assert_eq!(light.kind, LightKind::Spot);
    let (d_eps, reference) = render_methods(&base, &camera, &light);

    let mut failures = Vec::new();
    for s in SCALES {
        let scene = scaled(&base, s);
        let (scaled_d_eps, frames) =
            render_methods(&scene, &scaled_camera(&camera, s), &scaled_light(&light, s));
        // The default d_eps comes from the surface area, so it scales with the scene.
        assert!(
            (scaled_d_eps / (d_eps * s) - 1.0).abs() < 1e-4,
            "×{s}: d_eps {scaled_d_eps} vs {d_eps}·{s}"
        );
        for ((gi, frame), want) in methods().iter().zip(&frames).zip(&reference) {
            let mut buffers = vec![("hdr", frame.hdr.as_ref(), want.hdr.as_ref())];
            if gi.method != lightcast_server::gi::none::NONE {
                buffers.push(("indirect", frame.indirect.as_ref(), want.indirect.as_ref()));
            }
            for (name, got, want) in buffers {
                let (got, want) = (got.expect("captured"), want.expect("captured"));
                let error = relative_mae(got, want);
                eprintln!("×{s} {:?} {name}: relative MAE {error:.5}", gi.method);
                // NaN fails too.
                let tolerance = if gi.method == lightcast_server::gi::reference::REFERENCE {
                    REFERENCE_TOLERANCE
                } else {
                    TOLERANCE
                };
                if error.is_nan() || error > tolerance {
                    failures.push(format!("×{s} {:?} {name}: {error:.5}", gi.method));
                }
            }
        }
    }
    // The unscaled render must have something to compare: GI lights what the spot does not.
    let indirect = reference[1].indirect.as_ref().expect("captured");
    let lit = indirect
        .iter()
        .filter(|c| Vec3::new(c[0], c[1], c[2]).max_element() > 0.0);
    assert!(
        lit.count() > (W * H / 2) as usize,
        "LightSkin lit too little"
    );
    assert!(
        failures.is_empty(),
        "relative MAE above tolerance: {failures:?}"
    );
}

/// Scaling by a power of two is exact in floating point, so a method free of length
/// constants renders the very same pixels. `none`, the reference and `clustered` do; LightSkin's caches
/// come from a d_eps derived (and rounded) from the surface area, so it is held to the test
/// above instead.
#[test]
fn power_of_two_scales_give_identical_pixels_without_gi_with_the_reference_and_clustered() {
    let base = procedural::cornell_box();
    let (camera, light) = (base.cameras[0].clone(), base.lights[0].clone());
    let (_, unscaled) = render_methods(&base, &camera, &light);
    for s in [1.0 / 128.0, 1024.0] {
        let scene = scaled(&base, s);
        let (_, frames) =
            render_methods(&scene, &scaled_camera(&camera, s), &scaled_light(&light, s));
        for ((gi, frame), want) in methods().iter().zip(&frames).zip(&unscaled) {
            if !matches!(
                gi.method,
                lightcast_server::gi::none::NONE
                    | lightcast_server::gi::reference::REFERENCE
                    | lightcast_server::gi::clustered::CLUSTERED
            ) {
                continue;
            }
            for (name, got, want) in [
                ("hdr", &frame.hdr, &want.hdr),
                ("indirect", &frame.indirect, &want.indirect),
            ] {
                let (got, want) = (
                    got.as_ref().expect("captured"),
                    want.as_ref().expect("captured"),
                );
                assert!(
                    got == want,
                    "×{s} {:?} {name}: relative MAE {}",
                    gi.method,
                    relative_mae(got, want)
                );
            }
        }
    }
}
