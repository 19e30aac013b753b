//! Scenes the server holds: loaded once, shared by every session, with their GI methods'
//! precomputations (light caches, BVH; see `gi::precompute`) built in the background, one
//! set per kind and distinct parameters in use.
//!
//! The types are declared here; their behaviour is in one file per job: `registry` (the held
//! scenes: loading, leasing, listing, deleting, queueing precomputations), `entry` (one scene
//! and the state machine of its precomputations with their budgets and demands) and `worker`
//! (the job queue and the build of one set).

use super::budget::{over_budget, Held, MemoryBudget, Pool, Quota, TokenQuotas};
use super::error::ApiError;
use super::ids;
use super::sync::lock;
use crate::gi::precompute::{
    self, BudgetPool, BuildEnv, PrecomputeEntry, PrecomputeKey, Progress, SceneData, SceneFacts,
    Store, UnitBudget,
};
use crate::gpu::GpuContext;
use crate::passes::frame_uniforms::MAX_LIGHTS;
use crate::scene::default_light::{
    default_camera, default_light, default_lights, emitter_stand_in,
};
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

mod entry;
mod registry;
#[cfg(test)]
mod tests;
mod worker;

pub use entry::{precompute_failed, precompute_label, texture_bytes, triangles_over_budget};
pub use registry::owner_allows;

/// Most parameter sets of one precomputation kept per scene.
pub const MAX_VARIANTS: usize = 8;

/// Who waits for each precomputation of a scene: the holders of its [`Demand`]s and when the
/// last of them let go.
#[derive(Default)]
struct Demands(Mutex<HashMap<PrecomputeKey, (usize, Instant)>>);

/// A session's or a waiting request's claim on a precomputation of a scene: while one is
/// held (and for `--unwanted-precompute-secs` after the last is dropped: a one-shot render
/// answered 503 while it builds is retried by its client, a reloaded viewer asks again) the
/// build goes on.
pub struct Demand {
    demands: Arc<Demands>,
    key: PrecomputeKey,
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
    /// [`default_lights`] up to the most a frame holds; a server with a lower `max_lights`
    /// takes the first of them.
    pub default_lights: Vec<Light>,
    /// The default light when it stands in for the scene's emissive surfaces
    /// ([`emitter_stand_in`]): `render.gi.emitters` `null` turns them off under it.
    pub emitter_stand_in: Option<Light>,
    /// Summed once: checking a request's precomputation parameters against them happens per
    /// message.
    pub facts: SceneFacts,
    /// `SceneInfo::nodes` and `animations`, worked out once (a node's bounds sum its
    /// subtree's vertices).
    nodes: Vec<lightcast_protocol::NodeInfo>,
    animations: Vec<lightcast_protocol::AnimationInfo>,
    /// Each node's subtree bounds at rest (`Scene::node_bounds`), which poses are checked
    /// against.
    pub node_bounds: Vec<Option<crate::scene::Aabb>>,
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

/// A session's hold on a scene: while it lives the scene cannot be deleted.
pub struct SceneLease(pub Arc<SceneEntry>);

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

/// Precomputations waiting at most; beyond them a request is refused for now.
const MAX_QUEUED_JOBS: usize = 32;

/// All scenes, plus the worker threads that run their GI methods' precomputations.
pub struct SceneRegistry {
    scenes: Mutex<BTreeMap<String, Arc<SceneEntry>>>,
    jobs: Arc<JobQueue>,
    /// The worker threads, joined by [`SceneRegistry::stop_workers`].
    workers: Mutex<Vec<std::thread::JoinHandle<()>>>,
    max_scenes: usize,
    /// A scene's default lights are its first this many (`--max-lights`).
    max_lights: usize,
    budget: Arc<MemoryBudget>,
    quotas: TokenQuotas,
}
