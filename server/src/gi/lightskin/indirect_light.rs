//! Indirect light per pixel (`shaders/indirect_light.wgsl`): interpolation of the proxy
//! lights of the pixel's 16 light caches (eq. 8–9), into the indirect target.

use crate::gpu::shaders;
use crate::passes::{gbuffer::GBuffer, Target};
use bytemuck::{Pod, Zeroable};

use crate::passes::INDIRECT_FORMAT;

/// Mirrors `IndirectParams` in `shaders/indirect_light.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct IndirectParams {
    pub enabled: u32,
    pub triangle_ids: u32,
    pub pad0: u32,
    pub pad1: u32,
}

/// The light-cache and scene buffers the pass reads.
pub struct CacheInputs<'a> {
    pub caches: &'a wgpu::Buffer,
    pub lighting: &'a wgpu::Buffer,
    pub vertex_caches: &'a wgpu::Buffer,
    pub scene: &'a crate::passes::scene_buffers::SceneBuffers,
}

pub struct IndirectLightPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
}

impl IndirectLightPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("indirect light"),
            entries: &[
                crate::passes::params_entry(0),
                crate::passes::params_entry(1),
                crate::passes::compute_texture_entry(2, false),
                crate::passes::compute_texture_entry(3, false),
                crate::passes::compute_texture_entry(4, false),
                crate::passes::compute_texture_entry(5, false),
                wgpu::BindGroupLayoutEntry {
                    binding: 6,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Uint,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                crate::passes::storage_entry(7, true),
                crate::passes::storage_entry(8, true),
                crate::passes::storage_entry(9, true),
                crate::passes::storage_texture_entry(10, INDIRECT_FORMAT),
                crate::passes::storage_entry(11, true),
                crate::passes::storage_entry(12, true),
            ],
        });
        let module = shaders::INDIRECT_LIGHT.create_module(device);
        let params = crate::passes::params_buffer(
            device,
            "indirect params",
            std::mem::size_of::<IndirectParams>(),
        );
        Self {
            pipeline: crate::passes::compute_pipeline(
                device,
                "indirect light",
                &layout,
                &module,
                "main",
            ),
            layout,
            params,
        }
    }

    pub fn bind(
        &self,
        device: &wgpu::Device,
        camera: &wgpu::Buffer,
        gbuffer: &GBuffer,
        caches: &CacheInputs,
        indirect: &Target,
    ) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("indirect light"),
            layout: &self.layout,
            entries: &[
                crate::passes::buffer_binding(0, camera),
                crate::passes::buffer_binding(1, &self.params),
                crate::passes::view_binding(2, &gbuffer.position.view),
                crate::passes::view_binding(3, &gbuffer.normal_exponent.view),
                crate::passes::view_binding(4, &gbuffer.diffuse.view),
                crate::passes::view_binding(5, &gbuffer.glossy.view),
                crate::passes::view_binding(6, &gbuffer.id.view),
                crate::passes::buffer_binding(7, caches.caches),
                crate::passes::buffer_binding(8, caches.lighting),
                crate::passes::buffer_binding(9, caches.vertex_caches),
                crate::passes::view_binding(10, &indirect.view),
                crate::passes::buffer_binding(11, &caches.scene.indices),
                crate::passes::buffer_binding(12, &caches.scene.vertices),
            ],
        })
    }

    /// `triangle_ids` says what the G-buffer's id target holds.
    pub fn prepare(&self, queue: &wgpu::Queue, enabled: bool, triangle_ids: bool) {
        let params = IndirectParams {
            enabled: u32::from(enabled),
            triangle_ids: u32::from(triangle_ids),
            pad0: 0,
            pad1: 0,
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        width: u32,
        height: u32,
    ) {
        crate::passes::dispatch_2d(
            encoder,
            "indirect light",
            &self.pipeline,
            bind_group,
            width,
            height,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shaders::{layout_check::assert_struct, INDIRECT_LIGHT};
    use std::mem::{offset_of, size_of};

    #[test]
    fn indirect_params_match_wgsl() {
        assert_struct(
            &INDIRECT_LIGHT,
            "IndirectParams",
            size_of::<IndirectParams>(),
            &[
                ("enabled", offset_of!(IndirectParams, enabled)),
                ("triangle_ids", offset_of!(IndirectParams, triangle_ids)),
                ("pad0", offset_of!(IndirectParams, pad0)),
                ("pad1", offset_of!(IndirectParams, pad1)),
            ],
        );
    }
}
