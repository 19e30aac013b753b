//! On-disk store of precomputed light caches, keyed by a hash of everything the computation
//! reads, so each model is distributed once (the paper's per-model precomputation step).
//!
//! File layout (`<key>.lcc`): magic, an endianness tag, the format version, the key, the
//! parameters, the [`CacheStats`], the two counts, the raw [`LightCache`] array and the
//! per-vertex index array, then a SHA-256 of everything before it. Any file that does not check
//! out is ignored with a warning and recomputed; files are written to a temporary name and
//! renamed, so readers never see half a file.

use super::caches::{
    material_lobes, precompute, CacheError, CacheParams, CacheSet, CacheStats, LightCache,
    Progress, StepTimings, MAX_CACHES, NEIGHBOURS,
};
use crate::gi::precompute::Store;
use crate::scene::Scene;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Bump whenever the file layout or the cache algorithm's output changes.
/// Extension of the stored light-cache files (`<key>.lcc`).
pub const EXTENSION: &str = "lcc";
/// 2: caches distributed per model, each with its model (issue 35).
const FORMAT_VERSION: u32 = 2;
const MAGIC: [u8; 8] = *b"LCLCACHE";
/// Written in native byte order: a store shared with a machine of the other endianness reads
/// as foreign instead of as garbage (the arrays are stored in native order).
const ENDIAN_TAG: u32 = 0x0102_0304;
const KEY_LEN: usize = 64;
const STATS_LEN: usize = 17 * 8;
const HEADER_LEN: usize = 8 + 4 + 4 + KEY_LEN + 4 + 4 + STATS_LEN + 8 + 8;
const CHECKSUM_LEN: usize = 32;
const CACHE_SIZE: usize = std::mem::size_of::<LightCache>();
const VERTEX_ENTRY_SIZE: usize = 4 * NEIGHBOURS;

/// A directory of stored cache sets.
#[derive(Clone, Debug)]
pub struct CacheStore {
    dir: PathBuf,
    /// Total bytes of cache files kept; beyond it the least recently used go first.
    max_bytes: Option<u64>,
}

/// Why a stored file was not used (only ever logged).
#[derive(Debug, thiserror::Error)]
enum DecodeError {
    #[error("file is {0} bytes, too short for a cache file")]
    TooShort(usize),
    #[error("checksum mismatch (corrupt or truncated file)")]
    Checksum,
    #[error("not a light cache file (bad magic)")]
    Magic,
    #[error("written on a machine with a different byte order")]
    Endian,
    #[error("format version {found}, expected {FORMAT_VERSION}")]
    Version { found: u32 },
    #[error("file is for key {found}, not this scene")]
    Key { found: String },
    #[error("stored parameters {found:?} differ from the requested ones")]
    Params { found: CacheParams },
    #[error("{found} vertex entries stored, scene has {expected} vertices")]
    VertexCount { found: u64, expected: usize },
    #[error("{0} caches stored, more than the maximum of {MAX_CACHES}")]
    CacheCount(u64),
    #[error("length {found} does not match the {expected} bytes the counts imply")]
    Length { found: usize, expected: usize },
    #[error("vertex {vertex} refers to cache {index}, but there are {caches}")]
    Index {
        vertex: usize,
        index: u32,
        caches: usize,
    },
}

impl CacheStore {
    /// A store in `dir`, which is created on the first write.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            max_bytes: None,
        }
    }

    /// Keeps at most `max_bytes` of cache files: after each write the least recently used
    /// others are deleted (a server that takes uploads would otherwise fill its disk).
    pub fn with_max_bytes(mut self, max_bytes: u64) -> Self {
        self.max_bytes = Some(max_bytes);
        self
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// SHA-256 (hex) over the format version, the vertex and index bytes, the materials' lobe
    /// values (with texture means folded in) and the parameters: everything `precompute` reads.
    pub fn key(scene: &Scene, params: &CacheParams) -> String {
        let mut h = Sha256::new();
        h.update(MAGIC);
        h.update(FORMAT_VERSION.to_le_bytes());
        crate::gi::precompute::hash_geometry(&mut h, scene);
        let splits = material_lobes(scene);
        h.update((splits.len() as u64).to_le_bytes());
        for m in &splits {
            for v in m.diffuse.to_array().into_iter().chain(m.glossy.to_array()) {
                h.update(v.to_le_bytes());
            }
            h.update(m.exponent.to_le_bytes());
        }
        h.update(params.d_eps.to_le_bytes());
        h.update(params.theta_eps_degrees.to_le_bytes());
        hex(&h.finalize())
    }

    /// Path of the file for `key`.
    pub fn path(&self, key: &str) -> PathBuf {
        self.dir.join(format!("{key}.{EXTENSION}"))
    }

    /// Loads the cache set for (scene, params) if stored and valid, else computes and stores
    /// it. Returns whether it came from disk. Unreadable or invalid files and failed writes are
    /// logged as warnings; only invalid parameters are errors.
    pub fn load_or_compute(
        &self,
        scene: &Scene,
        params: &CacheParams,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<(CacheSet, bool), CacheError> {
        params.validate()?;
        let key = Self::key(scene, params);
        let path = self.path(&key);
        match Store::read_bounded(&path, max_file_len(scene.vertices.len())) {
            Ok(bytes) => match decode(&bytes, &key, params, scene.vertices.len()) {
                Ok(set) => {
                    tracing::info!(path = %path.display(), caches = set.caches.len(), "light caches loaded");
                    return Ok((set, true));
                }
                Err(e) => {
                    tracing::warn!(path = %path.display(), "ignoring stored light caches: {e}")
                }
            },
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => {
                tracing::warn!(path = %path.display(), "cannot read stored light caches: {e}")
            }
        }
        let set = precompute(scene, params, progress)?;
        match self.write(&key, &set) {
            Ok(()) => self.evict(&path),
            Err(e) => tracing::warn!(path = %path.display(), "cannot store light caches: {e}"),
        }
        Ok((set, false))
    }

    /// The store of every precomputed kind in the same directory, whose size limit covers
    /// them all.
    fn store(&self) -> Store {
        Store {
            dir: self.dir.clone(),
            max_bytes: self.max_bytes,
        }
    }

    fn evict(&self, keep: &Path) {
        self.store().evict(keep);
    }

    fn write(&self, key: &str, set: &CacheSet) -> std::io::Result<()> {
        self.store()
            .write_atomic(&format!("{key}.{EXTENSION}"), &encode(key, set))
            .map(drop)
    }
}

/// Largest valid file for a scene with `vertex_count` vertices.
fn max_file_len(vertex_count: usize) -> u64 {
    (HEADER_LEN + CHECKSUM_LEN) as u64
        + MAX_CACHES * CACHE_SIZE as u64
        + vertex_count as u64 * VERTEX_ENTRY_SIZE as u64
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn stats_fields(s: &CacheStats) -> [u64; 17] {
    let t = &s.timings;
    let nanos = |d: Duration| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
    [
        s.triangles,
        s.degenerate_triangles,
        s.samples,
        s.voxels,
        s.caches_before_merge,
        s.snapped,
        s.merged_away,
        s.dropped_empty,
        s.caches,
        s.surface_area.to_bits(),
        nanos(t.sampling),
        nanos(t.voxelising),
        nanos(t.clustering),
        nanos(t.merging),
        nanos(t.assigning),
        nanos(t.neighbours),
        nanos(t.total),
    ]
}

fn stats_from_fields(f: [u64; 17]) -> CacheStats {
    let d = Duration::from_nanos;
    CacheStats {
        triangles: f[0],
        degenerate_triangles: f[1],
        samples: f[2],
        voxels: f[3],
        caches_before_merge: f[4],
        snapped: f[5],
        merged_away: f[6],
        dropped_empty: f[7],
        caches: f[8],
        surface_area: f64::from_bits(f[9]),
        timings: StepTimings {
            sampling: d(f[10]),
            voxelising: d(f[11]),
            clustering: d(f[12]),
            merging: d(f[13]),
            assigning: d(f[14]),
            neighbours: d(f[15]),
            total: d(f[16]),
        },
    }
}

fn encode(key: &str, set: &CacheSet) -> Vec<u8> {
    let body = set.caches.len() * CACHE_SIZE + set.vertex_caches.len() * VERTEX_ENTRY_SIZE;
    let mut out = Vec::with_capacity(HEADER_LEN + body + CHECKSUM_LEN);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&ENDIAN_TAG.to_ne_bytes());
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    let mut key_bytes = [0u8; KEY_LEN];
    let n = key.len().min(KEY_LEN);
    key_bytes[..n].copy_from_slice(&key.as_bytes()[..n]);
    out.extend_from_slice(&key_bytes);
    out.extend_from_slice(&set.params.d_eps.to_le_bytes());
    out.extend_from_slice(&set.params.theta_eps_degrees.to_le_bytes());
    for field in stats_fields(&set.stats) {
        out.extend_from_slice(&field.to_le_bytes());
    }
    out.extend_from_slice(&(set.caches.len() as u64).to_le_bytes());
    out.extend_from_slice(&(set.vertex_caches.len() as u64).to_le_bytes());
    out.extend_from_slice(bytemuck::cast_slice(&set.caches));
    out.extend_from_slice(bytemuck::cast_slice(&set.vertex_caches));
    let checksum = Sha256::digest(&out);
    out.extend_from_slice(&checksum);
    out
}

/// Reads fixed-size fields front to back; callers check the total length first.
struct Reader<'a> {
    bytes: &'a [u8],
}

impl<'a> Reader<'a> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let (head, rest) = self.bytes.split_at(N);
        self.bytes = rest;
        let mut out = [0; N];
        out.copy_from_slice(head);
        out
    }

    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }

    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take())
    }

    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }
}

fn decode(
    bytes: &[u8],
    key: &str,
    params: &CacheParams,
    vertex_count: usize,
) -> Result<CacheSet, DecodeError> {
    if bytes.len() < HEADER_LEN + CHECKSUM_LEN {
        return Err(DecodeError::TooShort(bytes.len()));
    }
    let (content, checksum) = bytes.split_at(bytes.len() - CHECKSUM_LEN);
    if Sha256::digest(content).as_slice() != checksum {
        return Err(DecodeError::Checksum);
    }
    let mut r = Reader { bytes: content };
    if r.take::<8>() != MAGIC {
        return Err(DecodeError::Magic);
    }
    if r.take::<4>() != ENDIAN_TAG.to_ne_bytes() {
        return Err(DecodeError::Endian);
    }
    let version = r.u32();
    if version != FORMAT_VERSION {
        return Err(DecodeError::Version { found: version });
    }
    let stored_key = r.take::<KEY_LEN>();
    if stored_key.as_slice() != key.as_bytes() {
        return Err(DecodeError::Key {
            found: String::from_utf8_lossy(&stored_key).into_owned(),
        });
    }
    let stored = CacheParams {
        d_eps: r.f32(),
        theta_eps_degrees: r.f32(),
    };
    // Bitwise: the key hashed these exact bits.
    if stored.d_eps.to_bits() != params.d_eps.to_bits()
        || stored.theta_eps_degrees.to_bits() != params.theta_eps_degrees.to_bits()
    {
        return Err(DecodeError::Params { found: stored });
    }
    let stats = stats_from_fields(std::array::from_fn(|_| r.u64()));
    let cache_count = r.u64();
    let vertex_entries = r.u64();
    if vertex_entries != vertex_count as u64 {
        return Err(DecodeError::VertexCount {
            found: vertex_entries,
            expected: vertex_count,
        });
    }
    if cache_count > MAX_CACHES {
        return Err(DecodeError::CacheCount(cache_count));
    }
    let caches_len = cache_count as usize * CACHE_SIZE;
    let expected = caches_len.saturating_add(vertex_count.saturating_mul(VERTEX_ENTRY_SIZE));
    if r.bytes.len() != expected {
        return Err(DecodeError::Length {
            found: r.bytes.len(),
            expected,
        });
    }
    // Copy into typed vectors: the byte buffer has no alignment guarantee.
    let (cache_bytes, vertex_bytes) = r.bytes.split_at(caches_len);
    let mut caches = vec![<LightCache as bytemuck::Zeroable>::zeroed(); cache_count as usize];
    bytemuck::cast_slice_mut(&mut caches).copy_from_slice(cache_bytes);
    let mut vertex_caches = vec![[u32::MAX; NEIGHBOURS]; vertex_count];
    bytemuck::cast_slice_mut(&mut vertex_caches).copy_from_slice(vertex_bytes);
    for (vertex, entry) in vertex_caches.iter().enumerate() {
        if let Some(&index) = entry
            .iter()
            .find(|&&i| i != u32::MAX && i as usize >= caches.len())
        {
            return Err(DecodeError::Index {
                vertex,
                index,
                caches: caches.len(),
            });
        }
    }
    Ok(CacheSet {
        params: *params,
        visibility: None,
        caches,
        vertex_caches,
        stats,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_set(vertices: usize) -> CacheSet {
        let cache = LightCache {
            position: [1.0, 2.0, 3.0],
            area: 0.5,
            normal: [0.0, 1.0, 0.0],
            disk_area: 0.5,
            diffuse: [0.7, 0.6, 0.5],
            exponent: 1.0,
            glossy: [0.04; 3],
            model: 3,
        };
        let mut entry = [u32::MAX; NEIGHBOURS];
        entry[0] = 1;
        entry[1] = 0;
        CacheSet {
            params: CacheParams {
                d_eps: 0.25,
                theta_eps_degrees: 30.0,
            },
            visibility: None,
            caches: vec![cache; 2],
            vertex_caches: vec![entry; vertices],
            stats: CacheStats {
                caches: 2,
                surface_area: 1.0,
                timings: StepTimings {
                    total: Duration::from_millis(12),
                    ..StepTimings::default()
                },
                ..CacheStats::default()
            },
        }
    }

    #[test]
    fn keeps_the_most_recently_used_files_within_its_size() {
        let dir = tempfile::tempdir().expect("temp dir");
        let scene = crate::scene::procedural::cornell_box();
        let params = |d_eps| CacheParams {
            d_eps,
            theta_eps_degrees: 30.0,
        };
        let unlimited = CacheStore::new(dir.path());
        let run = |store: &CacheStore, d_eps| {
            store
                .load_or_compute(&scene, &params(d_eps), &mut |_| {})
                .expect("caches")
                .1
        };
        assert!(!run(&unlimited, 0.5));
        let one_file = std::fs::metadata(unlimited.path(&CacheStore::key(&scene, &params(0.5))))
            .expect("stored")
            .len();
        // Room for two files of about this size.
        let store = CacheStore::new(dir.path()).with_max_bytes(2 * one_file + one_file / 2);
        let stored = |d_eps| {
            store
                .path(&CacheStore::key(&scene, &params(d_eps)))
                .exists()
        };
        assert!(!run(&store, 0.51));
        std::thread::sleep(Duration::from_millis(20));
        // Loading 0.5 again makes it the most recently used; 0.51 is now the oldest.
        assert!(run(&store, 0.5));
        std::thread::sleep(Duration::from_millis(20));
        assert!(!run(&store, 0.52));
        assert!(stored(0.5) && stored(0.52) && !stored(0.51));
    }

    #[test]
    fn round_trips_and_rejects_every_single_byte_change() {
        let set = sample_set(3);
        let key = "a".repeat(64);
        let bytes = encode(&key, &set);
        assert_eq!(
            decode(&bytes, &key, &set.params, 3).expect("valid file"),
            set
        );
        for i in (0..bytes.len()).step_by(7) {
            let mut bad = bytes.clone();
            bad[i] ^= 0x40;
            assert!(decode(&bad, &key, &set.params, 3).is_err(), "flip at {i}");
        }
        for len in [0, 10, HEADER_LEN, bytes.len() - 1] {
            assert!(
                decode(&bytes[..len], &key, &set.params, 3).is_err(),
                "length {len}"
            );
        }
    }

    #[test]
    fn rejects_files_for_other_scenes_or_params() {
        let set = sample_set(3);
        let key = "b".repeat(64);
        let bytes = encode(&key, &set);
        let other_key = "c".repeat(64);
        assert!(matches!(
            decode(&bytes, &other_key, &set.params, 3),
            Err(DecodeError::Key { .. })
        ));
        assert!(matches!(
            decode(&bytes, &key, &set.params, 4),
            Err(DecodeError::VertexCount { .. })
        ));
        let params = CacheParams {
            d_eps: 0.5,
            ..set.params
        };
        assert!(matches!(
            decode(&bytes, &key, &params, 3),
            Err(DecodeError::Params { .. })
        ));
    }

    #[test]
    fn rejects_out_of_range_indices_even_with_a_valid_checksum() {
        let mut set = sample_set(2);
        set.vertex_caches[1][2] = 2;
        let key = "d".repeat(64);
        let bytes = encode(&key, &set);
        assert!(matches!(
            decode(&bytes, &key, &set.params, 2),
            Err(DecodeError::Index {
                vertex: 1,
                index: 2,
                caches: 2
            })
        ));
    }
}
