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
//! and a frame with another key makes them from its own view alone (so a session that changes
//! its light stops sharing at once, and its frame is what it would be alone). The proxies hold
//! one key's at a time: sessions of two keys taking turns make them every frame, each from its
//! key's sessions' views. Two inputs depend on the camera and are pooled over
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

/// What a frame does with the shared stages.
pub enum Plan {
    /// The proxies hold what this frame's inputs make, for this many sessions: skip the
    /// shared stages.
    Reuse { sessions: usize },
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
}

/// What the proxies hold, made by a sharing frame.
struct Made {
    key: Vec<u8>,
    /// The sessions whose views they were made from.
    pooled: Vec<u64>,
    /// The sessions that rendered with them (their maker first).
    users: Vec<u64>,
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
    /// What the proxies hold, if a sharing frame made them.
    made: Option<Made>,
    /// Counts the ticks: a tick starts where a session comes again to the proxies it used.
    tick: u64,
    slots: Vec<Slot>,
    /// Every slot's view samples, `per_slot` each, copied in after each sharing frame's gather.
    samples: Option<(wgpu::Buffer, u32)>,
}

impl Sharing {
    /// Decides what this frame does, and records its view. `sharer`: `None` for a frame that
    /// does not share (it makes the stages from its own view and leaves nothing to share).
    pub fn plan(&mut self, sharer: Option<&Sharer>, camera: [f32; 3]) -> Plan {
        let Some(s) = sharer else {
            self.made = None;
            return Plan::Make(Pool {
                cameras: vec![camera],
                slots: None,
                sessions: 0,
            });
        };
        let (pooled, users) = match self.made.take().filter(|m| m.key == s.key) {
            // Made from this session's view this tick, and not used by it yet.
            Some(mut m) if m.pooled.contains(&s.session) && !m.users.contains(&s.session) => {
                m.users.push(s.session);
                let sessions = m.pooled.len();
                self.made = Some(m);
                self.record(s);
                return Plan::Reuse { sessions };
            }
            // A session new to this tick: made again within the tick, its view added.
            Some(mut m) if !m.users.contains(&s.session) => {
                m.pooled.push(s.session);
                m.users.push(s.session);
                self.record(s);
                (m.pooled, m.users)
            }
            // Its own proxies again: a new tick, from the views of every session that rendered
            // with the same inputs in the last two.
            Some(_) => {
                self.tick += 1;
                self.record(s);
                (self.live(&s.key), vec![s.session])
            }
            // Other inputs: made for this frame alone, as nothing shares them yet (sessions of
            // two inputs taking turns make their own every frame, without pooling).
            None => {
                self.tick += 1;
                self.record(s);
                (vec![s.session], vec![s.session])
            }
        };
        let pool = self.pool(&pooled);
        self.made = Some(Made {
            key: s.key.clone(),
            pooled,
            users,
        });
        Plan::Make(pool)
    }

    /// The slot of `s`'s session, now holding its view at this tick.
    fn record(&mut self, s: &Sharer) {
        let tick = self.tick;
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

    /// The sessions with `key` that rendered in the last two ticks or this one.
    fn live(&self, key: &[u8]) -> Vec<u64> {
        self.slots
            .iter()
            .filter(|s| s.key == key && s.seen + 2 >= self.tick)
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
        // A frame that does not share leaves nothing to reuse.
        made(s.plan(None, [5.0, 0.0, 0.0]));
        made(s.plan(Some(&sharer(3, b"other", b"c")), [0.0; 3]));
    }

    /// Sessions of two keys taking turns make the stages every frame (the proxies hold one
    /// key's at a time), each key's from its own sessions' views only.
    #[test]
    fn two_keys_taking_turns_make_their_own() {
        let mut s = Sharing::default();
        for _ in 0..3 {
            for (session, key) in [(1, b"k"), (2, b"j"), (3, b"k")] {
                let frame = sharer(session, key, &[session as u8]);
                let pool = made(s.plan(Some(&frame), [0.0; 3]));
                assert_eq!(pool.cameras.contains(&[2.0, 0.0, 0.0]), session == 2);
            }
        }
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
