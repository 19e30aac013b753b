//! Scenes the server holds: loaded once, shared by every session, light caches precomputed in
//! the background (one set per distinct cache parameters in use).

use super::error::ApiError;
use super::ids;
use crate::gi::cache_store::CacheStore;
use crate::gi::caches::{CacheParams, CacheSet};
use crate::scene::default_light::{default_camera, default_light};
use crate::scene::Scene;
use lightcast_protocol::{
    Bounds, CacheVariant, Camera, Light, PrecomputeState, SceneInfo, DEFAULT_SCENE_ID,
};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{mpsc, Arc, Mutex, MutexGuard};
use std::time::Instant;

/// Most cache parameter sets kept per scene.
pub const MAX_CACHE_VARIANTS: usize = 8;

/// Locks a mutex, recovering the data if a panicking thread poisoned it (every critical
/// section here leaves the data consistent).
pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

struct Variant {
    params: CacheParams,
    state: PrecomputeState,
    step: Option<String>,
    progress: Option<f32>,
    seconds: Option<f64>,
    from_store: Option<bool>,
    error: Option<String>,
    caches: Option<Arc<CacheSet>>,
}

impl Variant {
    fn info(&self) -> CacheVariant {
        CacheVariant {
            state: self.state,
            cache_distance: self.params.d_eps,
            cache_angle: self.params.theta_eps_degrees,
            caches: self.caches.as_ref().map(|c| c.caches.len() as u64),
            step: self.step.clone(),
            progress: self.progress,
            seconds: self.seconds,
            from_store: self.from_store,
            error: self.error.clone(),
        }
    }
}

/// What a frame can use of a scene's light caches right now.
pub enum CachesNow {
    Ready(Arc<CacheSet>),
    Pending,
    Failed(String),
}

/// One scene held by the server.
pub struct SceneEntry {
    pub id: String,
    pub source: String,
    pub scene: Arc<Scene>,
    pub default_camera: Camera,
    pub default_light: Light,
    pub default_params: CacheParams,
    /// Summed once: checking a request's cache parameters against it happens per message.
    surface_area: f64,
    pub load_ms: f64,
    variants: Mutex<Vec<Variant>>,
    sessions: AtomicU64,
    removed: AtomicBool,
}

fn same_params(a: &CacheParams, b: &CacheParams) -> bool {
    a.d_eps.to_bits() == b.d_eps.to_bits()
        && a.theta_eps_degrees.to_bits() == b.theta_eps_degrees.to_bits()
}

impl SceneEntry {
    fn new(scene: Scene, source: String, id: String, load_ms: f64) -> Self {
        Self {
            id,
            source,
            default_camera: default_camera(&scene),
            default_light: default_light(&scene),
            default_params: CacheParams::for_scene(&scene),
            surface_area: crate::gi::caches::surface_area(&scene),
            scene: Arc::new(scene),
            load_ms,
            variants: Mutex::new(Vec::new()),
            sessions: AtomicU64::new(0),
            removed: AtomicBool::new(false),
        }
    }

    pub fn info(&self) -> SceneInfo {
        let s = &self.scene;
        SceneInfo {
            id: self.id.clone(),
            name: s.name.clone(),
            source: self.source.clone(),
            triangles: s.triangle_count() as u64,
            vertices: s.vertices.len() as u64,
            materials: s.materials.len() as u64,
            textures: s.textures.len() as u64,
            bounds: Bounds {
                min: s.bounds.min.into(),
                max: s.bounds.max.into(),
            },
            lights: s.lights.clone(),
            cameras: s.cameras.clone(),
            default_camera: self.default_camera.clone(),
            default_light: self.default_light.clone(),
            caches: lock(&self.variants).iter().map(Variant::info).collect(),
            sessions: self.sessions.load(Ordering::Relaxed),
            load_ms: self.load_ms,
        }
    }

    /// Cache parameters of a request: the scene's defaults where a value is not given.
    /// Refuses parameters that would give absurd cache counts, naming the field.
    pub fn cache_params(
        &self,
        distance: Option<f32>,
        angle: Option<f32>,
    ) -> Result<CacheParams, ApiError> {
        let params = CacheParams {
            d_eps: distance.unwrap_or(self.default_params.d_eps),
            theta_eps_degrees: angle.unwrap_or(self.default_params.theta_eps_degrees),
        };
        if let Err(e) = params.validate_for_area(self.surface_area) {
            let field = if matches!(e, crate::gi::caches::CacheError::InvalidAngle(_)) {
                "gi.cache_angle"
            } else {
                "gi.cache_distance"
            };
            return Err(ApiError::field(field, e.to_string()));
        }
        let variants = lock(&self.variants);
        if variants.len() >= MAX_CACHE_VARIANTS
            && !variants.iter().any(|v| same_params(&v.params, &params))
        {
            return Err(ApiError::field(
                "gi.cache_distance",
                format!(
                    "scene '{}' already has {MAX_CACHE_VARIANTS} sets of light caches; \
                     use the parameters of one of them",
                    self.id
                ),
            ));
        }
        Ok(params)
    }

    /// Marks the scene in use until the lease is dropped.
    pub fn lease(self: &Arc<Self>) -> SceneLease {
        self.sessions.fetch_add(1, Ordering::Relaxed);
        SceneLease(Arc::clone(self))
    }

    pub fn in_use(&self) -> u64 {
        self.sessions.load(Ordering::Relaxed)
    }
}

/// A session's hold on a scene: while it lives the scene cannot be deleted.
pub struct SceneLease(pub Arc<SceneEntry>);

impl Drop for SceneLease {
    fn drop(&mut self) {
        self.0.sessions.fetch_sub(1, Ordering::Relaxed);
    }
}

type Job = (Arc<SceneEntry>, CacheParams);

/// All scenes, plus the worker thread that precomputes their light caches.
pub struct SceneRegistry {
    scenes: Mutex<BTreeMap<String, Arc<SceneEntry>>>,
    jobs: Mutex<mpsc::Sender<Job>>,
    max_scenes: usize,
}

impl SceneRegistry {
    /// Starts the precompute worker (one thread; the precomputation itself uses rayon).
    pub fn new(store: CacheStore, max_scenes: usize) -> Arc<Self> {
        let (tx, rx) = mpsc::channel::<Job>();
        std::thread::Builder::new()
            .name("precompute".into())
            .spawn(move || {
                for (entry, params) in rx {
                    precompute(&store, &entry, params);
                }
            })
            .expect("spawning the precompute thread");
        Arc::new(Self {
            scenes: Mutex::new(BTreeMap::new()),
            jobs: Mutex::new(tx),
            max_scenes,
        })
    }

    /// Adds a loaded scene under `id` (a new random id when `None`) and queues the
    /// precomputation of its default light caches.
    pub fn insert(
        &self,
        scene: Scene,
        source: String,
        id: Option<&str>,
        load_ms: f64,
    ) -> Result<Arc<SceneEntry>, ApiError> {
        let entry = Arc::new(SceneEntry::new(
            scene,
            source,
            id.map_or_else(|| ids::new_id("sc"), str::to_string),
            load_ms,
        ));
        {
            let mut scenes = lock(&self.scenes);
            if scenes.len() >= self.max_scenes {
                return Err(ApiError::too_many(
                    "too_many_scenes",
                    format!(
                        "the server holds {} scenes, its limit; delete one first",
                        scenes.len()
                    ),
                ));
            }
            scenes.insert(entry.id.clone(), Arc::clone(&entry));
            metrics::gauge!(super::metrics::SCENES).set(scenes.len() as f64);
        }
        self.caches(&entry, entry.default_params);
        Ok(entry)
    }

    /// A scene outside the registry (a one-shot render's upload): nothing else can see it,
    /// and it is gone when the last holder drops it.
    pub fn detached(scene: Scene, load_ms: f64) -> Arc<SceneEntry> {
        Arc::new(SceneEntry::new(
            scene,
            "upload".to_string(),
            ids::new_id("upload"),
            load_ms,
        ))
    }

    pub fn get(&self, id: &str) -> Result<Arc<SceneEntry>, ApiError> {
        lock(&self.scenes)
            .get(id)
            .cloned()
            .ok_or_else(|| ApiError::not_found("scene", id))
    }

    pub fn list(&self) -> Vec<Arc<SceneEntry>> {
        lock(&self.scenes).values().cloned().collect()
    }

    pub fn contains(&self, id: &str) -> bool {
        lock(&self.scenes).contains_key(id)
    }

    /// Deletes a scene no session uses.
    pub fn remove(&self, id: &str) -> Result<(), ApiError> {
        let mut scenes = lock(&self.scenes);
        let entry = scenes
            .get(id)
            .ok_or_else(|| ApiError::not_found("scene", id))?;
        if id == DEFAULT_SCENE_ID {
            return Err(ApiError::conflict("the default scene cannot be deleted"));
        }
        let users = entry.in_use();
        if users > 0 {
            return Err(ApiError::conflict(format!(
                "scene '{id}' is used by {users} session(s); delete or move them first"
            )));
        }
        entry.removed.store(true, Ordering::Relaxed);
        scenes.remove(id);
        metrics::gauge!(super::metrics::SCENES).set(scenes.len() as f64);
        Ok(())
    }

    /// The light caches of `entry` for `params`, queueing their precomputation on first use.
    pub fn caches(&self, entry: &Arc<SceneEntry>, params: CacheParams) -> CachesNow {
        let mut variants = lock(&entry.variants);
        if let Some(v) = variants.iter().find(|v| same_params(&v.params, &params)) {
            return match (&v.caches, &v.error) {
                (Some(set), _) => CachesNow::Ready(Arc::clone(set)),
                (None, Some(e)) => CachesNow::Failed(e.clone()),
                (None, None) => CachesNow::Pending,
            };
        }
        variants.push(Variant {
            params,
            state: PrecomputeState::Queued,
            step: None,
            progress: None,
            seconds: None,
            from_store: None,
            error: None,
            caches: None,
        });
        drop(variants);
        if lock(&self.jobs).send((Arc::clone(entry), params)).is_err() {
            tracing::error!("the precompute thread has stopped");
        }
        CachesNow::Pending
    }
}

/// Runs on the precompute thread: loads or computes one set of caches and records the outcome.
fn precompute(store: &CacheStore, entry: &SceneEntry, params: CacheParams) {
    let update = |f: &mut dyn FnMut(&mut Variant)| {
        if let Some(v) = lock(&entry.variants)
            .iter_mut()
            .find(|v| same_params(&v.params, &params))
        {
            f(v);
        }
    };
    if entry.removed.load(Ordering::Relaxed) {
        return;
    }
    update(&mut |v| v.state = PrecomputeState::Running);
    let started = Instant::now();
    let mut progress = |p: crate::gi::caches::Progress| {
        update(&mut |v| {
            v.step = Some(p.step.to_string());
            v.progress = Some(if p.total == 0 {
                0.0
            } else {
                p.done as f32 / p.total as f32
            });
        })
    };
    let result = store.load_or_compute(&entry.scene, &params, &mut progress);
    let seconds = started.elapsed().as_secs_f64();
    match result {
        Ok((set, from_store)) => {
            tracing::info!(
                scene = %entry.id,
                caches = set.caches.len(),
                seconds,
                from_store,
                "light caches ready"
            );
            let mut set = Some(set);
            update(&mut |v| {
                v.state = PrecomputeState::Ready;
                v.step = None;
                v.progress = Some(1.0);
                v.seconds = Some(seconds);
                v.from_store = Some(from_store);
                v.caches = set.take().map(Arc::new);
            });
        }
        Err(e) => {
            tracing::warn!(scene = %entry.id, "light caches failed: {e}");
            update(&mut |v| {
                v.state = PrecomputeState::Failed;
                v.seconds = Some(seconds);
                v.error = Some(e.to_string());
            });
        }
    }
}
