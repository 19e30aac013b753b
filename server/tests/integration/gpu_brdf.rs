//! The BRDF on the GPU (`shaders/brdf_eval.wgsl`) against its CPU reference (`scene::brdf`):
//! f_r and the paper's lobes fitted to it, over materials and directions that cover grazing
//! angles, smooth and rough lobes, metals, dielectrics and the specular weight.

use crate::support;
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use lightcast_server::gi::common::shaders::BRDF_TEST;
use lightcast_server::gpu::readback::map_read;
use lightcast_server::passes::scene_buffers::brdf_table;
use lightcast_server::scene::brdf::Brdf;
use wgpu::util::DeviceExt;

/// Mirrors `BrdfCase` in `shaders/brdf_test.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct BrdfCase {
    base: [f32; 3],
    metallic: f32,
    n: [f32; 3],
    roughness: f32,
    to_light: [f32; 3],
    specular: f32,
    to_viewer: [f32; 3],
    pad0: f32,
}

/// A deterministic spread of cases: directions on the upper hemisphere of a tilted normal,
/// from normal incidence to 2° above the horizon.
fn cases() -> Vec<BrdfCase> {
    let n = Vec3::new(0.2, 1.0, -0.1).normalize();
    let (t, b) = n.any_orthonormal_pair();
    let dir = |cos: f32, phi: f32| {
        let sin = (1.0 - cos * cos).sqrt();
        (t * phi.cos() + b * phi.sin()) * sin + n * cos
    };
    let materials = [
        ([0.8, 0.6, 0.4], 0.0, 1.0, 1.0),
        ([0.5, 0.5, 0.5], 0.0, 0.3, 1.0),
        ([0.95, 0.64, 0.54], 1.0, 0.25, 1.0),
        ([0.9, 0.9, 0.9], 1.0, 0.045, 1.0),
        ([0.3, 0.7, 0.2], 0.4, 0.6, 0.5),
        ([0.7, 0.7, 0.7], 0.0, 0.8, 0.0),
    ];
    let cosines = [1.0, 0.8, 0.5, 0.2, 0.035];
    let mut out = Vec::new();
    for (base, metallic, roughness, specular) in materials {
        for (i, &cl) in cosines.iter().enumerate() {
            for (j, &cv) in cosines.iter().enumerate() {
                // Mirror-like pairs (opposite azimuths) and off-mirror ones.
                let phi_l = 0.3 + i as f32;
                let phi_v = phi_l
                    + if (i + j) % 2 == 0 {
                        std::f32::consts::PI
                    } else {
                        1.1
                    };
                out.push(BrdfCase {
                    base,
                    metallic,
                    n: n.to_array(),
                    roughness,
                    to_light: dir(cl, phi_l).to_array(),
                    specular,
                    to_viewer: dir(cv, phi_v).to_array(),
                    pad0: 0.0,
                });
            }
        }
    }
    out
}

#[test]
fn the_gpu_brdf_matches_its_cpu_reference() {
    let ctx = support::gpu();
    let device = &ctx.device;
    let cases = cases();
    let storage = |label, contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage: wgpu::BufferUsages::STORAGE | usage,
        })
    };
    let input = storage(
        "cases",
        bytemuck::cast_slice(&cases),
        wgpu::BufferUsages::empty(),
    );
    let results = storage(
        "results",
        &vec![0u8; cases.len() * 64],
        wgpu::BufferUsages::COPY_SRC,
    );
    let table = brdf_table(device);
    let module = BRDF_TEST.create_module(device);
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("brdf test"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[&input, &results, &table]
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect::<Vec<_>>(),
    });
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("brdf readback"),
        size: results.size(),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups((cases.len() as u32).div_ceil(64), 1, 1);
    }
    encoder.copy_buffer_to_buffer(&results, 0, &staging, 0, None);
    ctx.queue.submit([encoder.finish()]);
    let got: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&map_read(&ctx, &staging).expect("map"));

    // f32 on both sides, different operation orders and pow implementations: 1e-4 relative to
    // the larger of the value and a small floor. At the sharpest lobe (r = 0.045, α² = 4·10⁻⁶)
    // GGX's denominator near its peak is α² + (1 − (n·h)²), whose second term is f32 rounding
    // of n·h there: 1 % between any two f32 evaluations.
    let mut peak = 0.0f32;
    for (k, c) in cases.iter().enumerate() {
        let tolerance = if c.roughness < 0.1 { 1e-2 } else { 1e-4 };
        let close =
            |a: Vec3, b: Vec3| (a - b).abs().max_element() <= tolerance * b.max_element().max(1e-2);
        let brdf = Brdf::new(c.base.into(), c.metallic, c.roughness, c.specular);
        let (n, l, v) = (c.n.into(), c.to_light.into(), c.to_viewer.into());
        let f = brdf.eval(n, l, v);
        peak = peak.max(f.max_element());
        let lobes = brdf.lobes(Vec3::from(c.n).dot(v).max(0.0));
        let [f_gpu, d_gpu, g_gpu, fd_gpu] = [0, 1, 2, 3].map(|i| got[4 * k + i]);
        let f_diffuse = brdf.eval_diffuse(n, l, v);
        assert!(
            close(Vec3::from_slice(&fd_gpu), f_diffuse),
            "case {k}: diffuse f_r GPU {fd_gpu:?} vs CPU {f_diffuse}"
        );
        assert!(
            close(Vec3::from_slice(&f_gpu), f),
            "case {k} {c:?}: f_r GPU {f_gpu:?} vs CPU {f}"
        );
        assert!(
            close(Vec3::from_slice(&d_gpu), lobes.diffuse),
            "case {k}: diffuse lobe GPU {d_gpu:?} vs CPU {}",
            lobes.diffuse
        );
        assert!(
            close(Vec3::from_slice(&g_gpu), lobes.glossy),
            "case {k}: glossy lobe GPU {g_gpu:?} vs CPU {}",
            lobes.glossy
        );
        assert!((d_gpu[3] - lobes.exponent).abs() <= 1e-4 * lobes.exponent);
    }
    // The cases reach a mirror-like peak, so the check covers GGX's sharp end.
    assert!(peak > 100.0, "peak f_r {peak}");
}
