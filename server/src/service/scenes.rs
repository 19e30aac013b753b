//! Scenes the server holds: loaded once, shared by every session, light caches precomputed in
//! the background (one set per distinct cache parameters in use).

use super::budget::{over_budget, Held, MemoryBudget, Pool, Quota, TokenQuotas};
use super::error::ApiError;
use super::ids;
use crate::gi::lightskin::cache_store::CacheStore;
use crate::gi::lightskin::caches::{min_distance_for, CacheParams, CacheSet};
use crate::scene::default_light::{default_camera, default_light};
use crate::scene::Scene;
use lightcast_protocol::{
    Bounds, CacheVariant, Camera, Light, Limits, PrecomputeState, SceneInfo, DEFAULT_SCENE_ID,
};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{mpsc, Arc, Mutex, MutexGuard, Weak};
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
    /// This set's share of the total light-cache budget: the estimate until it is built,
    /// then the real count.
    held: Held,
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
    /// Not queued: the precompute queue is full; asking again later queues them.
    Busy,
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
    /// The token that uploaded the scene, the only one that may delete it (`None`: the
    /// server's own scenes, or auth off).
    owner: Option<String>,
    variants: Mutex<Vec<Variant>>,
    sessions: AtomicU64,
    removed: AtomicBool,
    budget: Arc<MemoryBudget>,
    /// The scene's texture bytes and triangles, taken from the server's budgets while it is
    /// held.
    _held: [Held; 2],
}

fn same_params(a: &CacheParams, b: &CacheParams) -> bool {
    a.d_eps.to_bits() == b.d_eps.to_bits()
        && a.theta_eps_degrees.to_bits() == b.theta_eps_degrees.to_bits()
}

/// 413 `triangle_budget`: a scene of `triangles` does not fit in what is left of `pool`.
pub fn triangles_over_budget(triangles: u64, pool: &Pool) -> ApiError {
    over_budget(
        "triangle_budget",
        format!(
            "the scene has {triangles} triangles (zero-area ones not counted); this server \
             holds at most {} over all scenes (--max-total-triangles) and has {} left; delete \
             a scene first",
            pool.limit(),
            pool.available()
        ),
    )
}

/// Decoded texture bytes of a scene, as the budgets count them.
pub fn texture_bytes(scene: &Scene) -> u64 {
    scene.textures.iter().map(|t| t.rgba8.len() as u64).sum()
}

impl SceneEntry {
    /// A scene with its texture bytes and triangles taken from `budget`, or 413 naming the
    /// budget it would overrun.
    fn new(
        scene: Scene,
        source: String,
        id: String,
        load_ms: f64,
        owner: Option<String>,
        budget: &Arc<MemoryBudget>,
    ) -> Result<Self, ApiError> {
        let textures = texture_bytes(&scene);
        let texture_held = budget.texture_bytes.try_take(textures).ok_or_else(|| {
            let pool = &budget.texture_bytes;
            over_budget(
                "texture_budget",
                format!(
                    "the scene's textures take {} MiB decoded; this server holds at most {} MiB \
                     of textures over all scenes (--max-total-texture-bytes) and has {} MiB \
                     left; delete a scene first",
                    textures.div_ceil(1 << 20),
                    pool.limit() >> 20,
                    pool.available() >> 20
                ),
            )
        })?;
        let triangles = scene.triangle_count() as u64;
        let triangles_held = budget
            .triangles
            .try_take(triangles)
            .ok_or_else(|| triangles_over_budget(triangles, &budget.triangles))?;
        Ok(Self {
            id,
            source,
            owner,
            default_camera: default_camera(&scene),
            default_light: default_light(&scene),
            default_params: CacheParams::for_scene(&scene),
            surface_area: crate::gi::lightskin::caches::surface_area(&scene),
            scene: Arc::new(scene),
            load_ms,
            variants: Mutex::new(Vec::new()),
            sessions: AtomicU64::new(0),
            removed: AtomicBool::new(false),
            budget: Arc::clone(budget),
            _held: [texture_held, triangles_held],
        })
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
        // The count is checked against the budgets below, which are within the format's own
        // cap (`validate_for_area`, which the precomputation applies too).
        if let Err(e) = params.validate() {
            let field = if matches!(e, crate::gi::lightskin::caches::CacheError::InvalidAngle(_)) {
                "gi.cache_angle"
            } else {
                "gi.cache_distance"
            };
            return Err(ApiError::field(field, e.to_string()));
        }
        let variants = lock(&self.variants);
        let exists = variants.iter().any(|v| same_params(&v.params, &params));
        if !exists {
            self.check_cache_budget(&params)?;
        }
        if variants.len() >= MAX_CACHE_VARIANTS && !exists {
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

    /// Refuses a new set of light caches whose estimated count exceeds the per-set limit or
    /// what is left of the total, before anything is queued or built.
    fn check_cache_budget(&self, params: &CacheParams) -> Result<(), ApiError> {
        let estimated = params.estimated_caches(self.surface_area);
        let per_set = self.budget.caches_per_set;
        if estimated > per_set {
            return Err(ApiError::field(
                "gi.cache_distance",
                format!(
                    "{} would make about {estimated} light caches for this scene's {:.6} square \
                     units of surface, more than this server's limit of {per_set} per set \
                     (--max-caches-per-set); use cache_distance >= {}",
                    params.d_eps,
                    self.surface_area,
                    min_distance_for(self.surface_area, per_set)
                ),
            ));
        }
        self.reserve_caches(params).map(drop)
    }

    /// Takes a new set's estimated light caches from the total budget.
    fn reserve_caches(&self, params: &CacheParams) -> Result<Held, ApiError> {
        let estimated = params.estimated_caches(self.surface_area);
        let pool = &self.budget.caches;
        pool.try_take(estimated).ok_or_else(|| {
            ApiError::field(
                "gi.cache_distance",
                format!(
                    "{} would make about {estimated} light caches, but only {} of this \
                     server's {} (--max-total-caches) are left; use a larger cache_distance \
                     or the parameters of a set that exists",
                    params.d_eps,
                    pool.available(),
                    pool.limit()
                ),
            )
        })
    }

    /// Makes a built set's share of the total budget its real count. The estimate is of flat
    /// geometry; curved or folded surfaces (or a small cache angle) can make more, and a set
    /// beyond the per-set limit or what is left of the total is refused, its memory freed.
    fn hold_built_caches(&self, params: &CacheParams, count: u64) -> Result<(), String> {
        let per_set = self.budget.caches_per_set;
        if count > per_set {
            return Err(format!(
                "{count} light caches were made, more than this server's limit of {per_set} \
                 per set (--max-caches-per-set); use a larger cache_distance or cache_angle"
            ));
        }
        let mut held = true;
        self.update_variant(params, &mut |v| held = v.held.resize(count));
        if held {
            Ok(())
        } else {
            Err(format!(
                "{count} light caches were made, more than the {} left of this server's {} \
                 (--max-total-caches); use a larger cache_distance",
                self.budget.caches.available(),
                self.budget.caches.limit()
            ))
        }
    }

    fn update_variant(&self, params: &CacheParams, f: &mut dyn FnMut(&mut Variant)) {
        if let Some(v) = lock(&self.variants)
            .iter_mut()
            .find(|v| same_params(&v.params, params))
        {
            f(v);
        }
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

/// A queued precomputation. The queue holds its scene weakly: a scene deleted, or a one-shot
/// render's upload whose request has ended, is skipped and its memory freed at once instead
/// of waiting in the queue.
type Job = (Weak<SceneEntry>, CacheParams);

/// Precomputations waiting at most; beyond them a request is refused for now.
const MAX_QUEUED_JOBS: usize = 32;

/// All scenes, plus the worker thread that precomputes their light caches.
pub struct SceneRegistry {
    scenes: Mutex<BTreeMap<String, Arc<SceneEntry>>>,
    jobs: Mutex<mpsc::SyncSender<Job>>,
    max_scenes: usize,
    budget: Arc<MemoryBudget>,
    quotas: TokenQuotas,
}

impl SceneRegistry {
    /// Starts the precompute worker (one thread; the precomputation itself uses rayon).
    pub fn new(store: CacheStore, limits: &Limits) -> Arc<Self> {
        Self::with_worker(limits, move |entry, params| {
            precompute(&store, entry, params)
        })
    }

    /// [`SceneRegistry::new`] with `work` run on the worker thread for each queued job.
    fn with_worker(
        limits: &Limits,
        mut work: impl FnMut(&SceneEntry, CacheParams) + Send + 'static,
    ) -> Arc<Self> {
        let (tx, rx) = mpsc::sync_channel::<Job>(MAX_QUEUED_JOBS);
        std::thread::Builder::new()
            .name("precompute".into())
            .spawn(move || {
                for (entry, params) in rx {
                    let Some(entry) = entry.upgrade() else {
                        continue;
                    };
                    // A bug in one scene's precomputation must not stop every later scene's.
                    let run = || work(&entry, params);
                    if std::panic::catch_unwind(std::panic::AssertUnwindSafe(run)).is_err() {
                        tracing::error!(scene = %entry.id, "the light-cache precomputation panicked");
                        entry.update_variant(&params, &mut |v| {
                            v.state = PrecomputeState::Failed;
                            v.error = Some(
                                "the precomputation failed on an internal error (see the \
                                 server log)"
                                    .into(),
                            );
                        });
                    }
                }
            })
            .expect("spawning the precompute thread");
        Arc::new(Self {
            scenes: Mutex::new(BTreeMap::new()),
            jobs: Mutex::new(tx),
            max_scenes: limits.max_scenes as usize,
            budget: Arc::new(MemoryBudget::new(limits)),
            quotas: TokenQuotas::new(limits),
        })
    }

    /// The memory budgets every scene is taken from.
    pub fn budget(&self) -> &MemoryBudget {
        &self.budget
    }

    /// Adds a loaded scene under `id` (a new random id when `None`), deletable only with the
    /// `owner` token when there is one, and queues the precomputation of its default light
    /// caches.
    pub fn insert(
        &self,
        scene: Scene,
        source: String,
        id: Option<&str>,
        load_ms: f64,
        owner: Option<String>,
    ) -> Result<Arc<SceneEntry>, ApiError> {
        let entry = Arc::new(SceneEntry::new(
            scene,
            source,
            id.map_or_else(|| ids::new_id("sc"), str::to_string),
            load_ms,
            owner,
            &self.budget,
        )?);
        {
            let mut scenes = lock(&self.scenes);
            let owner = entry.owner.as_deref();
            let owned = scenes
                .values()
                .filter(|e| owner.is_some() && e.owner.as_deref() == owner)
                .count();
            self.quotas.check_count(owner, Quota::Scenes, owned)?;
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
    /// and it is gone when the last holder drops it. It counts against the memory budgets
    /// while it lives.
    pub fn detached(&self, scene: Scene, load_ms: f64) -> Result<Arc<SceneEntry>, ApiError> {
        SceneEntry::new(
            scene,
            "upload".to_string(),
            ids::new_id("upload"),
            load_ms,
            None,
            &self.budget,
        )
        .map(Arc::new)
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

    /// Deletes a scene no session uses, for the `caller` token that uploaded it (scenes are
    /// shared, but one client must not pull another's scene away).
    pub fn remove(&self, id: &str, caller: Option<&str>) -> Result<(), ApiError> {
        let mut scenes = lock(&self.scenes);
        let entry = scenes
            .get(id)
            .ok_or_else(|| ApiError::not_found("scene", id))?;
        if id == DEFAULT_SCENE_ID {
            return Err(ApiError::conflict("the default scene cannot be deleted"));
        }
        if entry.owner.is_some() && entry.owner.as_deref() != caller {
            return Err(ApiError::forbidden(format!(
                "scene '{id}' was uploaded with another token; only that token can delete it"
            )));
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
        let held = match entry.reserve_caches(&params) {
            Ok(held) => held,
            Err(e) => return CachesNow::Failed(e.body.message),
        };
        match lock(&self.jobs).try_send((Arc::downgrade(entry), params)) {
            Ok(()) => {}
            Err(mpsc::TrySendError::Full(_)) => return CachesNow::Busy,
            Err(mpsc::TrySendError::Disconnected(_)) => {
                tracing::error!("the precompute thread has stopped");
                return CachesNow::Failed("the precompute thread has stopped".into());
            }
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
            held,
        });
        CachesNow::Pending
    }
}

/// Runs on the precompute thread: loads or computes one set of caches and records the outcome.
fn precompute(store: &CacheStore, entry: &SceneEntry, params: CacheParams) {
    let update = |f: &mut dyn FnMut(&mut Variant)| entry.update_variant(&params, f);
    if entry.removed.load(Ordering::Relaxed) {
        return;
    }
    update(&mut |v| v.state = PrecomputeState::Running);
    let started = Instant::now();
    let mut progress = |p: crate::gi::lightskin::caches::Progress| {
        update(&mut |v| {
            v.step = Some(p.step.to_string());
            v.progress = Some(if p.total == 0 {
                0.0
            } else {
                p.done as f32 / p.total as f32
            });
        })
    };
    let result = store
        .load_or_compute(&entry.scene, &params, &mut progress)
        .map_err(|e| e.to_string())
        .and_then(|(set, from_store)| {
            entry.hold_built_caches(&params, set.caches.len() as u64)?;
            Ok((set, from_store))
        });
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
                v.error = Some(e.clone());
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::procedural;
    use std::time::Duration;

    fn limits(max_scenes: u32) -> Limits {
        Limits {
            max_scenes,
            ..crate::service::config::tests::default_limits()
        }
    }

    fn params(d_eps: f32) -> CacheParams {
        CacheParams {
            d_eps,
            theta_eps_degrees: 30.0,
        }
    }

    fn state(entry: &SceneEntry, p: &CacheParams) -> Option<PrecomputeState> {
        lock(&entry.variants)
            .iter()
            .find(|v| same_params(&v.params, p))
            .map(|v| v.state)
    }

    /// A worker that reports each job's scene id and then waits for a go-ahead.
    fn gated() -> (Arc<SceneRegistry>, mpsc::Receiver<String>, mpsc::Sender<()>) {
        let (seen_tx, seen) = mpsc::channel();
        let (go, go_rx) = mpsc::channel::<()>();
        let registry = SceneRegistry::with_worker(&limits(4), move |entry, _| {
            let _ = seen_tx.send(entry.id.clone());
            let _ = go_rx.recv();
        });
        (registry, seen, go)
    }

    const WAIT: Duration = Duration::from_secs(10);

    /// A registry under `limits` whose worker does nothing.
    fn idle(limits: &Limits) -> Arc<SceneRegistry> {
        SceneRegistry::with_worker(limits, |_, _| {})
    }

    #[test]
    fn cache_sets_beyond_the_budgets_are_refused_before_anything_is_built() {
        let registry = idle(&limits(4));
        let entry = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        let area = entry.surface_area;
        // The smallest distance the format's own cap allows, which the server used to
        // suggest: about two million caches, far beyond one set's budget.
        let suggested = min_distance_for(area, crate::gi::lightskin::caches::MAX_CACHES) * 1.01;
        let e = entry
            .cache_params(Some(suggested), None)
            .expect_err("beyond --max-caches-per-set");
        assert_eq!(e.body.field.as_deref(), Some("gi.cache_distance"));
        assert!(
            e.body
                .message
                .contains("limit of 250000 per set (--max-caches-per-set)"),
            "{}",
            e.body.message
        );
        assert_eq!(registry.budget().caches.used(), 0, "nothing taken");

        let tight = Limits {
            max_caches_per_set: 10_000,
            max_total_caches: 15_000,
            ..limits(4)
        };
        let registry = idle(&tight);
        let entry = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        let smallest = min_distance_for(area, 10_000);
        let p = entry
            .cache_params(Some(smallest), None)
            .expect("10,000 fit");
        assert!(entry.cache_params(Some(smallest * 0.95), None).is_err());
        assert!(matches!(registry.caches(&entry, p), CachesNow::Pending));
        let taken = registry.budget().caches.used();
        assert!((9_000..=10_000).contains(&taken), "{taken}");
        let e = entry
            .cache_params(Some(smallest * 1.1), None)
            .expect_err("the total is spent");
        assert_eq!(e.body.field.as_deref(), Some("gi.cache_distance"));
        assert!(
            e.body.message.contains("(--max-total-caches)"),
            "{}",
            e.body.message
        );
        assert!(
            entry.cache_params(Some(smallest), None).is_ok(),
            "the set that exists is not counted twice"
        );
        drop(entry);
        assert_eq!(
            registry.budget().caches.used(),
            0,
            "given back with the scene"
        );
    }

    #[test]
    fn built_sets_hold_their_real_count_and_are_refused_beyond_the_per_set_limit() {
        let registry = idle(&Limits {
            max_caches_per_set: 10_000,
            ..limits(4)
        });
        let entry = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        let p = params(1.0);
        assert!(matches!(registry.caches(&entry, p), CachesNow::Pending));
        assert_eq!(entry.hold_built_caches(&p, 7), Ok(()));
        assert_eq!(registry.budget().caches.used(), 7);
        let e = entry.hold_built_caches(&p, 10_001).expect_err("over");
        assert!(e.contains("--max-caches-per-set"), "{e}");
    }

    #[test]
    fn scenes_take_their_triangles_and_textures_from_the_budgets_while_held() {
        let cornell = procedural::cornell_box();
        let triangles = cornell.triangle_count() as u64;
        let registry = idle(&Limits {
            max_total_triangles: triangles * 3 / 2,
            ..limits(4)
        });
        let first = registry
            .insert(cornell.clone(), "t".into(), None, 0.0, None)
            .expect("fits");
        let Err(e) = registry.insert(cornell.clone(), "t".into(), None, 0.0, None) else {
            panic!("over the total");
        };
        assert_eq!(e.status, axum::http::StatusCode::PAYLOAD_TOO_LARGE);
        assert_eq!(e.body.error, "triangle_budget");
        assert!(
            e.body.message.contains("--max-total-triangles"),
            "{}",
            e.body.message
        );
        assert!(
            registry.detached(cornell.clone(), 0.0).is_err(),
            "uploads count too"
        );
        let id = first.id.clone();
        drop(first);
        registry.remove(&id, None).expect("removed");
        assert!(registry
            .insert(cornell, "t".into(), None, 0.0, None)
            .is_ok());

        let mut textured = procedural::cornell_box();
        textured.textures.push(crate::scene::Texture {
            name: "t".into(),
            width: 64,
            height: 64,
            rgba8: vec![255; 64 * 64 * 4],
        });
        let registry = idle(&Limits {
            max_scene_texture_bytes: 64 * 64 * 4,
            max_total_texture_bytes: 64 * 64 * 4,
            ..limits(4)
        });
        let held = registry.detached(textured.clone(), 0.0).expect("fits");
        let Err(e) = registry.detached(textured.clone(), 0.0) else {
            panic!("the total is held");
        };
        assert_eq!(e.body.error, "texture_budget");
        assert!(
            e.body.message.contains("--max-total-texture-bytes"),
            "{}",
            e.body.message
        );
        drop(held);
        assert!(registry.detached(textured, 0.0).is_ok());
    }

    #[test]
    fn a_full_queue_refuses_new_work_until_it_drains() {
        let (registry, seen, go) = gated();
        let entry = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        assert!(matches!(
            registry.caches(&entry, params(1.0)),
            CachesNow::Pending
        ));
        assert_eq!(seen.recv_timeout(WAIT).as_deref(), Ok(entry.id.as_str()));
        // The worker holds the first job; the queue takes MAX_QUEUED_JOBS more.
        for k in 0..MAX_QUEUED_JOBS {
            let p = params(2.0 + k as f32);
            assert!(
                matches!(registry.caches(&entry, p), CachesNow::Pending),
                "job {k}"
            );
        }
        let refused = params(100.0);
        assert!(matches!(registry.caches(&entry, refused), CachesNow::Busy));
        assert_eq!(
            state(&entry, &refused),
            None,
            "a refused job leaves no variant"
        );
        go.send(()).expect("worker alive");
        assert!(seen.recv_timeout(WAIT).is_ok());
        assert!(matches!(
            registry.caches(&entry, refused),
            CachesNow::Pending
        ));
        drop(go);
    }

    #[test]
    fn jobs_of_scenes_gone_from_every_holder_are_skipped() {
        let (registry, seen, go) = gated();
        let kept = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        registry.caches(&kept, params(1.0));
        assert_eq!(seen.recv_timeout(WAIT).as_deref(), Ok(kept.id.as_str()));
        let dropped = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        registry.caches(&dropped, params(1.0));
        registry.caches(&kept, params(2.0));
        drop(dropped);
        go.send(()).expect("worker alive");
        go.send(()).expect("worker alive");
        assert_eq!(seen.recv_timeout(WAIT).as_deref(), Ok(kept.id.as_str()));
        drop(go);
        assert!(seen.recv_timeout(Duration::from_millis(200)).is_err());
    }

    #[test]
    fn a_panicking_precomputation_fails_its_variant_and_the_worker_goes_on() {
        let (done_tx, done) = mpsc::channel();
        let registry = SceneRegistry::with_worker(&limits(4), move |entry, p| {
            assert!(p.d_eps != 1.0, "a bug in the precomputation");
            let _ = done_tx.send(entry.id.clone());
        });
        let entry = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        registry.caches(&entry, params(1.0));
        registry.caches(&entry, params(2.0));
        assert_eq!(done.recv_timeout(WAIT).as_deref(), Ok(entry.id.as_str()));
        assert_eq!(state(&entry, &params(1.0)), Some(PrecomputeState::Failed));
        match registry.caches(&entry, params(1.0)) {
            CachesNow::Failed(e) => assert!(e.contains("internal error"), "{e}"),
            _ => panic!("the panicked variant must read as failed"),
        }
    }
}
