//! G-buffer pass: rasterises the scene from the camera (`shaders/gbuffer.wgsl`).

use super::{scene_buffers::SceneBuffers, Target};
use crate::gpu::shaders;
use crate::scene::{Material, Scene};
use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

/// Mirrors `MaterialGpu` in `shaders/gbuffer.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct MaterialGpu {
    pub base_color: [f32; 4],
    pub emissive: [f32; 3],
    pub metallic: f32,
    pub roughness: f32,
    pub alpha_cutoff: f32,
    pub pad0: f32,
    pub pad1: f32,
}

impl From<&Material> for MaterialGpu {
    fn from(m: &Material) -> Self {
        Self {
            base_color: m.base_color,
            emissive: m.emissive,
            metallic: m.metallic,
            roughness: m.roughness,
            alpha_cutoff: m.alpha_cutoff.unwrap_or(0.0),
            pad0: 0.0,
            pad1: 0.0,
        }
    }
}

/// Formats of the colour targets, in `GBufferOut` location order.
pub const FORMATS: [wgpu::TextureFormat; 5] = [
    wgpu::TextureFormat::Rgba32Float, // world position, w = coverage
    wgpu::TextureFormat::Rgba16Float, // normal, w = glossy exponent
    wgpu::TextureFormat::Rgba8Unorm,  // diffuse albedo
    wgpu::TextureFormat::Rgba8Unorm,  // glossy colour
    wgpu::TextureFormat::Rgba16Float, // emitted radiance
];
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The G-buffer's textures for one output size.
pub struct GBuffer {
    pub position: Target,
    pub normal_exponent: Target,
    pub diffuse: Target,
    pub glossy: Target,
    pub emissive: Target,
    pub depth: Target,
}

impl GBuffer {
    pub fn new(device: &wgpu::Device, width: u32, height: u32) -> Self {
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        let t = |label, format| Target::new(device, label, width, height, format, usage);
        Self {
            position: t("gbuffer position", FORMATS[0]),
            normal_exponent: t("gbuffer normal", FORMATS[1]),
            diffuse: t("gbuffer diffuse", FORMATS[2]),
            glossy: t("gbuffer glossy", FORMATS[3]),
            emissive: t("gbuffer emissive", FORMATS[4]),
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
            &self.normal_exponent.view,
            &self.diffuse.view,
            &self.glossy.view,
            &self.emissive.view,
        ]
    }
}

/// Per-scene bindings: camera + material table (group 0) and one texture group per material.
pub struct GBufferBindings {
    frame: wgpu::BindGroup,
    materials: Vec<wgpu::BindGroup>,
}

pub struct GBufferPass {
    pipeline: wgpu::RenderPipeline,
    frame_layout: wgpu::BindGroupLayout,
    material_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
}

impl GBufferPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("gbuffer frame"),
            entries: &[
                super::buffer_entry(
                    0,
                    wgpu::ShaderStages::VERTEX_FRAGMENT,
                    wgpu::BufferBindingType::Uniform,
                ),
                super::buffer_entry(
                    1,
                    wgpu::ShaderStages::FRAGMENT,
                    wgpu::BufferBindingType::Storage { read_only: true },
                ),
            ],
        });
        let material_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("gbuffer material"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: true },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
            ],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("gbuffer"),
            bind_group_layouts: &[Some(&frame_layout), Some(&material_layout)],
            immediate_size: 0,
        });
        let module = shaders::GBUFFER.create_module(device);
        let targets = FORMATS.map(|format| {
            Some(wgpu::ColorTargetState {
                format,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("gbuffer"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(SceneBuffers::vertex_layout(
                    &super::scene_buffers::VERTEX_ATTRIBUTES,
                ))],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &targets,
            }),
            multiview_mask: None,
            cache: None,
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("base colour"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        Self {
            pipeline,
            frame_layout,
            material_layout,
            sampler,
        }
    }

    /// Uploads the scene's materials and textures and binds them with `camera`.
    pub fn bind_scene(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        camera: &wgpu::Buffer,
    ) -> GBufferBindings {
        let table: Vec<MaterialGpu> = scene.materials.iter().map(MaterialGpu::from).collect();
        let material_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("materials"),
            contents: bytemuck::cast_slice(&table),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let frame = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("gbuffer frame"),
            layout: &self.frame_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: camera.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: material_buffer.as_entire_binding(),
                },
            ],
        });
        let white = upload_texture(device, queue, "white", 1, 1, &[255; 4]);
        let textures: Vec<wgpu::TextureView> = scene
            .textures
            .iter()
            .map(|t| upload_texture(device, queue, &t.name, t.width, t.height, &t.rgba8))
            .collect();
        let materials = scene
            .materials
            .iter()
            .map(|m| {
                let view = m
                    .base_color_texture
                    .and_then(|i| textures.get(i))
                    .unwrap_or(&white);
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(&m.name),
                    layout: &self.material_layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: wgpu::BindingResource::TextureView(view),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: wgpu::BindingResource::Sampler(&self.sampler),
                        },
                    ],
                })
            })
            .collect();
        GBufferBindings { frame, materials }
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        gbuffer: &GBuffer,
        scene: &SceneBuffers,
        bindings: &GBufferBindings,
    ) {
        let attachments = gbuffer.colour_views().map(|view| {
            Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })
        });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("gbuffer"),
            color_attachments: &attachments,
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &gbuffer.depth.view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bindings.frame, &[]);
        pass.set_vertex_buffer(0, scene.vertices.slice(..));
        pass.set_index_buffer(scene.indices.slice(..), wgpu::IndexFormat::Uint32);
        for range in &scene.ranges {
            pass.set_bind_group(1, &bindings.materials[range.material as usize], &[]);
            pass.draw_indexed(
                range.first_index..range.first_index + range.index_count,
                0,
                0..1,
            );
        }
    }
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
    use crate::scene::Vertex;
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
                ("pad0", offset_of!(MaterialGpu, pad0)),
                ("pad1", offset_of!(MaterialGpu, pad1)),
            ],
        );
    }

    #[test]
    fn vertex_attributes_match_the_vertex_struct() {
        let attrs = super::super::scene_buffers::VERTEX_ATTRIBUTES;
        assert_eq!(attrs[0].offset as usize, offset_of!(Vertex, position));
        assert_eq!(attrs[1].offset as usize, offset_of!(Vertex, normal));
        assert_eq!(attrs[2].offset as usize, offset_of!(Vertex, uv));
        assert_eq!(attrs[3].offset as usize, offset_of!(Vertex, material));
        assert_eq!(size_of::<Vertex>(), 36);
    }
}
