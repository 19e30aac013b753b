//! The scene's geometry on the GPU, shared by every rasterising pass.

use crate::scene::{MaterialRange, Scene, Vertex};
use wgpu::util::DeviceExt;

pub struct SceneBuffers {
    pub vertices: wgpu::Buffer,
    pub indices: wgpu::Buffer,
    pub ranges: Vec<MaterialRange>,
    /// Ranges whose material emits light: emitters stand for light sources, so they are not
    /// drawn into the shadow map (a lamp's bulb must not shadow its own light).
    pub shadow_casting: Vec<MaterialRange>,
}

impl SceneBuffers {
    pub fn new(device: &wgpu::Device, scene: &Scene) -> Self {
        let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("scene vertices"),
            contents: bytemuck::cast_slice(&scene.vertices),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let indices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("scene indices"),
            contents: bytemuck::cast_slice(&scene.indices),
            usage: wgpu::BufferUsages::INDEX,
        });
        let shadow_casting = scene
            .material_ranges
            .iter()
            .filter(|r| !scene.materials[r.material as usize].is_emissive())
            .copied()
            .collect();
        Self {
            vertices,
            indices,
            ranges: scene.material_ranges.clone(),
            shadow_casting,
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
}

/// All attributes of [`Vertex`] at locations 0–3.
pub const VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 4] =
    wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2, 3 => Uint32];
