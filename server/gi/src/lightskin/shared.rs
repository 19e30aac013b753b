//! Sessions sharing LightSkin's and BRSM's light-side work (issue 36).
//!
//! Sessions of one scene take turns on one renderer, and one `LightSkin` holds the proxy
//! lights of every cache. The RSM, BRSM's importance, cumulative sums and VAL draw, the cache
//! lighting and the proxy occlusion are made once per *tick* and used by every session whose
//! light-side inputs are the same; each session still runs its own G-buffer, view samples,
//! interpolation (eq. 8–9) and shading.
//!
//! **The rule.** A frame shares when it is a session's (it has a history id), pass reuse is
//! on and it shows the final image. Its *key* is every input of the shared stages that is not
//! the camera: the method and its (resolved) parameters, the lights uniform and poses
//! (`passes::reuse`, with the renderer's epoch) and which cache set is loaded; it is
//! conservative (a parameter only the per-view stages read, such as `indirect_downscale`,
//! separates sessions too). The proxies hold what one key made, from the views of a set of
//! sessions; a frame with that key
//! - reuses them if its session's view was among those and it has not used them yet;
//! - makes them again, adding its view, if its session is new to them (a session joining);
//! - starts a new *tick* if its session has used them already: they are made from the views of
//!   every session that rendered with this key in the last two ticks (their latest frames'
//!   views: a session the render loop skipped for one tick, throttled by its client, stays
//!   pooled and reuses the next tick's rather than making them again);
//!
//! and a frame with a key no proxies hold makes them from its own view alone (so a session that
//! changes its light stops sharing at once, and its frame is what it would be alone). The
//! proxies of up to [`MAX_SHARED_INPUTS`] keys are kept at once, each in a lighting buffer of
//! its own (made when first used, the least recently used one given to a new key), so groups
//! of sessions under different lights each share theirs; frames that do not share use a buffer
//! of their own. Two inputs depend on the camera and are pooled over
//! the *views* (camera and frame size) of those sessions, equal views counted once:
//! - BRSM's N_VS view samples (eq. 10–11): view j of m gives its first N_VS/m Halton
//!   samples, so the VALs are drawn for what every sharing session saw;
//! - the direction v of the glossy proxies' lobe (eq. 14/15): the mean of the unit directions
//!   from the cache to each view's camera (zero, so no glossy proxy, where they cancel).
//!
//! With one view (one session, or sessions whose cameras and sizes are equal and stay so) this
//! is exactly the unshared frame, bit for bit; with several, a session's indirect light differs
//! from its unshared frame by what `bench/results/lavapipe-shared-views.md` measures (two
//! views of the Cornell box: 0.15 % LightSkin, 1.0–1.3 % BRSM; 3.9 % where every lobe is sharp,
//! Phong exponent 64, whose proxies' mean direction suits neither camera). A moving camera's
//! view joins the pool at the next tick. Frames that do not share (one-shot renders,
//! reuse off, debug views) use their own view alone and leave nothing to share.

use super::sampling::SampleRange;

/// Views pooled at most (the oldest are left out beyond).
pub const MAX_POOLED_VIEWS: usize = 64;

/// A session's frame, as sharing sees it.
pub struct Sharer {
    pub session: u64,
    /// The light-side inputs (see the module's rule).
    pub key: Vec<u8>,
    /// The camera and size: sessions with equal views pool one view.
    pub view: Vec<u8>,
    pub camera: [f32; 3],
}

/// Distinct light-side inputs whose proxies are kept at once (each in a lighting buffer of
/// its own), so groups of sessions under different lights each share theirs.
pub const MAX_SHARED_INPUTS: usize = 4;

/// What a frame does with the shared stages.
pub enum Plan {
    /// The proxies in lighting buffer `lighting` hold what this frame's inputs make, for
    /// `sessions` sessions: skip the shared stages.
    Reuse { sessions: usize, lighting: usize },
    /// Make them, from these views.
    Make(Pool),
}

/// The views a frame makes the shared stages from.
#[derive(Debug, Default, PartialEq)]
pub struct Pool {
    /// Their cameras' positions (one: the frame's own).
    pub cameras: Vec<[f32; 3]>,
    /// Per view, the slot its view samples are kept in (`None`: the frame's own alone).
    pub slots: Option<Vec<usize>>,
    /// The sessions whose views they are (0: a frame that does not share).
    pub sessions: usize,
    /// The lighting buffer the proxies go to: 0 for a frame that does not share, 1 to
    /// [`MAX_SHARED_INPUTS`] for one input's.
    pub lighting: usize,
}

/// What one lighting buffer's proxies hold, made by sharing frames.
struct Made {
    key: Vec<u8>,
    /// Its lighting buffer (1 to [`MAX_SHARED_INPUTS`]).
    lighting: usize,
    /// The sessions whose views they were made from.
    pooled: Vec<u64>,
    /// The sessions that rendered with them (their maker first).
    users: Vec<u64>,
    /// This tick and the one two before it (ticks are numbered across all inputs).
    tick: u64,
    earlier: u64,
    previous: u64,
    /// When a frame last used them (the least recent gives its buffer to new inputs).
    used: u64,
}

struct Slot {
    session: u64,
    key: Vec<u8>,
    view: Vec<u8>,
    camera: [f32; 3],
    /// The tick it last rendered in.
    seen: u64,
}

/// The state of sharing on one `LightSkin`.
#[derive(Default)]
pub struct Sharing {
    /// What the shared lighting buffers hold.
    made: Vec<Made>,
    /// Numbers the ticks: a tick starts where a session comes again to the proxies it used.
    tick: u64,
    /// Counts sharing frames (for [`Made::used`]).
    frames: u64,
    slots: Vec<Slot>,
    /// Every slot's view samples, `per_slot` each, copied in after each sharing frame's gather.
    samples: Option<(wgpu::Buffer, u32)>,
}

impl Sharing {
    /// Decides what this frame does, and records its view. `sharer`: `None` for a frame that
    /// does not share (it makes the stages from its own view, in lighting buffer 0, and leaves
    /// nothing to share).
    pub fn plan(&mut self, sharer: Option<&Sharer>, camera: [f32; 3]) -> Plan {
        let Some(s) = sharer else {
            return Plan::Make(Pool {
                cameras: vec![camera],
                slots: None,
                sessions: 0,
                lighting: 0,
            });
        };
        self.frames += 1;
        let frames = self.frames;
        let at = match self.made.iter().position(|m| m.key == s.key) {
            Some(at) => at,
            // New inputs: made for this frame alone, in the least recently used buffer.
            None => {
                self.tick += 1;
                let made = Made {
                    key: s.key.clone(),
                    lighting: self.made.len() + 1,
                    pooled: vec![s.session],
                    users: vec![s.session],
                    tick: self.tick,
                    earlier: self.tick,
                    previous: self.tick,
                    used: frames,
                };
                let at = if self.made.len() < MAX_SHARED_INPUTS {
                    self.made.push(made);
                    self.made.len() - 1
                } else {
                    let (at, _) = self
                        .made
                        .iter()
                        .enumerate()
                        .min_by_key(|(_, m)| m.used)
                        .unwrap_or((0, &self.made[0]));
                    let lighting = self.made[at].lighting;
                    self.made[at] = Made { lighting, ..made };
                    at
                };
                self.record(s, self.tick);
                return self.make(at);
            }
        };
        let m = &mut self.made[at];
        m.used = frames;
        let tick = m.tick;
        if m.pooled.contains(&s.session) && !m.users.contains(&s.session) {
            // Made from this session's view this tick, and not used by it yet.
            m.users.push(s.session);
            let plan = Plan::Reuse {
                sessions: m.pooled.len(),
                lighting: m.lighting,
            };
            self.record(s, tick);
            return plan;
        }
        if !m.users.contains(&s.session) {
            // A session new to this tick: made again within the tick, its view added.
            m.pooled.push(s.session);
            m.users.push(s.session);
            self.record(s, tick);
            return self.make(at);
        }
        // Its own proxies again: a new tick, from the views of every session that rendered
        // with the same inputs in this tick or the two before.
        self.tick += 1;
        let m = &mut self.made[at];
        m.earlier = m.previous;
        m.previous = m.tick;
        m.tick = self.tick;
        m.users = vec![s.session];
        let (key, earlier) = (m.key.clone(), m.earlier);
        self.record(s, self.tick);
        let live = self.live(&key, earlier);
        self.made[at].pooled = live;
        self.make(at)
    }

    /// Makes the proxies of `made[at]` from its pooled sessions' views.
    fn make(&self, at: usize) -> Plan {
        let m = &self.made[at];
        Plan::Make(Pool {
            lighting: m.lighting,
            ..self.pool(&m.pooled)
        })
    }

    /// The slot of `s`'s session, now holding its view as of `tick`.
    fn record(&mut self, s: &Sharer, tick: u64) {
        let at = match self.slots.iter().position(|slot| slot.session == s.session) {
            Some(at) => at,
            None if self.slots.len() < MAX_POOLED_VIEWS => {
                self.slots.push(Slot {
                    session: s.session,
                    key: Vec::new(),
                    view: Vec::new(),
                    camera: s.camera,
                    seen: 0,
                });
                self.slots.len() - 1
            }
            None => {
                // The slot seen longest ago goes to the newcomer.
                let (at, _) = self
                    .slots
                    .iter()
                    .enumerate()
                    .min_by_key(|(_, slot)| slot.seen)
                    .unwrap_or((0, &self.slots[0]));
                self.slots[at].session = s.session;
                at
            }
        };
        let slot = &mut self.slots[at];
        slot.key.clone_from(&s.key);
        slot.view.clone_from(&s.view);
        slot.camera = s.camera;
        slot.seen = tick;
    }

    /// The sessions with `key` that rendered since tick `since`.
    fn live(&self, key: &[u8], since: u64) -> Vec<u64> {
        self.slots
            .iter()
            .filter(|s| s.key == key && s.seen >= since)
            .map(|s| s.session)
            .collect()
    }

    /// The views of `sessions` (those with a slot), by session, equal views once.
    fn pool(&self, sessions: &[u64]) -> Pool {
        let mut live: Vec<(usize, &Slot)> = self
            .slots
            .iter()
            .enumerate()
            .filter(|(_, s)| sessions.contains(&s.session))
            .collect();
        live.sort_by_key(|(_, s)| s.session);
        let mut views: Vec<(usize, &Slot)> = Vec::with_capacity(live.len());
        for (at, s) in live {
            if !views.iter().any(|(_, v)| v.view == s.view) {
                views.push((at, s));
            }
        }
        Pool {
            cameras: views.iter().map(|(_, s)| s.camera).collect(),
            slots: Some(views.iter().map(|&(at, _)| at).collect()),
            sessions: sessions.len(),
            lighting: 0,
        }
    }

    /// The slot `session` holds (after [`Self::plan`] for a sharing frame).
    fn slot_of(&self, session: u64) -> Option<usize> {
        self.slots.iter().position(|s| s.session == session)
    }

    /// Keeps the view samples of `session`'s frame (`samples`, N_VS of them) in its slot:
    /// encodes their copy.
    pub fn keep_samples(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        session: u64,
        samples: &wgpu::Buffer,
        per_slot: u32,
    ) {
        let Some(at) = self.slot_of(session) else {
            return;
        };
        let bytes = u64::from(per_slot) * SAMPLE_BYTES;
        if self.samples.as_ref().is_none_or(|(_, n)| *n != per_slot) {
            // A new N_VS: the samples kept for the old one mean nothing now (their sessions'
            // keys hold the old N_VS too, so no pool takes them).
            for s in self.slots.iter_mut().filter(|s| s.session != session) {
                s.key.clear();
            }
            self.samples = Some((
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("shared view samples"),
                    size: (bytes * MAX_POOLED_VIEWS as u64).max(16),
                    usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
                per_slot,
            ));
        }
        let Some((buffer, _)) = &self.samples else {
            return;
        };
        encoder.copy_buffer_to_buffer(samples, 0, buffer, at as u64 * bytes, Some(bytes));
    }

    /// Where importance takes its N_VS view samples from for `pool`: view j of m gives its
    /// first ⌊N_VS/m⌋ (the first N_VS mod m views one more); more views than samples give
    /// one each, the first N_VS of them. `None`: the frame's own.
    pub fn sample_ranges(&self, pool: &Pool) -> Option<Vec<SampleRange<'_>>> {
        let (buffer, per_slot) = self.samples.as_ref()?;
        let views = pool.slots.as_ref()?;
        Some(
            split(*per_slot, views.len())
                .into_iter()
                .zip(views)
                .map(|(count, &slot)| SampleRange {
                    buffer,
                    first: slot as u32 * per_slot,
                    count,
                })
                .filter(|r| r.count > 0)
                .collect(),
        )
    }
}

const SAMPLE_BYTES: u64 = std::mem::size_of::<super::importance::ViewSample>() as u64;

/// `total` samples over `views` views: each ⌊total/views⌋, the first `total mod views` one
/// more.
fn split(total: u32, views: usize) -> Vec<u32> {
    let views = views.max(1) as u32;
    (0..views)
        .map(|j| total / views + u32::from(j < total % views))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sharer(session: u64, key: &[u8], view: &[u8]) -> Sharer {
        Sharer {
            session,
            key: key.to_vec(),
            view: view.to_vec(),
            camera: [session as f32, 0.0, 0.0],
        }
    }

    fn made(plan: Plan) -> Pool {
        match plan {
            Plan::Make(pool) => pool,
            Plan::Reuse { .. } => panic!("expected the stages to be made"),
        }
    }

    fn reuses(s: &mut Sharing, session: u64, key: &[u8], view: &[u8]) -> bool {
        matches!(
            s.plan(Some(&sharer(session, key, view)), [0.0; 3]),
            Plan::Reuse { .. }
        )
    }

    /// Sessions joining make the stages again with their views added; then the first of a tick
    /// makes them from every view of the last one and the others reuse them.
    #[test]
    fn a_tick_makes_the_shared_stages_once_from_every_sharing_view() {
        let mut s = Sharing::default();
        let pool = made(s.plan(Some(&sharer(1, b"k", b"a")), [1.0, 0.0, 0.0]));
        assert_eq!(pool.cameras, vec![[1.0, 0.0, 0.0]]);
        // Session 2 joins: made again for views a and b; session 3's view equals 1's.
        let pool = made(s.plan(Some(&sharer(2, b"k", b"b")), [0.0; 3]));
        assert_eq!(pool.cameras, vec![[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
        assert_eq!(
            made(s.plan(Some(&sharer(3, b"k", b"a")), [0.0; 3]))
                .cameras
                .len(),
            2
        );
        // Session 1 again: a new tick from the three sessions' two views; 2 and 3 reuse it.
        let pool = made(s.plan(Some(&sharer(1, b"k", b"a")), [0.0; 3]));
        assert_eq!(pool.cameras, vec![[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
        assert!(reuses(&mut s, 2, b"k", b"b"));
        assert!(reuses(&mut s, 3, b"k", b"a"));
        assert!(
            !reuses(&mut s, 3, b"k", b"a"),
            "session 3 used them already"
        );
        assert!(reuses(&mut s, 1, b"k", b"a"));
        // Another key: made for itself, from its own view only.
        let pool = made(s.plan(Some(&sharer(2, b"other", b"b")), [0.0; 3]));
        assert_eq!(pool.cameras, vec![[2.0, 0.0, 0.0]]);
        // A frame that does not share makes its own in lighting buffer 0, leaving the shared
        // ones as they were: session 2, back at key k, reuses this tick's (made by session 3
        // from its view too).
        assert_eq!(made(s.plan(None, [5.0, 0.0, 0.0])).lighting, 0);
        assert!(reuses(&mut s, 2, b"k", b"b"));
    }

    /// Sessions of two keys taking turns share within each key, in a lighting buffer per key,
    /// each key's pool holding its own sessions' views only.
    #[test]
    fn two_keys_taking_turns_share_within_each() {
        let mut s = Sharing::default();
        let sessions = [(1, b"k"), (2, b"j"), (3, b"k"), (4, b"j")];
        for round in 0..3 {
            for (session, key) in sessions {
                let frame = sharer(session, key, &[session as u8]);
                match s.plan(Some(&frame), [0.0; 3]) {
                    Plan::Make(pool) => {
                        assert!(
                            round == 0 || session <= 2,
                            "round {round}, session {session}"
                        );
                        assert_eq!(pool.lighting, if key == b"k" { 1 } else { 2 });
                        let other = if key == b"k" { [2.0, 4.0] } else { [1.0, 3.0] };
                        assert!(pool.cameras.iter().all(|c| !other.contains(&c[0])));
                    }
                    Plan::Reuse { sessions, lighting } => {
                        assert!(round > 0 && session > 2, "round {round}, session {session}");
                        assert_eq!((sessions, lighting), (2, if key == b"k" { 1 } else { 2 }));
                    }
                }
            }
        }
    }

    /// More inputs than lighting buffers: the least recently used gives its buffer up.
    #[test]
    fn new_inputs_take_the_least_recently_used_buffer() {
        let mut s = Sharing::default();
        let keys: Vec<Vec<u8>> = (0..=MAX_SHARED_INPUTS as u8).map(|k| vec![k]).collect();
        let buffers: Vec<usize> = keys
            .iter()
            .enumerate()
            .map(|(i, key)| made(s.plan(Some(&sharer(i as u64, key, b"v")), [0.0; 3])).lighting)
            .collect();
        let mut want: Vec<usize> = (1..=MAX_SHARED_INPUTS).collect();
        want.push(1);
        assert_eq!(buffers, want, "the first input's buffer went to the last");
        // The first input comes again: made anew (its proxies are gone), in the next oldest.
        assert_eq!(
            made(s.plan(Some(&sharer(0, &keys[0], b"v")), [0.0; 3])).lighting,
            2
        );
    }

    /// A session gone for two whole ticks is no longer pooled.
    #[test]
    fn views_of_sessions_gone_two_ticks_are_left_out() {
        let mut s = Sharing::default();
        let mut views = |session| {
            made(s.plan(Some(&sharer(session, b"k", &[session as u8])), [0.0; 3])).cameras
        };
        views(1);
        views(2);
        // Session 2 rendered in the first tick: pooled into the second and third, not the
        // fourth.
        assert_eq!(views(1).len(), 2);
        assert_eq!(views(1).len(), 2);
        assert_eq!(views(1).len(), 1);
    }

    #[test]
    fn samples_are_split_evenly_over_the_views() {
        assert_eq!(split(256, 1), vec![256]);
        assert_eq!(split(256, 3), vec![86, 85, 85]);
        assert_eq!(split(2, 4), vec![1, 1, 0, 0]);
        for views in 1..70 {
            assert_eq!(split(256, views).iter().sum::<u32>(), 256);
        }
    }
}
