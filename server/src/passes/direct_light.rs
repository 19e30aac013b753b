//! Deferred direct lighting (`shaders/direct_light.wgsl`): emission plus one punctual light
//! with the paper's BRDF (eq. 3–4) and PCF shadows, into the HDR target.

use super::{gbuffer::GBuffer, shadow_map::ShadowMap, Target};
use crate::gpu::shaders;

pub const HDR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

pub struct DirectLightPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    shadow_sampler: wgpu::Sampler,
}

impl DirectLightPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let uniform = |binding| {
            super::buffer_entry(
                binding,
                wgpu::ShaderStages::COMPUTE,
                wgpu::BufferBindingType::Uniform,
            )
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("direct light"),
            entries: &[
                uniform(0),
                uniform(1),
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

    pub fn bind(
        &self,
        device: &wgpu::Device,
        camera: &wgpu::Buffer,
        light: &wgpu::Buffer,
        gbuffer: &GBuffer,
        shadow: &ShadowMap,
        hdr: &Target,
    ) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("direct light"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: camera.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: light.as_entire_binding(),
                },
                super::view_binding(2, &gbuffer.position.view),
                super::view_binding(3, &gbuffer.normal_exponent.view),
                super::view_binding(4, &gbuffer.diffuse.view),
                super::view_binding(5, &gbuffer.glossy.view),
                super::view_binding(6, &gbuffer.emissive.view),
                super::view_binding(7, &shadow.array_view),
                wgpu::BindGroupEntry {
                    binding: 8,
                    resource: wgpu::BindingResource::Sampler(&self.shadow_sampler),
                },
                super::view_binding(9, &hdr.view),
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
