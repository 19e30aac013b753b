//! Scenes the server holds: loaded once, shared by every session, with their GI methods'
//! precomputations (light caches, BVH; see `gi::precompute`) built in the background, one
//! set per kind and distinct parameters in use.

use super::budget::{over_budget, Held, MemoryBudget, Pool, Quota, TokenQuotas};
use super::error::ApiError;
use super::ids;
use super::sync::lock;
use crate::gi::precompute::{
    self, BudgetPool, BuildEnv, PrecomputeEntry, PrecomputeKey, Progress, SceneData, SceneFacts,
    Store, UnitBudget,
};
use crate::gpu::GpuContext;
use crate::scene::default_light::{default_camera, default_light, emitter_stand_in};
use crate::scene::Scene;
use lightcast_protocol::{
    Bounds, CacheVariant, Camera, GiParams, Light, Limits, PrecomputeState, Precomputed, SceneInfo,
    DEFAULT_SCENE_ID,
};
use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::AtomicBool;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, Weak};
use std::time::{Duration, Instant};

/// Most parameter sets of one precomputation kept per scene.
pub const MAX_VARIANTS: usize = 8;

/// Who waits for each precomputation of a scene: the holders of its [`Demand`]s and when the
/// last of them let go.
#[derive(Default)]
struct Demands(Mutex<HashMap<PrecomputeKey, (usize, Instant)>>);

impl Demands {
    /// Whether nobody has held a demand for `key` for `grace` (a key never demanded, such as
    /// a comparison's BVH, is not unwanted).
    fn unwanted(&self, key: &PrecomputeKey, grace: Duration) -> bool {
        lock(&self.0)
            .get(key)
            .is_some_and(|(holders, since)| *holders == 0 && since.elapsed() >= grace)
    }
}

/// A session's or a waiting request's claim on a precomputation of a scene: while one is
/// held (and for `--unwanted-precompute-secs` after the last is dropped: a one-shot render
/// answered 503 while it builds is retried by its client, a reloaded viewer asks again) the
/// build goes on.
pub struct Demand {
    demands: Arc<Demands>,
    key: PrecomputeKey,
}

impl Drop for Demand {
    fn drop(&mut self) {
        if let Some((holders, since)) = lock(&self.demands.0).get_mut(&self.key) {
            *holders = holders.saturating_sub(1);
            *since = Instant::now();
        }
    }
}

impl std::fmt::Debug for Demand {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Demand({})", self.key)
    }
}

/// One precomputation of the scene (one per kind and distinct parameters in use).
struct Variant {
    key: PrecomputeKey,
    entry: &'static PrecomputeEntry,
    state: PrecomputeState,
    step: Option<String>,
    progress: Option<f32>,
    seconds: Option<f64>,
    from_store: Option<bool>,
    error: Option<String>,
    units: Option<u64>,
    data: Option<SceneData>,
    /// This set's share of its kind's unit budget: the estimate until it is built, then the
    /// real count (nothing for unbudgeted kinds).
    held: Option<Held>,
}

impl Variant {
    /// Marks the set failed with `error` and gives its units back to the budget (it stays
    /// listed with the error, so that a request for it is answered at once, not rebuilt).
    fn fail(&mut self, error: String) {
        self.state = PrecomputeState::Failed;
        self.error = Some(error);
        self.held = None;
    }

    fn info(&self) -> Precomputed {
        Precomputed {
            kind: self.key.kind.to_string(),
            label: self.entry.label.to_string(),
            params: self
                .key
                .params
                .iter()
                .map(|(name, value)| (name.to_string(), *value))
                .collect(),
            state: self.state,
            units: self.entry.budget.as_ref().and(self.units),
            unit: self.entry.budget.as_ref().map(|b| b.unit.to_string()),
            step: self.step.clone(),
            progress: self.progress,
            seconds: self.seconds,
            from_store: self.from_store,
            error: self.error.clone(),
        }
    }
}

/// What a frame can use of a scene's precomputation right now.
pub enum Now {
    Ready(SceneData),
    Pending,
    /// Not queued: the precompute queue is full; asking again later queues it.
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
    /// The default light when it stands in for the scene's emissive surfaces
    /// ([`emitter_stand_in`]): `render.gi.emitters` `null` turns them off under it.
    pub emitter_stand_in: Option<Light>,
    /// Summed once: checking a request's precomputation parameters against them happens per
    /// message.
    facts: SceneFacts,
    pub load_ms: f64,
    /// The SHA-256 of the token that uploaded the scene, the only one that may delete it
    /// (`None`: the server's own scenes, or auth off); the token itself is never kept.
    owner: Option<String>,
    variants: Mutex<Vec<Variant>>,
    demands: Arc<Demands>,
    /// The demand for the default method's set, queued when the scene is added: kept while
    /// the scene is, so that a first viewer finds it ready.
    default_demand: Mutex<Option<Demand>>,
    sessions: AtomicU64,
    budget: Arc<MemoryBudget>,
    /// The scene's texture bytes and triangles, taken from the server's budgets while it is
    /// held.
    _held: [Held; 2],
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
            emitter_stand_in: emitter_stand_in(&scene),
            facts: SceneFacts::of(&scene),
            scene: Arc::new(scene),
            load_ms,
            variants: Mutex::new(Vec::new()),
            demands: Arc::default(),
            default_demand: Mutex::new(None),
            sessions: AtomicU64::new(0),
            budget: Arc::clone(budget),
            _held: [texture_held, triangles_held],
        })
    }

    pub fn info(&self) -> SceneInfo {
        let s = &self.scene;
        let precomputed: Vec<Precomputed> =
            lock(&self.variants).iter().map(Variant::info).collect();
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
            camera_region: s.camera_region.map(|r| Bounds {
                min: r.min.into(),
                max: r.max.into(),
            }),
            caches: precomputed
                .iter()
                .filter_map(CacheVariant::from_precomputed)
                .collect(),
            precomputed,
            sessions: self.sessions.load(Ordering::Relaxed),
            load_ms: self.load_ms,
        }
    }

    /// The precomputation a frame with GI parameters `gi` needs on this scene, if any: its
    /// parameters are the scene's defaults where `gi` gives none. Refuses parameters beyond
    /// the budgets before anything is queued or built, naming the field (under `gi`).
    pub fn precompute_key(&self, gi: &GiParams) -> Result<Option<PrecomputeKey>, ApiError> {
        let Some(entry) = precompute::entry_for(gi.method) else {
            return Ok(None);
        };
        let key = (entry.key)(gi, &self.facts)
            .map_err(|e| ApiError::field(format!("gi.{}", e.field), e.reason))?;
        let variants = lock(&self.variants);
        if variants.iter().any(|v| v.key == key) {
            return Ok(Some(key));
        }
        if let Some(budget) = &entry.budget {
            self.check_budget(entry, budget, &key)?;
        }
        let kept = variants.iter().filter(|v| v.key.kind == key.kind).count();
        if kept >= MAX_VARIANTS {
            let field = entry.budget.as_ref().map_or("method", |b| b.field);
            return Err(ApiError::field(
                format!("gi.{field}"),
                format!(
                    "scene '{}' already has {MAX_VARIANTS} sets of {}; use the parameters \
                     of one of them",
                    self.id, entry.label
                ),
            ));
        }
        Ok(Some(key))
    }

    /// Units of the set frames of `gi` read (light caches, surfel links) as estimated before
    /// it is built (0 for a method without one): what the frame's cost formulas count.
    pub fn estimated_set_units(&self, gi: &GiParams) -> u64 {
        precompute::entry_for(gi.method)
            .and_then(|entry| {
                Some((entry.estimate)(
                    &(entry.key)(gi, &self.facts).ok()?,
                    &self.facts,
                ))
            })
            .unwrap_or(0)
    }

    /// Refuses set `key` of `gi` when the scene does not hold it yet and its build is
    /// estimated over `--max-precompute-cost` (a set held or being built costs nothing more).
    pub fn check_precompute_cost(
        &self,
        gi: &GiParams,
        key: &PrecomputeKey,
        limits: &lightcast_protocol::Limits,
    ) -> Result<(), ApiError> {
        let Some(entry) = precompute::entry_for(gi.method) else {
            return Ok(());
        };
        if lock(&self.variants).iter().any(|v| v.key == *key) {
            return Ok(());
        }
        super::cost::check_precompute(entry, gi, key, &self.facts, limits)
    }

    /// Refuses a new set whose estimated size exceeds the per-set limit or what is left of
    /// the total.
    fn check_budget(
        &self,
        entry: &PrecomputeEntry,
        budget: &UnitBudget,
        key: &PrecomputeKey,
    ) -> Result<(), ApiError> {
        let estimated = (entry.estimate)(key, &self.facts);
        if let Some((per_set, flag)) = self.per_set_limit(budget.pool) {
            if estimated > per_set {
                return Err(ApiError::field(
                    format!("gi.{}", budget.field),
                    format!(
                        "{} would make about {estimated} {} for this scene's {:.6} square \
                         units of surface, more than this server's limit of {per_set} per set \
                         ({flag}); {}",
                        key,
                        budget.unit,
                        self.facts.surface_area,
                        (budget.advice)(&self.facts, per_set)
                    ),
                ));
            }
        }
        self.reserve(entry, key).map(drop)
    }

    /// The pool a kind's units are taken from, with its flag.
    fn pool(&self, pool: BudgetPool) -> Result<(&Arc<Pool>, &'static str), ApiError> {
        match pool {
            BudgetPool::Triangles => Ok((&self.budget.triangles, "--max-total-triangles")),
            BudgetPool::Declared { total, .. } => self
                .budget
                .gi_pool(total)
                .map(|pool| (pool, total.flag))
                .ok_or_else(|| {
                    ApiError::internal(format!("limit {} is not a registered one", total.name))
                }),
        }
    }

    /// The most units one set of the pool may hold, with its flag.
    fn per_set_limit(&self, pool: BudgetPool) -> Option<(u64, &'static str)> {
        match pool {
            BudgetPool::Declared {
                per_set: Some(limit),
                ..
            } => Some((self.budget.gi_limit(limit), limit.flag)),
            _ => None,
        }
    }

    /// Takes a new set's estimated units from its pool (nothing for unbudgeted kinds).
    fn reserve(
        &self,
        entry: &PrecomputeEntry,
        key: &PrecomputeKey,
    ) -> Result<Option<Held>, ApiError> {
        let Some(budget) = &entry.budget else {
            return Ok(None);
        };
        let estimated = (entry.estimate)(key, &self.facts);
        let (pool, flag) = self.pool(budget.pool)?;
        pool.try_take(estimated).map(Some).ok_or_else(|| {
            ApiError::field(
                format!("gi.{}", budget.field),
                format!(
                    "{} would hold about {estimated} {}, but only {} of this server's {} \
                     ({flag}) are left; {}",
                    key,
                    budget.unit,
                    pool.available(),
                    pool.limit(),
                    (budget.advice)(&self.facts, pool.available())
                ),
            )
        })
    }

    /// Makes a built set's share of its pool its real size. The light caches' estimate is of
    /// flat geometry; curved or folded surfaces (or a small cache angle) can make more, and a
    /// set beyond the per-set limit or what is left of the total is refused, its memory freed.
    fn hold_built(
        &self,
        entry: &PrecomputeEntry,
        key: &PrecomputeKey,
        units: u64,
    ) -> Result<(), String> {
        let Some(budget) = &entry.budget else {
            return Ok(());
        };
        let retry = format!("ask for fewer {} than {}", budget.unit, key);
        if let Some((per_set, flag)) = self.per_set_limit(budget.pool) {
            if units > per_set {
                return Err(format!(
                    "{units} {} were made, more than this server's limit of {per_set} per set \
                     ({flag}); {retry}",
                    budget.unit
                ));
            }
        }
        let mut held = true;
        self.update_variant(key, &mut |v| {
            held = v.held.as_mut().is_none_or(|h| h.resize(units));
        });
        if held {
            Ok(())
        } else {
            let (pool, flag) = self.pool(budget.pool).map_err(|e| e.body.message)?;
            Err(format!(
                "{units} {} were made, more than the {} left of this server's {} ({flag}); \
                 {retry}",
                budget.unit,
                pool.available(),
                pool.limit()
            ))
        }
    }

    fn update_variant(&self, key: &PrecomputeKey, f: &mut dyn FnMut(&mut Variant)) {
        if let Some(v) = lock(&self.variants).iter_mut().find(|v| v.key == *key) {
            f(v);
        }
    }

    /// Forgets precomputation `key`, cancelled because nobody waits for it (its units go back
    /// to the budget; a later request queues it afresh).
    fn drop_cancelled(&self, key: &PrecomputeKey) {
        tracing::info!(scene = %self.id, kind = key.kind, params = %key, "precomputation cancelled: nobody waits for it");
        lock(&self.variants).retain(|v| v.key != *key);
    }

    /// A claim on precomputation `key` of this scene, held by whoever waits for it.
    pub fn demand(&self, key: &PrecomputeKey) -> Demand {
        let mut demands = lock(&self.demands.0);
        let (holders, _) = demands
            .entry(key.clone())
            .or_insert_with(|| (0, Instant::now()));
        *holders += 1;
        Demand {
            demands: Arc::clone(&self.demands),
            key: key.clone(),
        }
    }

    /// Whether nobody has waited for `key` for `grace`.
    fn unwanted(&self, key: &PrecomputeKey, grace: Duration) -> bool {
        self.demands.unwanted(key, grace)
    }

    /// Whether the `caller` token may delete the scene: any caller where it has no owner.
    pub fn owned_by(&self, caller: Option<&str>) -> bool {
        owner_allows(self.owner.as_deref(), caller)
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

impl Drop for SceneRegistry {
    /// Ends the workers (a job running finishes first).
    fn drop(&mut self) {
        self.jobs.close();
    }
}

/// What people call precomputation `key` (`light caches`).
pub fn precompute_label(key: &PrecomputeKey) -> &'static str {
    precompute::entries()
        .find(|e| e.kind == key.kind)
        .map_or(key.kind, |e| e.label)
}

/// A frame's precomputation failed: the error names the request field that chose it (the
/// field sizing it, or the method), relative to the render object.
pub fn precompute_failed(scene: &SceneEntry, key: &PrecomputeKey, error: &str) -> ApiError {
    let field = precompute::entries()
        .find(|e| e.kind == key.kind)
        .and_then(|e| e.budget.as_ref())
        .map_or("method", |b| b.field);
    ApiError::field(
        format!("gi.{field}"),
        format!(
            "the {} of scene '{}' failed: {error}",
            precompute_label(key),
            scene.id
        ),
    )
}

/// A queued precomputation. The queue holds its scene weakly: a scene deleted, or a one-shot
/// render's upload whose request has ended, is skipped and its memory freed at once instead
/// of waiting in the queue.
struct Job {
    scene: Weak<SceneEntry>,
    key: PrecomputeKey,
    /// Its estimated seconds on 2 cores (`PrecomputeEntry::cost`).
    estimated: f64,
    queued: Instant,
}

/// Precomputations estimated at most this many seconds also run on a second worker, so that
/// a long build (a scene's surfel links, up to `--max-precompute-cost`) never holds up the
/// light caches and BVHs of every other scene and client.
const QUICK_JOB_SECONDS: f64 = 10.0;

/// The queue of precomputations and its two workers: the general one takes any job, the
/// quick one only jobs estimated at most [`QUICK_JOB_SECONDS`]. Each takes the job whose
/// estimate less its time waited is smallest: short jobs first, and a long one that has
/// waited as long as it will take goes before newer short ones.
#[derive(Default)]
struct JobQueue {
    jobs: Mutex<Vec<Job>>,
    changed: Condvar,
    closed: AtomicBool,
}

impl JobQueue {
    /// Queues `job` unless [`MAX_QUEUED_JOBS`] wait already.
    fn push(&self, job: Job) -> bool {
        let mut jobs = lock(&self.jobs);
        if jobs.len() >= MAX_QUEUED_JOBS {
            return false;
        }
        jobs.push(job);
        self.changed.notify_all();
        true
    }

    /// The next job estimated at most `max_seconds`, waiting for one; `None` once closed.
    fn next(&self, max_seconds: f64) -> Option<Job> {
        let mut jobs = lock(&self.jobs);
        loop {
            if self.closed.load(Ordering::Acquire) {
                return None;
            }
            let priority = |j: &Job| j.estimated - j.queued.elapsed().as_secs_f64();
            let best = jobs
                .iter()
                .enumerate()
                .filter(|(_, j)| j.estimated <= max_seconds)
                .min_by(|(_, a), (_, b)| priority(a).total_cmp(&priority(b)))
                .map(|(i, _)| i);
            if let Some(i) = best {
                return Some(jobs.swap_remove(i));
            }
            jobs = self
                .changed
                .wait(jobs)
                .unwrap_or_else(std::sync::PoisonError::into_inner);
        }
    }

    fn close(&self) {
        self.closed.store(true, Ordering::Release);
        let _guard = lock(&self.jobs);
        self.changed.notify_all();
    }
}

/// Whether `caller` may delete a scene whose owner digest is `owner` (`None`: anyone).
pub fn owner_allows(owner: Option<&str>, caller: Option<&str>) -> bool {
    owner.is_none_or(|digest| {
        caller.map(super::scene_store::owner_digest).as_deref() == Some(digest)
    })
}

/// Precomputations waiting at most; beyond them a request is refused for now.
const MAX_QUEUED_JOBS: usize = 32;

/// All scenes, plus the worker threads that run their GI methods' precomputations.
pub struct SceneRegistry {
    scenes: Mutex<BTreeMap<String, Arc<SceneEntry>>>,
    jobs: Arc<JobQueue>,
    max_scenes: usize,
    budget: Arc<MemoryBudget>,
    quotas: TokenQuotas,
}

impl SceneRegistry {
    /// Starts the precompute workers (two threads, see [`JobQueue`]; a precomputation may use
    /// rayon, and `gpu` where it can).
    pub fn new(store: Store, limits: &Limits, gpu: Option<GpuContext>) -> Arc<Self> {
        let grace = Duration::from_secs(limits.unwanted_precompute_secs);
        Self::with_workers(limits, Some(QUICK_JOB_SECONDS), move |entry, key| {
            precompute(&store, gpu.as_ref(), entry, key, grace)
        })
    }

    /// [`SceneRegistry::new`] with `work` run on a worker thread for each queued job, plus a
    /// second worker for jobs estimated at most `quick` seconds.
    fn with_workers(
        limits: &Limits,
        quick: Option<f64>,
        work: impl Fn(&Arc<SceneEntry>, &PrecomputeKey) + Send + Sync + 'static,
    ) -> Arc<Self> {
        let jobs = Arc::new(JobQueue::default());
        let work = Arc::new(work);
        let lanes = [("precompute", f64::INFINITY)]
            .into_iter()
            .chain(quick.map(|q| ("precompute-quick", q)));
        for (name, max_seconds) in lanes {
            let (jobs, work) = (Arc::clone(&jobs), Arc::clone(&work));
            std::thread::Builder::new()
                .name(name.into())
                .spawn(move || {
                    while let Some(job) = jobs.next(max_seconds) {
                        let Some(entry) = job.scene.upgrade() else {
                            continue;
                        };
                        let key = job.key;
                        // A bug in one scene's precomputation must not stop every later
                        // scene's.
                        let run = || work(&entry, &key);
                        if std::panic::catch_unwind(std::panic::AssertUnwindSafe(run)).is_err() {
                            tracing::error!(scene = %entry.id, kind = key.kind, "a precomputation panicked");
                            entry.update_variant(&key, &mut |v| {
                                v.fail(
                                    "the precomputation failed on an internal error (see the \
                                     server log)"
                                        .into(),
                                );
                            });
                        }
                    }
                })
                .expect("spawning a precompute thread");
        }
        Arc::new(Self {
            scenes: Mutex::new(BTreeMap::new()),
            jobs,
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
    /// token whose [`owner_digest`](super::scene_store::owner_digest) is `owner` when there is
    /// one, and queues the precomputation of its default light caches.
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
        // The default method's precomputation starts at once, so its first frame need not
        // wait for it.
        if let Ok(Some(key)) = entry.precompute_key(&GiParams::default()) {
            *lock(&entry.default_demand) = Some(entry.demand(&key));
            self.precomputed(&entry, &key);
        }
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
        if !entry.owned_by(caller) {
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
        scenes.remove(id);
        metrics::gauge!(super::metrics::SCENES).set(scenes.len() as f64);
        Ok(())
    }

    /// Drops scene `id` if no session uses it (it was deleted from the scene store by
    /// another replica); returns whether it was dropped.
    pub fn forget(&self, id: &str) -> bool {
        let mut scenes = lock(&self.scenes);
        let unused = scenes.get(id).is_some_and(|e| e.in_use() == 0);
        if unused {
            scenes.remove(id);
            metrics::gauge!(super::metrics::SCENES).set(scenes.len() as f64);
        }
        unused
    }

    /// The data of `scene`'s precomputation `key`, queueing it on first use.
    pub fn precomputed(&self, scene: &Arc<SceneEntry>, key: &PrecomputeKey) -> Now {
        let mut variants = lock(&scene.variants);
        if let Some(v) = variants.iter().find(|v| v.key == *key) {
            return match (&v.data, &v.error) {
                (Some(data), _) => Now::Ready(Arc::clone(data)),
                (None, Some(e)) => Now::Failed(e.clone()),
                (None, None) => Now::Pending,
            };
        }
        let Some(entry) = precompute::entries().find(|e| e.kind == key.kind) else {
            return Now::Failed(format!("no GI method precomputes '{}'", key.kind));
        };
        let held = match scene.reserve(entry, key) {
            Ok(held) => held,
            Err(e) => return Now::Failed(e.body.message),
        };
        let mut cost = crate::gi::cost::Cost::default();
        (entry.cost)(key, &scene.facts, &mut cost);
        let job = Job {
            scene: Arc::downgrade(scene),
            key: key.clone(),
            estimated: cost.seconds(1.0),
            queued: Instant::now(),
        };
        if !self.jobs.push(job) {
            return Now::Busy;
        }
        variants.push(Variant {
            key: key.clone(),
            entry,
            state: PrecomputeState::Queued,
            step: None,
            progress: None,
            seconds: None,
            from_store: None,
            error: None,
            units: None,
            data: None,
            held,
        });
        Now::Pending
    }
}

/// Runs on the precompute worker: loads or computes one precomputation and records the
/// outcome.
fn precompute(
    store: &Store,
    gpu: Option<&GpuContext>,
    scene: &Arc<SceneEntry>,
    key: &PrecomputeKey,
    grace: Duration,
) {
    let update = |f: &mut dyn FnMut(&mut Variant)| scene.update_variant(key, f);
    // Held by nobody but this worker (the scene was deleted and no request renders it any
    // more, or it was a one-shot render's upload whose request has ended), or nobody has
    // waited for it for `grace`: its session was deleted, its one-shot gave up.
    let cancelled = || Arc::strong_count(scene) == 1 || scene.unwanted(key, grace);
    let entry = match precompute::entries().find(|e| e.kind == key.kind) {
        Some(entry) if !cancelled() => entry,
        _ => {
            scene.drop_cancelled(key);
            return;
        }
    };
    update(&mut |v| v.state = PrecomputeState::Running);
    let started = Instant::now();
    let mut progress = |p: Progress| {
        update(&mut |v| {
            v.step = Some(p.step.to_string());
            v.progress = Some(if p.total == 0 {
                0.0
            } else {
                p.done as f32 / p.total as f32
            });
        })
    };
    let mut env = BuildEnv {
        store,
        progress: &mut progress,
        cancelled: &cancelled,
        gpu,
    };
    let result = (entry.build)(&scene.scene, key, &mut env).and_then(|built| {
        scene.hold_built(entry, key, built.units)?;
        Ok(built)
    });
    let seconds = started.elapsed().as_secs_f64();
    match result {
        Ok(built) => {
            tracing::info!(
                scene = %scene.id,
                kind = key.kind,
                units = built.units,
                seconds,
                from_store = built.from_store,
                "{} ready",
                entry.label
            );
            let mut data = Some(built.data);
            update(&mut |v| {
                v.state = PrecomputeState::Ready;
                v.step = None;
                v.progress = Some(1.0);
                v.seconds = Some(seconds);
                v.from_store = Some(built.from_store);
                v.units = Some(built.units);
                v.data = data.take();
            });
        }
        Err(_) if cancelled() => scene.drop_cancelled(key),
        Err(e) => {
            tracing::warn!(scene = %scene.id, kind = key.kind, "{} failed: {e}", entry.label);
            update(&mut |v| {
                v.seconds = Some(seconds);
                v.fail(e.clone());
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::lightskin::cache_key;
    use crate::gi::lightskin::caches::{min_distance_for, CacheParams};
    use crate::gi::lightskin::limits::{MAX_CACHES_PER_SET, MAX_TOTAL_CACHES};
    use crate::gi::limits::GiLimit;
    use crate::scene::procedural;
    use std::sync::mpsc;
    use std::time::Duration;

    fn limits(max_scenes: u32) -> Limits {
        Limits {
            max_scenes,
            ..crate::service::config::tests::default_limits()
        }
    }

    fn params(d_eps: f32) -> PrecomputeKey {
        cache_key(&CacheParams {
            d_eps,
            theta_eps_degrees: 30.0,
        })
    }

    /// The light caches a brsm frame asks for with `cache_distance`.
    fn key_for(entry: &SceneEntry, d_eps: f32) -> Result<Option<PrecomputeKey>, ApiError> {
        entry.precompute_key(&GiParams::default().with("cache_distance", Some(d_eps)))
    }

    fn state(entry: &SceneEntry, p: &PrecomputeKey) -> Option<PrecomputeState> {
        lock(&entry.variants)
            .iter()
            .find(|v| v.key == *p)
            .map(|v| v.state)
    }

    /// A worker that reports each job's scene id and then waits for a go-ahead.
    fn gated() -> (Arc<SceneRegistry>, mpsc::Receiver<String>, mpsc::Sender<()>) {
        let (seen_tx, seen) = mpsc::channel();
        let (go, go_rx) = mpsc::channel::<()>();
        let go_rx = Mutex::new(go_rx);
        let registry = SceneRegistry::with_workers(&limits(4), None, move |entry, _| {
            let _ = seen_tx.send(entry.id.clone());
            let _ = lock(&go_rx).recv();
        });
        (registry, seen, go)
    }

    const WAIT: Duration = Duration::from_secs(10);

    /// A registry under `limits` whose worker does nothing.
    fn idle(limits: &Limits) -> Arc<SceneRegistry> {
        SceneRegistry::with_workers(limits, None, |_, _| {})
    }

    /// `limits` with the GI limits `set`.
    fn with_gi(mut limits: Limits, set: &[(&GiLimit, u64)]) -> Limits {
        for (limit, value) in set {
            limits.gi.insert(limit.name.into(), (*value).into());
        }
        limits
    }

    /// The light caches held over every scene.
    fn caches_used(registry: &SceneRegistry) -> u64 {
        registry
            .budget()
            .gi_pool(&MAX_TOTAL_CACHES)
            .expect("a registered pool")
            .used()
    }

    #[test]
    fn cache_sets_beyond_the_budgets_are_refused_before_anything_is_built() {
        let registry = idle(&limits(4));
        let entry = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        let area = entry.facts.surface_area;
        // The smallest distance the format's own cap allows, which the server used to
        // suggest: about two million caches, far beyond one set's budget.
        let suggested = min_distance_for(area, crate::gi::lightskin::caches::MAX_CACHES) * 1.01;
        let e = key_for(&entry, suggested).expect_err("beyond --max-caches-per-set");
        assert_eq!(e.body.field.as_deref(), Some("gi.cache_distance"));
        assert!(
            e.body
                .message
                .contains("limit of 250000 per set (--max-caches-per-set)"),
            "{}",
            e.body.message
        );
        assert_eq!(caches_used(&registry), 0, "nothing taken");

        let tight = with_gi(
            limits(4),
            &[(&MAX_CACHES_PER_SET, 10_000), (&MAX_TOTAL_CACHES, 15_000)],
        );
        let registry = idle(&tight);
        let entry = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        let smallest = min_distance_for(area, 10_000);
        let p = key_for(&entry, smallest)
            .expect("10,000 fit")
            .expect("brsm needs light caches");
        assert!(key_for(&entry, smallest * 0.95).is_err());
        assert!(matches!(registry.precomputed(&entry, &p), Now::Pending));
        let taken = caches_used(&registry);
        assert!((9_000..=10_000).contains(&taken), "{taken}");
        let e = key_for(&entry, smallest * 1.1).expect_err("the total is spent");
        assert_eq!(e.body.field.as_deref(), Some("gi.cache_distance"));
        assert!(
            e.body.message.contains("(--max-total-caches)"),
            "{}",
            e.body.message
        );
        assert!(
            key_for(&entry, smallest).is_ok(),
            "the set that exists is not counted twice"
        );
        drop(entry);
        // The precompute worker may still hold the queued build's handle for a moment (it
        // did under the full suite's load): the reservation goes with the last one.
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
        while caches_used(&registry) != 0 && std::time::Instant::now() < deadline {
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        assert_eq!(caches_used(&registry), 0, "given back with the scene");
    }

    #[test]
    fn built_sets_hold_their_real_count_and_are_refused_beyond_the_per_set_limit() {
        let registry = idle(&with_gi(limits(4), &[(&MAX_CACHES_PER_SET, 10_000)]));
        let entry = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        let p = params(1.0);
        assert!(matches!(registry.precomputed(&entry, &p), Now::Pending));
        assert_eq!(
            entry.hold_built(&crate::gi::lightskin::PRECOMPUTE, &p, 7),
            Ok(())
        );
        assert_eq!(caches_used(&registry), 7);
        let e = entry
            .hold_built(&crate::gi::lightskin::PRECOMPUTE, &p, 10_001)
            .expect_err("over");
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
            registry.precomputed(&entry, &params(1.0)),
            Now::Pending
        ));
        assert_eq!(seen.recv_timeout(WAIT).as_deref(), Ok(entry.id.as_str()));
        // The worker holds the first job; the queue takes MAX_QUEUED_JOBS more.
        for k in 0..MAX_QUEUED_JOBS {
            let p = params(2.0 + k as f32);
            assert!(
                matches!(registry.precomputed(&entry, &p), Now::Pending),
                "job {k}"
            );
        }
        let refused = params(100.0);
        assert!(matches!(registry.precomputed(&entry, &refused), Now::Busy));
        assert_eq!(
            state(&entry, &refused),
            None,
            "a refused job leaves no variant"
        );
        go.send(()).expect("worker alive");
        assert!(seen.recv_timeout(WAIT).is_ok());
        assert!(matches!(
            registry.precomputed(&entry, &refused),
            Now::Pending
        ));
        drop(go);
    }

    #[test]
    fn the_queue_serves_short_jobs_first_and_a_long_one_once_it_has_waited_its_length() {
        let queue = JobQueue::default();
        let job = |estimated: f64, waited: f64| Job {
            scene: Weak::new(),
            key: params(estimated as f32),
            estimated,
            queued: Instant::now() - Duration::from_secs_f64(waited),
        };
        assert!(queue.push(job(500.0, 0.0)));
        assert!(queue.push(job(3.0, 0.0)));
        assert!(queue.push(job(20.0, 0.0)));
        let next = |max| queue.next(max).map(|j| j.estimated);
        assert_eq!(next(f64::INFINITY), Some(3.0));
        // The quick lane never takes a long job.
        assert!(queue.push(job(1.0, 0.0)));
        assert_eq!(next(QUICK_JOB_SECONDS), Some(1.0));
        assert_eq!(next(f64::INFINITY), Some(20.0));
        // A long job that has waited as long as it takes goes before a new short one.
        assert!(queue.push(job(600.0, 700.0)));
        assert!(queue.push(job(2.0, 0.0)));
        assert_eq!(next(f64::INFINITY), Some(600.0));
        queue.close();
        assert_eq!(next(f64::INFINITY), None, "closed");
    }

    #[test]
    fn a_long_precomputation_does_not_hold_up_short_ones() {
        let (started_tx, started) = mpsc::channel();
        let (release, release_rx) = mpsc::channel::<()>();
        let release_rx = Mutex::new(release_rx);
        let registry = SceneRegistry::with_workers(&limits(4), Some(QUICK_JOB_SECONDS), {
            move |_, key| {
                let _ = started_tx.send(key.kind);
                if key.kind == crate::gi::surfels::SURFEL_LINKS {
                    let _ = lock(&release_rx).recv();
                }
            }
        });
        let entry = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        let surfels = GiParams::new(crate::gi::surfels::SURFELS)
            .with("surfel_count", 262_144)
            .with("surfel_links", 16);
        let long = entry
            .precompute_key(&surfels)
            .expect("within the budgets")
            .expect("surfels precompute");
        let mut cost = crate::gi::cost::Cost::default();
        (crate::gi::surfels::PRECOMPUTE.cost)(&long, &entry.facts, &mut cost);
        assert!(cost.seconds(1.0) > QUICK_JOB_SECONDS, "{cost:?}");
        assert!(matches!(registry.precomputed(&entry, &long), Now::Pending));
        assert_eq!(
            started.recv_timeout(WAIT),
            Ok(crate::gi::surfels::SURFEL_LINKS)
        );
        // The general worker is busy with it; the light caches run on the quick one.
        assert!(matches!(
            registry.precomputed(&entry, &params(1.0)),
            Now::Pending
        ));
        assert_eq!(
            started.recv_timeout(WAIT),
            Ok(lightcast_protocol::LIGHT_CACHES)
        );
        drop(release);
    }

    #[test]
    fn jobs_of_scenes_gone_from_every_holder_are_skipped() {
        let (registry, seen, go) = gated();
        let kept = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        registry.precomputed(&kept, &params(1.0));
        assert_eq!(seen.recv_timeout(WAIT).as_deref(), Ok(kept.id.as_str()));
        let dropped = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        registry.precomputed(&dropped, &params(1.0));
        registry.precomputed(&kept, &params(2.0));
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
        let registry = SceneRegistry::with_workers(&limits(4), None, move |entry, p| {
            assert!(p != &params(1.0), "a bug in the precomputation");
            let _ = done_tx.send(entry.id.clone());
        });
        let entry = registry
            .detached(procedural::cornell_box(), 0.0)
            .expect("fits");
        registry.precomputed(&entry, &params(1.0));
        registry.precomputed(&entry, &params(2.0));
        // The jobs run cheapest first: the panic may come before or after the other job.
        match settled(&registry, &entry, &params(1.0)) {
            Now::Failed(e) => assert!(e.contains("internal error"), "{e}"),
            _ => panic!("the panicked variant must read as failed"),
        }
        assert_eq!(done.recv_timeout(WAIT).as_deref(), Ok(entry.id.as_str()));
        assert_eq!(state(&entry, &params(1.0)), Some(PrecomputeState::Failed));
        // The failed set gave its estimate back; the other still holds its own.
        let second = (crate::gi::lightskin::PRECOMPUTE.estimate)(&params(2.0), &entry.facts);
        assert_eq!(caches_used(&registry), second);
    }

    /// Waits until `key` of `entry` is ready or failed.
    fn settled(registry: &SceneRegistry, entry: &Arc<SceneEntry>, key: &PrecomputeKey) -> Now {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            match registry.precomputed(entry, key) {
                Now::Pending | Now::Busy if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(10))
                }
                now => return now,
            }
        }
    }

    #[test]
    fn the_bvh_is_built_on_the_worker_and_listed_with_the_light_caches() {
        let store = tempfile::tempdir().expect("temp dir");
        let registry = SceneRegistry::new(Store::new(store.path()), &limits(4), None);
        let entry = registry
            .insert(procedural::cornell_box(), "t".into(), None, 0.0, None)
            .expect("fits");
        let reference = GiParams::new(crate::gi::reference::REFERENCE);
        let bvh = entry
            .precompute_key(&reference)
            .expect("valid")
            .expect("the reference needs its BVH");
        assert_eq!(bvh.kind, "bvh");
        let none = GiParams::new(crate::gi::none::NONE);
        assert_eq!(entry.precompute_key(&none).expect("valid"), None);
        let Now::Ready(data) = settled(&registry, &entry, &bvh) else {
            panic!("the BVH must build");
        };
        let built = data
            .downcast_ref::<crate::gi::common::bvh::SceneBvh>()
            .expect("a BVH");
        assert_eq!(
            built.triangles.len(),
            entry.scene.triangle_count(),
            "every triangle in the BVH"
        );
        let caches = key_for(&entry, 0.37).expect("fits").expect("brsm");
        assert!(matches!(settled(&registry, &entry, &caches), Now::Ready(_)));
        let info = entry.info();
        let kinds: Vec<_> = info.precomputed.iter().map(|p| p.kind.as_str()).collect();
        // The default light caches are queued when the scene is added, before anything asks.
        assert_eq!(kinds, ["light_caches", "bvh", "light_caches"], "{kinds:?}");
        let bvh_info = &info.precomputed[1];
        assert_eq!(bvh_info.state, PrecomputeState::Ready);
        assert_eq!(bvh_info.progress, Some(1.0));
        assert!(bvh_info.params.is_empty());
        // The BVH holds a copy of every triangle: counted against the triangle budget again.
        let triangles = entry.scene.triangle_count() as u64;
        assert_eq!(bvh_info.units, Some(triangles));
        assert_eq!(bvh_info.unit.as_deref(), Some("triangles"));
        assert_eq!(registry.budget().triangles.used(), 2 * triangles);
        assert_eq!(info.caches.len(), 2, "only light caches in the old list");
        assert_eq!(info.caches[1].cache_distance, 0.37);
        assert_eq!(info.caches[1].caches, info.precomputed[2].units);
        assert!(info.caches[1].caches.is_some_and(|n| n > 0));
    }
}
