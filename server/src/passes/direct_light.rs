//! Deferred lighting (`shaders/direct_light.wgsl`): emission, one punctual light with the
//! paper's BRDF (eq. 3–4) and PCF shadows, plus the indirect target, into HDR.

use super::{gbuffer::GBuffer, shadow_map::ShadowMap, Target};
use crate::gpu::shaders;

pub const HDR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// What the lighting pass reads and writes.
pub struct DirectLightInputs<'a> {
    pub camera: &'a wgpu::Buffer,
    pub light: &'a wgpu::Buffer,
    pub gbuffer: &'a GBuffer,
    pub shadow: &'a ShadowMap,
    pub indirect: &'a Target,
    pub hdr: &'a Target,
}

pub struct DirectLightPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    shadow_sampler: wgpu::Sampler,
}

impl DirectLightPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("direct light"),
            entries: &[
                super::params_entry(0),
                super::params_entry(1),
                super::compute_texture_entry(2, false),
                super::compute_texture_entry(3, false),
                super::compute_texture_entry(4, false),
                super::compute_texture_entry(5, false),
                super::compute_texture_entry(6, false),
                wgpu::BindGroupLayoutEntry {
                    binding: 7,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 8,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Comparison),
                    count: None,
                },
                super::storage_texture_entry(9, HDR_FORMAT),
                super::compute_texture_entry(10, false),
            ],
        });
        let module = shaders::DIRECT_LIGHT.create_module(device);
        let pipeline = super::compute_pipeline(device, "direct light", &layout, &module, "main");
        let shadow_sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("shadow comparison"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            compare: Some(wgpu::CompareFunction::LessEqual),
            ..Default::default()
        });
        Self {
            pipeline,
            layout,
            shadow_sampler,
        }
    }

    pub fn bind(&self, device: &wgpu::Device, inputs: &DirectLightInputs) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("direct light"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: inputs.camera.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: inputs.light.as_entire_binding(),
                },
                super::view_binding(2, &inputs.gbuffer.position.view),
                super::view_binding(3, &inputs.gbuffer.normal_exponent.view),
                super::view_binding(4, &inputs.gbuffer.diffuse.view),
                super::view_binding(5, &inputs.gbuffer.glossy.view),
                super::view_binding(6, &inputs.gbuffer.emissive.view),
                super::view_binding(7, &inputs.shadow.array_view),
                wgpu::BindGroupEntry {
                    binding: 8,
                    resource: wgpu::BindingResource::Sampler(&self.shadow_sampler),
                },
                super::view_binding(9, &inputs.hdr.view),
                super::view_binding(10, &inputs.indirect.view),
            ],
        })
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
            "direct light",
            &self.pipeline,
            bind_group,
            width,
            height,
        );
    }
}
