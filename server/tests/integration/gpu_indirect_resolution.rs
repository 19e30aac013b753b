//! Indirect light at reduced resolution (`gi.indirect_downscale`): the G-buffer reduction and
//! the joint bilateral upsample on the GPU (lavapipe in CI) against their CPU port on a
//! synthetic G-buffer with a step edge, a perpendicular wall, background and a checker
//! texture; and whole frames at 1/2 and 1/4 resolution against full resolution.

use crate::support::*;
use glam::Vec3;
use lightcast_protocol::Camera;
use lightcast_server::gi::lightskin::caches::{precompute, CacheParams};
use lightcast_server::gi::lightskin::LightSkin;
use lightcast_server::gi::GiParams;
use lightcast_server::gpu::readback::TextureReadback;
use lightcast_server::gpu::GpuContext;
use lightcast_server::passes::frame_uniforms::CameraUniform;
use lightcast_server::passes::gbuffer::GBuffer;
use lightcast_server::passes::indirect_resolution::{
    upsample_cpu, FullTargets, IndirectResolutionPass, ReducedTargets, Texel, UpsampleParams,
};
use lightcast_server::passes::{Target, INDIRECT_FORMAT, PARAMS_USAGE};
use lightcast_server::renderer::Renderer;
use lightcast_server::scene::default_light::{default_camera, default_light};
use lightcast_server::scene::procedural;
use wgpu::util::DeviceExt;

const W: u32 = 61;
const H: u32 = 37;
const FOV: f32 = 45.0;
const EYE: Vec3 = Vec3::new(0.0, 0.0, 5.0);
/// Depth of the step: the right half of the image sees a plane this far behind the left's.
const STEP: f32 = 2.0;

/// What the synthetic G-buffer shows at a pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Region {
    /// The plane z = 0 facing the camera.
    Near,
    /// The plane z = −STEP, also facing the camera, across a step edge.
    Far,
    /// A wall facing +x, perpendicular to both.
    Wall,
    Background,
}

fn region(x: u32, y: u32) -> Region {
    if x > 52 && y < 6 {
        Region::Background
    } else if x < 25 {
        Region::Near
    } else if y < 26 {
        Region::Far
    } else {
        Region::Wall
    }
}

/// The full-resolution texel at (x, y), with its base colour and metallic as the G-buffer
/// stores them (half floats).
fn texel(x: u32, y: u32) -> (Texel, [f32; 4]) {
    let (sx, sy) = ((x as f32 - 30.0) * 0.1, (y as f32 - 18.0) * -0.1);
    let (position, normal) = match region(x, y) {
        Region::Near => (Vec3::new(sx, sy, 0.0), Vec3::Z),
        Region::Far => (Vec3::new(sx, sy, -STEP), Vec3::Z),
        Region::Wall => (Vec3::new(0.5, sy, -0.1 * (x as f32 - 25.0)), Vec3::X),
        Region::Background => (Vec3::ZERO, Vec3::Z),
    };
    // A checker finer than the reduced grid: only demodulation keeps it.
    let base = if (x + y).is_multiple_of(2) {
        [0.78, 0.47, 0.12]
    } else {
        [0.16, 0.35, 0.63]
    }
    .map(|c| half::f16::from_f32(c).to_f32());
    let covered = region(x, y) != Region::Background;
    (
        Texel {
            position,
            covered,
            normal,
            // A dielectric (metallic 0): its base colour plus the 4 % specular reflection.
            reflectance: Vec3::from(base) + 0.04,
        },
        [base[0], base[1], base[2], 0.0],
    )
}

fn upload(ctx: &GpuContext, target: &Target, width: u32, height: u32, bytes: &[u8], bpp: u32) {
    ctx.queue.write_texture(
        target.texture.as_image_copy(),
        bytes,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(width * bpp),
            rows_per_image: Some(height),
        },
        wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
    );
}

fn f16s(values: impl IntoIterator<Item = f32>) -> Vec<u8> {
    let halves: Vec<half::f16> = values.into_iter().map(half::f16::from_f32).collect();
    bytemuck::cast_slice(&halves).to_vec()
}

fn read(ctx: &GpuContext, texture: &wgpu::Texture, width: u32, height: u32, bpp: u32) -> Vec<u8> {
    let readback = TextureReadback::new(&ctx.device, "test readback", width, height, bpp);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    readback.encode_copy(&mut encoder, texture);
    ctx.queue.submit([encoder.finish()]);
    readback.read(ctx).expect("readback")
}

fn rgba16(bytes: &[u8]) -> Vec<[f32; 4]> {
    let halves: Vec<half::f16> = bytemuck::pod_collect_to_vec(bytes);
    halves
        .chunks_exact(4)
        .map(|c| [c[0].to_f32(), c[1].to_f32(), c[2].to_f32(), c[3].to_f32()])
        .collect()
}

/// The reduced G-buffer as the GPU wrote it, as upsample inputs.
fn read_reduced(ctx: &GpuContext, r: &ReducedTargets) -> Vec<Texel> {
    let (w, h) = (r.width, r.height);
    let positions: Vec<[f32; 4]> =
        bytemuck::pod_collect_to_vec(&read(ctx, &r.gbuffer.position.texture, w, h, 16));
    let normals = rgba16(&read(ctx, &r.gbuffer.normal_roughness.texture, w, h, 8));
    let base = rgba16(&read(ctx, &r.gbuffer.base_metallic.texture, w, h, 8));
    (0..(w * h) as usize)
        .map(|i| Texel {
            position: Vec3::new(positions[i][0], positions[i][1], positions[i][2]),
            covered: positions[i][3] != 0.0,
            normal: Vec3::new(normals[i][0], normals[i][1], normals[i][2]),
            reflectance: Vec3::new(base[i][0], base[i][1], base[i][2]) + 0.04 * (1.0 - base[i][3]),
        })
        .collect()
}

/// The synthetic G-buffer reduced by `factor` on the GPU, the reduced indirect light set to
/// `ratio(reduced texel) × its reflectance`, and upsampled: returns the full texels, the
/// reduced ones, the reduced indirect light and the upsampled result.
struct Run {
    full: Vec<Texel>,
    reduced: Vec<Texel>,
    reduced_width: u32,
    indirect: Vec<Vec3>,
    result: Vec<[f32; 4]>,
}

fn run(ctx: &GpuContext, factor: u32, ratio: impl Fn(&Texel) -> Vec3) -> Run {
    let device = &ctx.device;
    let gbuffer = GBuffer::with_usage(
        device,
        W,
        H,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    );
    let pixels: Vec<(Texel, [f32; 4])> = (0..H)
        .flat_map(|y| (0..W).map(move |x| texel(x, y)))
        .collect();
    let full: Vec<Texel> = pixels.iter().map(|p| p.0).collect();
    let position: Vec<f32> = full
        .iter()
        .flat_map(|t| {
            let w = if t.covered { 1.0 } else { 0.0 };
            [t.position.x, t.position.y, t.position.z, w]
        })
        .collect();
    upload(
        ctx,
        &gbuffer.position,
        W,
        H,
        bytemuck::cast_slice(&position),
        16,
    );
    let normals = f16s(
        full.iter()
            .flat_map(|t| [t.normal.x, t.normal.y, t.normal.z, 0.5]),
    );
    upload(ctx, &gbuffer.normal_roughness, W, H, &normals, 8);
    let base = f16s(pixels.iter().flat_map(|p| p.1));
    upload(ctx, &gbuffer.base_metallic, W, H, &base, 8);
    upload(
        ctx,
        &gbuffer.emissive_specular,
        W,
        H,
        &f16s(vec![0.0; (W * H * 4) as usize]),
        8,
    );
    let ids: Vec<u32> = (0..W * H).collect();
    upload(ctx, &gbuffer.id, W, H, bytemuck::cast_slice(&ids), 4);
    let indirect = Target::new(
        device,
        "full indirect",
        W,
        H,
        INDIRECT_FORMAT,
        wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
    );
    let camera = Camera {
        position: EYE.to_array(),
        target: [0.0, 0.0, 0.0],
        fov_y_degrees: FOV,
    };
    let uniform = CameraUniform {
        position: EYE.to_array(),
        ..bytemuck::Zeroable::zeroed()
    };
    let camera_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("camera"),
        contents: bytemuck::bytes_of(&uniform),
        usage: PARAMS_USAGE,
    });
    let pass = IndirectResolutionPass::new(device);
    let reduced = pass.targets(
        device,
        &FullTargets {
            camera: &camera_buffer,
            gbuffer: &gbuffer,
            indirect: &indirect,
            width: W,
            height: H,
        },
        factor,
    );
    pass.prepare(&ctx.queue, &reduced, camera.fov_y_degrees, H);
    let mut encoder = device.create_command_encoder(&Default::default());
    pass.encode_reduce(&mut encoder, &reduced);
    ctx.queue.submit([encoder.finish()]);
    let reduced_texels = read_reduced(ctx, &reduced);
    // Radiance as the GPU stores it (f16), so the CPU port reads the same numbers.
    let light: Vec<Vec3> = reduced_texels
        .iter()
        .map(|t| {
            let v = ratio(t) * t.reflectance;
            let q = |c: f32| half::f16::from_f32(c).to_f32();
            Vec3::new(q(v.x), q(v.y), q(v.z))
        })
        .collect();
    let bytes = f16s(light.iter().flat_map(|v| [v.x, v.y, v.z, 1.0]));
    upload(
        ctx,
        &reduced.indirect,
        reduced.width,
        reduced.height,
        &bytes,
        8,
    );
    let mut encoder = device.create_command_encoder(&Default::default());
    pass.encode_upsample(&mut encoder, &reduced, W, H);
    ctx.queue.submit([encoder.finish()]);
    let result = rgba16(&read(ctx, &indirect.texture, W, H, 8));
    Run {
        full,
        reduced: reduced_texels,
        reduced_width: reduced.width,
        indirect: light,
        result,
    }
}

fn at(result: &[[f32; 4]], x: u32, y: u32) -> Vec3 {
    let c = result[(y * W + x) as usize];
    Vec3::new(c[0], c[1], c[2])
}

#[test]
fn reduction_copies_the_block_centre_or_its_first_covered_pixel() {
    let ctx = gpu();
    for factor in [2, 3, 4] {
        let r = run(&ctx, factor, |_| Vec3::ONE);
        assert_eq!(r.reduced_width, W.div_ceil(factor));
        for (i, got) in r.reduced.iter().enumerate() {
            let (rx, ry) = (i as u32 % r.reduced_width, i as u32 / r.reduced_width);
            let clamp = |x: u32, y: u32| (x.min(W - 1), y.min(H - 1));
            let centre = clamp(rx * factor + factor / 2, ry * factor + factor / 2);
            let first_covered = (0..factor)
                .flat_map(|y| (0..factor).map(move |x| (x, y)))
                .map(|(x, y)| clamp(rx * factor + x, ry * factor + y))
                .find(|&(x, y)| region(x, y) != Region::Background);
            let pick = if region(centre.0, centre.1) != Region::Background {
                centre
            } else {
                first_covered.unwrap_or(centre)
            };
            let want = texel(pick.0, pick.1).0;
            assert_eq!(
                got.covered, want.covered,
                "factor {factor}, reduced {rx},{ry}"
            );
            assert!(
                got.position.distance(want.position) < 1e-6
                    && got.normal.distance(want.normal) < 1e-3
                    && got.reflectance.distance(want.reflectance) < 1e-6,
                "factor {factor}, reduced {rx},{ry}: {got:?}, want {want:?}"
            );
        }
    }
}

#[test]
fn upsample_matches_its_cpu_port() {
    let ctx = gpu();
    for factor in [2, 3, 4] {
        // Light that varies across the image, per unit reflectance.
        let r = run(&ctx, factor, |t| {
            Vec3::new(
                0.5 + 0.3 * t.position.x.sin(),
                0.4 + 0.1 * t.position.y,
                0.2 + 0.05 * t.position.z,
            )
        });
        let params = UpsampleParams::new(factor, FOV, H);
        let mut worst = 0.0f32;
        for y in 0..H {
            for x in 0..W {
                let want = upsample_cpu(
                    &params,
                    EYE,
                    &r.full,
                    W,
                    &r.reduced,
                    &r.indirect,
                    r.reduced_width,
                    (x, y),
                );
                let got = at(&r.result, x, y);
                // f16 output: 2^-11 relative, plus the weights' f32 rounding.
                let error = (got - want).abs().max_element() / (want.max_element() + 1e-3);
                worst = worst.max(error);
                assert!(
                    error < 2e-3,
                    "factor {factor}, pixel {x},{y}: GPU {got}, CPU {want}"
                );
            }
        }
        eprintln!("factor {factor}: worst relative difference GPU vs CPU {worst:.2e}");
    }
}

#[test]
fn upsample_keeps_light_on_its_own_side_of_edges_and_keeps_texture_detail() {
    let ctx = gpu();
    // One light level per surface, per unit reflectance: any blend across an edge shows.
    let level = |t: &Texel| {
        if !t.covered {
            Vec3::ZERO
        } else if t.normal.x > 0.5 {
            Vec3::splat(5.0)
        } else if t.position.z < -0.5 * STEP {
            Vec3::splat(20.0)
        } else {
            Vec3::ONE
        }
    };
    let r = run(&ctx, 2, level);
    let mut checked = 0;
    for y in 0..H {
        for x in 0..W {
            let (t, _) = texel(x, y);
            let got = at(&r.result, x, y);
            let want = level(&t) * t.reflectance;
            assert!(
                (got - want).abs().max_element() <= 0.01 * want.max_element() + 1e-3,
                "pixel {x},{y} ({:?}): {got}, its surface's level gives {want}",
                region(x, y)
            );
            checked += 1;
        }
    }
    assert_eq!(checked, W * H);
}

/// Indirect light (linear RGB) of the Cornell box with BRSM at `downscale`.
fn cornell_indirect(renderer: &mut Renderer, downscale: u32) -> (Vec<[f32; 4]>, Vec<[u8; 4]>) {
    let scene = procedural::cornell_box();
    let mut s = settings(128, 96, default_camera(&scene), default_light(&scene));
    s.gi = GiParams::new(lightcast_server::gi::lightskin::BRSM)
        .with("rsm_size", 64)
        .with("view_samples", 64)
        .with("val_count", 1024)
        .with("indirect_downscale", downscale);
    let frame = renderer.render(&s).expect("render");
    let ldr = frame
        .rgba8
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    (frame.indirect.expect("captured"), ldr)
}

#[test]
fn reduced_resolution_frames_stay_close_to_full_resolution() {
    let scene = procedural::cornell_box();
    let caches = precompute(&scene, &CacheParams::for_scene(&scene), &mut |_| {}).expect("caches");
    let mut renderer = Renderer::new(gpu(), scene);
    renderer
        .gi::<LightSkin>()
        .expect("LightSkin is registered")
        .set_caches(&caches)
        .expect("caches fit");
    let (full, full_ldr) = cornell_indirect(&mut renderer, 1);
    let luminance = |c: &[f32; 4]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    let mean: f32 = full.iter().map(luminance).sum::<f32>() / full.len() as f32;
    assert!(mean > 0.0, "the box has indirect light");
    let rgb = |p: &[[u8; 4]]| p.iter().map(|c| [c[0], c[1], c[2]]).collect::<Vec<_>>();
    for (downscale, max_relative_mae, min_psnr) in [(2, 0.06, 35.0), (4, 0.12, 30.0)] {
        let (reduced, ldr) = cornell_indirect(&mut renderer, downscale);
        let mae: f32 = full
            .iter()
            .zip(&reduced)
            .map(|(a, b)| (luminance(a) - luminance(b)).abs())
            .sum::<f32>()
            / full.len() as f32;
        let psnr = lightcast_server::quality::psnr(&rgb(&full_ldr), &rgb(&ldr));
        eprintln!(
            "indirect at 1/{downscale}: luminance MAE {:.2} % of the mean, final image PSNR {psnr:.1} dB",
            100.0 * mae / mean
        );
        assert!(
            mae / mean < max_relative_mae,
            "1/{downscale}: MAE {} of mean {mean}",
            mae
        );
        assert!(psnr > min_psnr, "1/{downscale}: PSNR {psnr}");
    }
    // Full resolution again after reduced frames: the renderer dropped the reduced targets.
    let (again, _) = cornell_indirect(&mut renderer, 1);
    let same = full
        .iter()
        .zip(&again)
        .all(|(a, b)| (luminance(a) - luminance(b)).abs() <= 1e-3 * mean.max(1e-3));
    assert!(
        same,
        "full resolution is unchanged by reduced frames in between"
    );
}
