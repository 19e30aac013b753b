//! Proxy-light occlusion (`shaders/proxy_occlusion.wgsl`): the paper's double projection of
//! each proxy's bounding sphere and the other caches' disks onto the target cache's unit disk;
//! the covered fraction dims the proxy.

use crate::passes::bind::{self, bind_group};
use bytemuck::{Pod, Zeroable};

/// Mirrors `OcclusionParams` in `shaders/proxy_occlusion.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct OcclusionParams {
    pub cache_count: u32,
    pub first_occluder: u32,
    pub end_occluder: u32,
    pub pad0: u32,
}

const WORKGROUP: u32 = 64;

bind_group! {
    /// Group 0 of `shaders/lightskin/proxy_occlusion.wgsl`.
    pub struct Resources as GROUP("proxy occlusion", wgpu::ShaderStages::COMPUTE) {
        params: bind::param_slot::<OcclusionParams>(),
        caches: bind::STORAGE,
        lighting: bind::STORAGE_RW,
        coverage: bind::STORAGE_RW,
    }
}

pub struct ProxyOcclusionPass {
    accumulate: wgpu::ComputePipeline,
    apply: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: crate::passes::ParamSlots,
}

impl ProxyOcclusionPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let params = crate::passes::ParamSlots::new::<OcclusionParams>(
            device,
            "occlusion params",
            crate::passes::MAX_CHUNKS,
        );
        let layout = GROUP.layout(device);
        let module = super::shaders::PROXY_OCCLUSION.create_module(device);
        Self {
            accumulate: crate::passes::compute_pipeline(
                device,
                "occlusion coverage",
                &layout,
                &module,
                "accumulate_coverage",
            ),
            apply: crate::passes::compute_pipeline(
                device,
                "proxy occlusion",
                &layout,
                &module,
                "apply_occlusion",
            ),
            layout,
            params,
        }
    }

    pub fn bind(
        &self,
        device: &wgpu::Device,
        caches: &wgpu::Buffer,
        lighting: &wgpu::Buffer,
        coverage: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        Resources {
            params: &self.params,
            caches,
            lighting,
            coverage,
        }
        .bind(device, &self.layout)
    }

    /// Writes one parameter slot per chunk of occluders; returns the number of chunks.
    pub fn prepare(&self, queue: &wgpu::Queue, cache_count: u32) -> u32 {
        let chunks =
            crate::passes::chunk_ranges(cache_count, u64::from(cache_count.max(1)), WORKGROUP);
        let params: Vec<OcclusionParams> = chunks
            .iter()
            .map(|range| OcclusionParams {
                cache_count,
                first_occluder: range.start,
                end_occluder: range.end,
                pad0: 0,
            })
            .collect();
        self.params.write(queue, &params);
        chunks.len() as u32
    }

    /// One dispatch per chunk of occluders, then one that dims the proxies.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        cache_count: u32,
        chunks: u32,
    ) {
        crate::passes::dispatch_chunked(
            encoder,
            "proxy occlusion",
            (&self.accumulate, &self.apply),
            bind_group,
            cache_count.div_ceil(WORKGROUP).max(1),
            chunks,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::lightskin::shaders::PROXY_OCCLUSION;
    use crate::gpu::shaders::layout_check::assert_struct;
    use std::mem::{offset_of, size_of};

    #[test]
    fn occlusion_params_match_wgsl() {
        assert_struct(
            &PROXY_OCCLUSION,
            "OcclusionParams",
            size_of::<OcclusionParams>(),
            &[
                ("cache_count", offset_of!(OcclusionParams, cache_count)),
                (
                    "first_occluder",
                    offset_of!(OcclusionParams, first_occluder),
                ),
                ("end_occluder", offset_of!(OcclusionParams, end_occluder)),
                ("pad0", offset_of!(OcclusionParams, pad0)),
            ],
        );
    }
}
