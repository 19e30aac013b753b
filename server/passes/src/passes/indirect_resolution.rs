//! Indirect light at a reduced resolution (`gi.indirect_downscale`): the G-buffer is reduced
//! to 1/factor of the output's width and height (`shaders/gbuffer_reduce.wgsl`), the GI method
//! computes indirect light there, and a joint bilateral upsample
//! (`shaders/indirect_upsample.wgsl`) brings it back to the output's pixels without bleeding
//! across edges. Indirect light is smooth, so a quarter or a sixteenth of the per-pixel work
//! of a method (a 48-cache interpolation, a loop over VPLs, a path tracer)
//! buys most of its cost back at little error; [`upsample_cpu`] is the CPU port the tests
//! compare with.

use super::bind::{self, bind_group, BindKind};
use super::gbuffer::{GBuffer, FORMATS};
use super::{Target, INDIRECT_FORMAT};
use crate::gpu::shaders;
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// Largest downscale factor accepted (1 is full resolution).
pub const MAX_DOWNSCALE: u32 = 4;

/// Mirrors `ReduceParams` in `shaders/gbuffer_reduce.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ReduceParams {
    pub factor: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// Mirrors `UpsampleParams` in `shaders/indirect_upsample.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct UpsampleParams {
    pub factor: u32,
    /// Side of a reduced pixel in scene units per unit of distance from the camera.
    pub footprint: f32,
    pub pad0: u32,
    pub pad1: u32,
}

impl UpsampleParams {
    /// For an output `height` pixels tall seen with a vertical field of view of `fov_y_degrees`.
    pub fn new(factor: u32, fov_y_degrees: f32, height: u32) -> Self {
        let pixel = 2.0 * (fov_y_degrees.to_radians() * 0.5).tan() / height.max(1) as f32;
        Self {
            factor,
            footprint: pixel * factor as f32,
            pad0: 0,
            pad1: 0,
        }
    }
}

bind_group! {
    /// Group 0 of `shaders/gbuffer_reduce.wgsl`.
    pub struct ReduceResources as REDUCE_GROUP("gbuffer reduce", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        g_position: bind::TEXTURE,
        g_normal_roughness: bind::TEXTURE,
        g_base_metallic: bind::TEXTURE,
        g_emissive_specular: bind::TEXTURE,
        g_id: BindKind::Texture {
            sample_type: wgpu::TextureSampleType::Uint,
            dimension: wgpu::TextureViewDimension::D2,
        },
        out_position: bind::storage_texture(FORMATS[0]),
        out_normal_roughness: bind::storage_texture(FORMATS[1]),
        out_base_metallic: bind::storage_texture(FORMATS[2]),
        out_emissive_specular: bind::storage_texture(FORMATS[3]),
        out_id: bind::storage_texture(FORMATS[4]),
    }
}

bind_group! {
    /// Group 0 of `shaders/indirect_upsample.wgsl`.
    pub struct UpsampleResources as UPSAMPLE_GROUP("indirect upsample", wgpu::ShaderStages::COMPUTE) {
        camera: bind::PARAMS,
        params: bind::PARAMS,
        g_position: bind::TEXTURE,
        g_normal_roughness: bind::TEXTURE,
        g_base_metallic: bind::TEXTURE,
        r_position: bind::TEXTURE,
        r_normal_roughness: bind::TEXTURE,
        r_base_metallic: bind::TEXTURE,
        r_indirect: bind::TEXTURE,
        indirect_out: bind::storage_texture(INDIRECT_FORMAT),
    }
}

/// The reduced G-buffer and indirect target of one output size and factor, with the bind
/// groups that fill them from and return them to the full-resolution targets.
pub struct ReducedTargets {
    pub factor: u32,
    pub width: u32,
    pub height: u32,
    pub gbuffer: GBuffer,
    pub indirect: Target,
    reduce_params: wgpu::Buffer,
    upsample_params: wgpu::Buffer,
    reduce_group: wgpu::BindGroup,
    upsample_group: wgpu::BindGroup,
}

/// The full-resolution targets a [`ReducedTargets`] is made for.
pub struct FullTargets<'a> {
    pub camera: &'a wgpu::Buffer,
    pub gbuffer: &'a GBuffer,
    pub indirect: &'a Target,
    pub width: u32,
    pub height: u32,
}

/// The reduce and upsample pipelines.
pub struct IndirectResolutionPass {
    reduce: wgpu::ComputePipeline,
    reduce_layout: wgpu::BindGroupLayout,
    upsample: wgpu::ComputePipeline,
    upsample_layout: wgpu::BindGroupLayout,
}

impl IndirectResolutionPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let reduce_layout = REDUCE_GROUP.layout(device);
        let upsample_layout = UPSAMPLE_GROUP.layout(device);
        let reduce_module = shaders::GBUFFER_REDUCE.create_module(device);
        let upsample_module = shaders::INDIRECT_UPSAMPLE.create_module(device);
        Self {
            reduce: super::compute_pipeline(
                device,
                "gbuffer reduce",
                &reduce_layout,
                &reduce_module,
                "main",
            ),
            upsample: super::compute_pipeline(
                device,
                "indirect upsample",
                &upsample_layout,
                &upsample_module,
                "main",
            ),
            reduce_layout,
            upsample_layout,
        }
    }

    /// Targets at 1/`factor` of `full`'s size (rounded up), bound to `full`.
    pub fn targets(
        &self,
        device: &wgpu::Device,
        full: &FullTargets,
        factor: u32,
    ) -> ReducedTargets {
        let width = full.width.div_ceil(factor);
        let height = full.height.div_ceil(factor);
        // The copy usages let tests read the reduction and write the indirect light.
        let gbuffer = GBuffer::with_usage(
            device,
            width,
            height,
            wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        let indirect = Target::new(
            device,
            "reduced indirect",
            width,
            height,
            INDIRECT_FORMAT,
            wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_DST,
        );
        let params = |label, size| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: super::PARAMS_USAGE,
                mapped_at_creation: false,
            })
        };
        let reduce_params = params(
            "gbuffer reduce params",
            std::mem::size_of::<ReduceParams>() as u64,
        );
        let upsample_params = params(
            "indirect upsample params",
            std::mem::size_of::<UpsampleParams>() as u64,
        );
        let g = full.gbuffer;
        let reduce_group = ReduceResources {
            params: &reduce_params,
            g_position: &g.position,
            g_normal_roughness: &g.normal_roughness,
            g_base_metallic: &g.base_metallic,
            g_emissive_specular: &g.emissive_specular,
            g_id: &g.id,
            out_position: &gbuffer.position,
            out_normal_roughness: &gbuffer.normal_roughness,
            out_base_metallic: &gbuffer.base_metallic,
            out_emissive_specular: &gbuffer.emissive_specular,
            out_id: &gbuffer.id,
        }
        .bind(device, &self.reduce_layout);
        let upsample_group = UpsampleResources {
            camera: full.camera,
            params: &upsample_params,
            g_position: &g.position,
            g_normal_roughness: &g.normal_roughness,
            g_base_metallic: &g.base_metallic,
            r_position: &gbuffer.position,
            r_normal_roughness: &gbuffer.normal_roughness,
            r_base_metallic: &gbuffer.base_metallic,
            r_indirect: &indirect,
            indirect_out: full.indirect,
        }
        .bind(device, &self.upsample_layout);
        ReducedTargets {
            factor,
            width,
            height,
            gbuffer,
            indirect,
            reduce_params,
            upsample_params,
            reduce_group,
            upsample_group,
        }
    }

    /// Writes this frame's parameters (the camera's field of view sets the plane tolerance).
    pub fn prepare(
        &self,
        queue: &wgpu::Queue,
        targets: &ReducedTargets,
        fov_y_degrees: f32,
        full_height: u32,
    ) {
        let reduce = ReduceParams {
            factor: targets.factor,
            pad0: 0,
            pad1: 0,
            pad2: 0,
        };
        queue.write_buffer(&targets.reduce_params, 0, bytemuck::bytes_of(&reduce));
        let upsample = UpsampleParams::new(targets.factor, fov_y_degrees, full_height);
        queue.write_buffer(&targets.upsample_params, 0, bytemuck::bytes_of(&upsample));
    }

    pub fn encode_reduce(&self, encoder: &mut wgpu::CommandEncoder, targets: &ReducedTargets) {
        super::dispatch_2d(
            encoder,
            "gbuffer reduce",
            &self.reduce,
            &targets.reduce_group,
            targets.width,
            targets.height,
        );
    }

    pub fn encode_upsample(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        targets: &ReducedTargets,
        full_width: u32,
        full_height: u32,
    ) {
        super::dispatch_2d(
            encoder,
            "indirect upsample",
            &self.upsample,
            &targets.upsample_group,
            full_width,
            full_height,
        );
    }
}

/// One G-buffer texel as the upsample reads it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Texel {
    pub position: Vec3,
    /// False for background.
    pub covered: bool,
    pub normal: Vec3,
    /// The material's reflectance: its base colour (what carries its texture detail) plus, for
    /// a dielectric, its 4 % specular reflection (`reflectance` in the WGSL).
    pub reflectance: Vec3,
}

/// Reflectance floor of the demodulation (`MIN_REFLECTANCE` in the WGSL).
const MIN_REFLECTANCE: f32 = 0.02;
const NORMAL_POWER: f32 = 16.0;
const PLANE_FOOTPRINTS: f32 = 1.0;
const MIN_WEIGHT: f32 = 1e-3;

/// CPU port of `shaders/indirect_upsample.wgsl` for the pixel at `texel` of a `full` image
/// (row-major, `full_width` wide) from the `reduced` G-buffer and its `indirect` radiance
/// (row-major, `reduced_width` wide), seen from `camera`.
#[allow(clippy::too_many_arguments)]
pub fn upsample_cpu(
    params: &UpsampleParams,
    camera: Vec3,
    full: &[Texel],
    full_width: u32,
    reduced: &[Texel],
    indirect: &[Vec3],
    reduced_width: u32,
    texel: (u32, u32),
) -> Vec3 {
    let p = full[(texel.1 * full_width + texel.0) as usize];
    if !p.covered {
        return Vec3::ZERO;
    }
    let reduced_height = reduced.len() as u32 / reduced_width;
    let last = (reduced_width as i32 - 1, reduced_height as i32 - 1);
    let at = |q: (i32, i32)| (q.1 as u32 * reduced_width + q.0 as u32) as usize;
    let clamp = |x: i32, y: i32| (x.clamp(0, last.0), y.clamp(0, last.1));
    let n_p = p.normal.normalize();
    let tolerance = PLANE_FOOTPRINTS * params.footprint * camera.distance(p.position).max(1e-6);
    let reflectance = |t: &Texel| t.reflectance.max(Vec3::splat(MIN_REFLECTANCE));
    let weights = |q: (i32, i32)| {
        let s = reduced[at(q)];
        if !s.covered {
            return (0.0, 0.0);
        }
        let plane = n_p.dot(s.position - p.position) / tolerance;
        let facing = n_p.dot(s.normal.normalize()).max(0.0);
        (
            facing.powf(NORMAL_POWER) * (-plane * plane).exp(),
            (facing + 0.01) / (1.0 + plane * plane),
        )
    };
    let demodulated = |q: (i32, i32)| indirect[at(q)] / reflectance(&reduced[at(q)]);
    let f = params.factor as f32;
    let u = (
        (texel.0 as f32 - (params.factor / 2) as f32) / f,
        (texel.1 as f32 - (params.factor / 2) as f32) / f,
    );
    let base = (u.0.floor() as i32, u.1.floor() as i32);
    let t = (u.0 - u.0.floor(), u.1 - u.1.floor());
    let mut sum = Vec3::ZERO;
    let mut total = 0.0;
    for dy in 0..2 {
        for dx in 0..2 {
            let q = clamp(base.0 + dx, base.1 + dy);
            let bx = if dx == 1 { t.0 } else { 1.0 - t.0 };
            let by = if dy == 1 { t.1 } else { 1.0 - t.1 };
            let w = bx * by * weights(q).0;
            sum += w * demodulated(q);
            total += w;
        }
    }
    let radiance = if total >= MIN_WEIGHT {
        sum / total
    } else {
        let nearest = clamp((u.0 + 0.5).floor() as i32, (u.1 + 0.5).floor() as i32);
        let mut best = (0.0, Vec3::ZERO);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let q = clamp(nearest.0 + dx, nearest.1 + dy);
                let w = weights(q).1;
                if w > best.0 {
                    best = (w, demodulated(q));
                }
            }
        }
        best.1
    };
    radiance * reflectance(&p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shaders::{layout_check::assert_struct, GBUFFER_REDUCE, INDIRECT_UPSAMPLE};
    use std::mem::{offset_of, size_of};

    #[test]
    fn resolution_structs_match_wgsl() {
        assert_struct(
            &GBUFFER_REDUCE,
            "ReduceParams",
            size_of::<ReduceParams>(),
            &[
                ("factor", offset_of!(ReduceParams, factor)),
                ("pad0", offset_of!(ReduceParams, pad0)),
                ("pad1", offset_of!(ReduceParams, pad1)),
                ("pad2", offset_of!(ReduceParams, pad2)),
            ],
        );
        assert_struct(
            &INDIRECT_UPSAMPLE,
            "UpsampleParams",
            size_of::<UpsampleParams>(),
            &[
                ("factor", offset_of!(UpsampleParams, factor)),
                ("footprint", offset_of!(UpsampleParams, footprint)),
                ("pad0", offset_of!(UpsampleParams, pad0)),
                ("pad1", offset_of!(UpsampleParams, pad1)),
            ],
        );
    }
}
