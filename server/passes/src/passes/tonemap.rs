//! Tone mapping (`shaders/tonemap.wgsl`): exposure, ACES-fitted curve, sRGB, 8-bit output.

use super::bind::{self, bind_group};
use super::Target;
use crate::gpu::shaders;

pub const LDR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

bind_group! {
    /// Group 0 of `shaders/tonemap.wgsl`.
    pub struct Resources as GROUP("tonemap", wgpu::ShaderStages::COMPUTE) {
        hdr: bind::TEXTURE,
        exposure: bind::STORAGE,
        ldr_out: bind::storage_texture(LDR_FORMAT),
    }
}

pub struct TonemapPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl TonemapPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = GROUP.layout(device);
        let module = shaders::TONEMAP.create_module(device);
        let pipeline = super::compute_pipeline(device, "tonemap", &layout, &module, "main");
        Self { pipeline, layout }
    }

    pub fn bind(
        &self,
        device: &wgpu::Device,
        hdr: &Target,
        exposure: &wgpu::Buffer,
        ldr: &Target,
    ) -> wgpu::BindGroup {
        Resources {
            hdr,
            exposure,
            ldr_out: ldr,
        }
        .bind(device, &self.layout)
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        width: u32,
        height: u32,
    ) {
        super::dispatch_2d(
            encoder,
            "tonemap",
            &self.pipeline,
            bind_group,
            width,
            height,
        );
    }
}

/// Rec. 709 luminance, as `luminance` in `shaders/reference/path_trace.wgsl`.
pub fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// CPU port of `shaders/tonemap.wgsl` for one linear colour: exposure, ACES fit, sRGB, 8 bits.
/// Used by debug views that tone-map buffers read back from the GPU, and by tests.
pub fn tonemap_cpu(linear: [f32; 3], exposure: f32) -> [u8; 3] {
    let aces = |x: f32| ((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0);
    let srgb = |c: f32| {
        if c <= 0.003_130_8 {
            c * 12.92
        } else {
            1.055 * c.powf(1.0 / 2.4) - 0.055
        }
    };
    linear.map(|c| (srgb(aces(c * exposure)) * 255.0).round() as u8)
}
