//! The render loop: the one thread that owns the GPU. Each turn it serves the next due session
//! (round robin, paced to each session's fps cap) or a queued one-shot render, then hands the
//! frame to the encoder pool; encoded frames land in the session's latest-frame slot.

use super::encode::{self, EncodePool};
use super::error::ApiError;
use super::params::{render_error, Resolved};
use super::scenes::{precompute_failed, precompute_label, Now, SceneEntry, SceneRegistry};
use super::sessions::{unix_us, FramePlan, Session, SessionRegistry};
use super::video::VideoConfig;
use crate::debug_views::{self, Image};
use crate::gi::common::params::{BOUNCES, GLOSSY_EXPONENT, SENDERS};
use crate::gi::precompute::{PrecomputeKey, SceneData};
use crate::gi::reference::params::SPP;
use crate::gpu::timing::{StageTiming, TimingSource};
use crate::gpu::GpuContext;
use crate::passes::yuv420::Yuv420;
use crate::quality::Truth;
use crate::renderer::{Frame, FrameProgress, PendingFrame, Picked, Renderer, VisibilityBuffer};
use lightcast_protocol::frame::{FLAG_GI_PENDING, FLAG_KEYFRAME, FLAG_MOVING, FLAG_STILL};
use lightcast_protocol::{Comparison, FrameHeader, GiMethod, Senders, ServerEvent, StageMs, View};
use std::collections::{HashMap, VecDeque};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};
use tokio::sync::oneshot;

/// Renderers kept at once (one per scene and light-cache set in use). As many as the default
/// `--max-scenes`, so that one viewer per scene does not make them rebuild in turn (each
/// rebuild uploads its scene again).
const MAX_RENDERERS: usize = 16;
/// A renderer unused this long is dropped even under the limit: its scene buffers, targets,
/// shadow maps and sampling buffers hold GPU memory nobody is watching.
const RENDERER_IDLE: Duration = Duration::from_secs(60);
/// Longest sleep when nothing is due, so new work is noticed even without a wake-up.
const IDLE_WAIT: Duration = Duration::from_millis(50);
/// Comparison renders (see `RenderRequest::compare_to`) kept for repeated comparisons: at most
/// this many bytes of their indirect light (12 bytes per pixel: 100 MB for the largest default
/// frame, 3840×2160, so two of those fit), the newest always kept.
const COMPARISON_CACHE_BYTES: usize = 256 << 20;

/// A frame that took longer than this from reaching the readback thread to being handed on
/// is heavy: the next is not submitted behind it (see [`InFlight`]).
const HEAVY_FRAME: Duration = Duration::from_millis(100);

/// The jobs handed to the readback thread and not yet handed on (a session's frame, or a
/// one-shot render with the frames it is compared with), and whether the last one was heavy.
/// Up to `depth` are in flight (`--frames-in-flight`): while the readback thread waits for one
/// frame and the GPU renders the next, the loop encodes and submits a third, so the GPU finds
/// the next session's work queued when it finishes a frame (issue 36; two, one read back while
/// the next renders, on CPU adapters, where deeper queues only made frames wait longer).
/// Behind a heavy frame (lavapipe's take up to `--max-frame-cost`) a frame queued only makes
/// whatever comes next wait for both: a session's first frame of a new method, a newcomer's
/// tiny render after a stream ended (issue 31: 1.3 s after an 800×450 stream, with two in
/// flight). So after a heavy frame the loop submits the next only once the readback thread is
/// idle, and nothing waits behind work it no longer needs; while the heavy frame is still in
/// flight (not yet known to be heavy) up to `depth - 1` may queue behind it.
struct InFlight {
    state: std::sync::Mutex<Queue>,
    idle: std::sync::Condvar,
    depth: usize,
}

#[derive(Default)]
struct Queue {
    jobs: usize,
    /// The last job handed on was heavy.
    heavy: bool,
    /// The readback thread has ended (it panicked, or the loop is stopping): nothing in flight
    /// will be handed on, and the loop must not wait for it.
    stopped: bool,
}

/// Marks the readback thread's end however it ends (`InFlight::stopped`).
struct StopOnDrop<'a>(&'a InFlight);

impl Drop for StopOnDrop<'_> {
    fn drop(&mut self) {
        self.0.lock().stopped = true;
        self.0.idle.notify_all();
    }
}

impl InFlight {
    fn new(depth: usize) -> Self {
        Self {
            state: Default::default(),
            idle: Default::default(),
            depth: depth.max(1),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Queue> {
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn sent(&self) {
        self.lock().jobs += 1;
    }

    /// A job was handed on after `took` on the readback thread.
    fn done(&self, took: Duration) {
        let mut state = self.lock();
        state.jobs = state.jobs.saturating_sub(1);
        state.heavy = took > HEAVY_FRAME;
        self.idle.notify_all();
    }

    /// Returns once the next frame may be submitted: when fewer than `depth` jobs are in
    /// flight after a light frame, when none is after a heavy one; at once when the readback
    /// thread has ended (handing the frame over then fails, and its session is told).
    fn wait_turn(&self) {
        let mut state = self.lock();
        while !state.stopped && state.jobs >= if state.heavy { 1 } else { self.depth } {
            state = self
                .idle
                .wait(state)
                .unwrap_or_else(std::sync::PoisonError::into_inner);
        }
    }
}

/// A one-shot render: the frame, read back and handed over unencoded.
pub struct OneShot {
    pub scene: Arc<SceneEntry>,
    pub resolved: Resolved,
    pub reply: oneshot::Sender<Result<OneShotResult, ApiError>>,
    pub queued: Instant,
    /// Render the same view with another method too, and compare.
    pub compare: Option<CompareWith>,
    /// Samples per submission of the request's path-traced renders (its own frame with the
    /// `reference`, its comparison): a longer one is accumulated over several turns of the
    /// loop, the sessions due served between them, and stops when nobody waits any more.
    pub chunk_spp: Option<u32>,
    chunks: Chunks,
}

impl OneShot {
    pub fn new(
        scene: Arc<SceneEntry>,
        resolved: Resolved,
        reply: oneshot::Sender<Result<OneShotResult, ApiError>>,
        compare: Option<CompareWith>,
        chunk_spp: Option<u32>,
    ) -> Self {
        Self {
            scene,
            resolved,
            reply,
            queued: Instant::now(),
            compare,
            chunk_spp,
            chunks: Chunks::default(),
        }
    }
}

/// What a one-shot is compared with: `method` (the reference) with `spp` samples, of the full
/// light transport and, when `modelled` names one, also of the transport the compared method
/// models (`RenderRequest::compare_modelled`).
#[derive(Clone, Copy, Debug)]
pub struct CompareWith {
    pub method: GiMethod,
    pub spp: u32,
    pub modelled: Option<Senders>,
}

impl CompareWith {
    /// The comparison renders, in the order they are rendered and reported: the full one
    /// first.
    fn transports(&self) -> impl Iterator<Item = Senders> {
        std::iter::once(Senders::Full).chain(self.modelled)
    }
}

/// At most this many comparison renders per one-shot (the full reference and the modelled).
const MAX_COMPARANDS: usize = 2;

/// How far a chunked one-shot is: samples accumulated ahead of its final submission (in image
/// histories of its own), and the chunk still on the GPU.
#[derive(Default)]
struct Chunks {
    /// How long it waited for its first turn.
    queue_ms: Option<f64>,
    /// Its own image's history, then its comparisons' (one each, in `transports` order).
    histories: Option<(u64, [u64; MAX_COMPARANDS])>,
    own: u32,
    /// Samples accumulated per comparison render.
    compared: [u32; MAX_COMPARANDS],
    in_flight: Option<PendingFrame>,
}

impl Chunks {
    /// Samples accumulated ahead of the final submission, over every image.
    fn samples(&self) -> u32 {
        self.own + self.compared.iter().sum::<u32>()
    }
}

/// Image histories of chunked one-shots: one per image a request accumulates (its own and
/// each comparison's), apart from the sessions' (a hash of their ids) by their top bit.
static NEXT_ONE_SHOT_HISTORY: std::sync::atomic::AtomicU64 =
    std::sync::atomic::AtomicU64::new(1 << 63);

/// A rendered frame: the image of the requested view plus what was measured.
pub struct Rendered {
    /// The view's image (empty pixels when `yuv420` holds the frame instead).
    pub image: Image,
    /// The final view as Y'CbCr 4:2:0, converted on the GPU for a video stream.
    pub yuv420: Option<Yuv420>,
    pub timings: Vec<StageTiming>,
    pub timing_source: TimingSource,
    pub readback_ms: f64,
    pub exposure_scale: f32,
    /// Linear HDR radiance and indirect light, when the settings asked to capture them.
    pub hdr: Option<Vec<[f32; 4]>>,
    pub indirect: Option<Vec<[f32; 4]>>,
    /// GI was requested but the light caches are still being computed (direct light only).
    pub gi_pending: bool,
    /// Convergence of a progressive GI method (`reference`).
    pub progress: Option<FrameProgress>,
    /// What the settings' `pick` texel shows.
    pub pick: Option<Picked>,
}

impl Rendered {
    pub fn gpu_ms(&self) -> f64 {
        self.timings.iter().map(|t| t.ms).sum()
    }

    /// The stage times in the protocol's form.
    pub fn stages(&self) -> Vec<StageMs> {
        self.timings
            .iter()
            .map(|t| StageMs {
                stage: t.stage.to_string(),
                ms: t.ms,
                reused: t.reused,
                shared_by: u32::from(t.shared_by),
            })
            .collect()
    }
}

/// What a one-shot render returns to its HTTP handler.
pub struct OneShotResult {
    pub rendered: Rendered,
    pub queue_ms: f64,
    /// Against the full reference, then (if asked) the modelled transport's.
    pub comparisons: Vec<Comparison>,
}

pub enum Command {
    Render(Box<OneShot>),
    /// Something changed (a session was created or steered): look again now.
    Wake,
    Stop,
}

fn record_metrics(frame: &Frame) {
    // A reused stage did no work: its 0 ms would drag the stage's quantiles down.
    for t in frame.timings.iter().filter(|t| !t.reused) {
        super::metrics::record_stage(t.stage.name(), t.ms);
    }
    use super::metrics::{
        record_duration, GPU_FRAME_MS, GPU_FRAME_SECONDS, READBACK_MS, READBACK_SECONDS,
    };
    record_duration(GPU_FRAME_SECONDS, GPU_FRAME_MS, frame.total_ms());
    record_duration(READBACK_SECONDS, READBACK_MS, frame.readback_ms);
}

/// A scene's renderer, one more for each parameter set of a precomputation that has them
/// (see `PrecomputeKey::has_variants`).
type RendererKey = (String, Option<PrecomputeKey>);

/// The renderers to drop, given when each was last used: those idle for [`RENDERER_IDLE`],
/// then the least recently used beyond [`MAX_RENDERERS`].
fn evictions<K>(mut used: Vec<(K, Instant)>, now: Instant) -> Vec<K> {
    used.sort_by_key(|(_, at)| std::cmp::Reverse(*at));
    let mut drop = Vec::new();
    for (rank, (key, at)) in used.into_iter().enumerate() {
        if rank >= MAX_RENDERERS || now.duration_since(at) >= RENDERER_IDLE {
            drop.push(key);
        }
    }
    drop
}

struct Slot {
    renderer: Renderer,
    /// The precomputations whose data the renderer's methods hold.
    applied: Vec<PrecomputeKey>,
    last_used: Instant,
}

struct Loop {
    ctx: GpuContext,
    scenes: Arc<SceneRegistry>,
    sessions: Arc<SessionRegistry>,
    renderers: HashMap<RendererKey, Slot>,
    one_shots: VecDeque<Box<OneShot>>,
    /// Index into the session list where the next round-robin search starts.
    next_session: usize,
    /// Alternates one-shot renders with sessions so neither starves the other.
    one_shot_turn: bool,
    /// Session frames waiting for the GPU, to the readback thread.
    readback: mpsc::SyncSender<ReadbackJob>,
    in_flight: Arc<InFlight>,
    /// Comparison renders by a hash of what they rendered (filled by the readback thread).
    comparisons: Arc<ComparisonCache>,
    options: LoopOptions,
}

/// How the render loop renders and queues frames (`serve`'s flags).
#[derive(Clone, Copy, Debug)]
pub struct LoopOptions {
    /// Renderers reuse the camera-independent passes' targets (`passes::reuse`) and share
    /// light-side stages between sessions (`--no-pass-reuse` turns it off).
    pub reuse: bool,
    /// Frames submitted and not yet read back at once (`--frames-in-flight`, see [`InFlight`]).
    pub frames_in_flight: usize,
    /// The G-buffer and the RSM as visibility buffers (`--visibility-buffer`).
    pub visibility_buffer: VisibilityBuffer,
}

/// Starts the render loop thread.
pub fn spawn(
    ctx: GpuContext,
    scenes: Arc<SceneRegistry>,
    sessions: Arc<SessionRegistry>,
    encoder: Arc<EncodePool>,
    options: LoopOptions,
) -> (mpsc::Sender<Command>, std::thread::JoinHandle<()>) {
    let (tx, rx) = mpsc::channel();
    // `InFlight` bounds the frames submitted and not read back; the channel holds those
    // waiting behind the one being read back, so handing one over never blocks the loop.
    let in_flight = Arc::new(InFlight::new(options.frames_in_flight));
    let (readback, readback_rx) = mpsc::sync_channel(in_flight.depth);
    let finished = Arc::clone(&in_flight);
    let readback_thread = std::thread::Builder::new()
        .name("readback".into())
        .spawn(move || readback_thread(readback_rx, encoder, &finished))
        .expect("spawning the readback thread");
    let handle = std::thread::Builder::new()
        .name("render-loop".into())
        .spawn(move || {
            let mut l = Loop {
                readback,
                in_flight,
                ctx,
                scenes,
                sessions,
                renderers: HashMap::new(),
                one_shots: VecDeque::new(),
                next_session: 0,
                one_shot_turn: false,
                comparisons: Arc::new(ComparisonCache::default()),
                options,
            };
            l.run(&rx);
            // Closing the channel lets the readback thread finish the frames in flight.
            drop(l);
            let _ = readback_thread.join();
        })
        .expect("spawning the render loop thread");
    (tx, handle)
}

impl Loop {
    fn run(&mut self, rx: &mpsc::Receiver<Command>) {
        loop {
            loop {
                match rx.try_recv() {
                    Ok(Command::Render(job)) => self.one_shots.push_back(job),
                    Ok(Command::Wake) => {}
                    Ok(Command::Stop) | Err(mpsc::TryRecvError::Disconnected) => return,
                    Err(mpsc::TryRecvError::Empty) => break,
                }
            }
            self.prune();
            let wait = match self.turn() {
                None => continue,
                Some(wait) => wait,
            };
            match rx.recv_timeout(wait.min(IDLE_WAIT)) {
                Ok(Command::Render(job)) => self.one_shots.push_back(job),
                Ok(Command::Wake) | Err(mpsc::RecvTimeoutError::Timeout) => {}
                Ok(Command::Stop) | Err(mpsc::RecvTimeoutError::Disconnected) => return,
            }
        }
    }

    /// Serves one session or one-shot. `None` when it did work; else how long until
    /// something is due.
    fn turn(&mut self) -> Option<Duration> {
        self.one_shot_turn = !self.one_shot_turn;
        if self.one_shot_turn {
            if let Some(job) = self.one_shots.pop_front() {
                self.one_shot(*job);
                return None;
            }
        }
        let sessions = self.sessions.all();
        let now = Instant::now();
        let mut wait = IDLE_WAIT;
        for i in 0..sessions.len() {
            let index = (self.next_session + i) % sessions.len();
            match sessions[index].plan(now) {
                Ok(plan) => {
                    self.next_session = index + 1;
                    self.session_frame(&sessions[index], plan);
                    return None;
                }
                Err(Some(w)) => wait = wait.min(w),
                Err(None) => {}
            }
        }
        if let Some(job) = self.one_shots.pop_front() {
            self.one_shot(*job);
            return None;
        }
        Some(wait)
    }

    /// Drops renderers of deleted scenes, idle ones, and the least recently used beyond the
    /// limit.
    fn prune(&mut self) {
        let scenes = &self.scenes;
        self.renderers.retain(|(id, _), _| scenes.contains(id));
        let used: Vec<(RendererKey, Instant)> = self
            .renderers
            .iter()
            .map(|(k, s)| (k.clone(), s.last_used))
            .collect();
        for key in evictions(used, Instant::now()) {
            self.renderers.remove(&key);
        }
    }

    /// Submits `resolved` of `scene` to the GPU; GI falls back to none while its caches are
    /// pending.
    fn submit(
        &mut self,
        scene: &Arc<SceneEntry>,
        resolved: &Resolved,
    ) -> Result<Submitted, ApiError> {
        let ready = Instant::now();
        self.in_flight.wait_turn();
        let mut settings = resolved.settings.clone();
        let (data, gi_pending) = match &resolved.precompute {
            None => (None, false),
            Some(key) => match self.scenes.precomputed(scene, key) {
                Now::Ready(data) => (Some((key, data)), false),
                Now::Pending | Now::Busy => (None, true),
                Now::Failed(e) => return Err(precompute_failed(scene, key, &e).within("render")),
            },
        };
        if gi_pending {
            settings.gi.method = crate::gi::none::NONE;
        }
        let view = if gi_pending {
            View::FINAL
        } else {
            resolved.view
        };
        // Debug views are composed on the CPU from RGBA; only the final view goes to video
        // as planes converted on the GPU.
        settings.yuv420 &= view == View::FINAL;
        let renderer_key = (
            scene.id.clone(),
            data.as_ref()
                .map(|(key, _)| *key)
                .filter(|key| key.has_variants())
                .cloned(),
        );
        let options = self.options;
        let slot = self.renderers.entry(renderer_key).or_insert_with(|| {
            let mut renderer = Renderer::new(self.ctx.clone(), Arc::clone(&scene.scene));
            renderer.set_reuse(options.reuse);
            // `on` was checked against the adapter at start; a scene too large for the
            // resolve's storage bindings keeps the rasterised targets.
            if let Err(e) = renderer.choose_visibility_buffer(options.visibility_buffer) {
                tracing::warn!(scene = %scene.id, "{e}; rasterising every target");
            }
            Slot {
                renderer,
                applied: Vec::new(),
                last_used: Instant::now(),
            }
        });
        slot.last_used = Instant::now();
        if let Some((key, data)) = &data {
            if !slot.applied.contains(key) {
                slot.renderer
                    .set_scene_data(settings.gi.method, data)
                    .map_err(|e| render_error(&e).within("render"))?;
                slot.applied.push((*key).clone());
            }
        }
        let pending = slot
            .renderer
            .submit(&settings)
            .map_err(|e| render_error(&e).within("render"))?;
        Ok(Submitted {
            pending,
            queued: Queued {
                ready,
                submitted: Instant::now(),
            },
            view,
            gi_pending,
            camera: settings.camera,
            data: data.map(|(_, data)| data),
        })
    }

    /// Submits a one-shot render (and the render it is compared with, unless cached); the
    /// readback thread waits for them and replies. A chunked one (see [`OneShot::chunk_spp`])
    /// first submits one chunk of its path tracing per call and goes back to the front of the
    /// queue.
    fn one_shot(&mut self, mut job: OneShot) {
        if job.reply.is_closed() {
            // Nobody waits for it any more (its request timed out or was dropped): it stops
            // here, between chunks, and its accumulations go back to the tracer's pool.
            if job.chunks.histories.is_some() {
                metrics::counter!(super::metrics::RENDERS_ABANDONED).increment(1);
                tracing::info!(
                    scene = %job.scene.id,
                    samples = job.chunks.samples(),
                    "one-shot render stopped between chunks: nobody waits for it any more"
                );
            }
            return;
        }
        let queue_ms = *job
            .chunks
            .queue_ms
            .get_or_insert_with(|| job.queued.elapsed().as_secs_f64() * 1e3);
        match self.next_chunk(&mut job) {
            Some(Ok(())) => {
                self.one_shots.push_front(Box::new(job));
                return;
            }
            Some(Err(e)) => {
                let _ = job.reply.send(Err(e));
                return;
            }
            None => {}
        }
        if let Some(previous) = job.chunks.in_flight.take() {
            if let Err(e) = previous.wait_submitted() {
                let _ = job.reply.send(Err(ApiError::internal(e.to_string())));
                return;
            }
        }
        metrics::counter!(super::metrics::RENDERS).increment(1);
        let compare: Result<Vec<Comparand>, ApiError> = match job.compare {
            None => Ok(Vec::new()),
            Some(with) => with
                .transports()
                .enumerate()
                .map(|(i, senders)| self.comparison(&job, with, i, senders))
                .collect(),
        };
        let (mut resolved, expected) = self.own_settings(&job);
        resolved.settings.capture_hdr |= compare.as_ref().is_ok_and(|c| !c.is_empty());
        let submitted = compare.and_then(|c| Ok((c, self.submit(&job.scene, &resolved)?)));
        let (compare, submitted) = match submitted {
            Ok(s) => s,
            Err(e) => {
                let _ = job.reply.send(Err(e));
                return;
            }
        };
        let readback = ReadbackJob {
            frame: FrameJob::from_submitted(submitted, Arc::clone(&job.scene)),
            target: Destination::OneShot {
                reply: job.reply,
                queue_ms,
                compare,
                expected,
            },
        };
        self.hand_over(readback);
    }

    /// The own frame's final settings (its samples after those its chunks accumulated), and
    /// the samples per pixel its image must then hold (`None`: not chunked).
    fn own_settings(&self, job: &OneShot) -> (Resolved, Option<u32>) {
        let mut resolved = job.resolved.clone();
        let spp = SPP.u32(&resolved.settings.gi);
        let traced = resolved.settings.gi.method == crate::gi::reference::REFERENCE;
        match job.chunks.histories {
            Some((own, _)) if traced => {
                resolved.settings.history = Some(own);
                resolved
                    .settings
                    .gi
                    .set(SPP.name, spp.saturating_sub(job.chunks.own).max(1));
                (resolved, Some(spp))
            }
            _ => (resolved, None),
        }
    }

    /// Submits the next chunk of a chunked one-shot's path tracing, if more than its final
    /// submission is left: its comparison's first, then its own frame's. `None` when the
    /// final submission is next.
    fn next_chunk(&mut self, job: &mut OneShot) -> Option<Result<(), ApiError>> {
        let step = job.chunk_spp?;
        let own_total = if job.resolved.settings.gi.method == crate::gi::reference::REFERENCE {
            SPP.u32(&job.resolved.settings.gi)
        } else {
            0
        };
        // The first comparison render with more than its last chunk left (the last chunk of
        // each is left to the final submission, which reads them back).
        let mut compare_next = None;
        if let Some(with) = job.compare {
            for (i, senders) in with.transports().enumerate() {
                let total = match self.truth(job, with, senders) {
                    Ok((_, key)) if self.comparisons.contains(key) => 0,
                    Ok(_) => with.spp,
                    Err(e) => return Some(Err(e)),
                };
                if job.chunks.compared[i] + step < total {
                    compare_next = Some((i, senders));
                    break;
                }
            }
        }
        if compare_next.is_none() && job.chunks.own + step >= own_total {
            return None;
        }
        let (own_history, compare_histories) = *job.chunks.histories.get_or_insert_with(|| {
            let first = NEXT_ONE_SHOT_HISTORY.fetch_add(
                1 + MAX_COMPARANDS as u64,
                std::sync::atomic::Ordering::Relaxed,
            );
            (first, std::array::from_fn(|i| first + 1 + i as u64))
        });
        // One chunk at a time on the GPU: the sessions' frames submitted since the last one
        // run before the next.
        if let Some(previous) = job.chunks.in_flight.take() {
            if let Err(e) = previous.wait_submitted() {
                return Some(Err(ApiError::internal(e.to_string())));
            }
        }
        let mut resolved = match (compare_next, job.compare) {
            (Some((_, senders)), Some(with)) => match self.truth(job, with, senders) {
                Ok((truth, _)) => truth,
                Err(e) => return Some(Err(e)),
            },
            _ => job.resolved.clone(),
        };
        resolved.settings.history = Some(match compare_next {
            Some((i, _)) => compare_histories[i],
            None => own_history,
        });
        resolved.settings.gi.set(SPP.name, step);
        resolved.settings.capture_hdr = false;
        let submitted = match self.submit(&job.scene, &resolved) {
            Ok(s) => s,
            Err(e) => return Some(Err(e)),
        };
        job.chunks.in_flight = Some(submitted.pending);
        match compare_next {
            Some((i, _)) => job.chunks.compared[i] += step,
            None => job.chunks.own += step,
        }
        Some(Ok(()))
    }

    /// The settings of a render a one-shot is compared with (`with`'s method and samples at
    /// the same view, reflecting direct light on as `senders` says), and their key in the
    /// comparison cache.
    fn truth(
        &self,
        job: &OneShot,
        with: CompareWith,
        senders: Senders,
    ) -> Result<(Resolved, u64), ApiError> {
        let CompareWith { method, spp, .. } = with;
        let mut truth = job.resolved.clone();
        let asked = &job.resolved.settings.gi;
        // Only what the comparison method reads, so that comparisons of one view at several
        // BRSM settings share one cached reference render (the key hashes these settings).
        let mut gi = lightcast_protocol::GiParams::new(method)
            .with("spp", spp)
            .with("bounces", BOUNCES.u32(asked))
            .with("emitters", crate::gi::reference_emitters(asked))
            .with(SENDERS.name, senders.name());
        if let Some(k) = asked.get(GLOSSY_EXPONENT.name) {
            gi.set(GLOSSY_EXPONENT.name, k.clone());
        }
        truth.settings.gi = gi;
        truth.settings.capture_hdr = true;
        truth.settings.history = None;
        truth.settings.debug_view = View::FINAL;
        truth.view = View::FINAL;
        truth.precompute = job
            .scene
            .precompute_key(&lightcast_protocol::GiParams::new(method))?;
        let key = {
            use std::hash::{Hash, Hasher};
            let mut h = std::collections::hash_map::DefaultHasher::new();
            // The parameters as the reference reads them, so `80` and `80.0` share a render.
            let mut settings = truth.settings.clone();
            settings.gi = crate::gi::params::resolved(&settings.gi);
            (&job.scene.id, format!("{settings:?}")).hash(&mut h);
            h.finish()
        };
        Ok((truth, key))
    }

    /// The `index`th frame a one-shot render is compared with (see [`Self::truth`]), from the
    /// cache or submitted now (after the samples its chunks accumulated).
    fn comparison(
        &mut self,
        job: &OneShot,
        with: CompareWith,
        index: usize,
        senders: Senders,
    ) -> Result<Comparand, ApiError> {
        let CompareWith { method, spp, .. } = with;
        let (mut truth, key) = self.truth(job, with, senders)?;
        // The HTTP handler waited for it; a comparison never falls back to direct light.
        if let Some(needed) = &truth.precompute {
            if !matches!(self.scenes.precomputed(&job.scene, needed), Now::Ready(_)) {
                return Err(ApiError::unavailable(format!(
                    "still computing the {} of this scene; try again shortly",
                    precompute_label(needed)
                )));
            }
        }
        let mut expected = None;
        let compared = job.chunks.compared[index];
        if let Some((_, histories)) = job.chunks.histories.filter(|_| compared > 0) {
            truth.settings.history = Some(histories[index]);
            truth
                .settings
                .gi
                .set(SPP.name, spp.saturating_sub(compared).max(1));
            expected = Some(spp);
        }
        let frame = match self.comparisons.lookup(key) {
            Some(frame) => ComparandFrame::Cached(frame),
            None => ComparandFrame::Pending(Box::new(self.submit(&job.scene, &truth)?.pending)),
        };
        Ok(Comparand {
            method,
            senders,
            key,
            frame,
            expected,
            cache: Arc::clone(&self.comparisons),
        })
    }

    /// Hands a submitted frame to the readback thread.
    fn hand_over(&self, job: ReadbackJob) {
        self.in_flight.sent();
        if let Err(mpsc::SendError(job)) = self.readback.send(job) {
            self.in_flight.done(Duration::ZERO);
            job.fail(ApiError::internal("the readback thread has stopped"));
        }
    }

    fn session_frame(&mut self, session: &Arc<Session>, mut plan: FramePlan) {
        let render_start_us = unix_us();
        // A progressive method keeps refining this session's image while nothing changes.
        plan.resolved.settings.history = Some(history_id(&session.id));
        plan.resolved.settings.still = plan.still;
        plan.resolved.settings.yuv420 = plan.codec.is_video();
        let settings = &mut plan.resolved.settings;
        settings.pick = plan.pick.map(|p| p.texel(settings.width, settings.height));
        match self.submit(&plan.lease_scene, &plan.resolved) {
            // The wait for the GPU happens on the readback thread while this one encodes the
            // next frame.
            Ok(submitted) => {
                let job = ReadbackJob {
                    frame: FrameJob::from_submitted(submitted, Arc::clone(&plan.lease_scene)),
                    target: Destination::Session {
                        session: Arc::clone(session),
                        plan: Box::new(plan),
                        render_start_us,
                    },
                };
                self.hand_over(job);
            }
            Err(e) => session.frame_failed(e.body),
        }
    }
}

/// A submitted frame and what composing its view needs, on its way to the readback thread.
struct FrameJob {
    pending: PendingFrame,
    queued: Queued,
    /// The view to compose (debug views from the data read back with the frame).
    view: View,
    camera: lightcast_protocol::Camera,
    scene: Arc<SceneEntry>,
    /// The GI method's precomputed scene data (the `caches` view draws the light caches).
    data: Option<SceneData>,
    gi_pending: bool,
}

impl FrameJob {
    fn from_submitted(s: Submitted, scene: Arc<SceneEntry>) -> Self {
        Self {
            pending: s.pending,
            queued: s.queued,
            view: s.view,
            camera: s.camera,
            scene,
            data: s.data,
            gi_pending: s.gi_pending,
        }
    }

    /// Waits for the frame and composes its view; `inspect` sees the frame first.
    fn wait(
        self,
        inspect: impl FnOnce(&Frame) -> Result<(), ApiError>,
    ) -> Result<Rendered, ApiError> {
        let frame = self
            .pending
            .wait()
            .map_err(|e| ApiError::internal(e.to_string()))?;
        inspect(&frame)?;
        let (camera, scene, data) = (self.camera, self.scene, self.data);
        finish(frame, self.view, self.gi_pending, |view, frame| {
            debug_views::compose(view, frame, &camera, &scene.scene.bounds, data.as_ref())
        })
    }
}

/// Where a read-back frame goes.
enum Destination {
    /// Encoded into the session's latest-frame slot.
    Session {
        session: Arc<Session>,
        plan: Box<FramePlan>,
        render_start_us: u64,
    },
    /// Handed to the waiting `POST /v1/render`, compared first if it asked.
    OneShot {
        reply: oneshot::Sender<Result<OneShotResult, ApiError>>,
        queue_ms: f64,
        /// Full reference first, as [`CompareWith::transports`] orders them.
        compare: Vec<Comparand>,
        /// The samples per pixel a chunked render's image must hold.
        expected: Option<u32>,
    },
}

/// A frame on its way from the GPU to its session or one-shot request.
struct ReadbackJob {
    frame: FrameJob,
    target: Destination,
}

impl ReadbackJob {
    fn fail(self, e: ApiError) {
        match self.target {
            Destination::Session { session, .. } => session.frame_failed(e.body),
            Destination::OneShot { reply, .. } => {
                let _ = reply.send(Err(e));
            }
        }
    }
}

/// The render a one-shot is compared with.
struct Comparand {
    method: GiMethod,
    senders: Senders,
    /// Its key in the cache.
    key: u64,
    frame: ComparandFrame,
    /// The samples per pixel a chunked comparison must hold.
    expected: Option<u32>,
    cache: Arc<ComparisonCache>,
}

/// A chunked render's image holds fewer samples than it was given: other renders took its
/// accumulation over (the tracer keeps a few histories at once) before it was read back.
fn check_samples(frame: &Frame, expected: Option<u32>) -> Result<(), ApiError> {
    let Some(expected) = expected else {
        return Ok(());
    };
    let samples = frame.progress.map_or(0, |p| p.samples);
    if samples == expected {
        Ok(())
    } else {
        Err(ApiError::unavailable(format!(
            "the path tracer's accumulation of this render was taken over by other renders \
             ({samples} of {expected} samples kept); try again"
        )))
    }
}

enum ComparandFrame {
    Cached(Arc<Truth>),
    /// Submitted before the one-shot's own frame.
    Pending(Box<PendingFrame>),
}

impl Comparand {
    /// The read-back frame, added to the cache when it was rendered for this request.
    fn wait(self) -> Result<(GiMethod, Senders, Arc<Truth>), ApiError> {
        let frame = match self.frame {
            ComparandFrame::Cached(frame) => frame,
            ComparandFrame::Pending(pending) => {
                let frame = pending
                    .wait()
                    .map_err(|e| ApiError::internal(e.to_string()))?;
                check_samples(&frame, self.expected)?;
                let frame = Arc::new(
                    Truth::from_frame(frame).map_err(|e| ApiError::internal(e.to_string()))?,
                );
                self.cache.insert(self.key, Arc::clone(&frame));
                frame
            }
        };
        Ok((self.method, self.senders, frame))
    }
}

/// Comparison renders kept for repeated comparisons, most recent first (the render loop looks
/// them up, the readback thread adds them).
#[derive(Default)]
struct ComparisonCache(std::sync::Mutex<Vec<(u64, Arc<Truth>)>>);

impl ComparisonCache {
    fn contains(&self, key: u64) -> bool {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .iter()
            .any(|(k, _)| *k == key)
    }

    fn lookup(&self, key: u64) -> Option<Arc<Truth>> {
        let mut entries = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let i = entries.iter().position(|(k, _)| *k == key)?;
        let hit = entries.remove(i);
        let frame = Arc::clone(&hit.1);
        entries.insert(0, hit);
        Some(frame)
    }

    fn insert(&self, key: u64, frame: Arc<Truth>) {
        let mut entries = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        entries.retain(|(k, _)| *k != key);
        entries.insert(0, (key, frame));
        let mut bytes = 0;
        let keep = entries
            .iter()
            .take_while(|(_, t)| {
                bytes += t.bytes();
                bytes <= COMPARISON_CACHE_BYTES
            })
            .count()
            .max(1);
        entries.truncate(keep);
    }
}

/// When the render loop took a frame up (before waiting for its turn) and when it submitted it.
#[derive(Clone, Copy, Debug)]
struct Queued {
    ready: Instant,
    submitted: Instant,
}

impl Queued {
    /// How long the GPU sat idle before this frame for want of it: from when the job before it
    /// was handed on (`previous`: the GPU was done with its frame by then) or, if later, from
    /// when the loop took this one up, to its submission. Zero where it was submitted before
    /// the previous one finished (it was queued behind it), or where nothing was due meanwhile
    /// (the GPU had no work to do, not work held back). Between session frames a lower bound:
    /// the GPU finished before the readback ended. GPU work no job carries is not seen: a chunk
    /// of a long path-traced render, or a one-shot's comparison frames (submitted before
    /// `ready`), so around those it may count time the GPU was busy.
    fn gpu_idle_before(&self, previous: Option<Instant>) -> Duration {
        previous.map_or(Duration::ZERO, |done| {
            self.submitted
                .saturating_duration_since(done.max(self.ready))
        })
    }
}

/// Waits for frames in submission order: session frames go to the encoder pool, one-shot
/// renders (compared first if asked) to their requests.
fn readback_thread(
    jobs: mpsc::Receiver<ReadbackJob>,
    encoder: Arc<EncodePool>,
    in_flight: &InFlight,
) {
    let _stop = StopOnDrop(in_flight);
    let mut previous = None;
    for job in jobs {
        let idle = job.frame.queued.gpu_idle_before(previous);
        metrics::histogram!(super::metrics::GPU_IDLE_SECONDS).record(idle.as_secs_f64());
        let started = Instant::now();
        read_back(job, &encoder);
        in_flight.done(started.elapsed());
        previous = Some(Instant::now());
    }
}

/// Waits for one frame and hands it on.
fn read_back(job: ReadbackJob, encoder: &EncodePool) {
    match job.target {
        Destination::Session {
            session,
            plan,
            render_start_us,
        } => match job.frame.wait(|_| Ok(())) {
            // A session that has ended is not encoded for.
            Ok(_) if session.is_closed() => {}
            Ok(r) => deliver(&session, &plan, r, render_start_us, encoder),
            Err(e) => session.frame_failed(e.body),
        },
        Destination::OneShot {
            reply,
            queue_ms,
            compare,
            expected,
        } => {
            let result =
                one_shot_result(job.frame, compare, expected).map(|(rendered, comparisons)| {
                    OneShotResult {
                        rendered,
                        queue_ms,
                        comparisons,
                    }
                });
            let _ = reply.send(result);
        }
    }
}

/// A one-shot frame read back, with its comparisons when they were asked for.
fn one_shot_result(
    frame: FrameJob,
    compare: Vec<Comparand>,
    expected: Option<u32>,
) -> Result<(Rendered, Vec<Comparison>), ApiError> {
    let truths = compare
        .into_iter()
        .map(Comparand::wait)
        .collect::<Result<Vec<_>, _>>()?;
    let mut comparisons = Vec::new();
    let rendered = frame.wait(|frame| {
        check_samples(frame, expected)?;
        for (method, senders, truth) in &truths {
            let c = crate::quality::compare(frame, truth, *method, *senders)
                .map_err(|e| ApiError::internal(e.to_string()))?;
            comparisons.push(c);
        }
        Ok(())
    })?;
    Ok((rendered, comparisons))
}

/// A read-back frame as the service hands it on: the image of `view` (made by `image`) plus
/// what was measured.
fn finish(
    mut frame: Frame,
    view: View,
    gi_pending: bool,
    image: impl FnOnce(View, Frame) -> Result<Image, debug_views::ViewError>,
) -> Result<Rendered, ApiError> {
    record_metrics(&frame);
    let hdr = frame.hdr.take();
    let indirect = if debug_views::reads_indirect(view) {
        frame.indirect.clone()
    } else {
        frame.indirect.take()
    };
    let timings = std::mem::take(&mut frame.timings);
    let yuv420 = frame.yuv420.take();
    let (timing_source, readback_ms, exposure_scale, progress, pick) = (
        frame.timing_source,
        frame.readback_ms,
        frame.exposure_scale,
        frame.progress,
        frame.pick,
    );
    let image = image(view, frame).map_err(|e| ApiError::internal(e.to_string()))?;
    Ok(Rendered {
        image,
        yuv420,
        timings,
        timing_source,
        readback_ms,
        exposure_scale,
        hdr,
        indirect,
        gi_pending,
        progress,
        pick,
    })
}

/// Node `id`'s local transform as the frame `plan` posed it (its own where no pose moved it).
fn framed_pose(plan: &FramePlan, id: u32) -> Option<lightcast_protocol::NodePose> {
    let posed = plan.resolved.settings.poses.iter().find(|(n, _)| *n == id);
    let local = posed
        .map(|(_, t)| *t)
        .or_else(|| plan.lease_scene.scene.node(id)?.local)?;
    Some(lightcast_protocol::NodePose {
        node: id,
        translation: Some(local.translation.into()),
        rotation: Some(local.rotation.into()),
        scale: Some(local.scale.into()),
    })
}

/// Records a session frame and encodes it on the pool; the encoded frame lands in the
/// session's latest-frame slot.
fn deliver(
    session: &Arc<Session>,
    plan: &FramePlan,
    rendered: Rendered,
    render_start_us: u64,
    encoder: &EncodePool,
) {
    let needed = plan.resolved.precompute.as_ref().map(|key| {
        (
            plan.lease_scene.id.as_str(),
            key.kind,
            precompute_label(key),
        )
    });
    session.note_precomputed(needed, rendered.gi_pending);
    if let (Some(request), Some(picked)) = (plan.pick, rendered.pick) {
        let surface = picked.surface;
        let movable = surface.and_then(|s| s.movable);
        // Nobody listening is no error: the client may have gone.
        let _ = session.events.send(ServerEvent::Picked {
            nonce: request.nonce,
            x: request.x,
            y: request.y,
            position: surface.map(|s| s.position),
            node: surface.and_then(|s| s.node),
            movable,
            pose: movable.and_then(|id| framed_pose(plan, id)),
        });
    }
    metrics::counter!(super::metrics::FRAMES_RENDERED).increment(1);
    session.record_render(&rendered.stages());
    let mut flags = 0;
    if plan.still {
        flags |= FLAG_STILL;
    }
    if plan.moving {
        flags |= FLAG_MOVING;
    }
    if rendered.gi_pending {
        flags |= FLAG_GI_PENDING;
    }
    let (codec, quality) = (plan.codec, plan.quality);
    let header = FrameHeader {
        seq: session.next_seq(),
        input_id: plan.input_id,
        render_start_us,
        send_us: 0,
        width: rendered.image.width,
        height: rendered.image.height,
        codec,
        flags,
        quality: if codec == lightcast_protocol::Codec::Jpeg {
            quality
        } else {
            0
        },
        encode_ms: 0.0,
        readback_ms: rendered.readback_ms as f32,
        gpu_ms: rendered.gpu_ms() as f32,
        payload_len: 0,
        stages: rendered
            .timings
            .iter()
            .map(|t| (t.stage.index(), t.ms as f32))
            .collect(),
        reused: rendered
            .timings
            .iter()
            .filter(|t| t.reused)
            .map(|t| t.stage.index())
            .collect(),
        shared: rendered
            .timings
            .iter()
            .filter(|t| t.shared_by > 1)
            .map(|t| (t.stage.index(), t.shared_by.min(255) as u8))
            .collect(),
        samples: rendered.progress.map_or(0, |p| p.samples),
        relative_error: rendered.progress.map_or(0.0, |p| p.relative_standard_error),
    };
    let seq = header.seq;
    let session = Arc::clone(session);
    let image = rendered.image;
    // Sends the encoded frame with the time its encoding took.
    let finish = move |session: &Session, started: Instant, payload: &[u8], flags: u8| {
        let encode_ms = started.elapsed().as_secs_f64() * 1e3;
        super::metrics::record_duration(
            super::metrics::ENCODE_SECONDS,
            super::metrics::ENCODE_MS,
            encode_ms,
        );
        let header = FrameHeader {
            encode_ms: encode_ms as f32,
            flags: header.flags | flags,
            ..header
        };
        session.deliver(seq, header.encode_with(payload), !codec.is_video());
    };
    if codec.is_video() {
        let config = VideoConfig::new(image.width, image.height, &plan.encoding, plan.fps);
        let (kind, yuv420, restarts) = (encoder.video, rendered.yuv420, plan.video_restarts);
        let target = Arc::clone(&session);
        session.queue_video(
            encoder,
            Box::new(move |stream| {
                let started = Instant::now();
                // Debug views are composed on the CPU and converted here.
                let frame = yuv420
                    .unwrap_or_else(|| Yuv420::from_rgba8(&image.rgba8, image.width, image.height));
                // `|`, not `||`: the keyframe also answers a pending request.
                let keyframe = target.take_keyframe_request() | restarts;
                match stream.encode(kind, config, &frame, keyframe) {
                    Ok(unit) => {
                        let flags = if unit.keyframe { FLAG_KEYFRAME } else { 0 };
                        finish(&target, started, &unit.data, flags);
                    }
                    Err(e) => target.frame_failed(ApiError::internal(e.to_string()).body),
                }
            }),
        );
        return;
    }
    encoder.spawn(move || {
        let started = Instant::now();
        match encode::encode(&image, codec, quality) {
            Ok(payload) => finish(&session, started, &payload, 0),
            Err(e) => session.frame_failed(ApiError::internal(e.to_string()).body),
        }
    });
}

/// A frame submitted by the render loop.
struct Submitted {
    pending: PendingFrame,
    queued: Queued,
    view: View,
    gi_pending: bool,
    camera: lightcast_protocol::Camera,
    /// The precomputed scene data the frame used, for debug views.
    data: Option<SceneData>,
}

/// The image history of a session (see `RenderSettings::history`): a hash of its id.
fn history_id(session_id: &str) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    session_id.hash(&mut hasher);
    hasher.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether `wait_turn` on `in_flight` returns within `within`; when it does not, a frame
    /// handed on lets it go.
    fn turn_comes(in_flight: &Arc<InFlight>, within: Duration) -> bool {
        let (tx, rx) = mpsc::channel();
        let waiter = {
            let in_flight = Arc::clone(in_flight);
            std::thread::spawn(move || {
                in_flight.wait_turn();
                let _ = tx.send(());
            })
        };
        let came = rx.recv_timeout(within).is_ok();
        if !came {
            in_flight.done(Duration::ZERO);
            rx.recv_timeout(Duration::from_secs(60))
                .expect("a finished frame lets the turn come");
        }
        waiter.join().expect("joins");
        came
    }

    /// Up to `depth` light frames are in flight (issue 36: the GPU finds the next queued); the
    /// next waits until one is read back.
    #[test]
    fn light_frames_are_submitted_until_depth_are_in_flight() {
        let in_flight = Arc::new(InFlight::new(3));
        for _ in 0..3 {
            assert!(turn_comes(&in_flight, Duration::from_secs(60)));
            in_flight.sent();
        }
        assert!(
            !turn_comes(&in_flight, Duration::from_millis(200)),
            "a fourth waits for the readback"
        );
        assert_eq!(in_flight.lock().jobs, 2, "it went once one was read back");
    }

    /// The GPU's idle time before a frame counts only what it waited for a frame the loop was
    /// preparing, not a frame queued behind another nor a time with nothing due.
    #[test]
    fn gpu_idle_time_counts_only_waits_for_a_frame_in_preparation() {
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let queued = |ready, submitted| Queued {
            ready: at(ready),
            submitted: at(submitted),
        };
        let ms = |d: Duration| d.as_millis();
        // The first frame: nothing came before it.
        assert_eq!(ms(queued(0, 5).gpu_idle_before(None)), 0);
        // Submitted before the previous frame was done: queued behind it.
        assert_eq!(ms(queued(0, 5).gpu_idle_before(Some(at(8)))), 0);
        // Taken up before the previous was done, submitted 4 ms after: 4 ms idle.
        assert_eq!(ms(queued(6, 12).gpu_idle_before(Some(at(8)))), 4);
        // Nothing was due until 20 ms: only its 3 ms of preparation count.
        assert_eq!(ms(queued(20, 23).gpu_idle_before(Some(at(8)))), 3);
    }

    /// Light frames are double-buffered at depth 2; after a heavy one the next waits until
    /// nothing is in flight (issue 31), and the readback thread's finishing the frame lets it
    /// go.
    #[test]
    fn after_a_heavy_frame_the_next_waits_for_the_readback_to_be_idle() {
        let in_flight = Arc::new(InFlight::new(2));
        in_flight.sent();
        in_flight.wait_turn();
        in_flight.sent();
        in_flight.done(HEAVY_FRAME * 2);
        let (tx, rx) = mpsc::channel();
        let waiter = {
            let in_flight = Arc::clone(&in_flight);
            std::thread::spawn(move || {
                in_flight.wait_turn();
                tx.send(()).expect("the test waits");
            })
        };
        assert!(
            rx.recv_timeout(Duration::from_millis(200)).is_err(),
            "a frame is still in flight behind a heavy one"
        );
        in_flight.done(Duration::ZERO);
        rx.recv_timeout(Duration::from_secs(60))
            .expect("the turn comes once the readback is idle");
        waiter.join().expect("joins");
        // Light again: frames in flight do not hold the next back.
        in_flight.sent();
        in_flight.wait_turn();
    }

    /// A readback thread that ends with frames in flight (a panic) lets the loop go on: it
    /// does not wait for frames nobody will hand on.
    #[test]
    fn a_readback_thread_that_ended_holds_nothing_back() {
        let in_flight = Arc::new(InFlight::new(1));
        in_flight.sent();
        let ended = {
            let in_flight = Arc::clone(&in_flight);
            std::thread::spawn(move || {
                let _stop = StopOnDrop(&in_flight);
                panic!("a readback that failed");
            })
        };
        assert!(ended.join().is_err(), "the thread panicked");
        assert!(turn_comes(&in_flight, Duration::from_secs(60)));
    }

    #[test]
    fn evicts_idle_renderers_and_the_least_recently_used_beyond_the_limit() {
        let now = Instant::now() + RENDERER_IDLE * 2;
        let ago = |ms: u64| now - Duration::from_millis(ms);
        // Within the limit and recently used: all kept.
        let recent: Vec<(usize, Instant)> =
            (0..MAX_RENDERERS).map(|k| (k, ago(k as u64))).collect();
        assert!(evictions(recent.clone(), now).is_empty());
        // One idle for longer than RENDERER_IDLE goes even though there is room.
        let mut with_idle = recent[..3].to_vec();
        with_idle.push((99, now - RENDERER_IDLE));
        assert_eq!(evictions(with_idle, now), vec![99]);
        // Two more than the limit: the two least recently used go.
        let mut over = recent;
        over.push((100, ago(5_000)));
        over.push((101, ago(4_000)));
        let mut dropped = evictions(over, now);
        dropped.sort();
        assert_eq!(dropped, vec![100, 101]);
    }
}
