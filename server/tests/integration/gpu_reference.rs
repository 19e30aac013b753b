//! The reference path tracer (`gi::reference`) on lavapipe against answers known without it:
//! the BVH traversal against brute-force intersection, one bounce between two plates against
//! a numerically integrated CPU value, and a closed emitting box against the geometric series
//! of its albedo.

use super::support::{self, brdf, floor_corners, hit_plane, plain_material, quad};
use glam::Vec3;
use lightcast_protocol::{Camera, Light, LightKind};
use lightcast_server::gi::reference::bvh::SceneBvh;
use lightcast_server::gi::reference::{
    luminance, PathTracer, ReferenceImage, ReferenceSettings, SurfaceGpu,
};
use lightcast_server::gpu::{readback::map_read, shaders, GpuContext};
use lightcast_server::scene::{material, Scene};
use wgpu::util::DeviceExt;

/// Renders `spp` samples per pixel in calls of at most 64.
fn converge(
    tracer: &mut PathTracer,
    (width, height): (u32, u32),
    camera: &Camera,
    light: &Light,
    settings: &ReferenceSettings,
    spp: u32,
) -> ReferenceImage {
    let mut left = spp;
    while left > 0 {
        let n = left.min(64);
        tracer
            .accumulate(width, height, camera, light, settings, n)
            .expect("accumulate");
        left -= n;
    }
    let image = tracer.read().expect("read").expect("samples");
    assert_eq!(image.samples, spp);
    image
}

fn point_light(position: Vec3, intensity: f32) -> Light {
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

/// Nearest hits of `rays` traced by the WGSL traversal.
fn gpu_hits(ctx: &GpuContext, bvh: &SceneBvh, rays: &[(Vec3, Vec3)]) -> Vec<[f32; 4]> {
    let device = &ctx.device;
    let storage = |label, bytes: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytes,
            usage: wgpu::BufferUsages::STORAGE | usage,
        })
    };
    let ray_data: Vec<[f32; 4]> = rays
        .iter()
        .flat_map(|(o, d)| [o.extend(f32::MAX).to_array(), d.extend(0.0).to_array()])
        .collect();
    let rays_buffer = storage(
        "rays",
        bytemuck::cast_slice(&ray_data),
        wgpu::BufferUsages::empty(),
    );
    let hits = storage(
        "hits",
        &vec![0u8; rays.len() * 16],
        wgpu::BufferUsages::COPY_SRC,
    );
    let nodes = storage(
        "nodes",
        bytemuck::cast_slice(&bvh.nodes),
        wgpu::BufferUsages::empty(),
    );
    let triangles = storage(
        "triangles",
        bytemuck::cast_slice(&bvh.triangles),
        wgpu::BufferUsages::empty(),
    );
    let module = shaders::REFERENCE_BVH_TEST.create_module(device);
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("bvh test"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let group = |index, buffers: [&wgpu::Buffer; 2]| {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(index),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: buffers[0].as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: buffers[1].as_entire_binding(),
                },
            ],
        })
    };
    let io = group(0, [&rays_buffer, &hits]);
    let scene = group(1, [&nodes, &triangles]);
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("hits readback"),
        size: hits.size(),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &io, &[]);
        pass.set_bind_group(1, &scene, &[]);
        pass.dispatch_workgroups((rays.len() as u32).div_ceil(64), 1, 1);
    }
    encoder.copy_buffer_to_buffer(&hits, 0, &staging, 0, None);
    ctx.queue.submit([encoder.finish()]);
    bytemuck::pod_collect_to_vec(&map_read(ctx, &staging).expect("map"))
}

#[test]
fn wgsl_traversal_finds_the_brute_force_hits() {
    let ctx = support::gpu();
    let scene = lightcast_server::scene::procedural::cornell_box();
    let bvh = SceneBvh::build(&scene).expect("bvh");
    // Rays from random points in and around the box to random directions.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let (lo, hi) = (scene.bounds.min, scene.bounds.max);
    let rays: Vec<(Vec3, Vec3)> = (0..4096)
        .map(|_| {
            let o = lo + (hi - lo) * Vec3::new(next(), next(), next()) * 1.4 - (hi - lo) * 0.2;
            let d = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize_or(Vec3::Y);
            (o, d)
        })
        .collect();
    let gpu = gpu_hits(&ctx, &bvh, &rays);
    let mut hits = 0;
    for ((o, d), g) in rays.iter().zip(&gpu) {
        let cpu = bvh.intersect_brute_force(*o, *d, f32::MAX);
        let gpu_triangle = g[1].to_bits();
        match cpu {
            Some(hit) => {
                hits += 1;
                assert_ne!(gpu_triangle, u32::MAX, "GPU missed {hit:?} of ray {o} {d}");
                assert!(
                    (g[0] - hit.t).abs() <= 1e-4 * hit.t.max(1.0),
                    "ray {o} {d}: GPU t {} vs CPU {hit:?}",
                    g[0]
                );
            }
            None => assert_eq!(
                gpu_triangle,
                u32::MAX,
                "GPU hit where the CPU found nothing"
            ),
        }
    }
    assert!(hits > 2000, "only {hits} of 4096 rays hit");
}

/// Plate A (floor, y = 0, 2×2, facing up) under plate B (y = 1, 2×2, facing down), a point
/// light between them, the camera looking down at A from under B. With one bounce A's
/// indirect light is the light B reflects onto it.
struct Plates {
    scene: Scene,
    camera: Camera,
    light: Light,
}

fn plates() -> Plates {
    let (mut vertices, mut indices) = (Vec::new(), Vec::new());
    quad(
        &mut vertices,
        &mut indices,
        floor_corners(0.0, 0.0, 0.0, 1.0),
        0,
    );
    let mut top = floor_corners(0.0, 0.0, 1.0, 1.0);
    top.reverse();
    quad(&mut vertices, &mut indices, top, 1);
    let materials = vec![
        plain_material([0.8, 0.7, 0.6], 0.0, 1.0),
        plain_material([0.3, 0.6, 0.9], 0.0, 0.5),
    ];
    Plates {
        scene: support::scene(vertices, indices, materials),
        camera: Camera {
            position: [0.05, 0.9, 0.1],
            target: [0.0, 0.0, 0.0],
            fov_y_degrees: 60.0,
        },
        light: point_light(Vec3::new(0.2, 0.55, -0.1), 1.0),
    }
}

/// One-bounce indirect radiance leaving `x` on plate A towards `eye`: the integral over plate
/// B of f_A · L_B · G, with L_B = f_B · E_B from the point light, by the midpoint rule.
fn plates_indirect(p: &Plates, x: Vec3, eye: Vec3, cells: u32) -> Vec3 {
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
            let l_b = brdf(ceiling, n_b, to_light, -w) * e_b;
            sum += brdf(floor, n_a, w, to_eye) * l_b * cos_x.max(0.0) * cos_y.max(0.0) / r2;
        }
    }
    sum * cell * cell
}

#[test]
fn one_bounce_between_two_plates_matches_numerical_integration() {
    let p = plates();
    let (w, h) = (16, 16);
    let mut tracer = PathTracer::new(support::gpu(), &p.scene).expect("tracer");
    let image = converge(
        &mut tracer,
        (w, h),
        &p.camera,
        &p.light,
        &ReferenceSettings::default(),
        512,
    );
    let eye = Vec3::from(p.camera.position);
    // Compare the mean over each half of the image (left/right), where the MC noise of
    // 128 pixels × 512 samples is well below the tolerance.
    for half in 0..2 {
        let (mut gpu, mut cpu) = (Vec3::ZERO, Vec3::ZERO);
        for y in 0..h {
            for x in half * w / 2..(half + 1) * w / 2 {
                let hit = hit_plane(&p.camera, &p.scene, w, h, x, y, 0.0).expect("sees A");
                cpu += plates_indirect(&p, hit, eye, 160);
                gpu += Vec3::from(image.indirect[(y * w + x) as usize]);
            }
        }
        let rel = (gpu - cpu).abs() / cpu;
        eprintln!("half {half}: relative error {rel}");
        assert!(
            rel.max_element() < 0.03,
            "half {half}: GPU {gpu} vs CPU {cpu} (relative {rel}; RSE {})",
            image.relative_standard_error
        );
    }
    assert!(image.relative_standard_error > 0.0 && image.relative_standard_error < 0.2);
}

/// A closed cube whose every face emits `emitted` and reflects `albedo` diffusely, and
/// nothing else: the radiance after k bounces is emitted·(albedo + … + albedo^k).
#[test]
fn a_closed_emitting_box_converges_to_the_geometric_series_of_its_albedo() {
    let (mut vertices, mut indices) = (Vec::new(), Vec::new());
    let c = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let faces = [
        [
            c(-1., -1., -1.),
            c(1., -1., -1.),
            c(1., -1., 1.),
            c(-1., -1., 1.),
        ],
        [
            c(-1., 1., -1.),
            c(-1., 1., 1.),
            c(1., 1., 1.),
            c(1., 1., -1.),
        ],
        [
            c(-1., -1., -1.),
            c(-1., 1., -1.),
            c(1., 1., -1.),
            c(1., -1., -1.),
        ],
        [
            c(-1., -1., 1.),
            c(1., -1., 1.),
            c(1., 1., 1.),
            c(-1., 1., 1.),
        ],
        [
            c(-1., -1., -1.),
            c(-1., -1., 1.),
            c(-1., 1., 1.),
            c(-1., 1., -1.),
        ],
        [
            c(1., -1., -1.),
            c(1., 1., -1.),
            c(1., 1., 1.),
            c(1., -1., 1.),
        ],
    ];
    for f in faces {
        quad(&mut vertices, &mut indices, f, 0);
    }
    let scene = support::scene(vertices, indices, vec![plain_material([0.5; 3], 0.0, 1.0)]);
    let (albedo, emitted) = (0.6f32, 0.25f32);
    let lambertian = SurfaceGpu::new(
        material::DiffuseGlossy {
            diffuse: Vec3::splat(albedo),
            glossy: Vec3::ZERO,
            exponent: 1.0,
        },
        [emitted; 3],
    );
    let mut tracer =
        PathTracer::with_surfaces(support::gpu(), &scene, &[lambertian]).expect("tracer");
    let camera = Camera {
        position: [0.1, 0.2, 0.3],
        target: [0.6, -0.4, 0.2],
        fov_y_degrees: 70.0,
    };
    let dark = point_light(Vec3::new(0.0, 0.5, 0.0), 0.0);
    for bounces in [1, 2, 4] {
        let settings = ReferenceSettings {
            bounces,
            ..ReferenceSettings::default()
        };
        let image = converge(&mut tracer, (16, 12), &camera, &dark, &settings, 8);
        let expected: f32 = (1..=bounces).map(|k| emitted * albedo.powi(k as i32)).sum();
        for (i, px) in image.indirect.iter().enumerate() {
            let got = luminance(*px);
            assert!(
                (got - expected).abs() <= 1e-3 * expected,
                "{bounces} bounces, pixel {i}: {got} vs {expected}"
            );
        }
        // Every path carries the same weight (cosine sampling of a Lambertian), so the
        // convergence estimate sees no variance.
        assert!(image.relative_standard_error < 1e-3);
    }
}

#[test]
fn the_same_request_gives_the_same_pixels_and_another_seed_others() {
    let p = plates();
    let render = |seed| {
        let mut tracer = PathTracer::new(support::gpu(), &p.scene).expect("tracer");
        let settings = ReferenceSettings {
            seed,
            ..ReferenceSettings::default()
        };
        converge(&mut tracer, (8, 8), &p.camera, &p.light, &settings, 4).indirect
    };
    let first = render(1);
    assert_eq!(first, render(1));
    assert_ne!(first, render(2));
}

#[test]
fn accumulation_restarts_when_the_camera_moves() {
    let p = plates();
    let mut tracer = PathTracer::new(support::gpu(), &p.scene).expect("tracer");
    let settings = ReferenceSettings::default();
    converge(&mut tracer, (8, 8), &p.camera, &p.light, &settings, 4);
    tracer
        .accumulate(8, 8, &p.camera, &p.light, &settings, 2)
        .expect("accumulate");
    assert_eq!(tracer.samples(), 6);
    let moved = Camera {
        position: [0.1, 0.8, 0.1],
        ..p.camera.clone()
    };
    tracer
        .accumulate(8, 8, &moved, &p.light, &settings, 2)
        .expect("accumulate");
    assert_eq!(tracer.samples(), 2);
}

/// `reference` as a frame's GI method: each frame adds `spp` samples to its history's
/// accumulation and writes the mean into the indirect buffer, equal (within the buffer's f16
/// precision) to the tracer's own accumulation of as many samples; histories do not reset
/// each other; frames without a history start afresh; the convergence the frame reports is
/// the CPU resolve's.
#[test]
fn reference_frames_accumulate_per_history_and_match_the_tracer() {
    use lightcast_server::gi::{GiMethod, GiSettings};
    use lightcast_server::renderer::Renderer;
    let p = plates();
    let (w, h) = (16, 12);
    let mut renderer = Renderer::new(support::gpu(), p.scene.clone());
    let mut settings = support::settings(w, h, p.camera.clone(), p.light.clone());
    settings.gi = GiSettings {
        method: GiMethod::Reference,
        spp: 8,
        ..GiSettings::default()
    };
    let mut frame_of = |history| {
        let mut s = settings.clone();
        s.history = history;
        renderer.render(&s).expect("frame")
    };
    let first = frame_of(Some(1));
    frame_of(Some(2));
    let third = frame_of(Some(1));
    let samples = |f: &lightcast_server::renderer::Frame| f.progress.expect("progress").samples;
    assert_eq!(samples(&first), 8);
    assert_eq!(samples(&third), 16, "history 2 must not restart history 1");
    let fresh = frame_of(None);
    assert_eq!(samples(&fresh), 8);
    assert_eq!(samples(&frame_of(None)), 8);

    let mut tracer = PathTracer::new(support::gpu(), &p.scene).expect("tracer");
    let truth = converge(
        &mut tracer,
        (w, h),
        &p.camera,
        &p.light,
        &ReferenceSettings::default(),
        16,
    );
    let indirect = third.indirect.as_ref().expect("captured");
    let mut lit = 0;
    for (got, want) in indirect.iter().zip(&truth.indirect) {
        for c in 0..3 {
            // f16 has an 11-bit significand: 2^-11 relative, plus denormals near 0.
            let tolerance = want[c].abs() * 2e-3 + 1e-6;
            assert!(
                (got[c] - want[c]).abs() <= tolerance,
                "frame {got:?} vs tracer {want:?}"
            );
        }
        lit += usize::from(luminance(*want) > 0.0);
    }
    assert!(lit > indirect.len() / 2, "most pixels see indirect light");
    let reported = third.progress.expect("progress").relative_standard_error;
    let expected = truth.relative_standard_error;
    assert!(
        (reported - expected).abs() <= expected * 1e-3,
        "GPU-reduced relative error {reported} vs CPU {expected}"
    );
    let after_8 = first.progress.expect("progress").relative_standard_error;
    assert!(
        reported < after_8,
        "error falls with samples: {after_8} at 8 spp, {reported} at 16"
    );
}
