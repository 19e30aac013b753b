//! Deferred lighting (`shaders/direct_light.wgsl`): emission, every light with the
//! materials' BRDF (`scene::brdf`) and PCF shadows, plus the indirect target, into HDR; the environment where
//! no geometry is; and the indirect light plus the environment's directional lights' light
//! into `indirect_out` (what a frame reports as its indirect light).

use super::bind::{self, bind_group, BindKind};
use super::{gbuffer::GBuffer, shadow_map::ShadowMap, Target};
use crate::gpu::shaders;

pub const HDR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// What the lighting pass reads and writes.
pub struct DirectLightInputs<'a> {
    pub camera: &'a wgpu::Buffer,
    /// The frame's `LightsUniform`.
    pub lights: &'a wgpu::Buffer,
    pub gbuffer: &'a GBuffer,
    pub shadow: &'a ShadowMap,
    pub indirect: &'a Target,
    /// The packed environment (`passes::environment`).
    pub environment: &'a wgpu::Buffer,
    /// `SceneBuffers::brdf_table`.
    pub brdf_table: &'a wgpu::Buffer,
    pub hdr: &'a Target,
    /// `indirect` plus the environment lights' direct light.
    pub indirect_out: &'a Target,
}

bind_group! {
    /// Group 0 of `shaders/direct_light.wgsl`.
    pub struct Resources as GROUP("direct light", wgpu::ShaderStages::COMPUTE) {
        camera: bind::PARAMS,
        lights: bind::PARAMS,
        g_position: bind::TEXTURE,
        g_normal_roughness: bind::TEXTURE,
        g_base_metallic: bind::TEXTURE,
        g_emissive_specular: bind::TEXTURE,
        shadow_map: BindKind::Texture {
            sample_type: wgpu::TextureSampleType::Depth,
            dimension: wgpu::TextureViewDimension::D2Array,
        },
        shadow_sampler: BindKind::Sampler(wgpu::SamplerBindingType::Comparison),
        hdr_out: bind::storage_texture(HDR_FORMAT),
        indirect: bind::TEXTURE,
        environment: bind::STORAGE,
        indirect_out: bind::storage_texture(super::INDIRECT_FORMAT),
        brdf_table: bind::STORAGE,
    }
}

pub struct DirectLightPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    shadow_sampler: wgpu::Sampler,
}

impl DirectLightPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = GROUP.layout(device);
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
        Resources {
            camera: inputs.camera,
            lights: inputs.lights,
            g_position: &inputs.gbuffer.position,
            g_normal_roughness: &inputs.gbuffer.normal_roughness,
            g_base_metallic: &inputs.gbuffer.base_metallic,
            g_emissive_specular: &inputs.gbuffer.emissive_specular,
            shadow_map: &inputs.shadow.array_view,
            shadow_sampler: &self.shadow_sampler,
            hdr_out: inputs.hdr,
            indirect: inputs.indirect,
            environment: inputs.environment,
            indirect_out: inputs.indirect_out,
            brdf_table: inputs.brdf_table,
        }
        .bind(device, &self.layout)
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
