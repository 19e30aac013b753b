//! G-buffer pass: rasterises the scene from the camera. With triangle ids (issue 36) the
//! raster writes a visibility buffer, the triangle id and the base colour
//! (`shaders/gbuffer_visibility.wgsl`, 12 bytes a pixel), and a compute pass resolves it into
//! the G-buffer's targets (`shaders/gbuffer_resolve.wgsl`); without them, or with the
//! visibility buffer turned off, the raster writes every target (`shaders/gbuffer.wgsl`, 44
//! bytes a pixel). Every later pass reads the same targets either way.

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
/// The visibility buffer's base colour (half floats, as [`FORMATS`]' base colour), with the
/// facing in alpha (1 front, 0.5 back, 0 background).
pub const BASE_FACING_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// The G-buffer's textures for one output size.
pub struct GBuffer {
    pub position: Target,
    pub normal_roughness: Target,
    pub base_metallic: Target,
    pub emissive_specular: Target,
    /// Scene-wide triangle id, or the provoking vertex without primitive indices.
    pub id: Target,
    pub depth: Target,
    /// The visibility buffer's base colour and facing (a frame's G-buffer; not the reduced
    /// ones, which a compute pass fills from it).
    pub base_facing: Option<Target>,
}

impl GBuffer {
    /// A frame's G-buffer: rasterised into, or with `visibility` resolved from its visibility
    /// buffer (which it then holds, and its targets take storage writes).
    pub fn new(device: &wgpu::Device, width: u32, height: u32, visibility: bool) -> Self {
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        if !visibility {
            return Self::with_usage(device, width, height, usage);
        }
        Self {
            base_facing: Some(Target::new(
                device,
                "gbuffer base colour and facing",
                width,
                height,
                BASE_FACING_FORMAT,
                usage,
            )),
            ..Self::with_usage(
                device,
                width,
                height,
                usage | wgpu::TextureUsages::STORAGE_BINDING,
            )
        }
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
            base_facing: None,
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

bind_group! {
    /// Group 0 of `shaders/gbuffer_resolve.wgsl`.
    pub struct ResolveResources as RESOLVE_GROUP(
        "gbuffer resolve",
        wgpu::ShaderStages::COMPUTE
    ) {
        camera: bind::PARAMS,
        vis_id: bind::UINT_TEXTURE,
        vis_base: bind::TEXTURE,
        indices: bind::STORAGE,
        vertices: bind::STORAGE,
        materials: bind::STORAGE,
        out_position: bind::storage_texture(FORMATS[0]),
        out_normal_roughness: bind::storage_texture(FORMATS[1]),
        out_base_metallic: bind::storage_texture(FORMATS[2]),
        out_emissive_specular: bind::storage_texture(FORMATS[3]),
    }
}

/// The visibility buffer's raster and resolve.
struct Visibility {
    raster: wgpu::RenderPipeline,
    resolve: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

pub struct GBufferPass {
    /// Rasterises every target.
    pipeline: wgpu::RenderPipeline,
    /// With triangle ids: the visibility buffer.
    visibility: Option<Visibility>,
    camera: wgpu::Buffer,
    camera_bind_group: wgpu::BindGroup,
}

impl GBufferPass {
    /// `triangle_ids` needs `Features::PRIMITIVE_INDEX` on the device; `visibility`: the pass
    /// can draw the visibility buffer (with triangle ids, and where the resolve can bind the
    /// scene's vertex and index buffers whole).
    pub fn new(
        device: &wgpu::Device,
        camera: &wgpu::Buffer,
        material_layout: &wgpu::BindGroupLayout,
        triangle_ids: bool,
        visibility: bool,
    ) -> Self {
        let camera_layout = CAMERA_GROUP.layout(device);
        let camera_bind_group = CameraResources { camera }.bind(device, &camera_layout);
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("gbuffer"),
            bind_group_layouts: &[Some(&camera_layout), Some(material_layout)],
            immediate_size: 0,
        });
        let raster = |label: &str, source: &shaders::ShaderSource, formats| {
            super::scene_buffers::material_pipeline(
                device,
                label,
                &layout,
                &source.create_module(device),
                formats,
                DEPTH_FORMAT,
            )
        };
        let source = if triangle_ids {
            &shaders::GBUFFER_TRIANGLE_IDS
        } else {
            &shaders::GBUFFER
        };
        let visibility = (triangle_ids && visibility).then(|| {
            let resolve_layout = RESOLVE_GROUP.layout(device);
            Visibility {
                raster: raster(
                    "gbuffer visibility",
                    &shaders::GBUFFER_VISIBILITY,
                    &[FORMATS[4], BASE_FACING_FORMAT],
                ),
                resolve: super::compute_pipeline(
                    device,
                    "gbuffer resolve",
                    &resolve_layout,
                    &shaders::GBUFFER_RESOLVE.create_module(device),
                    "resolve",
                ),
                layout: resolve_layout,
            }
        });
        Self {
            pipeline: raster("gbuffer", source, &FORMATS),
            visibility,
            camera: camera.clone(),
            camera_bind_group,
        }
    }

    /// Whether [`Self::encode`] can rasterise a visibility buffer (the device has triangle
    /// ids).
    pub fn has_visibility_buffer(&self) -> bool {
        self.visibility.is_some()
    }

    /// Rasterises the scene: the visibility buffer where `visibility` asks and the device has
    /// triangle ids ([`Self::encode_resolve`] then fills the targets), else every target.
    /// Returns whether it drew the visibility buffer.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        gbuffer: &GBuffer,
        scene: &SceneBuffers,
        visibility: bool,
    ) -> bool {
        let thin = self
            .visibility
            .as_ref()
            .filter(|_| visibility)
            .zip(gbuffer.base_facing.as_ref());
        let (pipeline, views) = match thin {
            Some((v, base)) => (&v.raster, vec![&gbuffer.id.view, &base.view]),
            None => (&self.pipeline, gbuffer.colour_views().to_vec()),
        };
        let mut pass = super::scene_buffers::begin_material_pass(
            encoder,
            "gbuffer",
            &views,
            &gbuffer.depth.view,
        );
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &self.camera_bind_group, &[]);
        scene.draw_with_materials(&mut pass, &scene.ranges);
        thin.is_some()
    }

    /// Resolves the visibility buffer [`Self::encode`] drew into the G-buffer's targets.
    pub fn encode_resolve(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        gbuffer: &GBuffer,
        scene: &SceneBuffers,
    ) {
        let (Some(v), Some(base)) = (&self.visibility, &gbuffer.base_facing) else {
            return;
        };
        let group = ResolveResources {
            camera: &self.camera,
            vis_id: &gbuffer.id,
            vis_base: base,
            indices: &scene.indices,
            vertices: &scene.vertices,
            materials: &scene.material_table,
            out_position: &gbuffer.position,
            out_normal_roughness: &gbuffer.normal_roughness,
            out_base_metallic: &gbuffer.base_metallic,
            out_emissive_specular: &gbuffer.emissive_specular,
        }
        .bind(device, &v.layout);
        let mut pass = super::begin_compute(encoder, "gbuffer resolve");
        pass.set_pipeline(&v.resolve);
        pass.set_bind_group(0, &group, &[]);
        let size = gbuffer.id.texture.size();
        pass.dispatch_workgroups(
            size.width.div_ceil(super::TILE),
            size.height.div_ceil(super::TILE),
            1,
        );
    }
}
