//! The gather on the GPU (lavapipe in CI) against its CPU reference (`pattern::gather`) from
//! the same RSM, at pixels of the Cornell box whose surface a ray cast finds unambiguously.
//! A test of the renderer crate (it renders frames), kept with the method: the renderer's
//! `tests/methods.rs` gathers every method's `gpu_tests.rs`.

use lightcast_gi::common::bvh::SceneBvh;
use lightcast_gi::rsm_gather::pattern::{gather, gather_centre, light_runs, RsmAtlas};
use lightcast_gi::rsm_gather::{GatherReadback, RsmGather, RSM_GATHER};
use lightcast_passes::gpu::{BackendChoice, GpuContext};
use lightcast_passes::passes::frame_uniforms::camera_view_proj;
use lightcast_render::renderer::{RenderSettings, Renderer};
use lightcast_scene::{brdf::Brdf, default_light, procedural, Scene};
use glam::{Vec3, Vec4Swizzles};
use lightcast_protocol::{GiParams, Light, LightKind};

const W: u32 = 48;
const H: u32 = 36;

/// The surface a pixel's centre sees, as the G-buffer stores it (the material's factors in
/// half floats), if the rays through four points around the centre meet the same plane.
fn surface_at(
    scene: &Scene,
    bvh: &SceneBvh,
    s: &RenderSettings,
    x: u32,
    y: u32,
) -> Option<(Vec3, Vec3, Brdf)> {
    let inv = camera_view_proj(&s.camera, W as f32 / H as f32, &scene.bounds).inverse();
    let hit = |fx: f32, fy: f32| {
        let ndc = (fx / W as f32 * 2.0 - 1.0, 1.0 - fy / H as f32 * 2.0);
        let unproject = |z: f32| {
            let p = inv * glam::Vec4::new(ndc.0, ndc.1, z, 1.0);
            p.xyz() / p.w
        };
        let (near, far) = (unproject(0.0), unproject(1.0));
        let d = (far - near).normalize();
        let h = bvh.intersect(near, d, f32::INFINITY)?;
        let corner = |k: usize| {
            Vec3::from(scene.vertices[scene.indices[h.triangle as usize * 3 + k] as usize].position)
        };
        let mut n = (corner(1) - corner(0))
            .cross(corner(2) - corner(0))
            .normalize();
        if n.dot(d) > 0.0 {
            n = -n;
        }
        Some((near + d * h.t, n, h.triangle, n.dot(corner(0))))
    };
    let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
    let (position, n, tri, plane) = hit(cx, cy)?;
    for (dx, dy) in [(-0.1, 0.0), (0.1, 0.0), (0.0, -0.1), (0.0, 0.1)] {
        let (_, other_n, _, other_plane) = hit(cx + dx, cy + dy)?;
        if other_n.dot(n) < 0.9999 || (other_plane - plane).abs() > 1e-4 {
            return None;
        }
    }
    let material = scene.vertices[scene.indices[tri as usize * 3] as usize].material;
    let m = scene.materials[material as usize].brdf();
    // As the G-buffer stores it, in half floats.
    let f16 = |v: f32| half::f16::from_f32(v).to_f32();
    Some((
        position,
        n,
        Brdf {
            base: m.base.to_array().map(f16).into(),
            metallic: f16(m.metallic),
            roughness: f16(m.roughness),
            specular: f16(m.specular),
        },
    ))
}

fn render(
    scene: &Scene,
    gi: GiParams,
    lights: Vec<Light>,
) -> (RenderSettings, GatherReadback, Vec<[f32; 4]>) {
    let ctx = GpuContext::new(BackendChoice::Auto).expect("a GPU adapter (lavapipe in CI)");
    let mut renderer = Renderer::new(ctx, scene.clone());
    let s = RenderSettings {
        width: W,
        height: H,
        camera: default_light::default_camera(scene),
        lights,
        environment: None,
        exposure: lightcast_passes::passes::exposure::Exposure::Manual(1.0),
        shadow_map_size: 256,
        capture_hdr: true,
        debug_view: lightcast_protocol::View::FINAL,
        gi,
        history: None,
        still: false,
        yuv420: false,
        poses: Vec::new(),
        pick: None,
    };
    let frame = renderer.render(&s).expect("a frame");
    let readback = renderer
        .gi::<RsmGather>()
        .expect("registered")
        .read_back()
        .expect("read back")
        .expect("after a frame");
    (s, readback, frame.indirect.expect("captured"))
}

/// Every checked pixel's indirect light equals the CPU's gather from the same RSM (the
/// indirect buffer is f16, the CPU's surface point a ray cast's: 2 %); the probe pixel's
/// projection equals the CPU's.
#[test]
fn the_gather_matches_the_cpu_reference() {
    let scene = procedural::cornell_box();
    gather_matches_the_cpu(&scene, vec![default_light::default_light(&scene)]);
}

/// The same with a point light (six faces) after the scene's spot: the gather sums each
/// light's pattern in its own faces.
#[test]
fn the_gather_of_two_lights_matches_the_cpu_reference() {
    let scene = procedural::cornell_box();
    let spot = default_light::default_light(&scene);
    let point = Light {
        kind: LightKind::Point,
        position: scene.bounds.center().into(),
        intensity: spot.intensity * 0.5,
        ..spot.clone()
    };
    gather_matches_the_cpu(&scene, vec![spot, point]);
}

/// The Cornell box's lamp alone (its spot at intensity 0): the emitter face is gathered whole,
/// every pixel reading the same texels, as the CPU does.
#[test]
fn the_gather_of_emitters_matches_the_cpu_reference() {
    let scene = procedural::cornell_box();
    let dark = Light {
        intensity: 0.0,
        ..default_light::default_light(&scene)
    };
    gather_matches_the_cpu(&scene, vec![dark]);
}

/// `emitters` on: the Cornell box's lamp lights through the emitter face besides `lights`.
fn gather_matches_the_cpu(scene: &Scene, lights: Vec<Light>) {
    let gi = GiParams::new(RSM_GATHER)
        .with("emitters", true)
        .with("rsm_size", 64)
        .with("gather_samples", 200)
        .with("gather_radius", 0.3);
    let (s, rb, indirect) = render(scene, gi, lights);
    let rsm = RsmAtlas {
        size: rb.rsm_size,
        faces: rb.faces,
        position: &rb.rsm_position,
        normal: &rb.rsm_normal,
        flux_area: &rb.rsm_flux_area,
        glossy: &rb.rsm_glossy,
    };
    let bvh = SceneBvh::build(scene).expect("a BVH");
    let viewer = Vec3::from(s.camera.position);
    let radius = 0.3;
    let (mut checked, mut worst) = (0, 0.0f32);
    for (x, y) in [
        (W / 2, H / 2),
        (8, 8),
        (30, 6),
        (12, 28),
        (40, 30),
        (20, 12),
        (36, 20),
        (6, 20),
    ] {
        let Some((p, n, brdf)) = surface_at(scene, &bvh, &s, x, y) else {
            continue;
        };
        if (x, y) == (W / 2, H / 2) {
            let (_, first_light) = light_runs(&rb.face_view_proj).next().expect("a light");
            let (face, centre) = gather_centre(&first_light, rb.rsm_size, p);
            let (gpu_face, gpu_centre) = rb.probe.expect("the probe sees a surface");
            assert_eq!(face, gpu_face);
            assert!(
                (centre - gpu_centre).length() < 0.05,
                "{centre} vs {gpu_centre}"
            );
        }
        let want = gather(
            &rsm,
            &rb.face_view_proj,
            &rb.samples,
            radius,
            p,
            n,
            viewer,
            &brdf,
        );
        let got = Vec3::from_slice(&indirect[(y * W + x) as usize][..3]);
        if want.max_element() == 0.0 {
            // Nothing lit within the radius (a pixel beside the light's frustum).
            assert_eq!(got, Vec3::ZERO, "pixel ({x}, {y})");
            continue;
        }
        let error = (got - want).abs().max_element() / want.max_element();
        worst = worst.max(error);
        assert!(error < 0.02, "pixel ({x}, {y}): GPU {got} vs CPU {want}");
        checked += 1;
    }
    assert!(
        checked >= 4,
        "only {checked} lit pixels with an unambiguous surface"
    );
    eprintln!("{checked} pixels, worst relative difference {worst:.4}");
}

/// The whole RSM gathered (a radius covering every texel from anywhere) against a small one:
/// more light, since every sample's light is positive.
#[test]
fn a_larger_radius_gathers_more_texels() {
    let scene = procedural::cornell_box();
    let mean = |radius: f64| {
        let gi = GiParams::new(RSM_GATHER)
            .with("rsm_size", 64)
            .with("gather_samples", 400)
            .with("gather_radius", radius);
        let (_, _, indirect) = render(&scene, gi, vec![default_light::default_light(&scene)]);
        indirect
            .iter()
            .map(|p| f64::from(p[0] + p[1] + p[2]))
            .sum::<f64>()
    };
    let (small, whole) = (mean(0.05), mean(1.5));
    assert!(whole > small * 1.5, "{small} vs {whole}");
}
