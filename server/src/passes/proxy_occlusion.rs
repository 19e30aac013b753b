//! Proxy-light occlusion (`shaders/proxy_occlusion.wgsl`): the paper's double projection of
//! each proxy's bounding sphere and the other caches' disks onto the target cache's unit disk;
//! the covered fraction dims the proxy.

use crate::gpu::shaders;
use bytemuck::{Pod, Zeroable};

/// Mirrors `OcclusionParams` in `shaders/proxy_occlusion.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct OcclusionParams {
    pub cache_count: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

const WORKGROUP: u32 = 64;

pub struct ProxyOcclusionPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
}

impl ProxyOcclusionPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("proxy occlusion"),
            entries: &[
                super::uniform_entry(0),
                super::storage_entry(1, true),
                super::storage_entry(2, false),
            ],
        });
        let module = shaders::PROXY_OCCLUSION.create_module(device);
        Self {
            pipeline: super::compute_pipeline(
                device,
                "proxy occlusion",
                &layout,
                &module,
                "occlude_proxies",
            ),
            layout,
            params: super::uniform_buffer(
                device,
                "occlusion params",
                std::mem::size_of::<OcclusionParams>(),
            ),
        }
    }

    pub fn bind(
        &self,
        device: &wgpu::Device,
        caches: &wgpu::Buffer,
        lighting: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("proxy occlusion"),
            layout: &self.layout,
            entries: &[
                super::buffer_binding(0, &self.params),
                super::buffer_binding(1, caches),
                super::buffer_binding(2, lighting),
            ],
        })
    }

    pub fn prepare(&self, queue: &wgpu::Queue, cache_count: u32) {
        let params = OcclusionParams {
            cache_count,
            pad0: 0,
            pad1: 0,
            pad2: 0,
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        cache_count: u32,
    ) {
        let mut pass = super::begin_compute(encoder, "proxy occlusion");
        pass.set_bind_group(0, bind_group, &[]);
        pass.set_pipeline(&self.pipeline);
        pass.dispatch_workgroups(cache_count.div_ceil(WORKGROUP).max(1), 1, 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shaders::{layout_check::assert_struct, PROXY_OCCLUSION};
    use std::mem::{offset_of, size_of};

    #[test]
    fn occlusion_params_match_wgsl() {
        assert_struct(
            &PROXY_OCCLUSION,
            "OcclusionParams",
            size_of::<OcclusionParams>(),
            &[
                ("cache_count", offset_of!(OcclusionParams, cache_count)),
                ("pad0", offset_of!(OcclusionParams, pad0)),
                ("pad1", offset_of!(OcclusionParams, pad1)),
                ("pad2", offset_of!(OcclusionParams, pad2)),
            ],
        );
    }
}
