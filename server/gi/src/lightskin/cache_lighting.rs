//! Cache lighting (`shaders/cache_lighting.wgsl`): the diffuse and glossy proxy lights of every
//! light cache from the VALs (eq. 3–7 for LightSkin, eq. 13–15 for the BRSM subset).

use super::cache_buffers::CacheBuffers;
use crate::passes::bind::{self, bind_group};
use crate::passes::rsm::Rsm;
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
    pub first_val: u32,
    pub end_val: u32,
    /// Phong exponent k for every cache, overriding the materials'; 0 keeps their own.
    pub glossy_exponent: f32,
    /// Side of each cache's visibility map (`cache_visibility`); 0: none.
    pub visibility_side: u32,
    /// Cameras in the views buffer the proxies are shared by; 0 or 1: `camera` alone.
    pub view_count: u32,
}

/// Mirrors `Accum` in `shaders/cache_lighting.wgsl`: per-cache sums carried between the
/// chunked dispatches (only its size matters on the CPU).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct CacheAccum {
    pub e_d: [f32; 3],
    pub s_d: f32,
    pub e_g: [f32; 3],
    pub s_g: f32,
    pub p_d: [f32; 3],
    pub pad0: f32,
    pub p_g: [f32; 3],
    pub pad1: f32,
    pub q_d: [f32; 3],
    pub pad2: f32,
    pub q_g: [f32; 3],
    pub pad3: f32,
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

bind_group! {
    /// Group 0 of `shaders/lightskin/cache_lighting.wgsl`.
    pub struct Resources as GROUP("cache lighting", wgpu::ShaderStages::COMPUTE) {
        params: bind::param_slot::<CacheLightingParams>(),
        caches: bind::STORAGE,
        vals: bind::STORAGE,
        rsm_position: bind::TEXTURE,
        rsm_normal: bind::TEXTURE,
        rsm_flux_area: bind::TEXTURE,
        lighting: bind::STORAGE_RW,
        accum: bind::STORAGE_RW,
        rsm_glossy: bind::UINT_TEXTURE,
        visibility: bind::STORAGE,
        views: bind::STORAGE,
    }
}

pub struct CacheLightingPass {
    accumulate: wgpu::ComputePipeline,
    finish: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: crate::passes::ParamSlots,
    /// The camera positions of the sessions sharing the proxies (`shared::MAX_POOLED_VIEWS`).
    views: wgpu::Buffer,
}

impl CacheLightingPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let params = crate::passes::ParamSlots::new::<CacheLightingParams>(
            device,
            "cache lighting params",
            crate::passes::MAX_CHUNKS,
        );
        let layout = GROUP.layout(device);
        let module = super::shaders::CACHE_LIGHTING.create_module(device);
        Self {
            accumulate: crate::passes::compute_pipeline(
                device,
                "cache lighting",
                &layout,
                &module,
                "accumulate_vals",
            ),
            finish: crate::passes::compute_pipeline(
                device,
                "proxy lights",
                &layout,
                &module,
                "finish_proxies",
            ),
            layout,
            params,
            views: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("shared views"),
                size: (super::shared::MAX_POOLED_VIEWS * 16) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        }
    }

    /// Binds the passes to `caches`, writing the proxies into its lighting buffer `lighting`
    /// (`CacheBuffers::lighting_at`).
    pub fn bind(
        &self,
        device: &wgpu::Device,
        (caches, lighting): (&CacheBuffers, usize),
        vals: &wgpu::Buffer,
        rsm: &Rsm,
    ) -> wgpu::BindGroup {
        Resources {
            params: &self.params,
            caches: &caches.caches,
            vals,
            rsm_position: &rsm.position,
            rsm_normal: &rsm.normal,
            rsm_flux_area: &rsm.flux_area,
            lighting: caches.lighting_at(lighting),
            accum: &caches.accum,
            rsm_glossy: &rsm.glossy,
            visibility: &caches.visibility,
            views: &self.views,
        }
        .bind(device, &self.layout)
    }

    /// Writes one parameter slot per chunk of VALs; returns the number of chunks to encode.
    /// `views`: the camera of the frame, or of every session the proxies are shared by (the
    /// glossy lobe's direction is then their mean, see `shared`).
    pub fn prepare(
        &self,
        queue: &wgpu::Queue,
        views: &[[f32; 3]],
        caches: &CacheBuffers,
        rsm: &Rsm,
        source: ValSource,
        glossy_exponent: Option<f32>,
    ) -> u32 {
        let cache_count = caches.count;
        let (val_count, every_texel) = match source {
            ValSource::Selected { count } => (count, 0),
            ValSource::EveryTexel => (rsm.texels(), 1),
        };
        let chunks =
            crate::passes::chunk_ranges(val_count, u64::from(cache_count.max(1)), WORKGROUP);
        let views = &views[..views.len().min(super::shared::MAX_POOLED_VIEWS)];
        let camera = views.first().copied().unwrap_or_default();
        if views.len() > 1 {
            let positions: Vec<[f32; 4]> = views.iter().map(|&[x, y, z]| [x, y, z, 0.0]).collect();
            queue.write_buffer(&self.views, 0, bytemuck::cast_slice(&positions));
        }
        let params: Vec<CacheLightingParams> = chunks
            .iter()
            .map(|range| CacheLightingParams {
                camera,
                cache_count,
                val_count,
                every_texel,
                rsm_width: rsm.width(),
                first_val: range.start,
                end_val: range.end,
                glossy_exponent: glossy_exponent.unwrap_or(0.0),
                visibility_side: caches.visibility_side,
                view_count: views.len() as u32,
            })
            .collect();
        self.params.write(queue, &params);
        chunks.len() as u32
    }

    /// One dispatch per chunk of VALs, then one that builds the proxy lights.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        cache_count: u32,
        chunks: u32,
    ) {
        crate::passes::dispatch_chunked(
            encoder,
            "cache lighting",
            (&self.accumulate, &self.finish),
            bind_group,
            cache_count.div_ceil(WORKGROUP).max(1),
            chunks,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::lightskin::caches::LightCache;
    use crate::gi::lightskin::shaders::CACHE_LIGHTING;
    use crate::gpu::shaders::layout_check::assert_struct;
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
                ("first_val", offset_of!(CacheLightingParams, first_val)),
                ("end_val", offset_of!(CacheLightingParams, end_val)),
                (
                    "glossy_exponent",
                    offset_of!(CacheLightingParams, glossy_exponent),
                ),
                (
                    "visibility_side",
                    offset_of!(CacheLightingParams, visibility_side),
                ),
                ("view_count", offset_of!(CacheLightingParams, view_count)),
            ],
        );
        assert_struct(
            &CACHE_LIGHTING,
            "Accum",
            size_of::<CacheAccum>(),
            &[
                ("e_d", offset_of!(CacheAccum, e_d)),
                ("s_d", offset_of!(CacheAccum, s_d)),
                ("e_g", offset_of!(CacheAccum, e_g)),
                ("s_g", offset_of!(CacheAccum, s_g)),
                ("p_d", offset_of!(CacheAccum, p_d)),
                ("pad0", offset_of!(CacheAccum, pad0)),
                ("p_g", offset_of!(CacheAccum, p_g)),
                ("pad1", offset_of!(CacheAccum, pad1)),
                ("q_d", offset_of!(CacheAccum, q_d)),
                ("pad2", offset_of!(CacheAccum, pad2)),
                ("q_g", offset_of!(CacheAccum, q_g)),
                ("pad3", offset_of!(CacheAccum, pad3)),
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
                ("model", offset_of!(LightCache, model)),
            ],
        );
    }
}
