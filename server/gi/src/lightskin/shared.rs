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
//! the camera: the method and its parameters, the lights uniform and poses (`passes::reuse`,
//! with the renderer's epoch) and which cache set is loaded. What the proxies hold was made
//! for one key; a frame with that key uses them unless its session has already used them
//! since they were made (then a tick has passed: they are made again), and a frame with
//! another key makes them for its own (so a session that changes its light stops sharing at
//! once, and its frame is what it would be alone). Two inputs do depend on the camera, and
//! are pooled over the *views* (camera and size) of the sessions that shared the last tick
//! or this one, identical views counted once:
//! - BRSM's N_VS view samples (eq. 10–11): view j of m gives its first N_VS/m Halton
//!   samples, so the VALs are drawn for what every sharing session sees;
//! - the direction v of the glossy proxies' lobe (eq. 14/15): the mean of the unit directions
//!   from the cache to each view's camera.
//!
//! With one view (one session, or sessions looking through the same camera) this is exactly
//! the unshared frame, bit for bit; with several, a session's indirect light differs from its
//! unshared frame by what `bench/results/*-shared-views.md` measures. Frames that do not
//! share (one-shot renders, reuse off, debug views) use their own view alone and leave
//! nothing to share.

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
    /// The proxies hold what this frame's inputs make: skip the shared stages.
    Reuse,
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
    /// The key the proxies were last made for by a sharing frame, and the sessions that used
    /// them since (its maker first).
    made: Option<(Vec<u8>, Vec<u64>)>,
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
            });
        };
        if let Some((key, users)) = &mut self.made {
            if *key == s.key && !users.contains(&s.session) {
                users.push(s.session);
                self.record(s);
                return Plan::Reuse;
            }
        }
        self.tick += 1;
        self.made = Some((s.key.clone(), vec![s.session]));
        self.record(s);
        Plan::Make(self.pool(&s.key))
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

    /// The views of the sessions with `key` seen in the last tick or this one, by session,
    /// equal views once.
    fn pool(&self, key: &[u8]) -> Pool {
        let mut live: Vec<(usize, &Slot)> = self
            .slots
            .iter()
            .enumerate()
            .filter(|(_, s)| s.key == key && s.seen + 1 >= self.tick)
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
            Plan::Reuse => panic!("expected the stages to be made"),
        }
    }

    /// Sessions in turn: the first of a tick makes the stages, the others reuse them, and the
    /// first one's next frame starts a tick pooling every view that shared the last one.
    #[test]
    fn a_tick_makes_the_shared_stages_once_from_every_sharing_view() {
        let mut s = Sharing::default();
        let pool = made(s.plan(Some(&sharer(1, b"k", b"a")), [1.0, 0.0, 0.0]));
        assert_eq!(pool.cameras, vec![[1.0, 0.0, 0.0]]);
        assert!(matches!(
            s.plan(Some(&sharer(2, b"k", b"b")), [0.0; 3]),
            Plan::Reuse
        ));
        assert!(matches!(
            s.plan(Some(&sharer(3, b"k", b"a")), [0.0; 3]),
            Plan::Reuse
        ));
        // Session 1 again: a new tick, pooling views a and b (session 3's equals session 1's).
        let pool = made(s.plan(Some(&sharer(1, b"k", b"a")), [0.0; 3]));
        assert_eq!(pool.cameras, vec![[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
        // Another key: made for itself, from its own view only.
        let pool = made(s.plan(Some(&sharer(2, b"other", b"b")), [0.0; 3]));
        assert_eq!(pool.cameras, vec![[2.0, 0.0, 0.0]]);
        // A frame that does not share leaves nothing to reuse.
        made(s.plan(None, [5.0, 0.0, 0.0]));
        made(s.plan(Some(&sharer(3, b"other", b"c")), [0.0; 3]));
    }

    /// A session gone for a whole tick is no longer pooled.
    #[test]
    fn views_of_sessions_gone_a_tick_are_left_out() {
        let mut s = Sharing::default();
        made(s.plan(Some(&sharer(1, b"k", b"a")), [0.0; 3]));
        assert!(matches!(
            s.plan(Some(&sharer(2, b"k", b"b")), [0.0; 3]),
            Plan::Reuse
        ));
        assert_eq!(
            made(s.plan(Some(&sharer(1, b"k", b"a")), [0.0; 3]))
                .cameras
                .len(),
            2
        );
        assert_eq!(
            made(s.plan(Some(&sharer(1, b"k", b"a")), [0.0; 3]))
                .cameras
                .len(),
            1
        );
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
