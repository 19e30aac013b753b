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

use super::{Material, Scene, SceneError, Texture, Vertex};
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
use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::{fs, io};

/// Extensions a file may list in `extensionsRequired`; anything else there is refused because
/// ignoring it would render the scene wrongly (compressed geometry, texture transforms, ...).
const SUPPORTED_EXTENSIONS: &[&str] = &["KHR_lights_punctual", "KHR_materials_emissive_strength"];

/// Largest texture width or height accepted; larger images exceed common GPU limits.
pub const MAX_TEXTURE_SIZE: u32 = 8192;

/// An accessor without a buffer view is zero-filled, so its size is not bounded by any data in
/// the file; without a cap a few bytes of JSON could ask for terabytes.
const MAX_UNBACKED_ELEMENTS: u64 = 1 << 24;

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

/// "mesh 3 ('Suzanne')", or "mesh 3" for unnamed parts.
fn named(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(name) if !name.is_empty() => format!("{kind} {index} ('{name}')"),
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
    load_gltf_slice(&bytes, Some(base_dir), &name)
}

/// Loads `.glb` or `.gltf` JSON bytes. External buffers and images are resolved against
/// `base_dir`; with `None`, a file that needs one is an error.
pub fn load_gltf_slice(
    bytes: &[u8],
    base_dir: Option<&Path>,
    name: &str,
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
        material_map: vec![None; root.materials.len()],
        default_material: None,
        image_map: vec![None; root.images.len()],
        materials: Vec::new(),
        textures: Vec::new(),
        vertices: Vec::new(),
        indices: Vec::new(),
        lights: Vec::new(),
        cameras: Vec::new(),
    };
    loader.traverse()?;
    Scene::new(
        name,
        loader.vertices,
        loader.indices,
        loader.materials,
        loader.textures,
        loader.lights,
        loader.cameras,
    )
    .map_err(LoadError::Scene)
}

/// Splits a GLB container into its JSON chunk and optional BIN chunk.
fn split_glb(bytes: &[u8]) -> Result<(&[u8], Option<&[u8]>), LoadError> {
    let u32_at = |offset: usize| {
        bytes
            .get(offset..offset.checked_add(4)?)
            .and_then(|b| <[u8; 4]>::try_from(b).ok())
            .map(u32::from_le_bytes)
    };
    let (Some(version), Some(length)) = (u32_at(4), u32_at(8)) else {
        return Err(LoadError::Glb(format!(
            "file is {} bytes, shorter than the 12-byte header",
            bytes.len()
        )));
    };
    if version != 2 {
        return Err(LoadError::Glb(format!(
            "container version {version} is not supported (only 2)"
        )));
    }
    let length = length as usize;
    if length < 12 {
        return Err(LoadError::Glb(format!(
            "header length {length} is smaller than the header itself"
        )));
    }
    if length > bytes.len() {
        return Err(LoadError::Glb(format!(
            "header says the file is {length} bytes, but only {} are present (truncated?)",
            bytes.len()
        )));
    }
    let mut json = None;
    let mut bin = None;
    let mut offset = 12;
    let mut chunk = 0;
    while offset < length {
        let header = u32_at(offset).zip(bytes.get(offset + 4..offset + 8));
        let Some((chunk_length, kind)) = header.filter(|_| offset + 8 <= length) else {
            return Err(LoadError::Glb(format!(
                "chunk {chunk} at byte {offset}: header is truncated"
            )));
        };
        let start = offset + 8;
        let data = start
            .checked_add(chunk_length as usize)
            .filter(|&end| end <= length)
            .and_then(|end| bytes.get(start..end));
        let Some(data) = data else {
            return Err(LoadError::Glb(format!(
                "chunk {chunk} at byte {offset}: length {chunk_length} runs past the end of \
                 the file ({length} bytes)"
            )));
        };
        match (chunk, kind) {
            (0, b"JSON") => json = Some(data),
            (0, _) => {
                return Err(LoadError::Glb(format!(
                    "first chunk has type {:?}, expected JSON",
                    String::from_utf8_lossy(kind)
                )))
            }
            (1, b"BIN\0") => bin = Some(data),
            // The spec requires loaders to skip chunks of unknown type.
            _ => {}
        }
        offset = start + data.len();
        chunk += 1;
    }
    let json = json.ok_or_else(|| LoadError::Glb(String::from("file has no JSON chunk")))?;
    Ok((json, bin))
}

/// Parses and validates the JSON document.
fn parse_document(json_bytes: &[u8]) -> Result<json::Root, LoadError> {
    // Version and required extensions are checked on the untyped value first, so that a
    // glTF 1.0 file or one relying on an unsupported extension gets that precise message
    // rather than a type error from the typed parse.
    let value: serde_json::Value = serde_json::from_slice(json_bytes).map_err(LoadError::Json)?;
    if let Some(version) = value
        .get("asset")
        .and_then(|asset| asset.get("version"))
        .and_then(serde_json::Value::as_str)
    {
        if !version.starts_with("2.") {
            return Err(invalid(
                "asset.version",
                format!("'{version}' is not supported (only glTF 2.x)"),
            ));
        }
    }
    if let Some(required) = value
        .get("extensionsRequired")
        .and_then(serde_json::Value::as_array)
    {
        for extension in required.iter().filter_map(serde_json::Value::as_str) {
            if !SUPPORTED_EXTENSIONS.contains(&extension) {
                return Err(LoadError::UnsupportedExtension(extension.to_owned()));
            }
        }
    }
    drop(value);
    let root: json::Root = serde_json::from_slice(json_bytes).map_err(LoadError::Json)?;
    let mut errors = Vec::new();
    root.validate(&root, json::Path::new, &mut |path, error| {
        errors.push(format!("{}: {error}", path()));
    });
    if !errors.is_empty() {
        let total = errors.len();
        errors.truncate(MAX_VALIDATION_ERRORS_SHOWN);
        let mut message = errors.join("; ");
        if total > MAX_VALIDATION_ERRORS_SHOWN {
            message.push_str(&format!(
                " (and {} more)",
                total - MAX_VALIDATION_ERRORS_SHOWN
            ));
        }
        return Err(LoadError::Validation(message));
    }
    Ok(root)
}

fn load_buffers<'a>(
    root: &json::Root,
    bin: Option<&'a [u8]>,
    base_dir: Option<&Path>,
) -> Result<Vec<Cow<'a, [u8]>>, LoadError> {
    let mut buffers = Vec::with_capacity(root.buffers.len());
    for (index, buffer) in root.buffers.iter().enumerate() {
        let part = named("buffer", index, buffer.name.as_deref());
        let data: Cow<'a, [u8]> = match (&buffer.uri, bin) {
            (Some(uri), _) => Cow::Owned(read_uri(uri, base_dir, &part)?),
            (None, Some(bin)) if index == 0 => Cow::Borrowed(bin),
            (None, None) if index == 0 => {
                return Err(invalid(
                    part,
                    "has no uri, and there is no GLB binary chunk",
                ))
            }
            (None, _) => {
                return Err(invalid(
                    part,
                    "has no uri; only buffer 0 of a .glb may refer to the binary chunk",
                ))
            }
        };
        let declared = buffer.byte_length.0;
        let available = data.len();
        // Trimming to the declared length makes views reaching into GLB padding an error.
        let data = match data {
            Cow::Borrowed(d) => usize::try_from(declared)
                .ok()
                .and_then(|n| d.get(..n))
                .map(Cow::Borrowed),
            Cow::Owned(mut d) => usize::try_from(declared)
                .ok()
                .filter(|&n| n <= d.len())
                .map(|n| {
                    d.truncate(n);
                    Cow::Owned(d)
                }),
        };
        let data = data.ok_or_else(|| {
            invalid(
                &part,
                format!("byteLength is {declared}, but only {available} bytes are available"),
            )
        })?;
        buffers.push(data);
    }
    Ok(buffers)
}

/// Reads the bytes a buffer or image URI refers to: a base64 `data:` URI or a relative path.
fn read_uri(uri: &str, base_dir: Option<&Path>, part: &str) -> Result<Vec<u8>, LoadError> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let Some((media, payload)) = rest.split_once(',') else {
            return Err(invalid(part, "data URI has no ',' before its payload"));
        };
        if !media.ends_with(";base64") {
            return Err(invalid(part, "data URI is not base64-encoded"));
        }
        return base64_decode(payload)
            .map_err(|message| invalid(part, format!("data URI: {message}")));
    }
    if has_scheme(uri) {
        return Err(invalid(
            part,
            format!("URI '{uri}' has an unsupported scheme (only relative paths and data: URIs)"),
        ));
    }
    let relative =
        percent_decode(uri).map_err(|message| invalid(part, format!("URI '{uri}': {message}")))?;
    let Some(base_dir) = base_dir else {
        return Err(invalid(
            part,
            format!(
                "refers to external file '{uri}', but the glTF was loaded from memory without \
                 a base directory"
            ),
        ));
    };
    let path = base_dir.join(relative);
    fs::read(&path).map_err(|error| LoadError::External {
        part: part.to_owned(),
        uri: uri.to_owned(),
        path,
        error,
    })
}

/// Whether a URI starts with an RFC 3986 scheme ("http:", "file:"). Single letters are not
/// treated as schemes so that Windows drive paths stay paths.
fn has_scheme(uri: &str) -> bool {
    let Some((scheme, _)) = uri.split_once(':') else {
        return false;
    };
    scheme.len() > 1
        && scheme.starts_with(|c: char| c.is_ascii_alphabetic())
        && scheme
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.'))
}

fn percent_decode(text: &str) -> Result<String, String> {
    let mut out = Vec::with_capacity(text.len());
    let mut bytes = text.bytes();
    while let Some(b) = bytes.next() {
        if b == b'%' {
            let hex = [bytes.next(), bytes.next()];
            let digits = hex.map(|h| h.and_then(|h| (h as char).to_digit(16)));
            let [Some(hi), Some(lo)] = digits else {
                return Err(String::from("invalid percent escape"));
            };
            out.push((hi * 16 + lo) as u8);
        } else {
            out.push(b);
        }
    }
    String::from_utf8(out).map_err(|_| String::from("percent escapes do not decode to UTF-8"))
}

fn base64_decode(text: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(text.len() / 4 * 3);
    let mut acc = 0u32;
    let mut bits = 0u32;
    let mut padding = false;
    for (offset, c) in text.bytes().enumerate() {
        let value = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => {
                padding = true;
                continue;
            }
            c if c.is_ascii_whitespace() => continue,
            c => {
                return Err(format!(
                    "invalid base64 character {:?} at offset {offset}",
                    c as char
                ))
            }
        };
        if padding {
            return Err(format!(
                "base64 data continues after '=' padding at offset {offset}"
            ));
        }
        acc = (acc << 6) | u32::from(value);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

/// `len` bytes from `offset`, if they lie inside `bytes`.
fn slice_at(bytes: &[u8], offset: u64, len: u64) -> Option<&[u8]> {
    let start = usize::try_from(offset).ok()?;
    let end = start.checked_add(usize::try_from(len).ok()?)?;
    bytes.get(start..end)
}

fn le_bytes<const N: usize>(bytes: &[u8]) -> [u8; N] {
    let mut out = [0; N];
    for (o, b) in out.iter_mut().zip(bytes) {
        *o = *b;
    }
    out
}

/// Decodes one component as a float, applying glTF's normalisation rules for integer types.
fn decode_float(component: ComponentType, normalized: bool, bytes: &[u8]) -> f32 {
    let (value, max) = match component {
        ComponentType::F32 => return f32::from_le_bytes(le_bytes(bytes)),
        ComponentType::I8 => (f32::from(i8::from_le_bytes(le_bytes(bytes))), 127.0),
        ComponentType::U8 => (f32::from(u8::from_le_bytes(le_bytes(bytes))), 255.0),
        ComponentType::I16 => (f32::from(i16::from_le_bytes(le_bytes(bytes))), 32767.0),
        ComponentType::U16 => (f32::from(u16::from_le_bytes(le_bytes(bytes))), 65535.0),
        ComponentType::U32 => (u32::from_le_bytes(le_bytes(bytes)) as f32, u32::MAX as f32),
    };
    if normalized {
        (value / max).max(-1.0)
    } else {
        value
    }
}

/// Decodes one unsigned integer component; other types are rejected before decoding.
fn decode_index(component: ComponentType, bytes: &[u8]) -> u32 {
    match component {
        ComponentType::U8 => u32::from(u8::from_le_bytes(le_bytes(bytes))),
        ComponentType::U16 => u32::from(u16::from_le_bytes(le_bytes(bytes))),
        _ => u32::from_le_bytes(le_bytes(bytes)),
    }
}

const INDEX_COMPONENTS: &[ComponentType] =
    &[ComponentType::U8, ComponentType::U16, ComponentType::U32];
const ANY_COMPONENT: &[ComponentType] = &[
    ComponentType::I8,
    ComponentType::U8,
    ComponentType::I16,
    ComponentType::U16,
    ComponentType::U32,
    ComponentType::F32,
];

/// Converts a triangle list, strip or fan into a list (spec §3.7.2.1 orderings).
fn triangle_list(mode: Mode, indices: &[u32]) -> Result<Vec<[u32; 3]>, String> {
    match mode {
        Mode::Triangles if !indices.len().is_multiple_of(3) => Err(format!(
            "index count {} is not a multiple of 3",
            indices.len()
        )),
        Mode::Triangles => Ok(indices
            .chunks_exact(3)
            .filter_map(|t| <[u32; 3]>::try_from(t).ok())
            .collect()),
        Mode::TriangleStrip => Ok(indices
            .windows(3)
            .enumerate()
            .filter_map(|(i, w)| match *w {
                [a, b, c] if i % 2 == 0 => Some([a, b, c]),
                [a, b, c] => Some([a, c, b]),
                _ => None,
            })
            .collect()),
        Mode::TriangleFan => {
            let (Some(&first), Some(rest)) = (indices.first(), indices.get(1..)) else {
                return Ok(Vec::new());
            };
            Ok(rest
                .windows(2)
                .filter_map(|w| match *w {
                    [b, c] => Some([b, c, first]),
                    _ => None,
                })
                .collect())
        }
        other => Err(format!("mode {other:?} is not supported (only triangles)")),
    }
}

/// Area-weighted vertex normals (the cross product's length is twice the triangle area).
fn generated_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut sums = vec![Vec3::ZERO; positions.len()];
    for triangle in triangles {
        let [a, b, c] = triangle.map(|i| positions.get(i as usize).copied().unwrap_or(Vec3::ZERO));
        let normal = (b - a).cross(c - a);
        for &i in triangle {
            if let Some(sum) = sums.get_mut(i as usize) {
                *sum += normal;
            }
        }
    }
    sums.into_iter()
        .map(|n| n.try_normalize().unwrap_or(Vec3::Y))
        .collect()
}

fn local_transform(node: &json::Node) -> Option<Mat4> {
    if let Some(matrix) = node.matrix {
        return Some(Mat4::from_cols_array(&matrix));
    }
    let translation = node.translation.map_or(Vec3::ZERO, Vec3::from);
    let scale = node.scale.map_or(Vec3::ONE, Vec3::from);
    let rotation = match &node.rotation {
        None => Quat::IDENTITY,
        Some(q) => {
            let q = Quat::from_array(q.0);
            if !q.is_finite() || q.length_squared() == 0.0 {
                return None;
            }
            q.normalize()
        }
    };
    Some(Mat4::from_scale_rotation_translation(
        scale,
        rotation,
        translation,
    ))
}

/// Walks the node hierarchy and accumulates the scene's parts.
struct Loader<'a> {
    root: &'a json::Root,
    buffers: &'a [Cow<'a, [u8]>],
    base_dir: Option<&'a Path>,
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
    cameras: Vec<Camera>,
}

impl Loader<'_> {
    /// Root nodes of the default scene, else scene 0, else every node that is nobody's child.
    fn root_nodes(&self) -> Result<Vec<usize>, LoadError> {
        let root = self.root;
        let scene = root
            .scene
            .map(|s| s.value())
            .or_else(|| (!root.scenes.is_empty()).then_some(0));
        if let Some(index) = scene {
            let scene = root
                .scenes
                .get(index)
                .ok_or_else(|| invalid(format!("scene {index}"), "does not exist"))?;
            return Ok(scene.nodes.iter().map(|n| n.value()).collect());
        }
        let mut is_child = vec![false; root.nodes.len()];
        for child in root.nodes.iter().flat_map(|n| n.children.iter().flatten()) {
            if let Some(flag) = is_child.get_mut(child.value()) {
                *flag = true;
            }
        }
        Ok(is_child
            .iter()
            .enumerate()
            .filter(|(_, &child)| !child)
            .map(|(i, _)| i)
            .collect())
    }

    fn traverse(&mut self) -> Result<(), LoadError> {
        let root = self.root;
        let mut visited = vec![false; root.nodes.len()];
        let mut stack: Vec<(usize, Mat4)> = self
            .root_nodes()?
            .into_iter()
            .rev()
            .map(|n| (n, Mat4::IDENTITY))
            .collect();
        while let Some((index, parent)) = stack.pop() {
            let node = root
                .nodes
                .get(index)
                .ok_or_else(|| invalid(format!("node {index}"), "does not exist"))?;
            let part = named("node", index, node.name.as_deref());
            match visited.get_mut(index) {
                Some(seen) if !*seen => *seen = true,
                _ => {
                    return Err(invalid(
                        part,
                        "appears more than once in the node hierarchy (a cycle or a node with \
                         two parents)",
                    ))
                }
            }
            let world = local_transform(node)
                .map(|local| parent * local)
                .filter(Mat4::is_finite)
                .ok_or_else(|| invalid(&part, "transform is not finite"))?;
            if let Some(mesh) = node.mesh {
                self.add_mesh(mesh.value(), &world)?;
            }
            if let Some(camera) = node.camera {
                self.add_camera(camera.value(), &world)?;
            }
            if let Some(light) = node
                .extensions
                .as_ref()
                .and_then(|e| e.khr_lights_punctual.as_ref())
            {
                self.add_light(light.light.value(), &world, &part)?;
            }
            for child in node.children.iter().flatten().rev() {
                stack.push((child.value(), world));
            }
        }
        Ok(())
    }

    fn add_mesh(&mut self, index: usize, world: &Mat4) -> Result<(), LoadError> {
        let mesh = self
            .root
            .meshes
            .get(index)
            .ok_or_else(|| invalid(format!("mesh {index}"), "does not exist"))?;
        let mesh_part = named("mesh", index, mesh.name.as_deref());
        for (i, primitive) in mesh.primitives.iter().enumerate() {
            self.add_primitive(primitive, &format!("{mesh_part} primitive {i}"), world)?;
        }
        Ok(())
    }

    fn add_primitive(
        &mut self,
        primitive: &json::mesh::Primitive,
        part: &str,
        world: &Mat4,
    ) -> Result<(), LoadError> {
        let Checked::Valid(mode) = primitive.mode else {
            return Err(invalid(part, "mode is invalid"));
        };
        // Checked before reading any data so that line and point primitives get this message.
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            return Err(invalid(
                part,
                format!("mode {mode:?} is not supported (only triangles)"),
            ));
        }
        let attribute = |semantic| {
            primitive
                .attributes
                .get(&Checked::Valid(semantic))
                .map(|a| a.value())
        };
        let position_accessor = attribute(Semantic::Positions)
            .ok_or_else(|| invalid(part, "has no POSITION attribute"))?;
        let positions = self.read_floats(position_accessor, Type::Vec3, part, "POSITION")?;
        let count = positions.len() / 3;
        let positions: Vec<Vec3> = positions.chunks_exact(3).map(Vec3::from_slice).collect();
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(invalid(part, format!("POSITION {i} is not finite")));
        }
        let normals = match attribute(Semantic::Normals) {
            Some(accessor) => {
                let normals = self.read_floats(accessor, Type::Vec3, part, "NORMAL")?;
                check_count(normals.len() / 3, count, part, "NORMAL")?;
                Some(
                    normals
                        .chunks_exact(3)
                        .map(Vec3::from_slice)
                        .collect::<Vec<_>>(),
                )
            }
            None => None,
        };
        let uvs = match attribute(Semantic::TexCoords(0)) {
            Some(accessor) => {
                let uvs = self.read_floats(accessor, Type::Vec2, part, "TEXCOORD_0")?;
                check_count(uvs.len() / 2, count, part, "TEXCOORD_0")?;
                uvs
            }
            None => vec![0.0; count * 2],
        };

        let indices = match primitive.indices {
            Some(accessor) => {
                let accessor = accessor.value();
                let indices = self.read_accessor(
                    accessor,
                    Type::Scalar,
                    INDEX_COMPONENTS,
                    part,
                    "indices",
                    |c, _, b| decode_index(c, b),
                )?;
                if let Some((position, index)) = indices
                    .iter()
                    .enumerate()
                    .find(|(_, &i)| i as usize >= count)
                {
                    return Err(invalid(
                        part,
                        format!(
                            "indices accessor {accessor}: index {index} at position {position} \
                             is out of range ({count} vertices)"
                        ),
                    ));
                }
                indices
            }
            None => {
                let count = u32::try_from(count)
                    .map_err(|_| invalid(part, format!("has too many vertices ({count})")))?;
                (0..count).collect()
            }
        };
        let mut triangles =
            triangle_list(mode, &indices).map_err(|message| invalid(part, message))?;

        let linear = Mat3::from_mat4(*world);
        // A mirroring transform turns counter-clockwise front faces clockwise.
        if linear.determinant() < 0.0 {
            for t in &mut triangles {
                t.swap(1, 2);
            }
        }
        let positions: Vec<Vec3> = positions
            .iter()
            .map(|&p| world.transform_point3(p))
            .collect();
        let normals: Vec<Vec3> = match normals {
            Some(normals) => {
                let normal_matrix = linear.inverse().transpose();
                normals
                    .into_iter()
                    .map(|n| (normal_matrix * n).try_normalize().unwrap_or(Vec3::Y))
                    .collect()
            }
            None => generated_normals(&positions, &triangles),
        };

        let material = self.material_index(primitive.material.map(|m| m.value()))?;
        let base = self.vertices.len();
        if u32::try_from(base + count).is_err() {
            return Err(invalid(part, "scene would exceed 2^32 vertices"));
        }
        let base = base as u32;
        self.vertices
            .extend(
                positions
                    .iter()
                    .zip(&normals)
                    .zip(uvs.chunks_exact(2))
                    .map(|((p, n), uv)| Vertex {
                        position: p.to_array(),
                        normal: n.to_array(),
                        uv: <[f32; 2]>::try_from(uv).unwrap_or_default(),
                        material,
                    }),
            );
        self.indices
            .extend(triangles.iter().flatten().map(|&i| base + i));
        Ok(())
    }

    fn read_floats(
        &self,
        accessor: usize,
        ty: Type,
        part: &str,
        usage: &str,
    ) -> Result<Vec<f32>, LoadError> {
        self.read_accessor(accessor, ty, ANY_COMPONENT, part, usage, decode_float)
    }

    /// Reads an accessor's elements (flattened components), including sparse substitution,
    /// checking every byte range against its buffer view and buffer.
    fn read_accessor<T: Clone + Default>(
        &self,
        index: usize,
        ty: Type,
        components: &[ComponentType],
        part: &str,
        usage: &str,
        decode: impl Fn(ComponentType, bool, &[u8]) -> T,
    ) -> Result<Vec<T>, LoadError> {
        let Some(accessor) = self.root.accessors.get(index) else {
            return Err(invalid(
                part,
                format!("{usage} accessor {index} does not exist"),
            ));
        };
        let part = format!(
            "{part}: {usage} {}",
            named("accessor", index, accessor.name.as_deref())
        );
        let Checked::Valid(actual) = accessor.type_ else {
            return Err(invalid(part, "type is invalid"));
        };
        if actual != ty {
            return Err(invalid(
                part,
                format!("type is {actual:?}, but {usage} needs {ty:?}"),
            ));
        }
        let Checked::Valid(GenericComponentType(component)) = accessor.component_type else {
            return Err(invalid(part, "componentType is invalid"));
        };
        if !components.contains(&component) {
            return Err(invalid(
                part,
                format!("componentType {component:?} cannot be used for {usage}"),
            ));
        }
        let multiplicity = ty.multiplicity();
        let component_size = component.size();
        let element_size = (multiplicity * component_size) as u64;
        let count = accessor.count.0;
        let too_large = || invalid(&part, format!("count {count} is too large"));
        if accessor.buffer_view.is_none() && count > MAX_UNBACKED_ELEMENTS {
            return Err(too_large());
        }
        let values_len = usize::try_from(count)
            .ok()
            .and_then(|c| c.checked_mul(multiplicity))
            .ok_or_else(too_large)?;
        let mut values = match accessor.buffer_view {
            None => vec![T::default(); values_len],
            Some(view) => {
                let view = view.value();
                let (bytes, stride) = self.view_bytes(view, &part)?;
                let stride = stride.map_or(element_size, |s| s as u64);
                if stride < element_size {
                    return Err(invalid(
                        part,
                        format!(
                            "buffer view {view} has byteStride {stride}, smaller than one \
                             element ({element_size} bytes)"
                        ),
                    ));
                }
                let offset = accessor.byte_offset.map_or(0, |o| o.0);
                let end = match count.checked_sub(1) {
                    None => Some(offset),
                    Some(last) => stride
                        .checked_mul(last)
                        .and_then(|x| x.checked_add(offset))
                        .and_then(|x| x.checked_add(element_size)),
                };
                if end.is_none_or(|end| end > bytes.len() as u64) {
                    return Err(invalid(
                        part,
                        format!(
                            "{count} elements of {element_size} bytes (stride {stride}) from \
                             byte {offset} run past the end of buffer view {view} ({} bytes)",
                            bytes.len()
                        ),
                    ));
                }
                let mut values = Vec::with_capacity(values_len);
                for element in 0..count {
                    let start = offset + element * stride;
                    for c in 0..multiplicity {
                        let at = start + (c * component_size) as u64;
                        let b = slice_at(bytes, at, component_size as u64)
                            .ok_or_else(|| invalid(&part, format!("byte {at} is out of range")))?;
                        values.push(decode(component, accessor.normalized, b));
                    }
                }
                values
            }
        };
        if let Some(sparse) = &accessor.sparse {
            let sparse_count = sparse.count.0;
            if sparse_count > count {
                return Err(invalid(
                    part,
                    format!("sparse count {sparse_count} exceeds the accessor count {count}"),
                ));
            }
            let Checked::Valid(IndexComponentType(index_component)) = sparse.indices.component_type
            else {
                return Err(invalid(part, "sparse indices componentType is invalid"));
            };
            let index_size = index_component.size() as u64;
            let (index_bytes, _) = self.view_bytes(sparse.indices.buffer_view.value(), &part)?;
            let (value_bytes, _) = self.view_bytes(sparse.values.buffer_view.value(), &part)?;
            for k in 0..sparse_count {
                let index_at = k
                    .checked_mul(index_size)
                    .and_then(|x| x.checked_add(sparse.indices.byte_offset.0));
                let target = index_at
                    .and_then(|at| slice_at(index_bytes, at, index_size))
                    .map(|b| decode_index(index_component, b))
                    .ok_or_else(|| {
                        invalid(
                            &part,
                            format!("sparse index {k} lies outside its buffer view"),
                        )
                    })?;
                if u64::from(target) >= count {
                    return Err(invalid(
                        part,
                        format!("sparse index {k} is {target}, out of range (count {count})"),
                    ));
                }
                for c in 0..multiplicity {
                    let value_at = (k * multiplicity as u64 + c as u64)
                        .checked_mul(component_size as u64)
                        .and_then(|x| x.checked_add(sparse.values.byte_offset.0));
                    let value = value_at
                        .and_then(|at| slice_at(value_bytes, at, component_size as u64))
                        .map(|b| decode(component, accessor.normalized, b))
                        .ok_or_else(|| {
                            invalid(
                                &part,
                                format!("sparse value {k} lies outside its buffer view"),
                            )
                        })?;
                    if let Some(slot) = values.get_mut(target as usize * multiplicity + c) {
                        *slot = value;
                    }
                }
            }
        }
        Ok(values)
    }

    /// The bytes of a buffer view and its stride; `context` names who refers to it.
    fn view_bytes(&self, index: usize, context: &str) -> Result<(&[u8], Option<usize>), LoadError> {
        let Some(view) = self.root.buffer_views.get(index) else {
            return Err(invalid(
                context,
                format!("buffer view {index} does not exist"),
            ));
        };
        let part = format!(
            "{context}: {}",
            named("buffer view", index, view.name.as_deref())
        );
        let buffer_index = view.buffer.value();
        let Some(buffer) = self.buffers.get(buffer_index) else {
            return Err(invalid(
                part,
                format!("buffer {buffer_index} does not exist"),
            ));
        };
        let offset = view.byte_offset.map_or(0, |o| o.0);
        let length = view.byte_length.0;
        let bytes = slice_at(buffer, offset, length).ok_or_else(|| {
            invalid(
                &part,
                format!(
                    "bytes {offset}..{} lie outside buffer {buffer_index} ({} bytes)",
                    offset.saturating_add(length),
                    buffer.len()
                ),
            )
        })?;
        Ok((bytes, view.byte_stride.map(|s| s.0)))
    }

    fn material_index(&mut self, material: Option<usize>) -> Result<u32, LoadError> {
        let Some(index) = material else {
            if let Some(default) = self.default_material {
                return Ok(default);
            }
            let default = self.materials.len() as u32;
            self.materials.push(Material::default());
            self.default_material = Some(default);
            return Ok(default);
        };
        if let Some(&Some(mapped)) = self.material_map.get(index) {
            return Ok(mapped);
        }
        let converted = self.convert_material(index)?;
        let mapped = self.materials.len() as u32;
        self.materials.push(converted);
        if let Some(slot) = self.material_map.get_mut(index) {
            *slot = Some(mapped);
        }
        Ok(mapped)
    }

    fn convert_material(&mut self, index: usize) -> Result<Material, LoadError> {
        let Some(material) = self.root.materials.get(index) else {
            return Err(invalid(format!("material {index}"), "does not exist"));
        };
        let part = named("material", index, material.name.as_deref());
        let pbr = &material.pbr_metallic_roughness;
        let strength = material
            .extensions
            .as_ref()
            .and_then(|e| e.emissive_strength.as_ref())
            .map_or(1.0, |s| s.emissive_strength.0);
        let emissive = material.emissive_factor.0.map(|e| e * strength);
        let base_color = pbr.base_color_factor.0;
        let (metallic, roughness) = (pbr.metallic_factor.0, pbr.roughness_factor.0);
        let factors = base_color
            .iter()
            .chain(&emissive)
            .chain([&metallic, &roughness]);
        if !factors.into_iter().all(|f| f.is_finite()) {
            return Err(invalid(part, "has a non-finite factor"));
        }
        let alpha_cutoff = match material.alpha_mode {
            Checked::Valid(AlphaMode::Opaque) => None,
            Checked::Valid(AlphaMode::Mask) => {
                Some(material.alpha_cutoff.as_ref().map_or(0.5, |c| c.0))
            }
            Checked::Valid(AlphaMode::Blend) => {
                tracing::warn!("{part}: alphaMode BLEND is not supported; rendering it opaque");
                None
            }
            Checked::Invalid => return Err(invalid(part, "alphaMode is invalid")),
        };
        let base_color_texture = match &pbr.base_color_texture {
            Some(info) if info.tex_coord != 0 => {
                tracing::warn!(
                    "{part}: base colour texture uses TEXCOORD_{}; only TEXCOORD_0 is \
                     supported, so the texture is ignored",
                    info.tex_coord
                );
                None
            }
            Some(info) => Some(self.texture(info.index.value(), &part)?),
            None => None,
        };
        Ok(Material {
            name: material
                .name
                .clone()
                .unwrap_or_else(|| format!("material {index}")),
            base_color,
            metallic,
            roughness,
            emissive,
            base_color_texture,
            alpha_cutoff,
        })
    }

    /// Index in `textures` of a glTF texture's image, decoding the image on first use.
    fn texture(&mut self, index: usize, context: &str) -> Result<usize, LoadError> {
        let root = self.root;
        let Some(texture) = root.textures.get(index) else {
            return Err(invalid(context, format!("texture {index} does not exist")));
        };
        let image_index = texture.source.value();
        if let Some(&Some(mapped)) = self.image_map.get(image_index) {
            return Ok(mapped);
        }
        let texture_part = named("texture", index, texture.name.as_deref());
        let Some(image) = root.images.get(image_index) else {
            return Err(invalid(
                texture_part,
                format!("image {image_index} does not exist"),
            ));
        };
        let part = format!(
            "{texture_part} ({})",
            named("image", image_index, image.name.as_deref())
        );
        let bytes: Cow<[u8]> = match (&image.uri, image.buffer_view) {
            (Some(uri), _) => Cow::Owned(read_uri(uri, self.base_dir, &part)?),
            (None, Some(view)) => Cow::Borrowed(self.view_bytes(view.value(), &part)?.0),
            (None, None) => return Err(invalid(part, "has neither a uri nor a bufferView")),
        };
        let name = image
            .name
            .clone()
            .or_else(|| image.uri.clone().filter(|u| !u.starts_with("data:")))
            .unwrap_or_else(|| format!("image {image_index}"));
        let decoded = decode_image(&bytes, name, &part)?;
        let mapped = self.textures.len();
        self.textures.push(decoded);
        if let Some(slot) = self.image_map.get_mut(image_index) {
            *slot = Some(mapped);
        }
        Ok(mapped)
    }

    fn add_camera(&mut self, index: usize, world: &Mat4) -> Result<(), LoadError> {
        let Some(camera) = self.root.cameras.get(index) else {
            return Err(invalid(format!("camera {index}"), "does not exist"));
        };
        let part = named("camera", index, camera.name.as_deref());
        match camera.type_ {
            Checked::Valid(CameraType::Perspective) => {
                let Some(perspective) = &camera.perspective else {
                    return Err(invalid(
                        part,
                        "is perspective but has no perspective object",
                    ));
                };
                let yfov = perspective.yfov;
                if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
                    return Err(invalid(
                        part,
                        format!("yfov {yfov} is not between 0 and π radians"),
                    ));
                }
                let position = world.transform_point3(Vec3::ZERO);
                let forward = world
                    .transform_vector3(Vec3::NEG_Z)
                    .try_normalize()
                    .ok_or_else(|| invalid(&part, "node transform collapses the view direction"))?;
                self.cameras.push(Camera {
                    position: position.to_array(),
                    target: (position + forward).to_array(),
                    fov_y_degrees: yfov.to_degrees(),
                });
            }
            Checked::Valid(CameraType::Orthographic) => {
                tracing::warn!("{part}: orthographic cameras are not supported; skipped");
            }
            Checked::Invalid => return Err(invalid(part, "type is invalid")),
        }
        Ok(())
    }

    fn add_light(&mut self, index: usize, world: &Mat4, node_part: &str) -> Result<(), LoadError> {
        let lights = self
            .root
            .extensions
            .as_ref()
            .and_then(|e| e.khr_lights_punctual.as_ref())
            .map_or(&[][..], |l| l.lights.as_slice());
        let Some(light) = lights.get(index) else {
            return Err(invalid(
                node_part,
                format!(
                    "refers to light {index}, but the file defines {} lights",
                    lights.len()
                ),
            ));
        };
        let part = named("light", index, light.name.as_deref());
        let kind = match light.type_ {
            Checked::Valid(LightType::Directional) => LightKind::Directional,
            Checked::Valid(LightType::Point) => LightKind::Point,
            Checked::Valid(LightType::Spot) => LightKind::Spot,
            Checked::Invalid => return Err(invalid(part, "type is invalid")),
        };
        let (inner_cone, outer_cone) = light
            .spot
            .as_ref()
            .map_or((0.0, std::f32::consts::FRAC_PI_4), |s| {
                (s.inner_cone_angle, s.outer_cone_angle)
            });
        let parameters = light
            .color
            .iter()
            .chain([&light.intensity, &inner_cone, &outer_cone]);
        if !parameters.into_iter().all(|p| p.is_finite()) {
            return Err(invalid(part, "has a non-finite parameter"));
        }
        let direction = world
            .transform_vector3(Vec3::NEG_Z)
            .try_normalize()
            .unwrap_or(Vec3::NEG_Z);
        self.lights.push(Light {
            kind,
            position: world.transform_point3(Vec3::ZERO).to_array(),
            direction: direction.to_array(),
            color: light.color,
            intensity: light.intensity,
            inner_cone,
            outer_cone,
        });
        Ok(())
    }
}

fn check_count(actual: usize, expected: usize, part: &str, usage: &str) -> Result<(), LoadError> {
    if actual == expected {
        Ok(())
    } else {
        Err(invalid(
            part,
            format!("{usage} has {actual} elements, but POSITION has {expected}"),
        ))
    }
}

/// Decodes a PNG or JPEG to RGBA8, keeping the sRGB-encoded bytes as they are.
fn decode_image(bytes: &[u8], name: String, part: &str) -> Result<Texture, LoadError> {
    let decode_error = |error| LoadError::ImageDecode {
        part: part.to_owned(),
        error,
    };
    let format = image::guess_format(bytes).map_err(decode_error)?;
    if !matches!(format, image::ImageFormat::Png | image::ImageFormat::Jpeg) {
        return Err(invalid(
            part,
            format!("image format {format:?} is not supported (only PNG and JPEG)"),
        ));
    }
    // Dimensions come from the header alone, so oversized images are refused before the
    // pixel buffer is allocated.
    let (width, height) = image::ImageReader::with_format(io::Cursor::new(bytes), format)
        .into_dimensions()
        .map_err(decode_error)?;
    if width > MAX_TEXTURE_SIZE || height > MAX_TEXTURE_SIZE {
        return Err(invalid(
            part,
            format!(
                "image is {width}×{height} pixels; at most {MAX_TEXTURE_SIZE} in either \
                 dimension is supported"
            ),
        ));
    }
    let rgba = image::load_from_memory_with_format(bytes, format)
        .map_err(decode_error)?
        .into_rgba8();
    Ok(Texture {
        name,
        width: rgba.width(),
        height: rgba.height(),
        rgba8: rgba.into_raw(),
    })
}
