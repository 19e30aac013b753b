//! The scene on the GPU, shared by every rasterising pass: geometry, the material table and one
//! bind group per material (`shaders/materials.wgsl`, group 1).

use super::bind::{self, bind_group, BindKind};
use crate::scene::{Material, MaterialRange, Scene, Vertex};
use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

/// Mirrors `MaterialGpu` in `shaders/material_model.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct MaterialGpu {
    pub base_color: [f32; 4],
    pub emissive: [f32; 3],
    pub metallic: f32,
    pub roughness: f32,
    pub alpha_cutoff: f32,
    pub specular: f32,
    pub pad0: f32,
}

impl From<&Material> for MaterialGpu {
    fn from(m: &Material) -> Self {
        Self {
            base_color: m.base_color,
            emissive: m.emissive,
            metallic: m.metallic,
            roughness: m.roughness,
            alpha_cutoff: m.alpha_cutoff.unwrap_or(0.0),
            specular: m.specular,
            pad0: 0.0,
        }
    }
}

pub struct SceneBuffers {
    pub vertices: wgpu::Buffer,
    pub indices: wgpu::Buffer,
    pub ranges: Vec<MaterialRange>,
    /// Ranges whose material does not emit light: emitters stand for light sources, so they are
    /// not drawn into the shadow map or the RSM (a lamp's bulb must neither shadow nor reflect
    /// its own light).
    pub shadow_casting: Vec<MaterialRange>,
    /// The ranges of [`Self::shadow_casting`] whose material has an alpha mask, which the
    /// shadow map draws with their materials to cut the masked texels away, and the others,
    /// which it draws depth-only.
    pub shadow_masked: Vec<MaterialRange>,
    pub shadow_opaque: Vec<MaterialRange>,
    /// Group 1 of `shaders/materials.wgsl`, indexed by material.
    pub materials: Vec<wgpu::BindGroup>,
    /// The material table ([`MaterialGpu`] per material) the groups bind as `materials`.
    pub material_table: wgpu::Buffer,
    /// `scene::brdf::BrdfTable` (`[f32; 4]` entries): what every pass that evaluates the BRDF
    /// binds as `brdf_table` (`shaders/brdf_eval.wgsl`).
    pub brdf_table: wgpu::Buffer,
}

bind_group! {
    /// Group 1 of `shaders/materials.wgsl`.
    pub struct MaterialResources as MATERIAL_GROUP("material", wgpu::ShaderStages::FRAGMENT) {
        base_color_texture: BindKind::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: true },
            dimension: wgpu::TextureViewDimension::D2,
        },
        base_color_sampler: BindKind::Sampler(wgpu::SamplerBindingType::Filtering),
        materials: bind::STORAGE,
        brdf_table: bind::STORAGE,
    }
}

impl SceneBuffers {
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        material_layout: &wgpu::BindGroupLayout,
    ) -> Self {
        let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("scene vertices"),
            contents: bytemuck::cast_slice(&scene.vertices),
            // Storage too: indirect light reads triangle corners to find barycentrics.
            // Written again where a frame poses movable nodes (`Renderer`'s poses).
            usage: wgpu::BufferUsages::VERTEX
                | wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST,
        });
        let indices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("scene indices"),
            contents: bytemuck::cast_slice(&scene.indices),
            usage: wgpu::BufferUsages::INDEX | wgpu::BufferUsages::STORAGE,
        });
        let shadow_casting: Vec<MaterialRange> = scene
            .material_ranges
            .iter()
            .filter(|r| !scene.materials[r.material as usize].is_emissive())
            .copied()
            .collect();
        let (shadow_masked, shadow_opaque) = shadow_casting
            .iter()
            .partition(|r| scene.materials[r.material as usize].alpha_cutoff.is_some());
        let brdf_table = brdf_table(device);
        let material_table = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("materials"),
            contents: bytemuck::cast_slice(
                &scene
                    .materials
                    .iter()
                    .map(MaterialGpu::from)
                    .collect::<Vec<_>>(),
            ),
            usage: wgpu::BufferUsages::STORAGE,
        });
        Self {
            vertices,
            indices,
            ranges: scene.material_ranges.clone(),
            shadow_casting,
            shadow_masked,
            shadow_opaque,
            materials: material_bind_groups(
                device,
                queue,
                scene,
                material_layout,
                (&material_table, &brdf_table),
            ),
            material_table,
            brdf_table,
        }
    }

    /// Vertex layout of [`Vertex`]; `attributes` picks the locations a pass reads.
    pub fn vertex_layout(attributes: &[wgpu::VertexAttribute]) -> wgpu::VertexBufferLayout<'_> {
        wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Vertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes,
        }
    }

    /// Draws `ranges` (all of [`Self::ranges`], or the light-facing [`Self::shadow_casting`])
    /// with each range's material bound as group 1. The instance index is the range's first
    /// triangle, so shaders can turn primitive indices into scene-wide triangle ids.
    pub fn draw_with_materials(&self, pass: &mut wgpu::RenderPass<'_>, ranges: &[MaterialRange]) {
        pass.set_vertex_buffer(0, self.vertices.slice(..));
        pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
        for range in ranges {
            pass.set_bind_group(1, &self.materials[range.material as usize], &[]);
            let first_triangle = range.first_index / 3;
            pass.draw_indexed(
                range.first_index..range.first_index + range.index_count,
                0,
                first_triangle..first_triangle + 1,
            );
        }
    }
}

/// A pipeline that rasterises the scene with its materials (group 1) into `formats` with a
/// depth test: the G-buffer and the RSM. Culling is off because glTF allows double-sided
/// materials; the shaders flip back-facing normals.
pub fn material_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    formats: &[wgpu::TextureFormat],
    depth_format: wgpu::TextureFormat,
) -> wgpu::RenderPipeline {
    let targets: Vec<Option<wgpu::ColorTargetState>> = formats
        .iter()
        .map(|&format| {
            Some(wgpu::ColorTargetState {
                format,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })
        })
        .collect();
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[Some(SceneBuffers::vertex_layout(&VERTEX_ATTRIBUTES))],
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: depth_format,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &targets,
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// Begins a render pass for a [`material_pipeline`]: colour targets cleared to zero (w = 0
/// marks "nothing here"), depth cleared to the far plane and discarded afterwards.
pub fn begin_material_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    colour_views: &[&wgpu::TextureView],
    depth_view: &wgpu::TextureView,
) -> wgpu::RenderPass<'e> {
    let attachments: Vec<Option<wgpu::RenderPassColorAttachment>> = colour_views
        .iter()
        .map(|view| Some(super::cleared_attachment(view)))
        .collect();
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &attachments,
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth_view,
            depth_ops: Some(wgpu::Operations {
                load: wgpu::LoadOp::Clear(1.0),
                store: wgpu::StoreOp::Discard,
            }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// All attributes of [`Vertex`] at locations 0–3.
pub const VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 4] =
    wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2, 3 => Uint32];

/// The BRDF's albedo table on the GPU.
pub fn brdf_table(device: &wgpu::Device) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("brdf table"),
        contents: bytemuck::cast_slice(&crate::scene::brdf::BrdfTable::get().entries),
        usage: wgpu::BufferUsages::STORAGE,
    })
}

fn material_bind_groups(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    scene: &Scene,
    layout: &wgpu::BindGroupLayout,
    (table, brdf_table): (&wgpu::Buffer, &wgpu::Buffer),
) -> Vec<wgpu::BindGroup> {
    let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("base colour"),
        address_mode_u: wgpu::AddressMode::Repeat,
        address_mode_v: wgpu::AddressMode::Repeat,
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        ..Default::default()
    });
    let white = upload_texture(device, queue, "white", 1, 1, &[255; 4]);
    let textures: Vec<wgpu::TextureView> = scene
        .textures
        .iter()
        .map(|t| upload_texture(device, queue, &t.name, t.width, t.height, &t.rgba8))
        .collect();
    scene
        .materials
        .iter()
        .map(|m| {
            let view = m
                .base_color_texture
                .and_then(|i| textures.get(i))
                .unwrap_or(&white);
            MaterialResources {
                base_color_texture: view,
                base_color_sampler: &sampler,
                materials: table,
                brdf_table,
            }
            .bind(device, layout)
        })
        .collect()
}

/// Uploads an sRGB RGBA8 image; the sRGB format makes sampling return linear colour.
fn upload_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    width: u32,
    height: u32,
    rgba8: &[u8],
) -> wgpu::TextureView {
    let texture = device.create_texture_with_data(
        queue,
        &wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8UnormSrgb,
            usage: wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        },
        wgpu::util::TextureDataOrder::LayerMajor,
        rgba8,
    );
    texture.create_view(&wgpu::TextureViewDescriptor::default())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shaders::{layout_check::assert_struct, GBUFFER};
    use std::mem::{offset_of, size_of};

    #[test]
    fn material_gpu_matches_wgsl() {
        assert_struct(
            &GBUFFER,
            "MaterialGpu",
            size_of::<MaterialGpu>(),
            &[
                ("base_color", offset_of!(MaterialGpu, base_color)),
                ("emissive", offset_of!(MaterialGpu, emissive)),
                ("metallic", offset_of!(MaterialGpu, metallic)),
                ("roughness", offset_of!(MaterialGpu, roughness)),
                ("alpha_cutoff", offset_of!(MaterialGpu, alpha_cutoff)),
                ("specular", offset_of!(MaterialGpu, specular)),
                ("pad0", offset_of!(MaterialGpu, pad0)),
            ],
        );
    }

    #[test]
    fn vertex_attributes_match_the_vertex_struct() {
        assert_eq!(
            VERTEX_ATTRIBUTES[0].offset as usize,
            offset_of!(Vertex, position)
        );
        assert_eq!(
            VERTEX_ATTRIBUTES[1].offset as usize,
            offset_of!(Vertex, normal)
        );
        assert_eq!(VERTEX_ATTRIBUTES[2].offset as usize, offset_of!(Vertex, uv));
        assert_eq!(
            VERTEX_ATTRIBUTES[3].offset as usize,
            offset_of!(Vertex, material)
        );
        assert_eq!(size_of::<Vertex>(), 36);
    }
}
