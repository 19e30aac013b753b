//! Shadow-map pass: depth of the scene from each light face (`shaders/shadow_map.wgsl`).

use super::bind::{self, bind_group};
use super::scene_buffers::{SceneBuffers, VERTEX_ATTRIBUTES};
use super::ParamSlots;
use crate::gpu::shaders;

pub const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// A point light's six faces for each of the most lights a frame has.
const MAX_FACES: u32 = 6 * super::frame_uniforms::MAX_LIGHTS as u32;

/// The depth array of a frame's lights (every light's faces, see `LightsUniform`) at one
/// resolution.
pub struct ShadowMap {
    texture: wgpu::Texture,
    /// Every layer, for the lighting pass.
    pub array_view: wgpu::TextureView,
    face_views: Vec<wgpu::TextureView>,
    pub size: u32,
    /// The light faces and poses its depth was last drawn with ([`super::reuse`]).
    pub made: super::reuse::MadeFrom,
}

impl ShadowMap {
    pub fn new(device: &wgpu::Device, size: u32, faces: u32) -> Self {
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("shadow map"),
            size: wgpu::Extent3d {
                width: size,
                height: size,
                depth_or_array_layers: faces,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let array_view = texture.create_view(&wgpu::TextureViewDescriptor {
            label: Some("shadow map array"),
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let face_views = (0..faces)
            .map(|layer| {
                texture.create_view(&wgpu::TextureViewDescriptor {
                    label: Some("shadow map face"),
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: layer,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
            .collect();
        Self {
            texture,
            array_view,
            face_views,
            size,
            made: Default::default(),
        }
    }

    pub fn faces(&self) -> u32 {
        self.texture.depth_or_array_layers()
    }
}

bind_group! {
    /// Group 0 of `shaders/shadow_map.wgsl`.
    pub struct Resources as GROUP("shadow map", wgpu::ShaderStages::VERTEX) {
        face_view_proj: bind::param_slot::<[[f32; 4]; 4]>(),
    }
}

pub struct ShadowMapPass {
    /// Depth-only, for opaque materials.
    pipeline: wgpu::RenderPipeline,
    /// With the materials bound as group 1, for alpha-masked ones.
    masked: wgpu::RenderPipeline,
    face_matrices: ParamSlots,
    bind_group: wgpu::BindGroup,
}

impl ShadowMapPass {
    pub fn new(device: &wgpu::Device, material_layout: &wgpu::BindGroupLayout) -> Self {
        let layout = GROUP.layout(device);
        let face_matrices =
            ParamSlots::new::<[[f32; 4]; 4]>(device, "shadow face matrices", MAX_FACES);
        let bind_group = Resources {
            face_view_proj: &face_matrices,
        }
        .bind(device, &layout);
        let module = shaders::SHADOW_MAP.create_module(device);
        let pipeline = |label, groups: &[Option<&wgpu::BindGroupLayout>], masked: bool| {
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: groups,
                immediate_size: 0,
            });
            let position = wgpu::vertex_attr_array![0 => Float32x3];
            let attributes: &[wgpu::VertexAttribute] = if masked {
                &VERTEX_ATTRIBUTES
            } else {
                &position
            };
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some(if masked { "vs_masked" } else { "vs_main" }),
                    compilation_options: Default::default(),
                    buffers: &[Some(SceneBuffers::vertex_layout(attributes))],
                },
                primitive: wgpu::PrimitiveState {
                    topology: wgpu::PrimitiveTopology::TriangleList,
                    cull_mode: None,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: FORMAT,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::LessEqual),
                    stencil: Default::default(),
                    // Only a tiny constant bias: acne is handled by the normal offset in the
                    // lookup. A slope-scaled bias pushes grazing occluder faces so far back
                    // that light leaks past box edges (measured by the Cornell ray-caster
                    // test).
                    bias: wgpu::DepthBiasState {
                        constant: 2,
                        slope_scale: 0.0,
                        clamp: 0.0,
                    },
                }),
                multisample: Default::default(),
                fragment: masked.then(|| wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_masked"),
                    compilation_options: Default::default(),
                    targets: &[],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        Self {
            pipeline: pipeline("shadow map", &[Some(&layout)], false),
            masked: pipeline(
                "shadow map (alpha-masked)",
                &[Some(&layout), Some(material_layout)],
                true,
            ),
            face_matrices,
            bind_group,
        }
    }

    /// Uploads the layer matrices (`LightsUniform::layer_view_proj`) for the next encode.
    pub fn set_faces(&self, queue: &wgpu::Queue, faces: &[[[f32; 4]; 4]]) {
        self.face_matrices.write(queue, faces);
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        map: &ShadowMap,
        scene: &SceneBuffers,
    ) {
        for (face, view) in map.face_views.iter().enumerate() {
            let mut pass = super::begin_depth_pass(encoder, "shadow map face", view);
            let offset = [ParamSlots::offset(face as u32)];
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &offset);
            pass.set_vertex_buffer(0, scene.vertices.slice(..));
            pass.set_index_buffer(scene.indices.slice(..), wgpu::IndexFormat::Uint32);
            for range in &scene.shadow_opaque {
                pass.draw_indexed(
                    range.first_index..range.first_index + range.index_count,
                    0,
                    0..1,
                );
            }
            if !scene.shadow_masked.is_empty() {
                pass.set_pipeline(&self.masked);
                pass.set_bind_group(0, &self.bind_group, &offset);
                scene.draw_with_materials(&mut pass, &scene.shadow_masked);
            }
        }
    }
}
