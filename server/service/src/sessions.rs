//! Sessions: the state a client steers, the latest-frame slot the render loop fills and the
//! WebSocket drains, and the registry the render loop walks round robin.

use super::budget::{Quota, TokenQuotas};
use super::error::ApiError;
use super::ids;
use super::params::Resolved;
use super::routing::{Owner, Routing};
use super::scenes::SceneLease;
use super::sync::lock;
use super::video::VideoStream;
use lightcast_protocol::{
    ErrorBody, Limits, ServerEvent, SessionInfo, SessionParams, SessionStats, StageMs, StreamMode,
};
use std::collections::{BTreeMap, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use tokio::sync::{broadcast, watch, Notify};

/// Frames a session may have rendered but not yet sent before its ticks are skipped.
pub const MAX_IN_FLIGHT: u32 = 2;

pub fn unix_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

pub fn unix_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// Holds a session's encoded frames until the socket sends them. A newer frame replaces the
/// unsent images (JPEG, PNG); unsent video frames stay queued, since the frames after them
/// are coded against them. The render loop's [`MAX_IN_FLIGHT`] bounds the queue.
#[derive(Default)]
pub struct FrameSlot {
    /// (message, whether a newer frame may replace it).
    frames: Mutex<VecDeque<(Vec<u8>, bool)>>,
    notify: Notify,
}

impl FrameSlot {
    /// Queues `message`; returns how many unsent frames it replaced.
    pub fn publish(&self, message: Vec<u8>, replaceable: bool) -> u32 {
        let mut frames = lock(&self.frames);
        let before = frames.len();
        frames.retain(|(_, replaceable)| !replaceable);
        let replaced = (before - frames.len()) as u32;
        frames.push_back((message, replaceable));
        drop(frames);
        self.notify.notify_one();
        replaced
    }

    /// Waits for the next frame.
    pub async fn take(&self) -> Vec<u8> {
        loop {
            if let Some((frame, _)) = lock(&self.frames).pop_front() {
                return frame;
            }
            self.notify.notified().await;
        }
    }
}

/// Work on a session's video stream, run in the order it was queued ([`Session::queue_video`]).
pub type VideoJob = Box<dyn FnOnce(&mut VideoStream) + Send>;

/// What the render loop should render for a session now.
pub struct FramePlan {
    pub resolved: Resolved,
    pub lease_scene: Arc<super::scenes::SceneEntry>,
    pub version: u64,
    pub input_id: u64,
    pub still: bool,
    /// A `pick` the frame answers.
    pub pick: Option<PickRequest>,
    pub moving: bool,
    pub codec: lightcast_protocol::Codec,
    /// The frame starts the video again after frames of another codec: a client that
    /// switched decoders needs a keyframe.
    pub video_restarts: bool,
    pub quality: u8,
    /// The session's encoding (video settings) and fps cap when the frame was planned.
    pub encoding: lightcast_protocol::Encoding,
    pub fps: f32,
}

/// A client's `pick`: a point of the view, as fractions of the frame from its top left.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PickRequest {
    pub x: f32,
    pub y: f32,
    pub nonce: u64,
}

impl PickRequest {
    /// The texel of a `width` × `height` frame under the point.
    pub fn texel(&self, width: u32, height: u32) -> [u32; 2] {
        let at = |f: f32, n: u32| ((f * n as f32) as u32).min(n.saturating_sub(1));
        [at(self.x, width), at(self.y, height)]
    }
}

struct State {
    params: SessionParams,
    resolved: Resolved,
    lease: SceneLease,
    /// Bumped on every change of parameters.
    version: u64,
    /// Version shown by the last rendered frame.
    rendered_version: u64,
    /// Version shown by the last still (0: none yet).
    still_version: u64,
    still_requested: bool,
    /// The latest `pick` not yet rendered (a newer one replaces it).
    pick: Option<PickRequest>,
    input_id: u64,
    last_change: Instant,
    next_due: Instant,
    /// The codec of the last streamed (not still) frame planned; `None` before the first.
    streamed_codec: Option<lightcast_protocol::Codec>,
    /// The (scene, kind) of the precomputation the client was last told its frames wait for.
    pending_told: Option<(String, String)>,
    clock: AnimationClock,
}

impl State {
    fn set_paused(&mut self, paused: bool, now: Instant) {
        self.clock.set_paused(paused, now);
        self.params.paused = paused;
    }
}

/// How long a session's animation has played: from when `render.animation` was last set,
/// standing still while the session is paused.
#[derive(Clone, Copy, Debug)]
struct AnimationClock {
    from: Instant,
    paused_at: Option<Instant>,
}

impl AnimationClock {
    fn new(now: Instant, paused: bool) -> Self {
        Self {
            from: now,
            paused_at: paused.then_some(now),
        }
    }

    /// Starts again from 0 at `now` (a new animation or time was set).
    fn restart(&mut self, now: Instant) {
        *self = Self::new(now, self.paused_at.is_some());
    }

    /// Seconds played by `now`.
    fn elapsed(&self, now: Instant) -> f64 {
        self.paused_at
            .unwrap_or(now)
            .saturating_duration_since(self.from)
            .as_secs_f64()
    }

    fn set_paused(&mut self, paused: bool, now: Instant) {
        match (self.paused_at, paused) {
            (None, true) => self.paused_at = Some(now),
            (Some(since), false) => {
                self.from += now.saturating_duration_since(since);
                self.paused_at = None;
            }
            _ => {}
        }
    }
}

/// One client's stream.
pub struct Session {
    pub id: String,
    /// The bearer token that created the session (auth on), which alone may use it.
    pub owner: Option<String>,
    pub created_unix_ms: u64,
    state: Mutex<State>,
    stats: Mutex<SessionStats>,
    pub slot: FrameSlot,
    pub events: broadcast::Sender<ServerEvent>,
    /// Rendered frames not yet sent or dropped.
    pub in_flight: AtomicU32,
    connected: AtomicBool,
    /// Since when no stream has been attached (creation, or the last disconnect).
    detached_at: Mutex<Instant>,
    seq: std::sync::atomic::AtomicU64,
    /// Sequence number of the newest frame put into the slot.
    newest_delivered: std::sync::atomic::AtomicU64,
    closed: watch::Sender<Option<String>>,
    /// The `h264` encoder, and the frames waiting for it in order.
    video: Mutex<VideoStream>,
    video_jobs: Mutex<VecDeque<VideoJob>>,
    /// The next video frame must be a keyframe (a stream attached, or the client asked).
    keyframe_wanted: AtomicBool,
}

impl Session {
    /// A session called `id` ([`SessionRegistry::new_id`]).
    pub fn new(
        id: String,
        owner: Option<String>,
        params: SessionParams,
        resolved: Resolved,
        lease: SceneLease,
    ) -> Arc<Self> {
        let now = Instant::now();
        let clock = AnimationClock::new(now, params.paused);
        Arc::new(Self {
            id,
            owner,
            created_unix_ms: unix_ms(),
            state: Mutex::new(State {
                params,
                resolved,
                lease,
                version: 1,
                rendered_version: 0,
                still_version: 0,
                still_requested: false,
                pick: None,
                input_id: 0,
                last_change: now,
                next_due: now,
                pending_told: None,
                clock,
                streamed_codec: None,
            }),
            stats: Mutex::new(SessionStats::default()),
            slot: FrameSlot::default(),
            events: broadcast::channel(64).0,
            in_flight: AtomicU32::new(0),
            connected: AtomicBool::new(false),
            detached_at: Mutex::new(now),
            seq: std::sync::atomic::AtomicU64::new(0),
            newest_delivered: std::sync::atomic::AtomicU64::new(0),
            closed: watch::channel(None).0,
            video: Mutex::new(VideoStream::default()),
            video_jobs: Mutex::new(VecDeque::new()),
            keyframe_wanted: AtomicBool::new(true),
        })
    }

    /// Claims the session's one stream; false when another is attached.
    pub fn attach(&self) -> bool {
        let attached = self
            .connected
            .compare_exchange(false, true, Ordering::AcqRel, Ordering::Acquire)
            .is_ok();
        if attached {
            // A new client's decoder starts at a keyframe.
            self.request_keyframe();
        }
        attached
    }

    /// Makes the next video frame a keyframe.
    pub fn request_keyframe(&self) {
        self.keyframe_wanted.store(true, Ordering::Release);
    }

    /// Whether the next video frame must be a keyframe (clears the request).
    pub fn take_keyframe_request(&self) -> bool {
        self.keyframe_wanted.swap(false, Ordering::AcqRel)
    }

    /// Queues `job` on the session's video stream and has `pool` run the queue: video frames
    /// must reach their encoder in order, while the pool's threads take jobs in any order.
    /// Whichever pool job holds the stream runs every queued job, oldest first.
    pub fn queue_video(self: &Arc<Self>, pool: &super::encode::EncodePool, job: VideoJob) {
        lock(&self.video_jobs).push_back(job);
        let session = Arc::clone(self);
        pool.spawn(move || {
            let mut stream = lock(&session.video);
            loop {
                let next = lock(&session.video_jobs).pop_front();
                let Some(job) = next else { break };
                job(&mut stream);
            }
        });
    }

    /// The stream went away (or never came).
    pub fn detach(&self) {
        *lock(&self.detached_at) = Instant::now();
        self.connected.store(false, Ordering::Release);
    }

    pub fn is_connected(&self) -> bool {
        self.connected.load(Ordering::Acquire)
    }

    /// How long the session has gone without a stream, as of `now` (`None` while attached).
    pub fn idle_for(&self, now: Instant) -> Option<Duration> {
        if self.is_connected() {
            None
        } else {
            Some(now.saturating_duration_since(*lock(&self.detached_at)))
        }
    }

    pub fn params(&self) -> SessionParams {
        lock(&self.state).params.clone()
    }

    pub fn info(&self) -> SessionInfo {
        let params = self.params();
        SessionInfo {
            stream: format!("/v1/sessions/{}/stream", self.id),
            id: self.id.clone(),
            params,
            connected: self.is_connected(),
            created_unix_ms: self.created_unix_ms,
            stats: lock(&self.stats).clone(),
        }
    }

    /// The scene the session renders now.
    pub fn scene(&self) -> Arc<super::scenes::SceneEntry> {
        Arc::clone(&lock(&self.state).lease.0)
    }

    pub fn scene_id(&self) -> String {
        lock(&self.state).lease.0.id.clone()
    }

    /// Replaces the parameters (already checked by the caller) and tells every listener.
    pub fn apply(&self, params: SessionParams, resolved: Resolved, lease: SceneLease, input: u64) {
        {
            let mut s = lock(&self.state);
            let now = Instant::now();
            if s.params.render.animation != params.render.animation {
                s.clock.restart(now);
            }
            let paused = params.paused;
            s.params = params;
            s.set_paused(paused, now);
            s.resolved = resolved;
            s.lease = lease;
            s.version += 1;
            if input > 0 {
                s.input_id = input;
            }
            s.last_change = Instant::now();
        }
        let _ = self.events.send(ServerEvent::Updated {
            session: Box::new(self.info()),
        });
    }

    /// Seconds into the animation the session plays at `now` (`None`: none plays).
    pub fn animation_time(&self, now: Instant) -> Option<f32> {
        let s = lock(&self.state);
        let playing = s.resolved.playing.as_ref()?;
        Some(playing.time_at(&s.lease.0.scene, s.clock.elapsed(now)))
    }

    pub fn set_paused(&self, paused: bool) {
        let mut s = lock(&self.state);
        if s.params.paused != paused {
            s.set_paused(paused, Instant::now());
            s.version += 1;
        }
    }

    pub fn request_still(&self) {
        lock(&self.state).still_requested = true;
    }

    /// Asks the next frame to read back what shows at (`x`, `y`), fractions of the frame.
    pub fn request_pick(&self, pick: PickRequest) -> Result<(), ApiError> {
        for (field, v) in [("x", pick.x), ("y", pick.y)] {
            if !(0.0..=1.0).contains(&v) {
                return Err(ApiError::field(
                    field,
                    format!("{v} is not a fraction of the frame in [0, 1]"),
                ));
            }
        }
        lock(&self.state).pick = Some(pick);
        Ok(())
    }

    /// Decides whether the session wants a frame at `now`. `Err(wait)` says how long until it
    /// might; `Ok(None)` that nothing is due until something changes.
    pub fn plan(&self, now: Instant) -> Result<FramePlan, Option<Duration>> {
        if !self.is_connected() {
            return Err(None);
        }
        let mut s = lock(&self.state);
        if s.params.paused && !s.still_requested && s.pick.is_none() {
            return Err(None);
        }
        if now < s.next_due {
            return Err(Some(s.next_due - now));
        }
        let enc = s.params.encoding.clone();
        let changed = s.version != s.rendered_version;
        let rest = Duration::from_millis(u64::from(enc.still_after_ms));
        // A playing animation changes every frame: never at rest.
        let playing = s.resolved.playing.is_some();
        let rested = !playing && now.duration_since(s.last_change) >= rest;
        // A pick on a resting view renders its still again: the lossy frame would replace it.
        let want_still = s.still_requested
            || (enc.still_after_ms > 0
                && rested
                && !changed
                && (s.still_version != s.version || s.pick.is_some()));
        let due = want_still
            || changed
            || playing
            || s.pick.is_some()
            || s.params.mode == StreamMode::Continuous;
        if !due {
            if enc.still_after_ms > 0 && s.still_version != s.version {
                return Err(Some(rest.saturating_sub(now.duration_since(s.last_change))));
            }
            return Err(None);
        }
        if self.in_flight.load(Ordering::Relaxed) >= MAX_IN_FLIGHT {
            drop(s);
            lock(&self.stats).frames_throttled += 1;
            metrics::counter!(super::metrics::FRAMES_THROTTLED).increment(1);
            return Err(Some(Duration::from_millis(2)));
        }
        let interval = Duration::from_secs_f32(1.0 / s.params.fps_cap);
        // Keep the cadence, but never bank ticks a slow frame missed.
        s.next_due = (s.next_due + interval).max(now);
        let moving = !rested;
        let (codec, quality) = if want_still {
            (enc.still_codec, enc.quality)
        } else if moving {
            (enc.codec, enc.moving_quality)
        } else {
            (enc.codec, enc.quality)
        };
        let mut video_restarts = false;
        if !want_still {
            video_restarts =
                codec.is_video() && s.streamed_codec.is_some_and(|last| !last.is_video());
            s.streamed_codec = Some(codec);
        }
        if want_still {
            s.still_requested = false;
            s.still_version = s.version;
        }
        s.rendered_version = s.version;
        let mut resolved = s.resolved.clone();
        if let Some(p) = &resolved.playing {
            p.pose(&mut resolved.settings, &s.lease.0, s.clock.elapsed(now));
        }
        if moving && !want_still {
            let settings = &mut resolved.settings;
            (settings.width, settings.height) =
                enc.interactive_size(settings.width, settings.height);
        }
        // In flight from now until it is sent, dropped or fails.
        self.in_flight.fetch_add(1, Ordering::Relaxed);
        Ok(FramePlan {
            resolved,
            lease_scene: Arc::clone(&s.lease.0),
            version: s.version,
            input_id: s.input_id,
            still: want_still,
            pick: s.pick.take(),
            moving,
            codec,
            video_restarts,
            quality,
            encoding: enc,
            fps: s.params.fps_cap,
        })
    }

    pub fn next_seq(&self) -> u64 {
        self.seq.fetch_add(1, Ordering::Relaxed) + 1
    }

    /// Tells the client once when its frames start lacking GI because the precomputation
    /// `needed` (scene, kind, label) of the frame's method is being built, and once when it
    /// is ready. A session that moves on to another scene or method before then is told
    /// about the new wait instead.
    pub fn note_precomputed(&self, needed: Option<(&str, &str, &str)>, pending: bool) {
        let mut s = lock(&self.state);
        let same = |told: &Option<(String, String)>, scene: &str, kind: &str| {
            told.as_ref()
                .is_some_and(|(s, k)| s.as_str() == scene && k.as_str() == kind)
        };
        let event = match needed {
            Some((scene, kind, what)) if pending && !same(&s.pending_told, scene, kind) => {
                s.pending_told = Some((scene.to_string(), kind.to_string()));
                ServerEvent::CachesPending {
                    scene: scene.to_string(),
                    kind: kind.to_string(),
                    what: what.to_string(),
                }
            }
            Some((scene, kind, what)) if !pending && same(&s.pending_told, scene, kind) => {
                s.pending_told = None;
                ServerEvent::CachesReady {
                    scene: scene.to_string(),
                    kind: kind.to_string(),
                    what: what.to_string(),
                }
            }
            Some(_) if pending => return,
            // The frame needed nothing it lacked: a wait it was told of no longer applies.
            _ => {
                s.pending_told = None;
                return;
            }
        };
        drop(s);
        let _ = self.events.send(event);
    }

    pub fn record_render(&self, stages: &[StageMs]) {
        let mut st = lock(&self.stats);
        st.frames_rendered += 1;
        st.last_stages = stages.to_vec();
    }

    /// A planned frame could not be rendered, read back or encoded.
    pub fn frame_failed(&self, error: ErrorBody) {
        self.in_flight.fetch_sub(1, Ordering::Relaxed);
        self.record_error(error);
    }

    pub fn record_error(&self, error: ErrorBody) {
        {
            let mut st = lock(&self.stats);
            st.errors += 1;
            st.last_error = Some(error.clone());
        }
        let _ = self.events.send(ServerEvent::RenderError { error });
    }

    /// Frame `seq` finished encoding: into the slot, counting the images it replaced as
    /// dropped. Images are encoded in parallel, so one may finish after a newer frame; it is
    /// dropped too. Video frames (`replaceable` false) are never dropped: they arrive in order
    /// and later frames are coded against them.
    pub fn deliver(&self, seq: u64, message: Vec<u8>, replaceable: bool) {
        let newer_sent = self.newest_delivered.fetch_max(seq, Ordering::AcqRel) > seq;
        let dropped = if replaceable && newer_sent {
            1
        } else {
            self.slot.publish(message, replaceable)
        };
        if dropped > 0 {
            self.in_flight.fetch_sub(dropped, Ordering::Relaxed);
            lock(&self.stats).frames_dropped += u64::from(dropped);
            metrics::counter!(super::metrics::FRAMES_DROPPED).increment(u64::from(dropped));
        }
    }

    /// A frame was written to the socket.
    pub fn record_sent(&self, bytes: usize) {
        self.in_flight.fetch_sub(1, Ordering::Relaxed);
        let mut st = lock(&self.stats);
        st.frames_sent += 1;
        st.bytes_sent += bytes as u64;
        metrics::counter!(super::metrics::FRAMES_SENT).increment(1);
        metrics::counter!(super::metrics::BYTES_SENT).increment(bytes as u64);
    }

    pub fn record_ack(&self) {
        lock(&self.stats).frames_acked += 1;
    }

    /// Asks the session's socket to close with `reason`.
    pub fn close(&self, reason: &str) {
        self.closed.send_replace(Some(reason.to_string()));
    }

    /// Whether the session has ended (its socket was asked to close).
    pub fn is_closed(&self) -> bool {
        self.closed.borrow().is_some()
    }

    pub fn closed(&self) -> watch::Receiver<Option<String>> {
        self.closed.subscribe()
    }
}

/// All sessions, in a stable order for round robin.
pub struct SessionRegistry {
    sessions: Mutex<BTreeMap<String, Arc<Session>>>,
    max: usize,
    quotas: TokenQuotas,
    /// This replica's name and the shared key, where several replicas serve.
    routing: Option<Routing>,
}

impl SessionRegistry {
    pub fn new(limits: &Limits, routing: Option<Routing>) -> Self {
        Self {
            sessions: Mutex::new(BTreeMap::new()),
            max: limits.max_sessions as usize,
            quotas: TokenQuotas::new(limits),
            routing,
        }
    }

    /// A new session id: `se_<random>`, or `REPLICA.se_<random>.<mac>` where replicas route.
    pub fn new_id(&self) -> String {
        self.routing
            .as_ref()
            .map_or_else(|| ids::new_id("se"), Routing::session_id)
    }

    /// This replica's name, where replicas route.
    pub fn replica(&self) -> Option<&str> {
        self.routing.as_ref().map(Routing::replica)
    }

    /// Adds a session within the server's limit and its token's quota.
    pub fn insert(&self, session: Arc<Session>) -> Result<(), ApiError> {
        let mut all = lock(&self.sessions);
        let owner = session.owner.as_deref();
        let owned = all
            .values()
            .filter(|s| owner.is_some() && s.owner.as_deref() == owner)
            .count();
        self.quotas.check_count(owner, Quota::Sessions, owned)?;
        if all.len() >= self.max {
            return Err(ApiError::too_many(
                "too_many_sessions",
                format!("the server holds {} sessions, its limit", all.len()),
            ));
        }
        all.insert(session.id.clone(), session);
        metrics::gauge!(super::metrics::SESSIONS).set(all.len() as f64);
        Ok(())
    }

    /// The session `id`, if `token` may use it (the creator's token when auth is on).
    /// Refuses an id this replica cannot hold: 421 naming the owner for another replica's
    /// genuine id, 404 for a forged one (as for any unknown id).
    pub fn check_here(&self, id: &str) -> Result<(), ApiError> {
        match self.routing.as_ref().map(|r| r.owner(id)) {
            None | Some(Owner::Here) => Ok(()),
            Some(Owner::Elsewhere(owner)) => Err(ApiError::misdirected(id, &owner)),
            Some(Owner::Forged) => Err(ApiError::not_found("session", id)),
        }
    }

    pub fn get(&self, id: &str, token: Option<&str>) -> Result<Arc<Session>, ApiError> {
        self.check_here(id)?;
        let session = lock(&self.sessions)
            .get(id)
            .cloned()
            .ok_or_else(|| ApiError::not_found("session", id))?;
        match (&session.owner, token) {
            (None, _) => Ok(session),
            (Some(owner), Some(t)) if ids::constant_time_eq(owner, t) => Ok(session),
            // Same answer as an unknown id: another token's sessions are not revealed.
            _ => Err(ApiError::not_found("session", id)),
        }
    }

    pub fn list(&self, token: Option<&str>) -> Vec<Arc<Session>> {
        lock(&self.sessions)
            .values()
            .filter(|s| match (&s.owner, token) {
                (None, _) => true,
                (Some(owner), Some(t)) => ids::constant_time_eq(owner, t),
                (Some(_), None) => false,
            })
            .cloned()
            .collect()
    }

    pub fn all(&self) -> Vec<Arc<Session>> {
        lock(&self.sessions).values().cloned().collect()
    }

    /// Removes and returns the sessions without a stream for longer than `timeout`. Each is
    /// claimed as if a stream attached, so a client attaching at this very moment gets 409
    /// instead of a socket to a session that is gone.
    pub fn remove_idle(&self, timeout: Duration, now: Instant) -> Vec<Arc<Session>> {
        let mut all = lock(&self.sessions);
        let mut idle = Vec::new();
        for s in all.values() {
            if s.idle_for(now).is_some_and(|d| d > timeout) && s.attach() {
                idle.push(Arc::clone(s));
            }
        }
        for s in &idle {
            all.remove(&s.id);
        }
        metrics::gauge!(super::metrics::SESSIONS).set(all.len() as f64);
        idle
    }

    pub fn remove(&self, id: &str) -> Option<Arc<Session>> {
        let mut all = lock(&self.sessions);
        let removed = all.remove(id);
        metrics::gauge!(super::metrics::SESSIONS).set(all.len() as f64);
        removed
    }
}

#[cfg(test)]
mod tests {
    use super::AnimationClock;
    use std::time::{Duration, Instant};

    /// A paused session's animation stands still and goes on from there when it resumes; a
    /// new animation starts from 0, still paused.
    #[test]
    fn the_animation_clock_stands_still_while_paused() {
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        let mut clock = AnimationClock::new(t0, false);
        assert_eq!(clock.elapsed(at(1.0)), 1.0);
        clock.set_paused(true, at(1.0));
        assert_eq!(clock.elapsed(at(5.0)), 1.0);
        clock.set_paused(true, at(6.0));
        clock.set_paused(false, at(7.0));
        assert_eq!(clock.elapsed(at(7.5)), 1.5);
        clock.set_paused(true, at(8.0));
        clock.restart(at(9.0));
        assert_eq!(clock.elapsed(at(20.0)), 0.0);
        clock.set_paused(false, at(20.0));
        assert_eq!(clock.elapsed(at(22.0)), 2.0);
        assert_eq!(AnimationClock::new(t0, true).elapsed(at(3.0)), 0.0);
    }
}
