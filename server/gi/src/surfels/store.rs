//! Surfel sets in the precomputation store (`<key>.lsl`), keyed by a hash of everything the
//! precomputation reads, so a scene's surfels, hierarchy and links are built once per
//! parameter set and not at every server start.
//!
//! Layout: magic, an endianness tag, the format version, the key, the parameters, the counts,
//! then the arrays in native byte order (surfels, the tree, the lattice, the links), then a
//! SHA-256 of everything before it. A file that does not check out (checksum, key,
//! parameters, counts, or an index out of range) is ignored with a warning and rebuilt.

use super::grid::{CacheGrid, MAX_CACHES};
use super::hierarchy::{ClusterWeights, Tree};
use super::links::{SurfelLinks, NO_NODE};
use super::sampling::{Surfel, RELAX_STEPS};
use super::{precompute, sh, SurfelError, SurfelParams, SurfelSet, MAX_SURFELS};
use crate::gi::precompute::{BuildEnv, Store};
use crate::scene::Scene;
use glam::{UVec3, Vec2, Vec3};
use sha2::{Digest, Sha256};
use std::path::PathBuf;

/// Extension of the stored surfel-set files (`<key>.lsl`).
pub const EXTENSION: &str = "lsl";
/// Bump whenever the layout or the precomputation's output changes.
const FORMAT_VERSION: u32 = 1;
const MAGIC: [u8; 8] = *b"LCSURFEL";
/// Native byte order: a file from a machine of the other endianness reads as foreign.
const ENDIAN_TAG: u32 = 0x0102_0304;
const KEY_LEN: usize = 64;
const CHECKSUM_LEN: usize = 32;
/// Most links per cache a stored file may claim.
const MAX_LINKS: u32 = 4096;

/// SHA-256 (hex) over the format version, the vertex and index bytes, the parameters, the
/// tree metric's weights and the relaxation steps: everything [`precompute`] reads.
pub fn key(scene: &Scene, params: &SurfelParams) -> String {
    let mut h = Sha256::new();
    h.update(MAGIC);
    h.update(FORMAT_VERSION.to_le_bytes());
    crate::gi::precompute::hash_geometry(&mut h, scene);
    h.update(params.surfels.to_le_bytes());
    h.update(params.cache_spacing.unwrap_or(f32::NAN).to_le_bytes());
    h.update(params.links.to_le_bytes());
    h.update(params.bands.to_le_bytes());
    let w = ClusterWeights::default();
    h.update(w.normal.to_le_bytes());
    h.update(w.balance.to_le_bytes());
    h.update(RELAX_STEPS.to_le_bytes());
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// Loads the surfel set of (`scene`, `params`) from `store` if a valid file is there, else
/// builds it and stores it. Returns whether it came from the store. Unreadable or invalid
/// files and failed writes are logged; only the build's own errors are errors.
pub fn load_or_compute(
    store: &Store,
    scene: &Scene,
    params: &SurfelParams,
    env: &mut BuildEnv,
) -> Result<(SurfelSet, bool), SurfelError> {
    let key = key(scene, params);
    let path = store.dir.join(format!("{key}.{EXTENSION}"));
    match Store::read_bounded(&path, max_file_len(params)) {
        Ok(bytes) => match decode(&bytes, &key, params) {
            Ok(set) => {
                tracing::info!(path = %path.display(), surfels = set.surfels.len(), "surfel set loaded");
                return Ok((set, true));
            }
            Err(e) => tracing::warn!(path = %path.display(), "ignoring a stored surfel set: {e}"),
        },
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => tracing::warn!(path = %path.display(), "cannot read a stored surfel set: {e}"),
    }
    let set = precompute(scene, params, env)?;
    match store.write_atomic(&format!("{key}.{EXTENSION}"), &encode(&key, params, &set)) {
        Ok(written) => store.evict(&written),
        Err(e) => tracing::warn!(path = %path.display(), "cannot store the surfel set: {e}"),
    }
    Ok((set, false))
}

/// The path a set of `key` is stored at in `store`.
pub fn path(store: &Store, key: &str) -> PathBuf {
    store.dir.join(format!("{key}.{EXTENSION}"))
}

/// Largest valid file for `params`: every count at its maximum.
fn max_file_len(params: &SurfelParams) -> u64 {
    let n = u64::from(MAX_SURFELS);
    let nodes = 2 * n;
    let caches = MAX_CACHES;
    let slots = caches * u64::from(params.links.min(MAX_LINKS));
    let coefficients = sh::coefficient_count(params.bands.min(sh::MAX_BANDS)) as u64;
    512 + n * 40 + nodes * 4 * 11 + slots * 4 * (1 + coefficients) + caches * 5
}

struct Writer(Vec<u8>);

impl Writer {
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_ne_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.0.extend_from_slice(&v.to_ne_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_ne_bytes());
    }
    fn vec3(&mut self, v: Vec3) {
        v.to_array().into_iter().for_each(|c| self.f32(c));
    }
    fn u32s(&mut self, v: &[u32]) {
        self.0.extend_from_slice(bytemuck::cast_slice(v));
    }
    fn f32s(&mut self, v: &[f32]) {
        self.0.extend_from_slice(bytemuck::cast_slice(v));
    }
}

fn encode(key: &str, params: &SurfelParams, set: &SurfelSet) -> Vec<u8> {
    let mut w = Writer(Vec::new());
    w.0.extend_from_slice(&MAGIC);
    w.u32(ENDIAN_TAG);
    w.u32(FORMAT_VERSION);
    w.0.extend_from_slice(key.as_bytes());
    w.u32(params.surfels);
    w.f32(params.cache_spacing.unwrap_or(f32::NAN));
    w.u32(params.links);
    w.u32(params.bands);
    let tree = &set.tree;
    w.u32(set.surfels.len() as u32);
    w.u32(tree.children.len() as u32);
    w.u32(tree.level_offsets.len() as u32);
    w.u32(set.links.per_cache);
    w.u32(set.links.bands);
    w.f64(set.surfel_area);
    for s in &set.surfels {
        w.vec3(s.position);
        w.vec3(s.normal);
        w.f32(s.uv.x);
        w.f32(s.uv.y);
        w.u32(s.triangle);
        w.u32(s.material);
    }
    w.u32s(bytemuck::cast_slice(&tree.children));
    w.u32s(&tree.parent);
    w.u32s(&tree.first_leaf);
    w.u32s(&tree.leaf_count);
    tree.centre.iter().for_each(|&c| w.vec3(c));
    tree.normal.iter().for_each(|&n| w.vec3(n));
    w.f32s(&tree.area);
    w.f32s(&tree.merge_distance);
    w.u32s(&tree.leaf_order);
    w.u32s(&tree.level_offsets);
    w.u32s(&tree.by_level);
    w.vec3(set.grid.origin);
    w.f32(set.grid.spacing);
    set.grid.dims.to_array().into_iter().for_each(|d| w.u32(d));
    w.u32s(&set.links.nodes);
    w.f32s(&set.links.coeffs);
    w.f32s(&set.links.visible);
    w.0.extend(set.links.inside.iter().map(|&b| u8::from(b)));
    let checksum = Sha256::digest(&w.0);
    w.0.extend_from_slice(&checksum);
    w.0
}

/// Why a stored file was not used (only ever logged).
#[derive(Debug, thiserror::Error, PartialEq)]
enum DecodeError {
    #[error("checksum mismatch (corrupt or truncated file)")]
    Checksum,
    #[error("not a surfel file (bad magic), or written on a machine of another byte order")]
    Foreign,
    #[error("format version {0}, expected {FORMAT_VERSION}")]
    Version(u32),
    #[error("file is for another scene or parameter set")]
    Key,
    #[error("the file ends early")]
    Short,
    #[error("{0}")]
    Invalid(String),
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], DecodeError> {
        let end = self.at.checked_add(n).ok_or(DecodeError::Short)?;
        let out = self.bytes.get(self.at..end).ok_or(DecodeError::Short)?;
        self.at = end;
        Ok(out)
    }
    fn u32(&mut self) -> Result<u32, DecodeError> {
        Ok(u32::from_ne_bytes(
            self.take(4)?.try_into().map_err(|_| DecodeError::Short)?,
        ))
    }
    fn f32(&mut self) -> Result<f32, DecodeError> {
        Ok(f32::from_bits(self.u32()?))
    }
    fn f64(&mut self) -> Result<f64, DecodeError> {
        Ok(f64::from_ne_bytes(
            self.take(8)?.try_into().map_err(|_| DecodeError::Short)?,
        ))
    }
    fn vec3(&mut self) -> Result<Vec3, DecodeError> {
        Ok(Vec3::new(self.f32()?, self.f32()?, self.f32()?))
    }
    fn u32s(&mut self, n: usize) -> Result<Vec<u32>, DecodeError> {
        let bytes = self.take(n.checked_mul(4).ok_or(DecodeError::Short)?)?;
        Ok(bytemuck::pod_collect_to_vec(bytes))
    }
    fn f32s(&mut self, n: usize) -> Result<Vec<f32>, DecodeError> {
        let bytes = self.take(n.checked_mul(4).ok_or(DecodeError::Short)?)?;
        Ok(bytemuck::pod_collect_to_vec(bytes))
    }
    fn vec3s(&mut self, n: usize) -> Result<Vec<Vec3>, DecodeError> {
        (0..n).map(|_| self.vec3()).collect()
    }
}

fn invalid(what: impl Into<String>) -> DecodeError {
    DecodeError::Invalid(what.into())
}

fn decode(bytes: &[u8], key: &str, params: &SurfelParams) -> Result<SurfelSet, DecodeError> {
    let body_len = bytes
        .len()
        .checked_sub(CHECKSUM_LEN)
        .ok_or(DecodeError::Short)?;
    if Sha256::digest(&bytes[..body_len]).as_slice() != &bytes[body_len..] {
        return Err(DecodeError::Checksum);
    }
    let mut r = Reader {
        bytes: &bytes[..body_len],
        at: 0,
    };
    if r.take(8)? != MAGIC || r.u32()? != ENDIAN_TAG {
        return Err(DecodeError::Foreign);
    }
    let version = r.u32()?;
    if version != FORMAT_VERSION {
        return Err(DecodeError::Version(version));
    }
    if r.take(KEY_LEN)? != key.as_bytes() {
        return Err(DecodeError::Key);
    }
    let stored = (r.u32()?, r.f32()?, r.u32()?, r.u32()?);
    let wanted = (
        params.surfels,
        params.cache_spacing.unwrap_or(f32::NAN),
        params.links,
        params.bands,
    );
    if (stored.0, stored.1.to_bits(), stored.2, stored.3)
        != (wanted.0, wanted.1.to_bits(), wanted.2, wanted.3)
    {
        return Err(DecodeError::Key);
    }
    let n = r.u32()? as usize;
    let internal = r.u32()? as usize;
    let levels = r.u32()? as usize;
    let per_cache = r.u32()?;
    let bands = r.u32()?;
    if n == 0 || n > MAX_SURFELS as usize || internal + 1 != n {
        return Err(invalid(format!(
            "{n} surfels with {internal} internal nodes"
        )));
    }
    if levels > n + 1
        || per_cache == 0
        || per_cache > MAX_LINKS
        || bands == 0
        || bands > sh::MAX_BANDS
    {
        return Err(invalid("counts out of range"));
    }
    let nodes = n + internal;
    let surfel_area = r.f64()?;
    let surfels = (0..n)
        .map(|_| {
            Ok(Surfel {
                position: r.vec3()?,
                normal: r.vec3()?,
                uv: Vec2::new(r.f32()?, r.f32()?),
                triangle: r.u32()?,
                material: r.u32()?,
            })
        })
        .collect::<Result<Vec<_>, DecodeError>>()?;
    let children_flat = r.u32s(2 * internal)?;
    let parent = r.u32s(nodes)?;
    let first_leaf = r.u32s(nodes)?;
    let leaf_count = r.u32s(nodes)?;
    let centre = r.vec3s(nodes)?;
    let normal = r.vec3s(nodes)?;
    let area = r.f32s(nodes)?;
    let merge_distance = r.f32s(internal)?;
    let leaf_order = r.u32s(n)?;
    let level_offsets = r.u32s(levels)?;
    let by_level = r.u32s(internal)?;
    let origin = r.vec3()?;
    let spacing = r.f32()?;
    let dims = UVec3::new(r.u32()?, r.u32()?, r.u32()?);
    let caches = u64::from(dims.x) * u64::from(dims.y) * u64::from(dims.z);
    if caches == 0 || caches > MAX_CACHES {
        return Err(invalid(format!("{caches} caches")));
    }
    let caches = caches as usize;
    let slots = caches * per_cache as usize;
    let link_nodes = r.u32s(slots)?;
    let coeffs = r.f32s(slots * sh::coefficient_count(bands))?;
    let visible = r.f32s(caches)?;
    let inside: Vec<bool> = r.take(caches)?.iter().map(|&b| b != 0).collect();
    if r.at != body_len {
        return Err(invalid("bytes after the last array"));
    }
    // Every index the passes follow must be in range: a stored file is input.
    let in_nodes = |v: &u32| (*v as usize) < nodes;
    let children: Vec<[u32; 2]> = children_flat.chunks(2).map(|c| [c[0], c[1]]).collect();
    if !children_flat.iter().all(in_nodes)
        || !children
            .iter()
            .enumerate()
            .all(|(k, c)| (c[0] as usize) < n + k && (c[1] as usize) < n + k)
        || !by_level.iter().all(|v| (n..nodes).contains(&(*v as usize)))
        || !parent.iter().all(|p| *p == u32::MAX || in_nodes(p))
        || !leaf_order.iter().all(|v| (*v as usize) < n)
        || !link_nodes.iter().all(|v| *v == NO_NODE || in_nodes(v))
        || !level_offsets.windows(2).all(|w| w[0] <= w[1])
        || level_offsets.last().is_some_and(|&l| l as usize > internal)
        || !first_leaf
            .iter()
            .zip(&leaf_count)
            .all(|(f, c)| (*f as usize).saturating_add(*c as usize) <= n)
    {
        return Err(invalid("an index out of range"));
    }
    Ok(SurfelSet {
        surfels,
        surfel_area,
        tree: Tree {
            children,
            parent,
            first_leaf,
            leaf_count,
            centre,
            normal,
            area,
            merge_distance,
            leaf_order,
            level_offsets,
            by_level,
        },
        grid: CacheGrid {
            origin,
            spacing,
            dims,
        },
        links: SurfelLinks {
            per_cache,
            bands,
            nodes: link_nodes,
            coeffs,
            visible,
            inside,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::surfels::test_scenes::{closed_box, surfel_set};

    fn params() -> SurfelParams {
        SurfelParams {
            surfels: 1024,
            cache_spacing: Some(1.0),
            links: 16,
            bands: 2,
        }
    }

    #[test]
    fn round_trips_and_rejects_changed_bytes_other_keys_and_bad_indices() {
        let scene = closed_box();
        let set = surfel_set(&scene, &params());
        let key = key(&scene, &params());
        let bytes = encode(&key, &params(), &set);
        let back = decode(&bytes, &key, &params()).expect("round trip");
        assert_eq!(back.surfels, set.surfels);
        assert_eq!(back.tree, set.tree);
        assert_eq!(back.grid, set.grid);
        assert_eq!(back.links, set.links);
        assert_eq!(back.surfel_area, set.surfel_area);
        // Every 97th byte flipped: the checksum catches it.
        for i in (0..bytes.len()).step_by(97) {
            let mut bad = bytes.clone();
            bad[i] ^= 0x40;
            assert!(decode(&bad, &key, &params()).is_err(), "byte {i}");
        }
        assert_eq!(
            decode(&bytes[..bytes.len() - 1], &key, &params()).err(),
            Some(DecodeError::Checksum)
        );
        let other = SurfelParams {
            links: 17,
            ..params()
        };
        assert_eq!(decode(&bytes, &key, &other).err(), Some(DecodeError::Key));
        // A valid checksum over an out-of-range link node is still refused.
        let mut broken = set.clone();
        broken.links.nodes[0] = 1 << 30;
        let bad = encode(&key, &params(), &broken);
        assert!(matches!(
            decode(&bad, &key, &params()),
            Err(DecodeError::Invalid(_))
        ));
    }

    #[test]
    fn a_second_build_loads_the_stored_set_and_a_scene_change_rebuilds() {
        let dir = tempfile::tempdir().expect("temporary directory");
        let store = Store::new(dir.path());
        let scene = closed_box();
        let build = |scene: &Scene| {
            let mut env = BuildEnv {
                store: &store,
                progress: &mut |_| {},
                cancelled: &|| false,
                gpu: None,
            };
            load_or_compute(&store, scene, &params(), &mut env).expect("built")
        };
        let (first, loaded) = build(&scene);
        assert!(!loaded);
        assert!(path(&store, &key(&scene, &params())).exists());
        let (second, loaded) = build(&scene);
        assert!(loaded, "the second build reads the store");
        assert_eq!(second.links, first.links);
        let mut moved = scene.clone();
        moved.vertices[0].position[0] += 0.25;
        let (_, loaded) = build(&moved);
        assert!(!loaded, "another scene has another key");
    }
}
