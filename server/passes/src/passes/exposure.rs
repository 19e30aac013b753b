//! Automatic exposure (`shaders/exposure.wgsl`): the log-average luminance of lit pixels is
//! mapped to middle grey, computed on the GPU in two reduction stages.

use super::bind::{self, bind_group};
use super::Target;
use crate::gpu::shaders;
use bytemuck::{Pod, Zeroable};

/// Mirrors `ExposureParams` in `shaders/exposure.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ExposureParams {
    pub tile_count: u32,
    pub key: f32,
    pub min_scale: f32,
    pub max_scale: f32,
}

/// Mirrors `ExposureResult` in `shaders/exposure_result.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ExposureResult {
    pub scale: f32,
    pub mean_log2_luminance: f32,
    pub lit_pixels: f32,
    pub pad0: f32,
}

/// Middle grey: the log-average luminance lands here after exposure.
pub const KEY: f32 = 0.18;
/// Exposure scales the automatic mode may choose (a black frame must not blow up to infinity).
const MIN_SCALE: f32 = 1e-6;
const MAX_SCALE: f32 = 1e6;
/// Matches the 16×16 workgroup of `reduce_tiles`.
const REDUCE_TILE: u32 = 16;

/// How the frame's exposure is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Exposure {
    /// Log-average luminance → middle grey.
    Auto,
    /// A fixed linear scale applied to HDR radiance before the tone curve.
    Manual(f32),
}

bind_group! {
    /// Group 0 of `shaders/exposure.wgsl`.
    pub struct Resources as GROUP("exposure", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        hdr: bind::TEXTURE,
        tiles: bind::STORAGE_RW,
        result: bind::STORAGE_RW,
    }
}

pub struct ExposurePass {
    reduce: wgpu::ComputePipeline,
    finish: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    /// The chosen exposure, read by the tone-map pass.
    pub result: wgpu::Buffer,
}

/// Bindings for one output size.
pub struct ExposureBindings {
    bind_group: wgpu::BindGroup,
    tiles: (u32, u32),
}

impl ExposurePass {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = GROUP.layout(device);
        let module = shaders::EXPOSURE.create_module(device);
        let reduce =
            super::compute_pipeline(device, "exposure tiles", &layout, &module, "reduce_tiles");
        let finish = super::compute_pipeline(device, "exposure finish", &layout, &module, "finish");
        let params = super::params_buffer(
            device,
            "exposure params",
            std::mem::size_of::<ExposureParams>(),
        );
        let result = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("exposure result"),
            size: std::mem::size_of::<ExposureResult>() as u64,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Self {
            reduce,
            finish,
            layout,
            params,
            result,
        }
    }

    pub fn bind(
        &self,
        device: &wgpu::Device,
        hdr: &Target,
        width: u32,
        height: u32,
    ) -> ExposureBindings {
        let tiles = (width.div_ceil(REDUCE_TILE), height.div_ceil(REDUCE_TILE));
        let tile_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("exposure tiles"),
            size: u64::from(tiles.0 * tiles.1) * 8,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let bind_group = Resources {
            params: &self.params,
            hdr,
            tiles: &tile_buffer,
            result: &self.result,
        }
        .bind(device, &self.layout);
        ExposureBindings { bind_group, tiles }
    }

    /// Writes the uniforms for the next frame. A manual exposure is written straight into the
    /// result buffer and [`ExposurePass::encode`] then records nothing.
    pub fn prepare(&self, queue: &wgpu::Queue, bindings: &ExposureBindings, exposure: Exposure) {
        match exposure {
            Exposure::Auto => queue.write_buffer(
                &self.params,
                0,
                bytemuck::bytes_of(&ExposureParams {
                    tile_count: bindings.tiles.0 * bindings.tiles.1,
                    key: KEY,
                    min_scale: MIN_SCALE,
                    max_scale: MAX_SCALE,
                }),
            ),
            Exposure::Manual(scale) => queue.write_buffer(
                &self.result,
                0,
                bytemuck::bytes_of(&ExposureResult {
                    scale,
                    ..Default::default()
                }),
            ),
        }
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bindings: &ExposureBindings,
        exposure: Exposure,
    ) {
        if exposure != Exposure::Auto {
            return;
        }
        let mut pass = super::begin_compute(encoder, "exposure");
        pass.set_bind_group(0, &bindings.bind_group, &[]);
        pass.set_pipeline(&self.reduce);
        pass.dispatch_workgroups(bindings.tiles.0, bindings.tiles.1, 1);
        pass.set_pipeline(&self.finish);
        pass.dispatch_workgroups(1, 1, 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shaders::{layout_check::assert_struct, EXPOSURE, TONEMAP};
    use std::mem::{offset_of, size_of};

    #[test]
    fn exposure_structs_match_wgsl() {
        assert_struct(
            &EXPOSURE,
            "ExposureParams",
            size_of::<ExposureParams>(),
            &[
                ("tile_count", offset_of!(ExposureParams, tile_count)),
                ("key", offset_of!(ExposureParams, key)),
                ("min_scale", offset_of!(ExposureParams, min_scale)),
                ("max_scale", offset_of!(ExposureParams, max_scale)),
            ],
        );
        for source in [&EXPOSURE, &TONEMAP] {
            assert_struct(
                source,
                "ExposureResult",
                size_of::<ExposureResult>(),
                &[
                    ("scale", offset_of!(ExposureResult, scale)),
                    (
                        "mean_log2_luminance",
                        offset_of!(ExposureResult, mean_log2_luminance),
                    ),
                    ("lit_pixels", offset_of!(ExposureResult, lit_pixels)),
                    ("pad0", offset_of!(ExposureResult, pad0)),
                ],
            );
        }
    }
}
