//! The precompute worker: a queue that serves short jobs first (a long one once it has
//! waited its length) and the build of one set, with progress and cancellation.

use super::*;

impl JobQueue {
    /// Queues `job` unless [`MAX_QUEUED_JOBS`] wait already.
    pub(super) fn push(&self, job: Job) -> bool {
        let mut jobs = lock(&self.jobs);
        if jobs.len() >= MAX_QUEUED_JOBS {
            return false;
        }
        jobs.push(job);
        self.changed.notify_all();
        true
    }

    /// The next job estimated at most `max_seconds`, waiting for one; `None` once closed.
    pub(super) fn next(&self, max_seconds: f64) -> Option<Job> {
        let mut jobs = lock(&self.jobs);
        loop {
            if self.is_closed() {
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

    pub(super) fn is_closed(&self) -> bool {
        self.closed.load(Ordering::Acquire)
    }

    pub(super) fn close(&self) {
        self.closed.store(true, Ordering::Release);
        let _guard = lock(&self.jobs);
        self.changed.notify_all();
    }
}

/// Runs on the precompute worker: loads or computes one precomputation and records the
/// outcome.
pub(super) fn precompute(
    store: &Store,
    gpu: Option<&GpuContext>,
    scene: &Arc<SceneEntry>,
    key: &PrecomputeKey,
    grace: Duration,
    stopping: &dyn Fn() -> bool,
) {
    let update = |f: &mut dyn FnMut(&mut Variant)| scene.update_variant(key, f);
    // Held by nobody but this worker (the scene was deleted and no request renders it any
    // more, or it was a one-shot render's upload whose request has ended), or nobody has
    // waited for it for `grace`: its session was deleted, its one-shot gave up.
    let cancelled = || stopping() || Arc::strong_count(scene) == 1 || scene.unwanted(key, grace);
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
