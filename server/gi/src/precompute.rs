//! Per-scene precomputation of GI methods: data a method builds once per scene and parameter
//! set (light caches, a BVH, links) and every
//! frame of that scene then reads.
//!
//! A method that needs one registers a [`PrecomputeEntry`] with its [`super::MethodEntry`]:
//! how a request's GI parameters name the set it needs ([`PrecomputeKey`]), how large a set
//! will be before it is built (for the service's budgets), and how to build it (or load it
//! from the content-hashed [`Store`]) with progress. The service builds sets on its
//! precompute worker, off the render loop, shows their progress in scene info and renders
//! direct light until a frame's set is ready; offline renders build them inline. The renderer
//! hands the finished [`SceneData`] to the method ([`super::Method::set_scene_data`]).

pub use super::common::scene_facts::SceneFacts;
use super::limits::GiLimit;
use super::InvalidSetting;
use crate::scene::Scene;
use lightcast_protocol::GiParams;
use std::any::Any;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Data a method precomputed for one scene, shared read-only by every renderer of the scene.
pub type SceneData = Arc<dyn Any + Send + Sync>;

/// Progress of a precomputation: `done` of `total` items of the named step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Progress {
    pub step: &'static str,
    pub done: u64,
    pub total: u64,
}

/// Which precomputation, with which parameters (resolved against the scene's defaults). Keys
/// are equal when their kinds and the bits of every parameter are, so a set asked for twice
/// is built once.
#[derive(Clone, Debug)]
pub struct PrecomputeKey {
    /// [`PrecomputeEntry::kind`].
    pub kind: &'static str,
    /// Parameters by their names in the request's `gi` object, e.g. `cache_distance`.
    pub params: Vec<(&'static str, f32)>,
}

impl PartialEq for PrecomputeKey {
    fn eq(&self, other: &Self) -> bool {
        self.kind == other.kind
            && self.params.len() == other.params.len()
            && self
                .params
                .iter()
                .zip(&other.params)
                .all(|((a, x), (b, y))| a == b && x.to_bits() == y.to_bits())
    }
}

impl Eq for PrecomputeKey {}

impl std::hash::Hash for PrecomputeKey {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.kind.hash(state);
        for (name, value) in &self.params {
            name.hash(state);
            value.to_bits().hash(state);
        }
    }
}

impl std::fmt::Display for PrecomputeKey {
    /// `cache_distance 0.5, cache_angle 30`, or the kind for a key without parameters.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.params.is_empty() {
            return f.write_str(self.kind);
        }
        for (k, (name, value)) in self.params.iter().enumerate() {
            let separator = if k == 0 { "" } else { ", " };
            write!(f, "{separator}{name} {value}")?;
        }
        Ok(())
    }
}

impl PrecomputeKey {
    /// The value of parameter `name`, if the key has it.
    pub fn param(&self, name: &str) -> Option<f32> {
        self.params
            .iter()
            .find_map(|(n, v)| (*n == name).then_some(*v))
    }

    /// Whether a scene may hold several sets of this kind at once. A method instance holds
    /// one set, so frames of each such set need a renderer of their own; a set without
    /// parameters is the scene's only one and shares the scene's renderer.
    pub fn has_variants(&self) -> bool {
        !self.params.is_empty()
    }
}

/// File extensions of the stored kinds (each entry's [`PrecomputeEntry::extension`]). One
/// size limit covers them all.
pub fn stored_extensions() -> impl Iterator<Item = &'static str> {
    entries().filter_map(|e| e.extension)
}

/// Where precomputed sets are kept between runs: files named by a hash of everything their
/// computation reads, so each model is precomputed once.
#[derive(Clone, Debug)]
pub struct Store {
    pub dir: PathBuf,
    /// Bytes of stored files kept at most; beyond them the least recently used go first.
    pub max_bytes: Option<u64>,
}

impl Store {
    /// A store in `dir` without a size limit.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            max_bytes: None,
        }
    }

    /// Writes `bytes` to `file_name` atomically: a temporary file in the same directory, then
    /// a rename, so readers never see half a file.
    pub fn write_atomic(&self, file_name: &str, bytes: &[u8]) -> std::io::Result<PathBuf> {
        std::fs::create_dir_all(&self.dir)?;
        let path = self.dir.join(file_name);
        let tmp = self.dir.join(format!(
            "{file_name}.tmp-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        let written = std::fs::File::create(&tmp).and_then(|mut f| {
            std::io::Write::write_all(&mut f, bytes)?;
            f.sync_all()
        });
        let renamed = written.and_then(|()| std::fs::rename(&tmp, &path));
        if renamed.is_err() {
            // Best effort: a leftover temporary file is harmless, the error below is what counts.
            let _ = std::fs::remove_file(&tmp);
        }
        renamed.map(|()| path)
    }

    /// Reads a stored file unless it is longer than `max` bytes (a foreign file is not worth
    /// the memory), and marks it used for [`Self::evict`].
    pub fn read_bounded(path: &Path, max: u64) -> std::io::Result<Vec<u8>> {
        let mut file = std::fs::File::open(path)?;
        let len = file.metadata()?.len();
        if len > max {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("file is {len} bytes, more than the {max} it can have"),
            ));
        }
        let mut bytes = Vec::with_capacity(len as usize);
        std::io::Read::read_to_end(&mut file, &mut bytes)?;
        // Eviction goes by modification time, so a use counts as one.
        let touched = std::fs::File::options()
            .append(true)
            .open(path)
            .and_then(|f| f.set_modified(std::time::SystemTime::now()));
        if let Err(e) = touched {
            tracing::debug!(path = %path.display(), "cannot mark the file used: {e}");
        }
        Ok(bytes)
    }

    /// Deletes the least recently used stored files of every kind ([`stored_extensions`])
    /// other than `keep` until the rest fit in `max_bytes`.
    pub fn evict(&self, keep: &Path) {
        let Some(max_bytes) = self.max_bytes else {
            return;
        };
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return;
        };
        let mut files: Vec<(std::time::SystemTime, u64, PathBuf)> = entries
            .flatten()
            .filter(|e| {
                e.path()
                    .extension()
                    .is_some_and(|x| stored_extensions().any(|k| x == k))
            })
            .filter_map(|e| {
                let meta = e.metadata().ok()?;
                Some((meta.modified().ok()?, meta.len(), e.path()))
            })
            .collect();
        let mut total: u64 = files.iter().map(|f| f.1).sum();
        files.sort();
        for (_, len, path) in files {
            if total <= max_bytes {
                break;
            }
            if path == keep {
                continue;
            }
            match std::fs::remove_file(&path) {
                Ok(()) => {
                    total -= len;
                    tracing::info!(path = %path.display(), "evicted a stored precomputation");
                }
                Err(e) => tracing::warn!(path = %path.display(), "cannot evict: {e}"),
            }
        }
    }

    /// `$LIGHTCAST_CACHE_DIR`, else `$XDG_CACHE_HOME/lightcast`, else `~/.cache/lightcast`,
    /// else `./.lightcast-cache`.
    pub fn default_dir() -> PathBuf {
        let var = |name: &str| {
            std::env::var_os(name)
                .filter(|v| !v.is_empty())
                .map(PathBuf::from)
        };
        if let Some(dir) = var("LIGHTCAST_CACHE_DIR") {
            return dir;
        }
        // The XDG spec says relative paths in XDG_CACHE_HOME are invalid and to be ignored.
        if let Some(dir) = var("XDG_CACHE_HOME").filter(|d| d.is_absolute()) {
            return dir.join("lightcast");
        }
        if let Some(home) = var("HOME") {
            return home.join(".cache").join("lightcast");
        }
        PathBuf::from(".lightcast-cache")
    }
}

/// A finished precomputation.
pub struct Built {
    pub data: SceneData,
    /// What the set holds in [`UnitBudget`] units (0 for unbudgeted kinds).
    pub units: u64,
    /// Whether it was loaded from the [`Store`] instead of computed.
    pub from_store: bool,
}

/// Which of the service's memory budgets a kind's sets are counted in.
#[derive(Clone, Copy, Debug)]
pub enum BudgetPool {
    /// Triangles, over every scene and precomputation (`--max-total-triangles`): a set that
    /// holds a copy of every triangle of its scene (a BVH) counts them a second time.
    Triangles,
    /// A pool the method declares: at most `total` units over every set of every scene and
    /// at most `per_set` in one set (both limits in its [`super::MethodEntry::limits`]).
    Declared {
        total: &'static GiLimit,
        per_set: Option<&'static GiLimit>,
    },
}

/// How a kind's sets are counted against the service's budgets: in units of its pool,
/// estimated before they are built and exact after.
pub struct UnitBudget {
    pub pool: BudgetPool,
    /// What a unit is, in messages (`light caches`).
    pub unit: &'static str,
    /// The request field under `gi` that sizes a set; refusals name it.
    pub field: &'static str,
    /// What to ask for instead when the set of `key` must stay within `allowed` units.
    pub advice: fn(&PrecomputeKey, &SceneFacts, allowed: u64) -> String,
}

/// One method family's per-scene precomputation.
pub struct PrecomputeEntry {
    /// Its name in scene info and logs (`light_caches`, `bvh`).
    pub kind: &'static str,
    /// What it is called in messages to people (`light caches`).
    pub label: &'static str,
    /// The set a frame with GI parameters `gi` needs on a scene; errors name the `gi` field.
    pub key: fn(gi: &GiParams, facts: &SceneFacts) -> Result<PrecomputeKey, InvalidSetting>,
    /// `None`: the set's size is bounded by its parameters' ranges alone.
    pub budget: Option<UnitBudget>,
    /// The set's size in [`UnitBudget`] units, estimated before it is built.
    pub estimate: fn(&PrecomputeKey, &SceneFacts) -> u64,
    /// Adds the build's estimated cost (reference ns of the 2-core CPU the weights were
    /// measured on, see [`super::cost`]), from its key and the scene.
    pub cost: fn(&PrecomputeKey, &SceneFacts, &mut super::cost::Cost),
    /// The request parameters that scale that cost, in the order a refusal suggests them.
    pub knobs: &'static [super::cost::Knob],
    /// Loads the set from the store or computes (and stores) it; errors are messages for the
    /// scene's info.
    pub build: BuildFn,
    /// The extension of its files in the [`Store`] (`<key>.<extension>`); `None`: not stored.
    pub extension: Option<&'static str>,
}

/// Feeds a store key everything about `scene`'s geometry a precomputation reads: the vertex
/// and index counts and bytes.
pub fn hash_geometry(h: &mut sha2::Sha256, scene: &Scene) {
    use sha2::Digest;
    h.update((scene.vertices.len() as u64).to_le_bytes());
    h.update(bytemuck::cast_slice(&scene.vertices));
    h.update((scene.indices.len() as u64).to_le_bytes());
    h.update(bytemuck::cast_slice(&scene.indices));
}

/// [`PrecomputeEntry::build`].
pub type BuildFn = fn(&Scene, &PrecomputeKey, &mut BuildEnv) -> Result<Built, String>;

/// What a build reads besides its scene and key.
pub struct BuildEnv<'a> {
    pub store: &'a Store,
    /// Called from the building thread as steps advance.
    pub progress: &'a mut dyn FnMut(Progress),
    /// True once nobody can use the result (its scene was deleted): a long build checks it
    /// between chunks of work and gives up (builds of minutes do; short ones run to the
    /// end).
    pub cancelled: &'a dyn Fn() -> bool,
    /// The adapter, for a build that can trace or compute on it (visibility rays);
    /// without one such builds run on the CPU.
    pub gpu: Option<&'a crate::gpu::GpuContext>,
}

/// The precomputation frames of `method` need, if any.
pub fn entry_for(method: lightcast_protocol::GiMethod) -> Option<&'static PrecomputeEntry> {
    super::entry(method).1.precompute
}

/// Every registered precomputation.
pub fn entries() -> impl Iterator<Item = &'static PrecomputeEntry> {
    super::REGISTRY.iter().filter_map(|e| e.precompute)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_compare_by_kind_and_parameter_bits() {
        let key = |kind, d: f32| PrecomputeKey {
            kind,
            params: vec![("cache_distance", d)],
        };
        assert_eq!(key("a", 1.0), key("a", 1.0));
        assert_ne!(key("a", 1.0), key("b", 1.0));
        assert_ne!(key("a", 1.0), key("a", 1.0 + f32::EPSILON));
        assert_ne!(key("a", 0.0), key("a", -0.0), "bits, not numeric equality");
        assert_eq!(key("a", f32::NAN), key("a", f32::NAN));
        assert!(key("a", 1.0).has_variants());
        assert!(!PrecomputeKey {
            kind: "bvh",
            params: Vec::new()
        }
        .has_variants());
        assert_eq!(key("a", 2.5).param("cache_distance"), Some(2.5));
        assert_eq!(key("a", 2.5).param("cache_angle"), None);
        assert_eq!(key("a", 2.5).to_string(), "cache_distance 2.5");
    }

    #[test]
    fn every_kind_is_registered_once() {
        let kinds: Vec<_> = entries().map(|e| e.kind).collect();
        let mut unique = kinds.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), kinds.len(), "{kinds:?}");
        assert!(kinds.contains(&"light_caches") && kinds.contains(&"bvh"));
        // A stored kind's files are its own: one extension per kind.
        let mut extensions: Vec<_> = stored_extensions().collect();
        let count = extensions.len();
        extensions.sort_unstable();
        extensions.dedup();
        assert_eq!(extensions.len(), count, "{extensions:?}");
        assert!(extensions.contains(&"lcc") && extensions.contains(&"lsl"));
    }

    /// One size limit covers every stored kind: the oldest files go first, whatever their
    /// kind, and the file just written stays; files of other kinds are left alone.
    #[test]
    fn eviction_counts_every_stored_kind() {
        let dir = tempfile::tempdir().expect("temporary directory");
        let store = Store {
            dir: dir.path().to_path_buf(),
            max_bytes: Some(250),
        };
        let old = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
        for (i, name) in ["a.lsl", "b.lcc", "c.lsl", "notes.txt"].iter().enumerate() {
            let path = store.write_atomic(name, &[0u8; 100]).expect("written");
            let when = old + std::time::Duration::from_secs(i as u64 * 60);
            std::fs::File::options()
                .append(true)
                .open(&path)
                .and_then(|f| f.set_modified(when))
                .expect("dated");
        }
        let kept = store.write_atomic("d.lcc", &[0u8; 100]).expect("written");
        store.evict(&kept);
        let left: Vec<String> = {
            let mut names: Vec<String> = std::fs::read_dir(dir.path())
                .expect("listed")
                .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
                .collect();
            names.sort();
            names
        };
        assert_eq!(left, ["c.lsl", "d.lcc", "notes.txt"]);
    }
}
