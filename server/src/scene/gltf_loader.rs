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
//! Geometry is static: skins, morph targets and animations are ignored (meshes appear in their
//! bind pose), as are tangents, vertex colours, texture sets other than `TEXCOORD_0`, samplers,
//! and all textures except the base colour one.

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
    check_version_and_extensions(json_bytes)?;
    let root: json::Root = serde_json::from_slice(json_bytes).map_err(LoadError::Json)?;
    // gltf-json's validation indexes `accessors` with the POSITION attribute unchecked.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let position = primitive
                .attributes
                .get(&Checked::Valid(Semantic::Positions));
            if let Some(accessor) = position.filter(|a| a.value() >= root.accessors.len()) {
                return Err(invalid(
                    format!("{} primitive {p}", named("mesh", m, mesh.name.as_deref())),
                    format!("POSITION accessor {} does not exist", accessor.value()),
                ));
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(&root, json::Path::new, &mut |path, error| {
        let path = path();
        // Bounds are computed from the vertices, and many exporters omit POSITION min/max.
        let position_bounds = path.as_str().ends_with("[\"POSITION\"].min")
            || path.as_str().ends_with("[\"POSITION\"].max");
        if !(position_bounds && error == json::validation::Error::Missing) {
            errors.push(format!("{path}: {error}"));
        }
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

/// Checks the version and required extensions on the untyped JSON, so that a glTF 1.0 file or
/// one relying on an unsupported extension gets that message rather than a type error from
/// the typed parse.
fn check_version_and_extensions(json_bytes: &[u8]) -> Result<(), LoadError> {
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
    Ok(())
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
/// Whether a triangle covers any area (distinct corners that are not collinear).
fn has_area(positions: &[Vec3], t: &[u32; 3]) -> bool {
    let [a, b, c] = t.map(|i| positions[i as usize].as_dvec3());
    (b - a).cross(c - a).length_squared() > 0.0
}

/// The vertices of `count` that `triangles` use, in their order (a file without unused
/// vertices keeps its numbering), and the triangles renumbered to index that list.
fn compact(count: usize, triangles: &[[u32; 3]]) -> (Vec<u32>, Vec<[u32; 3]>) {
    let mut new_index = vec![u32::MAX; count];
    for &i in triangles.iter().flatten() {
        new_index[i as usize] = 0;
    }
    let mut kept = Vec::new();
    for (old, slot) in new_index.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = kept.len() as u32;
            kept.push(old as u32);
        }
    }
    let renumbered = triangles
        .iter()
        .map(|t| t.map(|i| new_index[i as usize]))
        .collect();
    (kept, renumbered)
}

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
        self.check_budget(
            mode,
            position_accessor,
            primitive.indices.map(|a| a.value()),
            part,
        )?;
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
        // Zero-area triangles light nothing and cover no pixel, but cost memory in every
        // buffer and light-cache step: a few hundred bytes of zero-filled accessors would
        // otherwise hold millions of them. Only the vertices the rest use are kept.
        triangles.retain(|t| has_area(&positions, t));
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
        let (kept, triangles) = compact(count, &triangles);

        let material = self.material_index(primitive.material.map(|m| m.value()))?;
        let base = self.vertices.len();
        if u32::try_from(base + kept.len()).is_err() {
            return Err(invalid(part, "scene would exceed 2^32 vertices"));
        }
        let base = base as u32;
        self.vertices.extend(kept.iter().map(|&i| {
            let i = i as usize;
            Vertex {
                position: positions[i].to_array(),
                normal: normals[i].to_array(),
                uv: [uvs[2 * i], uvs[2 * i + 1]],
                material,
            }
        }));
        self.indices
            .extend(triangles.iter().flatten().map(|&i| base + i));
        Ok(())
    }

    /// Refuses a primitive whose accessor counts alone would take the scene past its limits,
    /// before any of its data is read.
    fn check_budget(
        &self,
        mode: Mode,
        positions: usize,
        indices: Option<usize>,
        part: &str,
    ) -> Result<(), LoadError> {
        let count = |accessor: usize| self.root.accessors.get(accessor).map_or(0, |a| a.count.0);
        let vertices = count(positions);
        let corners = indices.map_or(vertices, count);
        let triangles = match mode {
            Mode::Triangles => corners / 3,
            _ => corners.saturating_sub(2),
        };
        // Triangles first: the vertex limit follows from theirs, and a scene too large for
        // the triangle budget is told so.
        let total_triangles = (self.indices.len() as u64 / 3).saturating_add(triangles);
        if total_triangles > self.limits.max_triangles {
            return Err(LoadError::TriangleBudget {
                part: part.to_owned(),
                triangles: total_triangles,
                limit: self.limits.max_triangles,
            });
        }
        let total_vertices = (self.vertices.len() as u64).saturating_add(vertices);
        if total_vertices > self.limits.max_vertices {
            return Err(invalid(
                part,
                format!(
                    "the scene would have {total_vertices} vertices or more; at most {} are \
                     allowed",
                    self.limits.max_vertices
                ),
            ));
        }
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
        if accessor.buffer_view.is_none() {
            let unbacked = self.unbacked_elements.get().saturating_add(count);
            if unbacked > MAX_UNBACKED_ELEMENTS {
                return Err(invalid(
                    &part,
                    format!(
                        "has no buffer view, and with it the file's zero-filled accessors \
                         hold {unbacked} elements; at most {MAX_UNBACKED_ELEMENTS} are allowed"
                    ),
                ));
            }
            self.unbacked_elements.set(unbacked);
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
        let remaining = self.limits.max_texture_bytes - self.texture_bytes;
        let decoded = decode_image(&bytes, name, &part, remaining, self.limits.max_texture_size)?;
        self.texture_bytes += decoded.rgba8.len() as u64;
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
                // A valid file may ask for a field of view the renderer refuses; the camera is
                // still the file's intended view, so it is kept within the renderer's range.
                let fov_y_degrees = yfov.to_degrees().clamp(1.0, 179.0);
                if fov_y_degrees != yfov.to_degrees() {
                    tracing::warn!(
                        "{part}: yfov of {}° is outside 1°–179°; using {fov_y_degrees}°",
                        yfov.to_degrees()
                    );
                }
                self.cameras.push(Camera {
                    position: position.to_array(),
                    target: (position + forward).to_array(),
                    fov_y_degrees,
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
        // KHR_lights_punctual's own ranges, which the renderer relies on too.
        if light.color.iter().any(|&c| c < 0.0) || light.intensity < 0.0 {
            return Err(invalid(part, "color and intensity must not be negative"));
        }
        if !(0.0 <= inner_cone
            && inner_cone <= outer_cone
            && outer_cone <= std::f32::consts::FRAC_PI_2)
        {
            return Err(invalid(
                part,
                format!(
                    "spot cone angles need 0 ≤ innerConeAngle ≤ outerConeAngle ≤ π/2, got \
                     {inner_cone} and {outer_cone}"
                ),
            ));
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

/// The size an image of `width`×`height` is kept at: within `max_side` on both axes, the
/// aspect ratio kept (each side at least 1).
pub fn kept_size(width: u32, height: u32, max_side: u32) -> (u32, u32) {
    let longest = width.max(height);
    if longest <= max_side {
        return (width, height);
    }
    let scale = |side: u32| {
        let scaled = u64::from(side) * u64::from(max_side) / u64::from(longest);
        (scaled as u32).max(1)
    };
    (scale(width), scale(height))
}

/// Decodes a PNG or JPEG to RGBA8, keeping the sRGB-encoded bytes as they are, downscaled to
/// at most `max_side` texels a side, if its kept pixels fit in `max_bytes`.
fn decode_image(
    bytes: &[u8],
    name: String,
    part: &str,
    max_bytes: u64,
    max_side: u32,
) -> Result<Texture, LoadError> {
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
    let (kept_width, kept_height) = kept_size(width, height, max_side);
    let kept_bytes = 4 * u64::from(kept_width) * u64::from(kept_height);
    if kept_bytes > max_bytes {
        return Err(LoadError::TextureBudget {
            part: part.to_owned(),
            width,
            height,
            kept_width,
            kept_height,
            needed: kept_bytes,
            available: max_bytes,
        });
    }
    let mut rgba = image::load_from_memory_with_format(bytes, format)
        .map_err(decode_error)?
        .into_rgba8();
    if (kept_width, kept_height) != (width, height) {
        // Filtered in the sRGB encoding the bytes are in: a slight darkening of high-contrast
        // detail, invisible at the frame sizes that made the full size unnecessary.
        rgba = image::imageops::resize(
            &rgba,
            kept_width,
            kept_height,
            image::imageops::FilterType::Triangle,
        );
    }
    Ok(Texture {
        name,
        width: rgba.width(),
        height: rgba.height(),
        rgba8: rgba.into_raw(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{json, Value};
    use std::sync::atomic::{AtomicUsize, Ordering};

    const CORNELL_BOX: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/cornell-box/cornell-box.glb"
    );

    /// A directory under the system temp dir, removed on drop.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new(tag: &str) -> Self {
            static COUNTER: AtomicUsize = AtomicUsize::new(0);
            let dir = std::env::temp_dir().join(format!(
                "lightcast-gltf-{}-{tag}-{}",
                std::process::id(),
                COUNTER.fetch_add(1, Ordering::Relaxed)
            ));
            fs::create_dir_all(&dir).expect("create temp dir");
            Self(dir)
        }

        fn write(&self, name: &str, bytes: &[u8]) -> PathBuf {
            let path = self.0.join(name);
            fs::write(&path, bytes).expect("write fixture");
            path
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = fs::remove_dir_all(&self.0);
        }
    }

    /// A little-endian binary buffer with one buffer view and accessor per pushed array.
    #[derive(Default)]
    struct Bin {
        bytes: Vec<u8>,
        views: Vec<Value>,
        accessors: Vec<Value>,
    }

    impl Bin {
        fn push(&mut self, data: &[u8], mut accessor: Value) -> usize {
            while !self.bytes.len().is_multiple_of(4) {
                self.bytes.push(0);
            }
            self.views.push(json!({
                "buffer": 0,
                "byteOffset": self.bytes.len(),
                "byteLength": data.len(),
            }));
            self.bytes.extend_from_slice(data);
            accessor["bufferView"] = json!(self.views.len() - 1);
            self.accessors.push(accessor);
            self.accessors.len() - 1
        }

        fn floats<const N: usize>(&mut self, data: &[[f32; N]], ty: &str) -> usize {
            let bytes: Vec<u8> = data
                .iter()
                .flatten()
                .flat_map(|f| f.to_le_bytes())
                .collect();
            self.push(
                &bytes,
                json!({"componentType": 5126, "type": ty, "count": data.len()}),
            )
        }

        fn vec3(&mut self, data: &[[f32; 3]]) -> usize {
            self.floats(data, "VEC3")
        }

        fn vec2(&mut self, data: &[[f32; 2]]) -> usize {
            self.floats(data, "VEC2")
        }

        fn indices(&mut self, data: &[u16]) -> usize {
            let bytes: Vec<u8> = data.iter().flat_map(|i| i.to_le_bytes()).collect();
            self.push(
                &bytes,
                json!({"componentType": 5123, "type": "SCALAR", "count": data.len()}),
            )
        }

        /// The glTF document: `rest`'s top-level fields plus asset, buffer, views, accessors.
        fn document(&self, uri: Option<&str>, rest: Value) -> Value {
            let mut buffer = json!({"byteLength": self.bytes.len()});
            if let Some(uri) = uri {
                buffer["uri"] = json!(uri);
            }
            let mut doc = json!({
                "asset": {"version": "2.0"},
                "buffers": [buffer],
                "bufferViews": self.views,
                "accessors": self.accessors,
            });
            if let (Some(doc), Value::Object(rest)) = (doc.as_object_mut(), rest) {
                doc.extend(rest);
            }
            doc
        }
    }

    /// Counter-clockwise seen from +Y, so its geometric normal is +Y.
    const QUAD: [[f32; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [1.0, 0.0, 0.0],
    ];
    const QUAD_UV: [[f32; 2]; 4] = [[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]];
    const QUAD_INDICES: [u16; 6] = [0, 1, 2, 0, 2, 3];

    fn quad_primitive(bin: &mut Bin, with_normals: bool) -> Value {
        let mut attributes = json!({"POSITION": bin.vec3(&QUAD), "TEXCOORD_0": bin.vec2(&QUAD_UV)});
        if with_normals {
            attributes["NORMAL"] = json!(bin.vec3(&[[0.0, 1.0, 0.0]; 4]));
        }
        json!({"attributes": attributes, "indices": bin.indices(&QUAD_INDICES)})
    }

    /// Scene fields for one node holding one mesh named "quad" with the given primitives.
    fn single_mesh(primitives: Value) -> Value {
        json!({
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"name": "quad", "primitives": primitives}],
        })
    }

    fn quad_document(uri: Option<&str>) -> (Value, Bin) {
        let mut bin = Bin::default();
        let primitive = quad_primitive(&mut bin, true);
        (bin.document(uri, single_mesh(json!([primitive]))), bin)
    }

    /// Writes `doc` as scene.gltf next to `bin` as data.bin and loads it.
    fn load_document(doc: &Value, bin: &[u8]) -> Result<Scene, LoadError> {
        let dir = TempDir::new("doc");
        dir.write("data.bin", bin);
        let path = dir.write("scene.gltf", &serde_json::to_vec(doc).expect("serialise"));
        load_gltf(&path)
    }

    fn load_error(doc: &Value, bin: &[u8]) -> String {
        load_document(doc, bin)
            .expect_err("fixture must be refused")
            .to_string()
    }

    fn glb(doc: &Value, bin: &[u8]) -> Vec<u8> {
        let mut json = serde_json::to_vec(doc).expect("serialise");
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = bin.to_vec();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    }

    fn base64(bytes: &[u8]) -> String {
        const ALPHABET: &[u8; 64] =
            b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let mut out = String::new();
        for chunk in bytes.chunks(3) {
            let mut b = [0u8; 3];
            b[..chunk.len()].copy_from_slice(chunk);
            let n = u32::from(b[0]) << 16 | u32::from(b[1]) << 8 | u32::from(b[2]);
            for i in 0..4 {
                if i <= chunk.len() {
                    out.push(char::from(ALPHABET[(n >> (18 - 6 * i)) as usize & 63]));
                } else {
                    out.push('=');
                }
            }
        }
        out
    }

    fn png(width: u32, height: u32, pixels: &[u8]) -> Vec<u8> {
        let image = image::RgbaImage::from_raw(width, height, pixels.to_vec()).expect("pixels");
        let mut out = io::Cursor::new(Vec::new());
        image
            .write_to(&mut out, image::ImageFormat::Png)
            .expect("encode png");
        out.into_inner()
    }

    fn position(scene: &Scene, index: u32) -> Vec3 {
        Vec3::from(scene.vertices[index as usize].position)
    }

    fn geometric_normals(scene: &Scene) -> Vec<Vec3> {
        scene
            .indices
            .chunks_exact(3)
            .map(|t| {
                let [a, b, c] = [t[0], t[1], t[2]].map(|i| position(scene, i));
                (b - a).cross(c - a).normalize()
            })
            .collect()
    }

    fn assert_close(actual: Vec3, expected: Vec3) {
        assert!(
            actual.abs_diff_eq(expected, 1e-5),
            "{actual} is not {expected}"
        );
    }

    #[test]
    fn loads_the_cornell_box() {
        let scene = load_gltf(Path::new(CORNELL_BOX)).expect("cornell box loads");
        assert_eq!(scene.name, "cornell-box");
        assert!(scene.triangle_count() > 500, "{}", scene.triangle_count());
        let size = scene.bounds.max - scene.bounds.min;
        assert!(
            size.cmpgt(Vec3::splat(1.5)).all() && size.cmplt(Vec3::splat(2.6)).all(),
            "size {size}"
        );
        assert!(
            scene.bounds.center().length() < 0.5,
            "centre {}",
            scene.bounds.center()
        );

        let find = |dominant: usize| {
            scene
                .materials
                .iter()
                .position(|m| {
                    let c = m.base_color;
                    (0..3).all(|i| i == dominant || c[dominant] > 2.0 * c[i] + 0.2)
                })
                .unwrap_or_else(|| panic!("no material dominated by channel {dominant}"))
                as u32
        };
        let xs_of = |material: u32| -> Vec<f32> {
            scene
                .vertices
                .iter()
                .filter(|v| v.material == material)
                .map(|v| v.position[0])
                .collect()
        };
        let red = xs_of(find(0));
        let green = xs_of(find(1));
        assert!(!red.is_empty() && red.iter().all(|&x| x < 0.0), "{red:?}");
        assert!(
            !green.is_empty() && green.iter().all(|&x| x > 0.0),
            "{green:?}"
        );
        assert!(scene.materials.iter().any(Material::is_emissive));
        assert!(scene
            .vertices
            .iter()
            .all(|v| (Vec3::from(v.normal).length() - 1.0).abs() < 1e-3));
    }

    #[test]
    fn loads_an_external_bin_buffer() {
        let (doc, bin) = quad_document(Some("data.bin"));
        let scene = load_document(&doc, &bin.bytes).expect("loads");
        assert_eq!(scene.name, "scene");
        assert_eq!(scene.vertices.len(), 4);
        assert_eq!(scene.triangle_count(), 2);
        assert_eq!(scene.materials, vec![Material::default()]);
        for (v, (p, uv)) in scene.vertices.iter().zip(QUAD.iter().zip(QUAD_UV)) {
            assert_eq!(v.position, *p);
            assert_eq!(v.uv, uv);
            assert_eq!(v.normal, [0.0, 1.0, 0.0]);
            assert_eq!(v.material, 0);
        }
        for n in geometric_normals(&scene) {
            assert_close(n, Vec3::Y);
        }
        // Parts not referenced by the scene's nodes are not needed.
        assert!(scene.lights.is_empty() && scene.cameras.is_empty());
    }

    #[test]
    fn loads_an_embedded_base64_buffer_from_memory() {
        let (_, bin) = quad_document(None);
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64(&bin.bytes)
        );
        let (doc, _) = quad_document(Some(&uri));
        let bytes = serde_json::to_vec(&doc).expect("serialise");
        let scene = load_gltf_slice(&bytes, None, "embedded", LoadLimits::NONE)
            .expect("loads without base dir");
        let (external, bin) = quad_document(Some("data.bin"));
        let reference = load_document(&external, &bin.bytes).expect("loads");
        assert_eq!(scene.name, "embedded");
        assert_eq!(scene.vertices, reference.vertices);
        assert_eq!(scene.indices, reference.indices);
    }

    #[test]
    fn loads_a_hand_assembled_glb() {
        let (doc, bin) = quad_document(None);
        let bytes = glb(&doc, &bin.bytes);
        let dir = TempDir::new("glb");
        let scene = load_gltf(&dir.write("box.glb", &bytes)).expect("loads");
        let (external, bin) = quad_document(Some("data.bin"));
        let reference = load_document(&external, &bin.bytes).expect("loads");
        assert_eq!(scene.name, "box");
        assert_eq!(scene.vertices, reference.vertices);
        assert_eq!(scene.indices, reference.indices);
        let from_memory =
            load_gltf_slice(&bytes, None, "mem", LoadLimits::NONE).expect("glb needs no base dir");
        assert_eq!(from_memory.vertices, reference.vertices);
    }

    #[test]
    fn generates_normals_for_indexed_and_non_indexed_triangles() {
        let mut bin = Bin::default();
        let position = bin.vec3(&QUAD);
        let indices = bin.indices(&QUAD_INDICES);
        let indexed = json!({"attributes": {"POSITION": position}, "indices": indices});
        let soup: Vec<[f32; 3]> = QUAD_INDICES.iter().map(|&i| QUAD[i as usize]).collect();
        let soup = bin.vec3(&soup);
        let non_indexed = json!({"attributes": {"POSITION": soup}});
        let doc = bin.document(Some("data.bin"), single_mesh(json!([indexed, non_indexed])));
        let scene = load_document(&doc, &bin.bytes).expect("loads");
        assert_eq!(scene.vertices.len(), 4 + 6);
        assert_eq!(scene.triangle_count(), 4);
        for v in &scene.vertices {
            assert_close(Vec3::from(v.normal), Vec3::Y);
            assert_eq!(v.uv, [0.0, 0.0]);
        }
        for n in geometric_normals(&scene) {
            assert_close(n, Vec3::Y);
        }
    }

    #[test]
    fn converts_strips_and_fans_with_consistent_winding() {
        let mut bin = Bin::default();
        let strip = bin.vec3(&[
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
            [1.0, 0.0, 1.0],
        ]);
        let fan = bin.vec3(&QUAD);
        let doc = bin.document(
            Some("data.bin"),
            single_mesh(json!([
                {"attributes": {"POSITION": strip}, "mode": 5},
                {"attributes": {"POSITION": fan}, "mode": 6},
            ])),
        );
        let scene = load_document(&doc, &bin.bytes).expect("loads");
        assert_eq!(scene.triangle_count(), 4);
        for n in geometric_normals(&scene) {
            assert_close(n, Vec3::Y);
        }
    }

    #[test]
    fn applies_the_node_hierarchy_and_loads_all_roots_without_scenes() {
        let mut bin = Bin::default();
        let primitive = quad_primitive(&mut bin, true);
        let doc = bin.document(
            Some("data.bin"),
            json!({
                "nodes": [
                    // Column-major: uniform scale 2, then translate by (10, 0, 0).
                    {"children": [1], "matrix": [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 10, 0, 0, 1]},
                    {"mesh": 0, "translation": [0, 1, 0]},
                ],
                "meshes": [{"primitives": [primitive]}],
            }),
        );
        let scene = load_document(&doc, &bin.bytes).expect("loads");
        assert_eq!(scene.vertices.len(), 4, "the child is visited once");
        assert_close(scene.bounds.min, Vec3::new(10.0, 2.0, 0.0));
        assert_close(scene.bounds.max, Vec3::new(12.0, 2.0, 2.0));
        for v in &scene.vertices {
            assert_close(Vec3::from(v.normal), Vec3::Y);
        }
    }

    #[test]
    fn negative_scale_flips_winding_to_keep_front_faces() {
        let mut bin = Bin::default();
        let primitive = quad_primitive(&mut bin, true);
        let mut fields = single_mesh(json!([primitive]));
        fields["nodes"][0]["scale"] = json!([-1, 1, 1]);
        let doc = bin.document(Some("data.bin"), fields);
        let scene = load_document(&doc, &bin.bytes).expect("loads");
        assert_close(scene.bounds.min, Vec3::new(-1.0, 0.0, 0.0));
        for v in &scene.vertices {
            assert_close(Vec3::from(v.normal), Vec3::Y);
        }
        for n in geometric_normals(&scene) {
            assert_close(n, Vec3::Y);
        }
    }

    #[test]
    fn loads_materials_and_shares_textures_per_image() {
        let pixels: Vec<u8> = [
            [255, 0, 0, 255],
            [0, 255, 0, 255],
            [0, 0, 255, 255],
            [255, 255, 255, 128],
        ]
        .concat();
        let mut bin = Bin::default();
        let primitives: Vec<Value> = (0..4)
            .map(|material| {
                let mut p = quad_primitive(&mut bin, true);
                p["material"] = json!(material);
                p
            })
            .collect();
        let mut fields = single_mesh(json!(primitives));
        fields["extensionsUsed"] = json!(["KHR_materials_emissive_strength", "EXT_unknown"]);
        fields["images"] = json!([{"uri": "tex%20ture.png"}, {"uri": "unused-missing.png"}]);
        fields["textures"] = json!([{"source": 0}, {"source": 0}, {"source": 1}]);
        fields["materials"] = json!([
            {
                "name": "masked",
                "pbrMetallicRoughness": {
                    "baseColorFactor": [0.5, 0.5, 0.5, 1],
                    "baseColorTexture": {"index": 0},
                    "metallicFactor": 0.25,
                    "roughnessFactor": 0.75,
                },
                "alphaMode": "MASK",
                "alphaCutoff": 0.3,
                "emissiveFactor": [1, 0.5, 0],
                "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4}},
            },
            {"name": "shared", "pbrMetallicRoughness": {"baseColorTexture": {"index": 1}}},
            {
                "name": "second-uv-set",
                "pbrMetallicRoughness": {"baseColorTexture": {"index": 2, "texCoord": 1}},
                "alphaMode": "BLEND",
            },
            {"name": "mask-default", "alphaMode": "MASK"},
        ]);
        let doc = bin.document(Some("data.bin"), fields);
        let dir = TempDir::new("texture");
        dir.write("tex ture.png", &png(2, 2, &pixels));
        dir.write("data.bin", &bin.bytes);
        let path = dir.write("scene.gltf", &serde_json::to_vec(&doc).expect("serialise"));
        let scene = load_gltf(&path).expect("loads");

        assert_eq!(scene.textures.len(), 1, "one texture per image");
        let texture = &scene.textures[0];
        assert_eq!((texture.width, texture.height), (2, 2));
        assert_eq!(texture.rgba8, pixels);
        assert_eq!(texture.name, "tex%20ture.png");

        let material = |name: &str| {
            scene
                .materials
                .iter()
                .find(|m| m.name == name)
                .unwrap_or_else(|| panic!("material {name}"))
        };
        let masked = material("masked");
        assert_eq!(masked.base_color, [0.5, 0.5, 0.5, 1.0]);
        assert_eq!((masked.metallic, masked.roughness), (0.25, 0.75));
        assert_eq!(masked.emissive, [4.0, 2.0, 0.0]);
        assert_eq!(masked.alpha_cutoff, Some(0.3));
        assert_eq!(masked.base_color_texture, Some(0));
        assert_eq!(material("shared").base_color_texture, Some(0));
        assert_eq!(material("shared").base_color, [1.0; 4]);
        let ignored = material("second-uv-set");
        assert_eq!(ignored.base_color_texture, None);
        assert_eq!(ignored.alpha_cutoff, None);
        assert_eq!(material("mask-default").alpha_cutoff, Some(0.5));
        let mut used: Vec<u32> = scene.vertices.iter().map(|v| v.material).collect();
        used.dedup();
        assert_eq!(used.len(), 4);
    }

    #[test]
    fn decodes_an_image_from_a_glb_buffer_view_without_mime_type() {
        let pixels = [10u8, 20, 30, 255];
        let mut bin = Bin::default();
        let mut primitive = quad_primitive(&mut bin, true);
        primitive["material"] = json!(0);
        let encoded = png(1, 1, &pixels);
        let view = bin.push(
            &encoded,
            json!({"componentType": 5121, "type": "SCALAR", "count": 0}),
        );
        let mut fields = single_mesh(json!([primitive]));
        fields["images"] = json!([{"bufferView": view}]);
        fields["textures"] = json!([{"source": 0}]);
        fields["materials"] = json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
        let doc = bin.document(None, fields);
        let scene =
            load_gltf_slice(&glb(&doc, &bin.bytes), None, "t", LoadLimits::NONE).expect("loads");
        assert_eq!(scene.textures.len(), 1);
        assert_eq!(scene.textures[0].rgba8, pixels);
    }

    #[test]
    fn places_spot_and_point_lights_from_their_nodes() {
        let mut bin = Bin::default();
        let primitive = quad_primitive(&mut bin, true);
        let half = std::f32::consts::FRAC_1_SQRT_2;
        let doc = bin.document(
            Some("data.bin"),
            json!({
                "extensionsUsed": ["KHR_lights_punctual"],
                "extensionsRequired": ["KHR_lights_punctual"],
                "extensions": {"KHR_lights_punctual": {"lights": [
                    {"type": "spot", "color": [1, 0.5, 0.25], "intensity": 40,
                     "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}},
                    {"type": "point"},
                    {"type": "directional", "name": "unattached"},
                ]}},
                "scene": 0,
                "scenes": [{"nodes": [0, 1]}],
                "nodes": [
                    {"mesh": 0},
                    {"translation": [0, 5, 0], "children": [2, 3]},
                    // +90° about X turns the light's -Z axis to +Y.
                    {"translation": [1, 0, 0], "rotation": [half, 0, 0, half],
                     "extensions": {"KHR_lights_punctual": {"light": 0}}},
                    {"extensions": {"KHR_lights_punctual": {"light": 1}}},
                ],
                "meshes": [{"primitives": [primitive]}],
            }),
        );
        let scene = load_document(&doc, &bin.bytes).expect("loads");
        assert_eq!(scene.lights.len(), 2, "lights without a node are ignored");
        let spot = &scene.lights[0];
        assert_eq!(spot.kind, LightKind::Spot);
        assert_close(Vec3::from(spot.position), Vec3::new(1.0, 5.0, 0.0));
        assert_close(Vec3::from(spot.direction), Vec3::Y);
        assert_eq!(spot.color, [1.0, 0.5, 0.25]);
        assert_eq!(spot.intensity, 40.0);
        assert_eq!((spot.inner_cone, spot.outer_cone), (0.2, 0.5));
        let point = &scene.lights[1];
        assert_eq!(point.kind, LightKind::Point);
        assert_close(Vec3::from(point.position), Vec3::new(0.0, 5.0, 0.0));
        assert_eq!(point.color, [1.0; 3]);
        assert_eq!(point.intensity, 1.0);
        assert_eq!(
            (point.inner_cone, point.outer_cone),
            (0.0, std::f32::consts::FRAC_PI_4)
        );
    }

    #[test]
    fn refuses_lights_outside_their_ranges_and_clamps_extreme_fields_of_view() {
        let document = |light: Value, yfov: f64| {
            let mut bin = Bin::default();
            let primitive = quad_primitive(&mut bin, true);
            let doc = bin.document(
                Some("data.bin"),
                json!({
                    "extensionsUsed": ["KHR_lights_punctual"],
                    "extensions": {"KHR_lights_punctual": {"lights": [light]}},
                    "cameras": [{"type": "perspective", "perspective": {"yfov": yfov, "znear": 0.1}}],
                    "scene": 0,
                    "scenes": [{"nodes": [0, 1, 2]}],
                    "nodes": [
                        {"mesh": 0},
                        {"translation": [0, 5, 0], "extensions": {"KHR_lights_punctual": {"light": 0}}},
                        {"translation": [0, 1, 5], "camera": 0},
                    ],
                    "meshes": [{"primitives": [primitive]}],
                }),
            );
            (doc, bin)
        };
        for (light, expected) in [
            (
                json!({"type": "point", "color": [1, -0.5, 1]}),
                "must not be negative",
            ),
            (
                json!({"type": "point", "intensity": -3}),
                "must not be negative",
            ),
            (
                json!({"type": "spot", "spot": {"innerConeAngle": 0.6, "outerConeAngle": 0.5}}),
                "innerConeAngle ≤ outerConeAngle",
            ),
            (
                json!({"type": "spot", "spot": {"outerConeAngle": 2.0}}),
                "outerConeAngle ≤ π/2",
            ),
        ] {
            let (doc, bin) = document(light.clone(), 0.8);
            let err = load_error(&doc, &bin.bytes);
            assert!(
                err.starts_with("light 0") && err.contains(expected),
                "{light}: {err}"
            );
        }
        let (doc, bin) = document(json!({"type": "point"}), 0.001);
        let scene = load_document(&doc, &bin.bytes).expect("a tiny yfov is valid glTF");
        assert_eq!(scene.cameras[0].fov_y_degrees, 1.0);
    }

    #[test]
    fn refuses_scenes_too_large_for_f32() {
        let mut bin = Bin::default();
        let far = [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [3e30, 0.0, 1.0]];
        let primitive = json!({"attributes": {"POSITION": bin.vec3(&far)}});
        let doc = bin.document(Some("data.bin"), single_mesh(json!([primitive])));
        let err = load_error(&doc, &bin.bytes);
        assert!(err.contains("scene spans 3e30 units"), "{err}");
    }

    #[test]
    fn loads_perspective_cameras_and_skips_orthographic_ones() {
        let mut bin = Bin::default();
        let primitive = quad_primitive(&mut bin, true);
        let doc = bin.document(
            Some("data.bin"),
            json!({
                "scene": 0,
                "scenes": [{"nodes": [0, 1, 2]}],
                "nodes": [
                    {"mesh": 0},
                    {"camera": 0, "translation": [0, 1, 5]},
                    {"camera": 1},
                ],
                "cameras": [
                    {"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}},
                    {"type": "orthographic",
                     "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.1, "zfar": 10}},
                ],
                "meshes": [{"primitives": [primitive]}],
            }),
        );
        let scene = load_document(&doc, &bin.bytes).expect("loads");
        assert_eq!(scene.cameras.len(), 1);
        let camera = &scene.cameras[0];
        assert_eq!(camera.position, [0.0, 1.0, 5.0]);
        assert_close(Vec3::from(camera.target), Vec3::new(0.0, 1.0, 4.0));
        assert!((camera.fov_y_degrees - 0.8f32.to_degrees()).abs() < 1e-4);
    }

    #[test]
    fn refuses_truncated_glb_at_every_offset() {
        let (doc, bin) = quad_document(None);
        let bytes = glb(&doc, &bin.bytes);
        for cut in 0..bytes.len() {
            let truncated = &bytes[..cut];
            assert!(
                load_gltf_slice(truncated, None, "t", LoadLimits::NONE).is_err(),
                "cut at {cut}"
            );
            // Also with a header that agrees with the new length, to reach the chunk checks.
            if cut >= 12 {
                let mut patched = truncated.to_vec();
                patched[8..12].copy_from_slice(&(cut as u32).to_le_bytes());
                assert!(
                    load_gltf_slice(&patched, None, "t", LoadLimits::NONE).is_err(),
                    "patched cut at {cut}"
                );
            }
        }
        let message = |bytes: &[u8]| {
            load_gltf_slice(bytes, None, "t", LoadLimits::NONE)
                .expect_err("truncated")
                .to_string()
        };
        assert!(message(&bytes[..8]).contains("12-byte header"));
        assert!(message(&bytes[..100]).contains("truncated"));
        let json_end = 12 + 8 + u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        let mut no_bin = bytes[..json_end].to_vec();
        no_bin[8..12].copy_from_slice(&(json_end as u32).to_le_bytes());
        let err = message(&no_bin);
        assert!(
            err.contains("buffer 0") && err.contains("binary chunk"),
            "{err}"
        );
        let mut short_chunk = bytes[..json_end + 20].to_vec();
        short_chunk[8..12].copy_from_slice(&((json_end + 20) as u32).to_le_bytes());
        let err = message(&short_chunk);
        assert!(
            err.contains("chunk 1") && err.contains("runs past the end"),
            "{err}"
        );
    }

    #[test]
    fn refuses_random_bytes() {
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state as u8
        };
        for length in (0..2000).step_by(37) {
            let mut bytes: Vec<u8> = (0..length).map(|_| next()).collect();
            assert!(load_gltf_slice(&bytes, None, "t", LoadLimits::NONE).is_err());
            for prefix in [&b"glTF\x02\0\0\0"[..], b"{", b"{\"asset\":"] {
                let n = prefix.len().min(bytes.len());
                bytes[..n].copy_from_slice(&prefix[..n]);
                assert!(load_gltf_slice(&bytes, None, "t", LoadLimits::NONE).is_err());
            }
        }
    }

    #[test]
    fn refuses_wrong_json_types_and_other_versions() {
        let err = load_gltf_slice(
            br#"{"asset":{"version":"2.0"},"meshes":"nope"}"#,
            None,
            "t",
            LoadLimits::NONE,
        )
        .expect_err("wrong type")
        .to_string();
        assert!(err.starts_with("invalid glTF JSON"), "{err}");
        let err = load_gltf_slice(
            br#"{"asset":{"version":"1.0"},"meshes":{}}"#,
            None,
            "t",
            LoadLimits::NONE,
        )
        .expect_err("glTF 1")
        .to_string();
        assert!(
            err.contains("asset.version") && err.contains("1.0"),
            "{err}"
        );
        let err =
            load_gltf_slice(b"[1, 2]", None, "t", LoadLimits::NONE).expect_err("not an object");
        assert!(matches!(err, LoadError::Json(_)), "{err}");
    }

    #[test]
    fn refuses_dangling_references_with_their_json_path() {
        let (mut doc, bin) = quad_document(Some("data.bin"));
        doc["meshes"][0]["primitives"][0]["indices"] = json!(99);
        let err = load_error(&doc, &bin.bytes);
        assert!(err.contains("meshes[0].primitives[0].indices"), "{err}");

        // gltf-json's own validation would panic on this one.
        let (mut doc, bin) = quad_document(Some("data.bin"));
        doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(99);
        let err = load_error(&doc, &bin.bytes);
        assert_eq!(
            err,
            "mesh 0 ('quad') primitive 0: POSITION accessor 99 does not exist"
        );
    }

    /// A GLB whose one primitive reuses a POSITION accessor (one real triangle) and a
    /// zero-filled index accessor (`corners` indices), `primitives` times. glTF only allows an
    /// accessor without a buffer view when it is sparse: the substitutions make the first 100
    /// triangles (fewer when `corners` is smaller) the real one; the rest are [0, 0, 0], of zero
    /// area.
    fn reused_unbacked_accessors(corners: u64, primitives: usize) -> Vec<u8> {
        let mut bin = Bin::default();
        let positions = bin.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        let real = (corners / 3).min(100) as u32;
        let targets: Vec<u32> = (0..real).flat_map(|t| [3 * t + 1, 3 * t + 2]).collect();
        let values: Vec<u32> = (0..real).flat_map(|_| [1, 2]).collect();
        let u32_view = |bin: &mut Bin, data: &[u32]| {
            let view = bin.views.len();
            let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
            bin.push(&bytes, json!({}));
            bin.accessors.pop();
            view
        };
        let (targets, values) = (u32_view(&mut bin, &targets), u32_view(&mut bin, &values));
        bin.accessors.push(json!({
            "componentType": 5125, "type": "SCALAR", "count": corners,
            "sparse": {
                "count": 2 * real,
                "indices": {"bufferView": targets, "componentType": 5125},
                "values": {"bufferView": values},
            },
        }));
        let primitive = json!({"attributes": {"POSITION": positions}, "indices": 1});
        let doc = bin.document(None, single_mesh(json!(vec![primitive; primitives])));
        glb(&doc, &bin.bytes)
    }

    #[test]
    fn refuses_reused_accessors_beyond_the_triangle_limit_before_building_them() {
        let limits = LoadLimits::upload(1_000);
        let small = reused_unbacked_accessors(300, 3);
        let scene = load_gltf_slice(&small, None, "t", limits).expect("300 triangles fit");
        assert_eq!(scene.triangle_count(), 300);

        // ~50 KB asking for 200 million triangles through one reused accessor: refused at the
        // primitive that would cross the limit, before its data is read.
        let bomb = reused_unbacked_accessors(600_000, 1_000);
        assert!(bomb.len() < 64 << 10);
        let err = load_gltf_slice(&bomb, None, "t", LoadLimits::upload(150_000))
            .expect_err("bomb")
            .to_string();
        assert!(
            err.contains("mesh 0 ('quad') primitive 0:")
                && err.contains("at most 150000 are allowed"),
            "{err}"
        );
        let err = load_gltf_slice(&small, None, "t", LoadLimits::upload(250))
            .expect_err("third primitive crosses")
            .to_string();
        assert!(
            err.contains("primitive 2:") && err.contains("300 triangles"),
            "{err}"
        );
        let nine_vertices_too_many = LoadLimits {
            max_vertices: 8,
            ..LoadLimits::NONE
        };
        let err = load_gltf_slice(&small, None, "t", nine_vertices_too_many)
            .expect_err("too many vertices")
            .to_string();
        assert!(
            err.contains("primitive 2:") && err.contains("9 vertices"),
            "{err}"
        );
    }

    #[test]
    fn caps_zero_filled_elements_over_the_whole_file() {
        // One such accessor is allowed, but its reuse adds up.
        // Whole triangles, more than half the cap: twice them cross it.
        let corners = (MAX_UNBACKED_ELEMENTS / 2 / 3 + 1) * 3;
        let once = reused_unbacked_accessors(corners, 1);
        assert!(load_gltf_slice(&once, None, "t", LoadLimits::NONE).is_ok());
        let twice = reused_unbacked_accessors(corners, 2);
        let err = load_gltf_slice(&twice, None, "t", LoadLimits::NONE)
            .expect_err("second reuse crosses the cap")
            .to_string();
        assert!(
            err.contains("primitive 1") && err.contains("zero-filled"),
            "{err}"
        );
    }

    #[test]
    fn caps_decoded_texture_memory_over_all_images() {
        // Three images that are the same 64×64 PNG (16 KiB each decoded): a cap of exactly
        // three admits them, one byte less refuses the third.
        let png = png(64, 64, &[128; 64 * 64 * 4]);
        let mut bin = Bin::default();
        let primitives: Vec<Value> = (0..3)
            .map(|material| {
                let mut p = quad_primitive(&mut bin, true);
                p["material"] = json!(material);
                p
            })
            .collect();
        let image_view = bin.views.len();
        bin.views
            .push(json!({"buffer": 0, "byteOffset": bin.bytes.len(), "byteLength": png.len()}));
        bin.bytes.extend_from_slice(&png);
        let mut fields = single_mesh(json!(primitives));
        fields["images"] = json!([
            {"bufferView": image_view, "mimeType": "image/png"},
            {"bufferView": image_view, "mimeType": "image/png"},
            {"bufferView": image_view, "mimeType": "image/png"},
        ]);
        fields["textures"] = json!([{"source": 0}, {"source": 1}, {"source": 2}]);
        fields["materials"] =
            json!([0, 1, 2]
                .map(|t| json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": t}}})));
        let doc = glb(&bin.document(None, fields), &bin.bytes);
        let limits = |max_texture_bytes| LoadLimits {
            max_texture_bytes,
            ..LoadLimits::NONE
        };
        let scene = load_gltf_slice(&doc, None, "t", limits(3 * 64 * 64 * 4)).expect("fits");
        assert_eq!(scene.textures.len(), 3);
        let err = load_gltf_slice(&doc, None, "t", limits(3 * 64 * 64 * 4 - 1))
            .expect_err("third image crosses")
            .to_string();
        assert!(
            err.contains("texture 2 (image 2)") && err.contains("texture memory limit"),
            "{err}"
        );
    }

    /// A PNG of its signature, a header declaring `width`×`height` and an empty data chunk:
    /// its dimensions can be read, but any attempt to decode its pixels fails.
    fn png_header_only(width: u32, height: u32) -> Vec<u8> {
        let chunk = |kind: &[u8; 4], data: &[u8]| {
            let body = [&kind[..], data].concat();
            let crc = crc32(&body);
            [
                &(data.len() as u32).to_be_bytes()[..],
                &body,
                &crc.to_be_bytes(),
            ]
            .concat()
        };
        let header = [
            &width.to_be_bytes()[..],
            &height.to_be_bytes(),
            &[8, 6, 0, 0, 0],
        ]
        .concat();
        [
            &b"\x89PNG\r\n\x1a\n"[..],
            &chunk(b"IHDR", &header),
            &chunk(b"IDAT", &[]),
            &chunk(b"IEND", &[]),
        ]
        .concat()
    }

    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in bytes {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 == 1 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    /// A GLB of one textured quad whose base colour is `image` (PNG bytes).
    fn textured_quad(image: &[u8]) -> Vec<u8> {
        let mut bin = Bin::default();
        let mut primitive = quad_primitive(&mut bin, true);
        primitive["material"] = json!(0);
        let view = bin.views.len();
        bin.views
            .push(json!({"buffer": 0, "byteOffset": bin.bytes.len(), "byteLength": image.len()}));
        bin.bytes.extend_from_slice(image);
        let mut fields = single_mesh(json!([primitive]));
        fields["images"] = json!([{"bufferView": view, "mimeType": "image/png"}]);
        fields["textures"] = json!([{"source": 0}]);
        fields["materials"] = json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
        glb(&bin.document(None, fields), &bin.bytes)
    }

    #[test]
    fn refuses_textures_beyond_the_budget_from_their_declared_size_before_decoding() {
        // 8192² declared in a few bytes: kept at 2048² (16 MiB), more than 8 MiB allowed. The
        // error is the budget's, not a decode failure: no pixel was decoded.
        let file = textured_quad(&png_header_only(8192, 8192));
        assert!(file.len() < 2048);
        let limits = LoadLimits {
            max_texture_bytes: 8 << 20,
            max_texture_size: 2048,
            ..LoadLimits::NONE
        };
        match load_gltf_slice(&file, None, "t", limits) {
            Err(LoadError::TextureBudget {
                part,
                kept_width,
                kept_height,
                needed,
                available,
                ..
            }) => {
                assert_eq!(part, "texture 0 (image 0)");
                assert_eq!((kept_width, kept_height), (2048, 2048));
                assert_eq!((needed, available), (16 << 20, 8 << 20));
            }
            other => panic!("expected the texture budget's refusal, got {other:?}"),
        }
        // Within the budget the same file is decoded, and fails as a truncated image.
        let roomy = LoadLimits {
            max_texture_bytes: 16 << 20,
            ..limits
        };
        assert!(matches!(
            load_gltf_slice(&file, None, "t", roomy),
            Err(LoadError::ImageDecode { .. })
        ));
    }

    #[test]
    fn downscales_textures_beyond_the_largest_kept_side() {
        // 64×32: left half red, right half blue; kept at 16×8 it keeps both halves.
        let pixels: Vec<u8> = (0..32)
            .flat_map(|_| {
                (0..64).flat_map(|x| {
                    if x < 32 {
                        [255, 0, 0, 255]
                    } else {
                        [0, 0, 255, 255]
                    }
                })
            })
            .collect();
        let file = textured_quad(&png(64, 32, &pixels));
        let limits = LoadLimits {
            max_texture_size: 16,
            ..LoadLimits::NONE
        };
        let scene = load_gltf_slice(&file, None, "t", limits).expect("loads");
        let t = &scene.textures[0];
        assert_eq!((t.width, t.height), (16, 8));
        assert_eq!(t.rgba8.len(), 16 * 8 * 4);
        assert_eq!(&t.rgba8[4 * (16 + 1)..][..4], &[255, 0, 0, 255]);
        assert_eq!(&t.rgba8[4 * (16 + 14)..][..4], &[0, 0, 255, 255]);
        let full = load_gltf_slice(&file, None, "t", LoadLimits::NONE).expect("loads");
        assert_eq!((full.textures[0].width, full.textures[0].height), (64, 32));
        assert_eq!(kept_size(8192, 1, 2048), (2048, 1));
        assert_eq!(kept_size(100, 8192, 2048), (25, 2048));
    }

    #[test]
    fn drops_zero_area_triangles_and_the_vertices_only_they_use() {
        // A few hundred bytes: 600,000 zero-filled positions (200,000 triangles) of which a
        // sparse substitution makes three a real triangle.
        let mut bin = Bin {
            bytes: [[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0]]
                .iter()
                .flatten()
                .flat_map(|f| f.to_le_bytes())
                .chain([1u32, 2].iter().flat_map(|i| i.to_le_bytes()))
                .collect(),
            ..Bin::default()
        };
        bin.views = vec![
            json!({"buffer": 0, "byteOffset": 0, "byteLength": 24}),
            json!({"buffer": 0, "byteOffset": 24, "byteLength": 8}),
        ];
        bin.accessors = vec![json!({
            "componentType": 5126, "type": "VEC3", "count": 600_000,
            "sparse": {
                "count": 2,
                "indices": {"bufferView": 1, "componentType": 5125},
                "values": {"bufferView": 0},
            },
        })];
        let doc = bin.document(None, single_mesh(json!([{"attributes": {"POSITION": 0}}])));
        let file = glb(&doc, &bin.bytes);
        assert!(file.len() < 1024);
        let scene = load_gltf_slice(&file, None, "t", LoadLimits::upload(1_000_000))
            .expect("one real triangle");
        assert_eq!(scene.triangle_count(), 1);
        assert_eq!(scene.vertices.len(), 3);
        let corners: Vec<[f32; 3]> = scene.vertices.iter().map(|v| v.position).collect();
        assert_eq!(corners, [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);

        // Nothing but zeros is no scene at all.
        let mut zeros = doc.clone();
        zeros["accessors"][0]["sparse"]["count"] = json!(1);
        let err = load_gltf_slice(&glb(&zeros, &bin.bytes), None, "t", LoadLimits::NONE)
            .expect_err("no area")
            .to_string();
        assert!(err.contains("no triangles"), "{err}");
    }

    #[test]
    fn refuses_millions_of_zero_filled_positions_before_allocating_them() {
        let (mut doc, bin) = quad_document(None);
        doc["accessors"][0] = json!({
            "componentType": 5126, "type": "VEC3", "count": 3_000_000,
            "sparse": {
                "count": 1,
                "indices": {"bufferView": 2, "componentType": 5123},
                "values": {"bufferView": 0},
            },
        });
        let err = load_gltf_slice(&glb(&doc, &bin.bytes), None, "t", LoadLimits::NONE)
            .expect_err("3 million zero-filled positions")
            .to_string();
        assert!(
            err.contains("POSITION accessor 0: has no buffer view")
                && err.contains("at most 1048576 are allowed"),
            "{err}"
        );
    }

    #[test]
    fn refuses_a_missing_bin_file() {
        let (doc, bin) = quad_document(Some("x.bin"));
        let err = load_error(&doc, &bin.bytes);
        assert!(err.starts_with("buffer 0: file 'x.bin' not found"), "{err}");
    }

    #[test]
    fn refuses_external_files_when_loading_from_memory_without_base_dir() {
        let (doc, _) = quad_document(Some("data.bin"));
        let bytes = serde_json::to_vec(&doc).expect("serialise");
        let err = load_gltf_slice(&bytes, None, "t", LoadLimits::NONE)
            .expect_err("needs a base dir")
            .to_string();
        assert!(
            err.contains("buffer 0") && err.contains("base directory"),
            "{err}"
        );
    }

    #[test]
    fn refuses_unsupported_required_extensions_only() {
        let (mut doc, bin) = quad_document(Some("data.bin"));
        doc["extensionsUsed"] = json!(["KHR_texture_transform", "KHR_draco_mesh_compression"]);
        load_document(&doc, &bin.bytes).expect("used-only extensions are ignored");
        doc["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
        let err = load_error(&doc, &bin.bytes);
        assert_eq!(
            err,
            "required extension 'KHR_draco_mesh_compression' is not supported"
        );
    }

    #[test]
    fn refuses_line_primitives() {
        let (mut doc, bin) = quad_document(Some("data.bin"));
        doc["meshes"][0]["primitives"][0]["mode"] = json!(1);
        let err = load_error(&doc, &bin.bytes);
        assert_eq!(
            err,
            "mesh 0 ('quad') primitive 0: mode Lines is not supported (only triangles)"
        );
    }

    #[test]
    fn refuses_indices_out_of_vertex_range() {
        let mut bin = Bin::default();
        let position = bin.vec3(&QUAD);
        let indices = bin.indices(&[0, 1, 2, 0, 2, 7]);
        let primitive = json!({"attributes": {"POSITION": position}, "indices": indices});
        let doc = bin.document(Some("data.bin"), single_mesh(json!([primitive])));
        let err = load_error(&doc, &bin.bytes);
        assert!(
            err.starts_with(
                "mesh 0 ('quad') primitive 0: indices accessor 1: index 7 at position 5 is out \
                 of range"
            ),
            "{err}"
        );
    }

    #[test]
    fn refuses_accessors_and_views_past_the_end_of_their_data() {
        let (mut doc, bin) = quad_document(Some("data.bin"));
        doc["accessors"][0]["count"] = json!(1000);
        let err = load_error(&doc, &bin.bytes);
        assert!(
            err.starts_with("mesh 0 ('quad') primitive 0: POSITION accessor 0:")
                && err.contains("run past the end of buffer view 0"),
            "{err}"
        );

        let (mut doc, bin) = quad_document(Some("data.bin"));
        doc["bufferViews"][1]["byteLength"] = json!(100_000);
        let err = load_error(&doc, &bin.bytes);
        assert!(
            err.contains("TEXCOORD_0 accessor 1: buffer view 1: bytes")
                && err.contains("outside buffer 0"),
            "{err}"
        );

        let (mut doc, bin) = quad_document(Some("data.bin"));
        doc["buffers"][0]["byteLength"] = json!(bin.bytes.len() + 1);
        let err = load_error(&doc, &bin.bytes);
        assert!(err.starts_with("buffer 0: byteLength is"), "{err}");
    }

    #[test]
    fn refuses_hostile_numbers_without_panicking() {
        let huge = json!(u64::MAX);
        let cases: [(&str, usize, &str, Value); 6] = [
            ("accessors", 0, "count", huge.clone()),
            ("accessors", 0, "byteOffset", json!(1u64 << 63)),
            ("bufferViews", 0, "byteOffset", huge.clone()),
            ("bufferViews", 0, "byteLength", huge.clone()),
            ("bufferViews", 0, "byteStride", json!(252)),
            ("buffers", 0, "byteLength", huge),
        ];
        for (array, index, field, value) in cases {
            let (mut doc, bin) = quad_document(Some("data.bin"));
            doc[array][index][field] = value;
            let result = load_document(&doc, &bin.bytes);
            assert!(result.is_err(), "{array}[{index}].{field}");
        }
        let (mut doc, bin) = quad_document(Some("data.bin"));
        doc["accessors"][0]
            .as_object_mut()
            .expect("object")
            .remove("bufferView");
        doc["accessors"][0]["count"] = json!(1u64 << 40);
        doc["accessors"][0]["sparse"] = json!({
            "count": 1,
            "indices": {"bufferView": 0, "componentType": 5125},
            "values": {"bufferView": 0},
        });
        let err = load_error(&doc, &bin.bytes);
        assert!(
            err.contains("POSITION accessor 0: has no buffer view")
                && err.contains(&format!("at most {MAX_UNBACKED_ELEMENTS} are allowed")),
            "{err}"
        );
    }

    #[test]
    fn applies_sparse_substitutions() {
        let mut bin = Bin::default();
        let primitive = quad_primitive(&mut bin, true);
        let targets = bin.indices(&[2]);
        let values = bin.vec3(&[[5.0, 6.0, 7.0]]);
        let view = |accessor: usize| bin.accessors[accessor]["bufferView"].clone();
        let sparse = json!({
            "count": 1,
            "indices": {"bufferView": view(targets), "componentType": 5123},
            "values": {"bufferView": view(values)},
        });
        let mut doc = bin.document(Some("data.bin"), single_mesh(json!([primitive])));
        doc["accessors"][0]["sparse"] = sparse;
        let scene = load_document(&doc, &bin.bytes).expect("loads");
        let positions: Vec<[f32; 3]> = scene.vertices.iter().map(|v| v.position).collect();
        assert_eq!(positions, [QUAD[0], QUAD[1], [5.0, 6.0, 7.0], QUAD[3]]);
    }

    #[test]
    fn refuses_cycles_and_non_finite_positions() {
        let (mut doc, bin) = quad_document(Some("data.bin"));
        doc["nodes"][0]["children"] = json!([0]);
        let err = load_error(&doc, &bin.bytes);
        assert!(err.starts_with("node 0: appears more than once"), "{err}");

        let mut bin = Bin::default();
        let position = bin.vec3(&[[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [1.0, 0.0, 0.0]]);
        let doc = bin.document(
            Some("data.bin"),
            single_mesh(json!([{"attributes": {"POSITION": position}}])),
        );
        let err = load_error(&doc, &bin.bytes);
        assert_eq!(err, "mesh 0 ('quad') primitive 0: POSITION 1 is not finite");
    }

    #[test]
    fn refuses_corrupt_and_oversized_images() {
        for (image, expected) in [
            (
                b"\x89PNG\r\n\x1a\nnot really a png".to_vec(),
                "image decode failed",
            ),
            (
                png(
                    MAX_TEXTURE_SIZE + 1,
                    1,
                    &[0; (MAX_TEXTURE_SIZE as usize + 1) * 4],
                ),
                "at most 8192",
            ),
        ] {
            let mut bin = Bin::default();
            let mut primitive = quad_primitive(&mut bin, true);
            primitive["material"] = json!(0);
            let mut fields = single_mesh(json!([primitive]));
            fields["images"] =
                json!([{"uri": format!("data:image/png;base64,{}", base64(&image))}]);
            fields["textures"] = json!([{"source": 0}]);
            fields["materials"] =
                json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
            let err = load_error(&bin.document(Some("data.bin"), fields), &bin.bytes);
            assert!(
                err.starts_with("texture 0 (image 0): ") && err.contains(expected),
                "{err}"
            );
        }
    }

    #[test]
    fn decodes_uri_escapes() {
        assert_eq!(base64_decode("aGVsbG8=").as_deref(), Ok(&b"hello"[..]));
        assert_eq!(base64_decode("aGVs bG8").as_deref(), Ok(&b"hello"[..]));
        assert!(base64_decode("aGV*").is_err());
        assert!(base64_decode("aG=Vs").is_err());
        assert_eq!(percent_decode("a%20b%C3%A9").as_deref(), Ok("a bé"));
        assert!(percent_decode("a%2").is_err());
        assert!(percent_decode("%FF").is_err());
        assert!(has_scheme("http://x/y.bin") && has_scheme("file:x"));
        assert!(!has_scheme("dir/x.bin") && !has_scheme("C:\\x.bin"));
    }
}
