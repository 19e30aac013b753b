//! Scenes as the renderer consumes them: world-space triangle soup grouped by material, plus
//! materials, textures, lights and cameras.
//!
//! Every loader (glTF files, the built-in procedural scenes) produces a [`Scene`] through
//! [`Scene::new`], which validates indices, computes bounds and sorts triangles so that each
//! material is one contiguous index range (one draw call per material).

pub mod brdf;
pub mod default_light;
pub mod emitters;
pub mod environment;
pub mod environment_image;
pub mod gltf_loader;
pub mod halton;
pub mod material;
pub mod nodes;
pub mod octahedral;
pub mod procedural;

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use lightcast_protocol::{Camera, Light};
use std::path::Path;

pub use gltf_loader::{load_gltf, LoadError};
pub use material::Material;

/// One vertex in world space. Mirrored by `VertexInput` in `shaders/gbuffer.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Vertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub uv: [f32; 2],
    /// Index into [`Scene::materials`].
    pub material: u32,
}

/// An RGBA8 image in sRGB encoding (glTF base colour textures are sRGB).
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// `width * height * 4` bytes, rows top to bottom.
    pub rgba8: Vec<u8>,
}

/// Axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Radius of the bounding sphere around [`Aabb::center`].
    pub fn radius(&self) -> f32 {
        (self.max - self.min).length() * 0.5
    }

    pub fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min, self.max);
        [
            Vec3::new(a.x, a.y, a.z),
            Vec3::new(b.x, a.y, a.z),
            Vec3::new(a.x, b.y, a.z),
            Vec3::new(b.x, b.y, a.z),
            Vec3::new(a.x, a.y, b.z),
            Vec3::new(b.x, a.y, b.z),
            Vec3::new(a.x, b.y, b.z),
            Vec3::new(b.x, b.y, b.z),
        ]
    }
}

/// A contiguous range of [`Scene::indices`] that uses one material.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MaterialRange {
    pub material: u32,
    pub first_index: u32,
    pub index_count: u32,
}

/// Why [`Scene::new`] refused its input.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SceneError {
    #[error("scene has no triangles")]
    Empty,
    #[error(transparent)]
    Nodes(#[from] nodes::NodeError),
    #[error("index count {0} is not a multiple of 3")]
    PartialTriangle(usize),
    #[error("index {index} at position {position} is out of range ({vertex_count} vertices)")]
    IndexOutOfRange {
        position: usize,
        index: u32,
        vertex_count: usize,
    },
    #[error("vertex {vertex} uses material {material}, but there are {material_count} materials")]
    MaterialOutOfRange {
        vertex: usize,
        material: u32,
        material_count: usize,
    },
    #[error("material {material} refers to texture {texture}, but there are {texture_count}")]
    TextureOutOfRange {
        material: usize,
        texture: usize,
        texture_count: usize,
    },
    #[error("vertex {0} has a non-finite position")]
    NonFinitePosition(usize),
    #[error("scene has {0} vertices; at most {max} are supported", max = u32::MAX)]
    TooManyVertices(usize),
    #[error(
        "scene spans {0:e} units; at most {max:e} are supported (f32 positions lose all \
         detail beyond that, and derived light intensities overflow)",
        max = MAX_SCENE_EXTENT
    )]
    TooLarge(f32),
}

/// Largest extent of a scene's bounding box along any axis, in scene units.
pub const MAX_SCENE_EXTENT: f32 = 1e7;

/// A renderable scene.
#[derive(Clone, Debug)]
pub struct Scene {
    pub name: String,
    pub vertices: Vec<Vertex>,
    /// Triangle list, sorted so each material is one contiguous range.
    pub indices: Vec<u32>,
    pub material_ranges: Vec<MaterialRange>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub lights: Vec<Light>,
    pub cameras: Vec<Camera>,
    pub bounds: Aabb,
    /// The punctual lights stand in for the emissive surfaces (the Cornell box's spot for its
    /// lamp): lighting with both counts that light twice. A scene without lights of its own
    /// gets such a stand-in as its default light (`default_light::emitter_stand_in`).
    pub lights_stand_in_for_emitters: bool,
    /// Where a viewer keeps the camera: a room seen from inside or through an opening, whose
    /// walls are black from outside. `None`: anywhere (an object is orbited freely).
    pub camera_region: Option<Aabb>,
    /// The equirectangular HDR image uploaded with the scene, which `render.environment`
    /// of kind `image` lights it with.
    pub environment_image: Option<std::sync::Arc<environment_image::EnvironmentImage>>,
    /// The node hierarchy (roots first, each node after its parent; empty: one static whole)
    /// and which parts may move (see [`nodes`]).
    pub nodes: Vec<nodes::Node>,
    /// The glTF file's animations of its nodes.
    pub animations: Vec<nodes::Animation>,
    /// The node carrying each of [`Self::lights`] (by index; shorter or `None`: a light of the
    /// scene as a whole): a light under a movable node moves with it.
    pub light_nodes: Vec<Option<u32>>,
}

impl Scene {
    /// Validates the parts and groups triangles by the material of their first vertex.
    pub fn new(
        name: impl Into<String>,
        vertices: Vec<Vertex>,
        indices: Vec<u32>,
        materials: Vec<Material>,
        textures: Vec<Texture>,
        lights: Vec<Light>,
        cameras: Vec<Camera>,
    ) -> Result<Self, SceneError> {
        if indices.is_empty() {
            return Err(SceneError::Empty);
        }
        if !indices.len().is_multiple_of(3) {
            return Err(SceneError::PartialTriangle(indices.len()));
        }
        if u32::try_from(vertices.len()).is_err() {
            return Err(SceneError::TooManyVertices(vertices.len()));
        }
        for (position, &index) in indices.iter().enumerate() {
            if index as usize >= vertices.len() {
                return Err(SceneError::IndexOutOfRange {
                    position,
                    index,
                    vertex_count: vertices.len(),
                });
            }
        }
        for (i, v) in vertices.iter().enumerate() {
            if v.material as usize >= materials.len() {
                return Err(SceneError::MaterialOutOfRange {
                    vertex: i,
                    material: v.material,
                    material_count: materials.len(),
                });
            }
            if !v.position.iter().all(|c| c.is_finite()) {
                return Err(SceneError::NonFinitePosition(i));
            }
        }
        for (i, m) in materials.iter().enumerate() {
            if let Some(t) = m.base_color_texture {
                if t >= textures.len() {
                    return Err(SceneError::TextureOutOfRange {
                        material: i,
                        texture: t,
                        texture_count: textures.len(),
                    });
                }
            }
        }

        let mut min = Vec3::splat(f32::INFINITY);
        let mut max = Vec3::splat(f32::NEG_INFINITY);
        for &i in &indices {
            let p = Vec3::from(vertices[i as usize].position);
            min = min.min(p);
            max = max.max(p);
        }
        let extent = (max - min).max_element();
        if extent.is_nan() || extent > MAX_SCENE_EXTENT {
            return Err(SceneError::TooLarge(extent));
        }

        let mut triangles: Vec<[u32; 3]> = indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect();
        triangles.sort_by_key(|t| vertices[t[0] as usize].material);
        let mut sorted = Vec::with_capacity(indices.len());
        let mut material_ranges: Vec<MaterialRange> = Vec::new();
        for t in &triangles {
            let material = vertices[t[0] as usize].material;
            match material_ranges.last_mut() {
                Some(r) if r.material == material => r.index_count += 3,
                _ => material_ranges.push(MaterialRange {
                    material,
                    first_index: sorted.len() as u32,
                    index_count: 3,
                }),
            }
            sorted.extend_from_slice(t);
        }

        Ok(Self {
            name: name.into(),
            vertices,
            indices: sorted,
            material_ranges,
            materials,
            textures,
            lights,
            cameras,
            bounds: Aabb { min, max },
            lights_stand_in_for_emitters: false,
            camera_region: None,
            environment_image: None,
            nodes: Vec::new(),
            animations: Vec::new(),
            light_nodes: Vec::new(),
        })
    }

    /// Gives the scene its node hierarchy and animations, checked against its vertices and
    /// triangles ([`nodes::validate`]).
    pub fn set_nodes(
        &mut self,
        nodes: Vec<nodes::Node>,
        animations: Vec<nodes::Animation>,
    ) -> Result<(), SceneError> {
        nodes::validate(
            &nodes,
            &animations,
            self.vertices.len() as u32,
            &self.indices,
        )?;
        // The bounds hold every pose the animations reach: the light and shadow maps are
        // fitted to them.
        let positions: Vec<Vec3> = self.vertices.iter().map(|v| v.position.into()).collect();
        let subtrees = nodes::subtree_bounds(&nodes, &positions);
        if let Some(reach) = nodes::animation_reach(&nodes, &animations, &subtrees) {
            let bounds = Aabb {
                min: self.bounds.min.min(reach.min),
                max: self.bounds.max.max(reach.max),
            };
            let extent = (bounds.max - bounds.min).max_element();
            if extent.is_nan() || extent > MAX_SCENE_EXTENT {
                return Err(SceneError::TooLarge(extent));
            }
            self.bounds = bounds;
        }
        self.nodes = nodes;
        self.animations = animations;
        Ok(())
    }

    /// The node clients call `id`.
    pub fn node(&self, id: u32) -> Option<&nodes::Node> {
        self.nodes.iter().find(|n| n.id == id)
    }

    /// World bounds of every node's subtree at rest, in [`Self::nodes`]' order (`None`
    /// without geometry).
    pub fn node_bounds(&self) -> Vec<Option<Aabb>> {
        let positions: Vec<Vec3> = self.vertices.iter().map(|v| v.position.into()).collect();
        nodes::subtree_bounds(&self.nodes, &positions)
    }

    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Loads a scene named on the command line: a `.gltf`/`.glb` path, or a built-in procedural
    /// scene such as `procedural:cornell` or `procedural:street?blocks=8`.
    pub fn open(spec: &str) -> Result<Self, OpenError> {
        if let Some(rest) = spec.strip_prefix("procedural:") {
            return Ok(procedural::build(rest)?);
        }
        Ok(load_gltf(Path::new(spec))?)
    }
}

/// Why [`Scene::open`] failed.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error(transparent)]
    Gltf(#[from] LoadError),
    #[error(transparent)]
    Procedural(#[from] procedural::ProceduralError),
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vertex(p: [f32; 3], material: u32) -> Vertex {
        Vertex {
            position: p,
            normal: [0.0, 1.0, 0.0],
            uv: [0.0, 0.0],
            material,
        }
    }

    #[test]
    fn groups_triangles_by_material_and_computes_bounds() {
        let vertices = vec![
            vertex([0.0, 0.0, 0.0], 1),
            vertex([1.0, 0.0, 0.0], 1),
            vertex([0.0, 0.0, 1.0], 1),
            vertex([0.0, 2.0, 0.0], 0),
            vertex([1.0, 2.0, 0.0], 0),
            vertex([0.0, 2.0, -3.0], 0),
        ];
        let indices = vec![0, 1, 2, 3, 4, 5, 2, 1, 0];
        let materials = vec![Material::default(), Material::default()];
        let scene = Scene::new("t", vertices, indices, materials, vec![], vec![], vec![])
            .expect("valid scene");
        assert_eq!(
            scene.material_ranges,
            vec![
                MaterialRange {
                    material: 0,
                    first_index: 0,
                    index_count: 3
                },
                MaterialRange {
                    material: 1,
                    first_index: 3,
                    index_count: 6
                }
            ]
        );
        assert_eq!(&scene.indices[0..3], &[3, 4, 5]);
        assert_eq!(scene.bounds.min, Vec3::new(0.0, 0.0, -3.0));
        assert_eq!(scene.bounds.max, Vec3::new(1.0, 2.0, 1.0));
        assert_eq!(scene.triangle_count(), 3);
    }

    #[test]
    fn rejects_out_of_range_index_and_material() {
        let v = vec![vertex([0.0; 3], 0); 3];
        let err = Scene::new(
            "t",
            v.clone(),
            vec![0, 1, 3],
            vec![Material::default()],
            vec![],
            vec![],
            vec![],
        )
        .expect_err("index 3 is out of range");
        assert_eq!(
            err,
            SceneError::IndexOutOfRange {
                position: 2,
                index: 3,
                vertex_count: 3
            }
        );
        let err = Scene::new("t", v, vec![0, 1, 2], vec![], vec![], vec![], vec![])
            .expect_err("no materials");
        assert!(matches!(err, SceneError::MaterialOutOfRange { .. }));
    }
}
