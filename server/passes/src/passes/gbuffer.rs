//! G-buffer pass: rasterises the scene from the camera (`shaders/gbuffer.wgsl`).

use super::bind::{self, bind_group};
use super::{scene_buffers::SceneBuffers, Target};
use crate::gpu::shaders;

/// Formats of the colour targets, in `GBufferOut` location order. The material's factors
/// are stored, not a diffuse/glossy split, so every pass shades with the same BRDF
/// (`shaders/brdf_eval.wgsl`); base colour in half floats keeps dark albedos exact to
/// 0.05 % (8-bit linear lost a few per cent below 0.1).
pub const FORMATS: [wgpu::TextureFormat; 5] = [
    wgpu::TextureFormat::Rgba32Float, // world position, w = coverage
    wgpu::TextureFormat::Rgba16Float, // normal, w = roughness
    wgpu::TextureFormat::Rgba16Float, // linear base colour, w = metallic
    wgpu::TextureFormat::Rgba16Float, // emitted radiance, w = dielectric specular weight
    wgpu::TextureFormat::R32Uint,     // triangle or provoking-vertex id (finds the light caches)
];
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The G-buffer's textures for one output size.
pub struct GBuffer {
    pub position: Target,
    pub normal_roughness: Target,
    pub base_metallic: Target,
    pub emissive_specular: Target,
    /// Scene-wide triangle id, or the provoking vertex without primitive indices.
    pub id: Target,
    pub depth: Target,
}

impl GBuffer {
    pub fn new(device: &wgpu::Device, width: u32, height: u32) -> Self {
        Self::with_usage(
            device,
            width,
            height,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        )
    }

    /// A G-buffer whose colour targets have `usage` (a compute pass writing them, as
    /// [`super::indirect_resolution`]'s reduction does, needs `STORAGE_BINDING`).
    pub fn with_usage(
        device: &wgpu::Device,
        width: u32,
        height: u32,
        usage: wgpu::TextureUsages,
    ) -> Self {
        let t = |label, format| Target::new(device, label, width, height, format, usage);
        // A viewer's click reads one texel of these back (`RenderSettings::pick`).
        let picked = usage | wgpu::TextureUsages::COPY_SRC;
        Self {
            position: Target::new(
                device,
                "gbuffer position",
                width,
                height,
                FORMATS[0],
                picked,
            ),
            normal_roughness: t("gbuffer normal", FORMATS[1]),
            base_metallic: t("gbuffer base colour", FORMATS[2]),
            emissive_specular: t("gbuffer emissive", FORMATS[3]),
            id: Target::new(device, "gbuffer id", width, height, FORMATS[4], picked),
            depth: Target::new(
                device,
                "gbuffer depth",
                width,
                height,
                DEPTH_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
            ),
        }
    }

    fn colour_views(&self) -> [&wgpu::TextureView; 5] {
        [
            &self.position.view,
            &self.normal_roughness.view,
            &self.base_metallic.view,
            &self.emissive_specular.view,
            &self.id.view,
        ]
    }
}

bind_group! {
    /// Group 0 of `shaders/gbuffer.wgsl` (group 1 is [`super::scene_buffers::MATERIAL_GROUP`]).
    pub struct CameraResources as CAMERA_GROUP(
        "gbuffer camera",
        wgpu::ShaderStages::VERTEX_FRAGMENT
    ) {
        camera: bind::PARAMS,
    }
}

pub struct GBufferPass {
    pipeline: wgpu::RenderPipeline,
    camera_bind_group: wgpu::BindGroup,
}

impl GBufferPass {
    /// `triangle_ids` needs `Features::PRIMITIVE_INDEX` on the device.
    pub fn new(
        device: &wgpu::Device,
        camera: &wgpu::Buffer,
        material_layout: &wgpu::BindGroupLayout,
        triangle_ids: bool,
    ) -> Self {
        let camera_layout = CAMERA_GROUP.layout(device);
        let camera_bind_group = CameraResources { camera }.bind(device, &camera_layout);
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("gbuffer"),
            bind_group_layouts: &[Some(&camera_layout), Some(material_layout)],
            immediate_size: 0,
        });
        let source = if triangle_ids {
            &shaders::GBUFFER_TRIANGLE_IDS
        } else {
            &shaders::GBUFFER
        };
        let module = source.create_module(device);
        let pipeline = super::scene_buffers::material_pipeline(
            device,
            "gbuffer",
            &layout,
            &module,
            &FORMATS,
            DEPTH_FORMAT,
        );
        Self {
            pipeline,
            camera_bind_group,
        }
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        gbuffer: &GBuffer,
        scene: &SceneBuffers,
    ) {
        let mut pass = super::scene_buffers::begin_material_pass(
            encoder,
            "gbuffer",
            &gbuffer.colour_views(),
            &gbuffer.depth.view,
        );
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.camera_bind_group, &[]);
        scene.draw_with_materials(&mut pass, &scene.ranges);
    }
}
