//! The reference path tracer (`gi::reference`) on lavapipe against answers known without it:
//! the BVH traversal against brute-force intersection, one bounce between two plates against
//! a numerically integrated CPU value, a closed emitting box against the geometric series
//! of its albedo (and dark with `emitters` off), textured and alpha-masked surfaces against untextured and absent ones,
//! diffuse senders (`senders: diffuse`) against the same integral with the sender's diffuse lobe.

use super::support::plates::{glossy_plates, plates, plates_indirect, point_light};
use super::support::{self, floor_corners, hit_plane, plain_material, quad};
use glam::Vec3;
use lightcast_protocol::{Camera, Light};
use lightcast_server::gi::common::bvh::SceneBvh;
use lightcast_server::gi::common::shaders;
use lightcast_server::gi::reference::{
    PathTracer, ReferenceImage, ReferenceSettings, Senders, SurfaceGpu,
};
use lightcast_server::gpu::{readback::map_read, GpuContext};
use lightcast_server::passes::tonemap::luminance;
use lightcast_server::scene::{brdf::Brdf, Material, Scene, Texture, Vertex};
use wgpu::util::DeviceExt;

/// Renders `spp` samples per pixel in calls of at most 64.
fn converge(
    tracer: &mut PathTracer,
    (width, height): (u32, u32),
    camera: &Camera,
    lights: &[Light],
    settings: &ReferenceSettings,
    spp: u32,
) -> ReferenceImage {
    let mut left = spp;
    while left > 0 {
        let n = left.min(64);
        tracer
            .accumulate(width, height, camera, lights, None, settings, n)
            .expect("accumulate");
        left -= n;
    }
    let image = tracer.read().expect("read").expect("samples");
    assert_eq!(image.samples, spp);
    image
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
    let top_nodes = storage(
        "top nodes",
        bytemuck::cast_slice(&bvh.top.nodes),
        wgpu::BufferUsages::empty(),
    );
    let instances = storage(
        "instances",
        bytemuck::cast_slice(&bvh.top.instances),
        wgpu::BufferUsages::empty(),
    );
    let module = shaders::BVH_TEST.create_module(device);
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("bvh test"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let group = |index, buffers: &[&wgpu::Buffer]| {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(binding, b)| wgpu::BindGroupEntry {
                binding: binding as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(index),
            entries: &entries,
        })
    };
    let io = group(0, &[&rays_buffer, &hits]);
    let scene = group(1, &[&nodes, &triangles, &top_nodes, &instances]);
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

/// At rest and with the short box moved (the two-level BVH's top level placing its bottom
/// level; issue 35).
#[test]
fn wgsl_traversal_finds_the_brute_force_hits() {
    let scene = lightcast_server::scene::procedural::cornell_box();
    let rest = SceneBvh::build(&scene).expect("bvh");
    let mut posed = rest.clone();
    let base = scene
        .node(1)
        .and_then(|n| n.local)
        .expect("box")
        .translation;
    let requested = [lightcast_protocol::NodePose {
        node: 1,
        translation: Some((base + Vec3::new(-0.5, 0.3, -0.2)).to_array()),
        rotation: Some(glam::Quat::from_rotation_x(0.4).to_array()),
        scale: None,
    }];
    let poses = lightcast_server::scene::nodes::resolve_poses(
        &scene.nodes,
        &scene.node_bounds(),
        &scene.bounds,
        &requested,
    )
    .expect("inside the room");
    let worlds = lightcast_server::scene::nodes::posed_worlds(&scene.nodes, &poses);
    posed.set_top(posed.top_level(&scene.nodes, &worlds));
    for bvh in [rest, posed] {
        wgsl_traversal_matches(&scene, &bvh);
    }
}

fn wgsl_traversal_matches(scene: &lightcast_server::scene::Scene, bvh: &SceneBvh) {
    let ctx = support::gpu();
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
    let gpu = gpu_hits(&ctx, bvh, &rays);
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

/// Both transports: the whole BRDF at the glossy ceiling (roughness 0.5, half metal), and its
/// diffuse lobe alone (what the RSM-based methods model), which must differ from it by far
/// more than the tolerance for the check to tell them apart.
#[test]
fn one_bounce_between_two_plates_matches_numerical_integration() {
    let p = glossy_plates(1);
    let (w, h) = (16, 16);
    let mut tracer = PathTracer::new(support::gpu(), &p.scene).expect("tracer");
    let eye = Vec3::from(p.camera.position);
    let mut means = Vec::new();
    for senders in [Senders::Full, Senders::Diffuse] {
        let image = converge(
            &mut tracer,
            (w, h),
            &p.camera,
            std::slice::from_ref(&p.light),
            &ReferenceSettings {
                senders,
                ..ReferenceSettings::default()
            },
            512,
        );
        // Compare the mean over each half of the image (left/right), where the MC noise of
        // 128 pixels × 512 samples is well below the tolerance.
        let mut total = Vec3::ZERO;
        for half in 0..2 {
            let (mut gpu, mut cpu) = (Vec3::ZERO, Vec3::ZERO);
            for y in 0..h {
                for x in half * w / 2..(half + 1) * w / 2 {
                    let hit = hit_plane(&p.camera, &p.scene, w, h, x, y, 0.0).expect("sees A");
                    cpu += plates_indirect(&p, hit, eye, 160, senders);
                    gpu += Vec3::from(image.indirect[(y * w + x) as usize]);
                }
            }
            let rel = (gpu - cpu).abs() / cpu;
            eprintln!("{senders:?} senders, half {half}: relative error {rel}");
            assert!(
                rel.max_element() < 0.03,
                "{senders:?} senders, half {half}: GPU {gpu} vs CPU {cpu} (relative {rel}; RSE {})",
                image.relative_standard_error
            );
            total += cpu;
        }
        means.push(total);
        assert!(image.relative_standard_error > 0.0 && image.relative_standard_error < 0.2);
    }
    let glossy_share = (means[0] - means[1]) / means[0];
    eprintln!("the ceiling's glossy share of the floor's light: {glossy_share}");
    assert!(glossy_share.min_element() > 0.2, "{glossy_share}");
}

/// A closed cube (2 m) whose faces face inwards: emitters emit from the side their normals
/// face. The camera inside looks at a corner.
fn closed_box() -> (Scene, Camera) {
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
    // Wound to face inwards: emitters emit from the side their normals face.
    for mut f in faces {
        f.reverse();
        quad(&mut vertices, &mut indices, f, 0);
    }
    let scene = support::scene(vertices, indices, vec![plain_material([0.5; 3], 0.0, 1.0)]);
    let camera = Camera {
        position: [0.1, 0.2, 0.3],
        target: [0.6, -0.4, 0.2],
        fov_y_degrees: 70.0,
    };
    (scene, camera)
}

/// A closed cube whose every face emits `emitted` and reflects `albedo` diffusely, and
/// nothing else: the radiance after k bounces is emitted·(albedo + … + albedo^k).
#[test]
fn a_closed_emitting_box_converges_to_the_geometric_series_of_its_albedo() {
    let (scene, camera) = closed_box();
    let (albedo, emitted) = (0.6f32, 0.25f32);
    let lambertian = SurfaceGpu::new(&Brdf::lambertian(Vec3::splat(albedo)), [emitted; 3]);
    let mut tracer =
        PathTracer::with_surfaces(support::gpu(), &scene, |_| vec![lambertian]).expect("tracer");
    let dark = point_light(Vec3::new(0.0, 0.5, 0.0), 0.0);
    for bounces in [1, 2, 4] {
        let settings = ReferenceSettings {
            bounces,
            ..ReferenceSettings::default()
        };
        let image = converge(
            &mut tracer,
            (16, 12),
            &camera,
            std::slice::from_ref(&dark),
            &settings,
            8,
        );
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
        // Without emitters the box has no light at all.
        let dark_box = ReferenceSettings {
            emitters: false,
            ..settings
        };
        let image = converge(
            &mut tracer,
            (16, 12),
            &camera,
            std::slice::from_ref(&dark),
            &dark_box,
            8,
        );
        assert!(
            image.indirect.iter().all(|px| luminance(*px) == 0.0),
            "{bounces} bounces without emitters: {:?}",
            image
                .indirect
                .iter()
                .map(|px| luminance(*px))
                .fold(0.0, f32::max)
        );
    }
}

/// The white furnace: the same closed box with glTF's white dielectric (base colour 1,
/// metallic 0) reflects all it receives at any roughness, so after k bounces the radiance is
/// k·emitted; a white metal loses what single-scattering GGX loses and stays below.
#[test]
fn a_white_closed_box_reflects_all_it_receives() {
    let (scene, camera) = closed_box();
    let emitted = 0.25f32;
    let bounces = 3;
    let dark = point_light(Vec3::new(0.0, 0.5, 0.0), 0.0);
    let settings = ReferenceSettings {
        bounces,
        ..ReferenceSettings::default()
    };
    let mean_of = |brdf: Brdf| {
        let surface = SurfaceGpu::new(&brdf, [emitted; 3]);
        let mut tracer =
            PathTracer::with_surfaces(support::gpu(), &scene, |_| vec![surface]).expect("tracer");
        let image = converge(
            &mut tracer,
            (16, 12),
            &camera,
            std::slice::from_ref(&dark),
            &settings,
            128,
        );
        let values: Vec<f32> = image.indirect.iter().map(|px| luminance(*px)).collect();
        values.iter().sum::<f32>() / values.len() as f32
    };
    let expected = emitted * bounces as f32;
    for roughness in [0.3, 0.6, 1.0] {
        let got = mean_of(Brdf::new(Vec3::ONE, 0.0, roughness, 1.0));
        // Monte Carlo noise of 16×12×128 paths and the albedo table's interpolation (0.07 %
        // or less on lavapipe).
        assert!(
            (got - expected).abs() <= 2e-3 * expected,
            "white dielectric, roughness {roughness}: {got} vs {expected}"
        );
    }
    let metal = mean_of(Brdf::new(Vec3::ONE, 1.0, 0.6, 1.0));
    assert!(
        metal < 0.97 * expected && metal > 0.5 * expected,
        "white metal: {metal} vs {expected}"
    );
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
        converge(
            &mut tracer,
            (8, 8),
            &p.camera,
            std::slice::from_ref(&p.light),
            &settings,
            4,
        )
        .indirect
    };
    let first = render(1);
    assert_eq!(first, render(1));
    assert_ne!(first, render(2));
}

/// Next-event estimation sums every light on the same paths (the random stream does not
/// depend on the lights), so two lights give the sum of each alone: exactly, up to f32
/// rounding of the sums (1e-5 relative).
#[test]
fn two_lights_give_the_sum_of_each_alone() {
    let p = plates();
    let second = point_light(Vec3::new(-0.2, 0.4, 0.15), 0.7);
    let render = |lights: &[Light]| {
        let mut tracer = PathTracer::new(support::gpu(), &p.scene).expect("tracer");
        let settings = ReferenceSettings::default();
        converge(&mut tracer, (8, 8), &p.camera, lights, &settings, 4).indirect
    };
    let first = render(std::slice::from_ref(&p.light));
    let other = render(std::slice::from_ref(&second));
    let both = render(&[p.light.clone(), second.clone()]);
    let (mut lit, mut worst) = (0, 0.0f32);
    for ((a, b), ab) in first.iter().zip(&other).zip(&both) {
        let sum = Vec3::from_slice(&a[..3]) + Vec3::from_slice(&b[..3]);
        let got = Vec3::from_slice(&ab[..3]);
        if sum.max_element() > 0.0 {
            lit += 1;
            worst = worst.max((got - sum).abs().max_element() / sum.max_element());
        }
    }
    assert!(lit > 32, "only {lit} lit pixels");
    assert!(worst < 1e-5, "two lights differ from the sum by {worst}");
}

/// A sample is traced in bands of rows, each one dispatch of at most `BAND_RAYS` rays (issue
/// 30: lavapipe silently cuts a dispatch of more than ~2.8 s short): bands of two rows, and
/// of rows that do not divide the image, add up to exactly the image one dispatch per sample
/// makes.
#[test]
fn bands_of_rows_add_up_to_the_whole_image() {
    let p = plates();
    let settings = ReferenceSettings {
        bounces: 2,
        ..ReferenceSettings::default()
    };
    let (width, height) = (24, 21);
    let render = |band_rays: Option<u64>| {
        let tracer = PathTracer::new(support::gpu(), &p.scene).expect("tracer");
        let mut tracer = match band_rays {
            Some(rays) => tracer.with_band_rays(rays),
            None => tracer,
        };
        converge(
            &mut tracer,
            (width, height),
            &p.camera,
            std::slice::from_ref(&p.light),
            &settings,
            3,
        )
    };
    let whole = render(None);
    let rays_per_row = u64::from(width) * (1 + 2 * 2);
    for rows in [2, 5] {
        let banded = render(Some(rays_per_row * rows));
        assert_eq!(banded.indirect, whole.indirect, "bands of {rows} rows");
    }
    assert!(
        whole.indirect.iter().any(|p| p[0] > 0.0),
        "the plates are lit"
    );
}

#[test]
fn accumulation_restarts_when_the_camera_moves() {
    let p = plates();
    let mut tracer = PathTracer::new(support::gpu(), &p.scene).expect("tracer");
    let settings = ReferenceSettings::default();
    converge(
        &mut tracer,
        (8, 8),
        &p.camera,
        std::slice::from_ref(&p.light),
        &settings,
        4,
    );
    tracer
        .accumulate(
            8,
            8,
            &p.camera,
            std::slice::from_ref(&p.light),
            None,
            &settings,
            2,
        )
        .expect("accumulate");
    assert_eq!(tracer.samples(), 6);
    let moved = Camera {
        position: [0.1, 0.8, 0.1],
        ..p.camera.clone()
    };
    tracer
        .accumulate(
            8,
            8,
            &moved,
            std::slice::from_ref(&p.light),
            None,
            &settings,
            2,
        )
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
    use lightcast_server::gi::GiParams;
    use lightcast_server::renderer::Renderer;
    let p = plates();
    let (w, h) = (16, 12);
    let mut renderer = Renderer::new(support::gpu(), p.scene.clone());
    support::set_bvh(&mut renderer);
    let mut settings = support::settings(w, h, p.camera.clone(), p.light.clone());
    settings.gi = GiParams::new(lightcast_server::gi::reference::REFERENCE).with("spp", 8);
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
        std::slice::from_ref(&p.light),
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

/// Linear value of an sRGB-encoded byte (what sampling an `Rgba8UnormSrgb` texel returns).
fn srgb_to_linear(c: u8) -> f32 {
    let c = f32::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_rgb(c: [u8; 4]) -> [f32; 3] {
    [c[0], c[1], c[2]].map(srgb_to_linear)
}

/// An RGBA8 texture whose left half of columns is `left` and right half `right`.
fn halves(width: u32, height: u32, left: [u8; 4], right: [u8; 4]) -> Texture {
    Texture {
        name: "halves".into(),
        width,
        height,
        rgba8: (0..width * height)
            .flat_map(|i| if i % width < width / 2 { left } else { right })
            .collect(),
    }
}

/// The plates with other materials and textures (material 2 is free for extra geometry).
fn plates_with(
    extra: impl FnOnce(&mut Vec<Vertex>, &mut Vec<u32>),
    materials: Vec<Material>,
    textures: Vec<Texture>,
) -> Scene {
    let p = plates();
    let (mut vertices, mut indices) = (p.scene.vertices, p.scene.indices);
    extra(&mut vertices, &mut indices);
    Scene::new(
        "plates",
        vertices,
        indices,
        materials,
        textures,
        vec![],
        vec![],
    )
    .expect("scene")
}

/// The floor of the plates carries an 8×2 texture, red in its left half of columns and blue in
/// its right, and the ceiling a uniform one. Where bilinear filtering reads only one half
/// (u in [1/16, 7/16] or [9/16, 15/16]), the textured receiver's indirect light must be that of
/// the untextured scene whose floor base colour is factor × the texel's linear colour; with
/// the same seed the paths are the same, so the images agree up to float rounding.
#[test]
fn a_textured_receiver_reflects_as_the_untextured_colour_of_its_texel() {
    let (red, blue, sky) = ([230, 60, 40, 255], [40, 90, 220, 255], [150, 200, 240, 255]);
    let factor = [0.9, 0.8, 1.0];
    let textured_floor = Material {
        base_color_texture: Some(0),
        ..plain_material(factor, 0.0, 1.0)
    };
    let textured_ceiling = Material {
        base_color_texture: Some(1),
        ..plain_material([1.0; 3], 0.0, 0.5)
    };
    let textured = plates_with(
        |_, _| {},
        vec![textured_floor, textured_ceiling],
        vec![halves(8, 2, red, blue), halves(2, 2, sky, sky)],
    );
    let untextured = |texel: [u8; 4]| {
        let c = linear_rgb(texel);
        plates_with(
            |_, _| {},
            vec![
                plain_material(std::array::from_fn(|i| factor[i] * c[i]), 0.0, 1.0),
                plain_material(linear_rgb(sky), 0.0, 0.5),
            ],
            vec![],
        )
    };
    let p = plates();
    let (w, h) = (16, 16);
    let render = |scene: &Scene| {
        let mut tracer = PathTracer::new(support::gpu(), scene).expect("tracer");
        let settings = ReferenceSettings::default();
        converge(
            &mut tracer,
            (w, h),
            &p.camera,
            std::slice::from_ref(&p.light),
            &settings,
            64,
        )
    };
    let got = render(&textured);
    let (as_red, as_blue) = (render(&untextured(red)), render(&untextured(blue)));
    // u = (x + 1) / 2 on the floor; a margin keeps pixels off the filter's blend zones.
    let margin = 0.01;
    let (mut red_pixels, mut blue_pixels) = (0, 0);
    let (mut red_mean, mut blue_mean) = (Vec3::ZERO, Vec3::ZERO);
    let mut worst = 0f32;
    for y in 0..h {
        for x in 0..w {
            let hit = hit_plane(&p.camera, &p.scene, w, h, x, y, 0.0).expect("sees the floor");
            let u = (hit.x + 1.0) / 2.0;
            let expected = if (1.0 / 16.0 + margin..7.0 / 16.0 - margin).contains(&u) {
                red_pixels += 1;
                &as_red
            } else if (9.0 / 16.0 + margin..15.0 / 16.0 - margin).contains(&u) {
                blue_pixels += 1;
                &as_blue
            } else {
                continue;
            };
            let i = (y * w + x) as usize;
            let (g, e) = (
                Vec3::from(got.indirect[i]),
                Vec3::from(expected.indirect[i]),
            );
            let relative = ((g - e).abs() / e).max_element();
            worst = worst.max(relative);
            assert!(
                relative < 1e-4,
                "pixel ({x}, {y}) at u {u}: textured {g} vs untextured {e}"
            );
            if std::ptr::eq(expected, &as_red) {
                red_mean += g;
            } else {
                blue_mean += g;
            }
        }
    }
    eprintln!(
        "{red_pixels} red and {blue_pixels} blue pixels; worst relative difference {worst:e}"
    );
    assert!(
        red_pixels >= 20 && blue_pixels >= 20,
        "{red_pixels} red, {blue_pixels} blue"
    );
    // The halves differ as their texels do: red over the red texels, blue over the blue ones.
    let (red_mean, blue_mean) = (red_mean / red_pixels as f32, blue_mean / blue_pixels as f32);
    eprintln!("mean over red texels {red_mean}, over blue texels {blue_mean}");
    assert!(red_mean.x > 2.0 * red_mean.z, "{red_mean}");
    assert!(blue_mean.z > 2.0 * blue_mean.x, "{blue_mean}");
}

/// A black square just above the light of the plates hides the ceiling's lit centre from it.
/// Fully alpha-masked, every ray passes through it: the image is the one without the blocker
/// (same seed, same paths). The same texture on an opaque material (glTF `OPAQUE` or `BLEND`)
/// blocks and darkens; masked on one half only, it darkens less. (Black, so that an opaque
/// blocker does not reflect the light it catches back down.)
#[test]
fn rays_pass_through_alpha_masked_texels() {
    let p = plates();
    let blocker = |vertices: &mut Vec<Vertex>, indices: &mut Vec<u32>| {
        quad(vertices, indices, floor_corners(0.2, -0.1, 0.6, 0.15), 2);
    };
    let (clear, solid) = ([0, 0, 0, 0], [0, 0, 0, 255]);
    let render = |texture: Texture, alpha_cutoff: Option<f32>| {
        let cover = Material {
            base_color_texture: Some(0),
            alpha_cutoff,
            ..plain_material([1.0; 3], 0.0, 1.0)
        };
        let mut materials = p.scene.materials.clone();
        materials.push(cover);
        let scene = plates_with(blocker, materials, vec![texture]);
        let mut tracer = PathTracer::new(support::gpu(), &scene).expect("tracer");
        let settings = ReferenceSettings::default();
        converge(
            &mut tracer,
            (16, 16),
            &p.camera,
            std::slice::from_ref(&p.light),
            &settings,
            64,
        )
    };
    let mut tracer = PathTracer::new(support::gpu(), &p.scene).expect("tracer");
    let settings = ReferenceSettings::default();
    let open = converge(
        &mut tracer,
        (16, 16),
        &p.camera,
        std::slice::from_ref(&p.light),
        &settings,
        64,
    );
    let masked = render(halves(2, 2, clear, clear), Some(0.5));
    let opaque = render(halves(2, 2, clear, clear), None);
    let half_masked = render(halves(4, 2, clear, solid), Some(0.5));
    // Camera rays cross the blocker too, not only bounce and shadow rays.
    let seen = (0..16 * 16)
        .filter_map(|i| hit_plane(&p.camera, &p.scene, 16, 16, i % 16, i / 16, 0.6))
        .filter(|q| (q.x - 0.2).abs() < 0.15 && (q.z + 0.1).abs() < 0.15)
        .count();
    assert!(seen >= 10, "the camera sees the blocker in {seen} pixels");
    let mut worst = 0f32;
    for (m, o) in masked.indirect.iter().zip(&open.indirect) {
        let (m, o) = (Vec3::from(*m), Vec3::from(*o));
        let difference = (m - o).abs().max_element() / o.max_element().max(1e-12);
        worst = worst.max(difference);
        assert!(difference < 1e-5, "masked {m} vs no blocker {o}");
    }
    let mean = |image: &ReferenceImage| {
        image.indirect.iter().map(|c| luminance(*c)).sum::<f32>() / image.indirect.len() as f32
    };
    let (open, opaque, half) = (mean(&open), mean(&opaque), mean(&half_masked));
    eprintln!(
        "blocker in {seen} pixels; masked vs open: worst relative difference {worst:e}; \
         mean luminance open {open}, \
         half-masked {half}, opaque {opaque}"
    );
    assert!(opaque < 0.5 * open, "opaque {opaque} vs open {open}");
    assert!(
        opaque * 1.1 < half && half < 0.9 * open,
        "half-masked {half} between opaque {opaque} and open {open}"
    );
}

/// Emissive surfaces stand for light sources and cast no shadows in the raster passes
/// (`SceneBuffers::shadow_casting`); the reference's shadow rays pass through them alike: a
/// small black lamp quad just above the point light, between it and the upper plate, changes
/// the floor's indirect light little (bounce rays still meet it), where the same quad without
/// emission shadows the plate (before the fix: 23 % of the light left).
#[test]
fn shadow_rays_pass_through_emissive_surfaces() {
    let p = plates();
    // A 0.12 m quad 5 cm above the light, between it and the upper plate, emitting
    // `quad_emission`; none without.
    let render = |quad_emission: Option<[f32; 3]>| {
        let scene = match quad_emission {
            None => p.scene.clone(),
            Some(emissive) => {
                let mut materials = p.scene.materials.clone();
                // Black (metallic with a black base reflects nothing), so only its shadow counts.
                materials.push(Material {
                    emissive,
                    ..plain_material([0.0; 3], 1.0, 1.0)
                });
                let lamp = |vertices: &mut Vec<Vertex>, indices: &mut Vec<u32>| {
                    quad(vertices, indices, floor_corners(0.2, -0.1, 0.6, 0.06), 2);
                };
                plates_with(lamp, materials, Vec::new())
            }
        };
        let mut tracer = PathTracer::new(support::gpu(), &scene).expect("tracer");
        let settings = ReferenceSettings {
            emitters: false,
            ..ReferenceSettings::default()
        };
        let image = converge(
            &mut tracer,
            (16, 16),
            &p.camera,
            std::slice::from_ref(&p.light),
            &settings,
            64,
        );
        image.indirect.iter().map(|c| luminance(*c)).sum::<f32>() / image.indirect.len() as f32
    };
    let open = render(None);
    let lamp = render(Some([4.0, 4.0, 4.0]));
    let blocker = render(Some([0.0; 3]));
    assert!(open > 0.0);
    assert!(
        (lamp / open - 1.0).abs() < 0.05,
        "emissive quad {lamp} vs none {open}"
    );
    assert!(blocker < 0.9 * open, "plain quad {blocker} vs none {open}");
}
