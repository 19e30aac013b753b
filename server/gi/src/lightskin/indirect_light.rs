//! Indirect light per pixel (`shaders/indirect_light.wgsl`): interpolation of the proxy
//! lights of the pixel's 16 light caches (eq. 8–9), into the indirect target.

use crate::passes::bind::{self, bind_group, BindKind};
use crate::passes::{gbuffer::GBuffer, Target, INDIRECT_FORMAT};
use bytemuck::{Pod, Zeroable};

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

bind_group! {
    /// Group 0 of `shaders/lightskin/indirect_light.wgsl`.
    pub struct Resources as GROUP("indirect light", wgpu::ShaderStages::COMPUTE) {
        camera: bind::PARAMS,
        params: bind::PARAMS,
        g_position: bind::TEXTURE,
        g_normal_roughness: bind::TEXTURE,
        g_base_metallic: bind::TEXTURE,
        g_emissive_specular: bind::TEXTURE,
        g_id: BindKind::Texture {
            sample_type: wgpu::TextureSampleType::Uint,
            dimension: wgpu::TextureViewDimension::D2,
        },
        caches: bind::STORAGE,
        lighting: bind::STORAGE,
        vertex_caches: bind::STORAGE,
        indirect_out: bind::storage_texture(INDIRECT_FORMAT),
        indices: bind::STORAGE,
        vertices: bind::STORAGE,
        brdf_table: bind::STORAGE,
    }
}

pub struct IndirectLightPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
}

impl IndirectLightPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = GROUP.layout(device);
        let module = super::shaders::INDIRECT_LIGHT.create_module(device);
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
        Resources {
            camera,
            params: &self.params,
            g_position: &gbuffer.position,
            g_normal_roughness: &gbuffer.normal_roughness,
            g_base_metallic: &gbuffer.base_metallic,
            g_emissive_specular: &gbuffer.emissive_specular,
            g_id: &gbuffer.id,
            caches: caches.caches,
            lighting: caches.lighting,
            vertex_caches: caches.vertex_caches,
            indirect_out: indirect,
            indices: &caches.scene.indices,
            vertices: &caches.scene.vertices,
            brdf_table: &caches.scene.brdf_table,
        }
        .bind(device, &self.layout)
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
    use crate::gi::lightskin::shaders::INDIRECT_LIGHT;
    use crate::gpu::shaders::layout_check::assert_struct;
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
