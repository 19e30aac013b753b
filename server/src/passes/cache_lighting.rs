//! Cache lighting (`shaders/cache_lighting.wgsl`): the diffuse and glossy proxy lights of every
//! light cache from the VALs (eq. 3–7 for LightSkin, eq. 13–15 for the BRSM subset).

use super::rsm::Rsm;
use crate::gpu::shaders;
use bytemuck::{Pod, Zeroable};

/// Mirrors `CacheLighting` in `shaders/light_caches.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct CacheLighting {
    pub diffuse_position: [f32; 3],
    pub diffuse_radius: f32,
    pub diffuse_flux: [f32; 3],
    pub pad0: f32,
    pub glossy_position: [f32; 3],
    pub glossy_radius: f32,
    pub glossy_flux: [f32; 3],
    pub pad1: f32,
}

/// Mirrors `CacheLightingParams` in `shaders/cache_lighting.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct CacheLightingParams {
    pub camera: [f32; 3],
    pub cache_count: u32,
    pub val_count: u32,
    pub every_texel: u32,
    pub rsm_width: u32,
    pub pad0: u32,
}

/// Where the VALs come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValSource {
    /// The BRSM selection: `count` weighted VALs.
    Selected { count: u32 },
    /// LightSkin: every RSM texel, weight 1.
    EveryTexel,
}

const WORKGROUP: u32 = 64;

pub struct CacheLightingPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
}

impl CacheLightingPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let read = wgpu::BufferBindingType::Storage { read_only: true };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("cache lighting"),
            entries: &[
                super::buffer_entry(
                    0,
                    wgpu::ShaderStages::COMPUTE,
                    wgpu::BufferBindingType::Uniform,
                ),
                super::buffer_entry(1, wgpu::ShaderStages::COMPUTE, read),
                super::buffer_entry(2, wgpu::ShaderStages::COMPUTE, read),
                super::compute_texture_entry(3, false),
                super::compute_texture_entry(4, false),
                super::compute_texture_entry(5, false),
                super::buffer_entry(
                    6,
                    wgpu::ShaderStages::COMPUTE,
                    wgpu::BufferBindingType::Storage { read_only: false },
                ),
            ],
        });
        let module = shaders::CACHE_LIGHTING.create_module(device);
        Self {
            pipeline: super::compute_pipeline(
                device,
                "cache lighting",
                &layout,
                &module,
                "light_caches",
            ),
            layout,
            params: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("cache lighting params"),
                size: std::mem::size_of::<CacheLightingParams>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        }
    }

    pub fn bind(
        &self,
        device: &wgpu::Device,
        caches: &wgpu::Buffer,
        vals: &wgpu::Buffer,
        rsm: &Rsm,
        lighting: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("cache lighting"),
            layout: &self.layout,
            entries: &[
                super::buffer_binding(0, &self.params),
                super::buffer_binding(1, caches),
                super::buffer_binding(2, vals),
                super::view_binding(3, &rsm.position.view),
                super::view_binding(4, &rsm.normal.view),
                super::view_binding(5, &rsm.flux_area.view),
                super::buffer_binding(6, lighting),
            ],
        })
    }

    pub fn prepare(
        &self,
        queue: &wgpu::Queue,
        camera: [f32; 3],
        cache_count: u32,
        rsm: &Rsm,
        source: ValSource,
    ) {
        let (val_count, every_texel) = match source {
            ValSource::Selected { count } => (count, 0),
            ValSource::EveryTexel => (rsm.texels(), 1),
        };
        let params = CacheLightingParams {
            camera,
            cache_count,
            val_count,
            every_texel,
            rsm_width: rsm.width(),
            pad0: 0,
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        cache_count: u32,
    ) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("cache lighting"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, bind_group, &[]);
        pass.set_pipeline(&self.pipeline);
        pass.dispatch_workgroups(cache_count.div_ceil(WORKGROUP).max(1), 1, 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::caches::LightCache;
    use crate::gpu::shaders::{layout_check::assert_struct, CACHE_LIGHTING};
    use std::mem::{offset_of, size_of};

    #[test]
    fn cache_structs_match_wgsl() {
        assert_struct(
            &CACHE_LIGHTING,
            "CacheLighting",
            size_of::<CacheLighting>(),
            &[
                (
                    "diffuse_position",
                    offset_of!(CacheLighting, diffuse_position),
                ),
                ("diffuse_radius", offset_of!(CacheLighting, diffuse_radius)),
                ("diffuse_flux", offset_of!(CacheLighting, diffuse_flux)),
                ("pad0", offset_of!(CacheLighting, pad0)),
                (
                    "glossy_position",
                    offset_of!(CacheLighting, glossy_position),
                ),
                ("glossy_radius", offset_of!(CacheLighting, glossy_radius)),
                ("glossy_flux", offset_of!(CacheLighting, glossy_flux)),
                ("pad1", offset_of!(CacheLighting, pad1)),
            ],
        );
        assert_struct(
            &CACHE_LIGHTING,
            "CacheLightingParams",
            size_of::<CacheLightingParams>(),
            &[
                ("camera", offset_of!(CacheLightingParams, camera)),
                ("cache_count", offset_of!(CacheLightingParams, cache_count)),
                ("val_count", offset_of!(CacheLightingParams, val_count)),
                ("every_texel", offset_of!(CacheLightingParams, every_texel)),
                ("rsm_width", offset_of!(CacheLightingParams, rsm_width)),
                ("pad0", offset_of!(CacheLightingParams, pad0)),
            ],
        );
        assert_struct(
            &CACHE_LIGHTING,
            "LightCache",
            size_of::<LightCache>(),
            &[
                ("position", offset_of!(LightCache, position)),
                ("area", offset_of!(LightCache, area)),
                ("normal", offset_of!(LightCache, normal)),
                ("disk_area", offset_of!(LightCache, disk_area)),
                ("diffuse", offset_of!(LightCache, diffuse)),
                ("exponent", offset_of!(LightCache, exponent)),
                ("glossy", offset_of!(LightCache, glossy)),
                ("pad0", offset_of!(LightCache, pad0)),
            ],
        );
    }
}
