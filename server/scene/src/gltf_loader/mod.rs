//! glTF 2.0 import (`.gltf` with external files or embedded `data:` URIs, and `.glb`) into a
//! world-space [`Scene`].
//!
//! The loader reads the raw JSON document (`gltf::json`) and does its own GLB splitting, URI
//! resolution and accessor decoding instead of using the `gltf` crate's importer, wrapper types
//! and readers: those unwrap or slice without bounds checks on some malformed inputs (a GLB
//! header length below 12, an image with a `bufferView` but no `mimeType`, an accessor past the
//! end of its buffer view), and their errors do not say which part of the file is at fault.
//! Here every failure is a [`LoadError`] that names the mesh, primitive, accessor, buffer, node,
//! texture or extension concerned.
//!
//! Nodes are kept (`crate::nodes`: ids, names, which may move, the vertices of each subtree),
//! and animations' channels are read and checked; skins and morph targets are ignored (meshes
//! appear in their bind pose), as are tangents, vertex colours, texture sets other than `TEXCOORD_0`, samplers,
//! and all textures except the base colour one.
//!
//! One file per job: `container` (GLB chunks, the JSON document, buffers and URIs),
//! `accessors` (typed elements from buffer views), `geometry` (the node graph and its
//! primitives as world-space triangles), `materials` (materials and their images) and
//! `lights` (cameras and punctual lights); this module holds the limits, the errors and the
//! `Loader` they fill.

mod accessors;
mod animations;
mod container;
mod geometry;
mod lights;
mod materials;
#[cfg(test)]
mod tests;

use super::nodes::{Node, Transform};
use super::{Material, Scene, SceneError, Texture, Vertex};
use accessors::*;
use animations::marked_movable;
use container::*;
use glam::{Mat3, Mat4, Quat, Vec3};
use gltf::json::{
    self,
    accessor::{ComponentType, GenericComponentType, IndexComponentType, Type},
    camera::Type as CameraType,
    extensions::scene::khr_lights_punctual::Type as LightType,
    material::AlphaMode,
    mesh::{Mode, Semantic},
    validation::{Checked, Validate},
};
use lightcast_protocol::{Camera, Light, LightKind};
pub use materials::kept_size;
use std::borrow::Cow;
use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::{fs, io};

/// Extensions a file may list in `extensionsRequired`; anything else there is refused because
/// ignoring it would render the scene wrongly (compressed geometry, texture transforms, ...).
const SUPPORTED_EXTENSIONS: &[&str] = &["KHR_lights_punctual", "KHR_materials_emissive_strength"];

/// Largest texture width or height accepted; larger images exceed common GPU limits.
pub const MAX_TEXTURE_SIZE: u32 = 8192;

/// Accessors without a buffer view are zero-filled, so their size is not bounded by any data in
/// the file; without a cap on their total a few bytes of JSON could ask for terabytes. Only
/// their sparse substitutions can make geometry (zeros make zero-area triangles, which are
/// dropped), so real files need few: the cap bounds the loader's transient memory to tens of
/// MiB (positions, normals, texture coordinates and vertices of each element).
const MAX_UNBACKED_ELEMENTS: u64 = 1 << 20;

/// What one load may build. A few bytes of JSON can reuse one accessor in thousands of
/// primitives, or one small but highly compressible image in many textures, so sizes are
/// bounded while loading, before the memory is taken, rather than checked afterwards.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoadLimits {
    pub max_triangles: u64,
    /// Vertices over all primitives.
    pub max_vertices: u64,
    /// Decoded RGBA8 bytes over all textures, after downscaling to `max_texture_size`.
    pub max_texture_bytes: u64,
    /// Largest texture side kept; larger images are downscaled to it after decoding.
    pub max_texture_size: u32,
}

impl LoadLimits {
    /// For files the operator names: only the hard caps of the format apply.
    pub const NONE: Self = Self {
        max_triangles: u64::MAX,
        max_vertices: u64::MAX,
        max_texture_bytes: u64::MAX,
        max_texture_size: MAX_TEXTURE_SIZE,
    };

    /// Decoded texture memory an upload may take: four textures at the largest size.
    pub const UPLOAD_TEXTURE_BYTES: u64 = 4 * 4 * (MAX_TEXTURE_SIZE as u64).pow(2);

    /// Limits for an upload to a server that allows `max_triangles`. Three vertices per
    /// triangle is what a scene without shared vertices needs; more would be unreferenced.
    pub fn upload(max_triangles: u64) -> Self {
        Self {
            max_triangles,
            max_vertices: max_triangles.saturating_mul(3),
            max_texture_bytes: Self::UPLOAD_TEXTURE_BYTES,
            max_texture_size: MAX_TEXTURE_SIZE,
        }
    }
}

/// Validation can report thousands of problems for a broken file; the first few locate it.
const MAX_VALIDATION_ERRORS_SHOWN: usize = 5;

/// Why a glTF file could not be loaded. Messages name the part of the file at fault.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error("cannot read '{}': {error}", path.display())]
    Read { path: PathBuf, error: io::Error },
    #[error("invalid .glb: {0}")]
    Glb(String),
    #[error("invalid glTF JSON: {0}")]
    Json(serde_json::Error),
    #[error("invalid glTF: {0}")]
    Validation(String),
    #[error("required extension '{0}' is not supported")]
    UnsupportedExtension(String),
    #[error("{part}: {}", describe_external(uri, path, error))]
    External {
        part: String,
        uri: String,
        path: PathBuf,
        error: io::Error,
    },
    #[error("{part}: image decode failed: {error}")]
    ImageDecode {
        part: String,
        error: image::ImageError,
    },
    #[error("{part}: {message}")]
    Invalid { part: String, message: String },
    /// The declared triangle counts take the scene past `LoadLimits::max_triangles`; found
    /// before the primitive that crosses it is read.
    #[error(
        "{part}: the scene would have {triangles} triangles or more; at most {limit} are allowed"
    )]
    TriangleBudget {
        part: String,
        triangles: u64,
        limit: u64,
    },
    /// Decoding an image would take the scene past `LoadLimits::max_texture_bytes`; found
    /// from the image's declared dimensions, before any pixel is decoded.
    #[error(
        "{part}: decoding this {width}×{height} image (kept at {kept_width}×{kept_height}) takes \
         {} MiB, more than the {} MiB left of the scene's texture memory limit",
        needed.div_ceil(1 << 20),
        available >> 20
    )]
    TextureBudget {
        part: String,
        width: u32,
        height: u32,
        kept_width: u32,
        kept_height: u32,
        needed: u64,
        available: u64,
    },
    #[error("assembled scene is invalid: {0}")]
    Scene(SceneError),
}

fn describe_external(uri: &str, path: &Path, error: &io::Error) -> String {
    if error.kind() == io::ErrorKind::NotFound {
        format!("file '{uri}' not found (looked for {})", path.display())
    } else {
        format!("cannot read file '{uri}' ({}): {error}", path.display())
    }
}

fn invalid(part: impl Into<String>, message: impl Into<String>) -> LoadError {
    LoadError::Invalid {
        part: part.into(),
        message: message.into(),
    }
}

/// "mesh 3 ('Suzanne')", or "mesh 3" for unnamed parts. Names are cut to 64 characters: a
/// file's name can be megabytes long, and errors repeat it.
fn named(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(name) if !name.is_empty() => format!("{kind} {index} ('{name:.64}')"),
        _ => format!("{kind} {index}"),
    }
}

/// Loads a `.gltf` or `.glb` file; external files are resolved next to it. The scene is named
/// after the file stem.
pub fn load_gltf(path: &Path) -> Result<Scene, LoadError> {
    let bytes = fs::read(path).map_err(|error| LoadError::Read {
        path: path.to_owned(),
        error,
    })?;
    let name = path.file_stem().map_or_else(
        || String::from("scene"),
        |s| s.to_string_lossy().into_owned(),
    );
    let base_dir = path.parent().unwrap_or(Path::new(""));
    load_gltf_slice(&bytes, Some(base_dir), &name, LoadLimits::NONE)
}

/// Loads `.glb` or `.gltf` JSON bytes. External buffers and images are resolved against
/// `base_dir`; with `None`, a file that needs one is an error.
pub fn load_gltf_slice(
    bytes: &[u8],
    base_dir: Option<&Path>,
    name: &str,
    limits: LoadLimits,
) -> Result<Scene, LoadError> {
    let (json_bytes, bin) = if bytes.starts_with(b"glTF") {
        split_glb(bytes)?
    } else {
        (bytes, None)
    };
    let root = parse_document(json_bytes)?;
    let buffers = load_buffers(&root, bin, base_dir)?;
    let mut loader = Loader {
        root: &root,
        buffers: &buffers,
        base_dir,
        limits,
        unbacked_elements: Cell::new(0),
        texture_bytes: 0,
        material_map: vec![None; root.materials.len()],
        default_material: None,
        image_map: vec![None; root.images.len()],
        materials: Vec::new(),
        textures: Vec::new(),
        vertices: Vec::new(),
        indices: Vec::new(),
        lights: Vec::new(),
        light_nodes: Vec::new(),
        cameras: Vec::new(),
    };
    let mut animations = loader.animations()?;
    let mut moving = vec![false; root.nodes.len()];
    // Morph weights are not played: they move no node.
    let posing = |c: &&crate::nodes::Channel| c.property != crate::nodes::Property::Weights;
    for channel in animations.iter().flat_map(|a| &a.channels).filter(posing) {
        if let Some(m) = moving.get_mut(channel.node as usize) {
            *m = true;
        }
    }
    let nodes = loader.traverse(&moving)?;
    // Channels of nodes outside the scene drawn (another glTF scene's) move nothing seen.
    let drawn: std::collections::HashSet<u32> = nodes.iter().map(|n| n.id).collect();
    for animation in &mut animations {
        animation.channels.retain(|c| drawn.contains(&c.node));
    }
    let light_nodes = loader.light_nodes.into_iter().map(Some).collect();
    let mut scene = Scene::new(
        name,
        loader.vertices,
        loader.indices,
        loader.materials,
        loader.textures,
        loader.lights,
        loader.cameras,
    )
    .map_err(LoadError::Scene)?;
    scene.light_nodes = light_nodes;
    scene
        .set_nodes(nodes, animations)
        .map_err(LoadError::Scene)?;
    Ok(scene)
}

/// Walks the node hierarchy and accumulates the scene's parts.
struct Loader<'a> {
    root: &'a json::Root,
    buffers: &'a [Cow<'a, [u8]>],
    base_dir: Option<&'a Path>,
    limits: LoadLimits,
    /// Zero-filled elements handed out so far, against [`MAX_UNBACKED_ELEMENTS`].
    unbacked_elements: Cell<u64>,
    /// Decoded texture bytes so far, against `limits.max_texture_bytes`.
    texture_bytes: u64,
    /// glTF material index → index in `materials`, filled on first use.
    material_map: Vec<Option<u32>>,
    default_material: Option<u32>,
    /// glTF image index → index in `textures`, so materials sharing an image share a texture.
    image_map: Vec<Option<usize>>,
    materials: Vec<Material>,
    textures: Vec<Texture>,
    vertices: Vec<Vertex>,
    indices: Vec<u32>,
    lights: Vec<Light>,
    /// The node carrying each light (its glTF index).
    light_nodes: Vec<u32>,
    cameras: Vec<Camera>,
}
