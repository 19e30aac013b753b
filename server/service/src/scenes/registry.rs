//! The registry of held scenes: loading, leasing, listing and deleting them, and handing
//! precomputations to the worker.

use super::*;

impl Drop for SceneRegistry {
    /// Ends the workers (a job running finishes first).
    fn drop(&mut self) {
        self.jobs.close();
    }
}

/// Whether `caller` may delete a scene whose owner digest is `owner` (`None`: anyone).
pub fn owner_allows(owner: Option<&str>, caller: Option<&str>) -> bool {
    owner.is_none_or(|digest| {
        caller
            .map(crate::service::scene_store::owner_digest)
            .as_deref()
            == Some(digest)
    })
}

impl SceneRegistry {
    /// Starts the precompute workers (two threads, see [`JobQueue`]; a precomputation may use
    /// rayon, and `gpu` where it can).
    pub fn new(store: Store, limits: &Limits, gpu: Option<GpuContext>) -> Arc<Self> {
        let grace = Duration::from_secs(limits.unwanted_precompute_secs);
        Self::with_workers(
            limits,
            Some(QUICK_JOB_SECONDS),
            move |entry, key, stopping| {
                worker::precompute(&store, gpu.as_ref(), entry, key, grace, stopping)
            },
        )
    }

    /// [`SceneRegistry::new`] with `work` run on a worker thread for each queued job, plus a
    /// second worker for jobs estimated at most `quick` seconds. `work`'s third argument says
    /// whether the registry is stopping (a build may end early then).
    pub(super) fn with_workers(
        limits: &Limits,
        quick: Option<f64>,
        work: impl Fn(&Arc<SceneEntry>, &PrecomputeKey, &dyn Fn() -> bool) + Send + Sync + 'static,
    ) -> Arc<Self> {
        let jobs = Arc::new(JobQueue::default());
        let work = Arc::new(work);
        let lanes = [("precompute", f64::INFINITY)]
            .into_iter()
            .chain(quick.map(|q| ("precompute-quick", q)));
        let mut workers = Vec::new();
        for (name, max_seconds) in lanes {
            let (jobs, work) = (Arc::clone(&jobs), Arc::clone(&work));
            let worker = std::thread::Builder::new()
                .name(name.into())
                .spawn(move || {
                    while let Some(job) = jobs.next(max_seconds) {
                        let Some(entry) = job.scene.upgrade() else {
                            continue;
                        };
                        let key = job.key;
                        // A bug in one scene's precomputation must not stop every later
                        // scene's.
                        let stopping = || jobs.is_closed();
                        let run = || work(&entry, &key, &stopping);
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
            workers.push(worker);
        }
        Arc::new(Self {
            scenes: Mutex::new(BTreeMap::new()),
            jobs,
            workers: Mutex::new(workers),
            max_scenes: limits.max_scenes as usize,
            max_lights: limits.max_lights as usize,
            budget: Arc::new(MemoryBudget::new(limits)),
            quotas: TokenQuotas::new(limits),
        })
    }

    /// Ends the precompute workers and waits for them: a build running stops at its next
    /// cancellation check. Their GPU context goes with them, so that a process exiting after
    /// this leaves no thread inside the driver (lavapipe crashed at exit when one was).
    pub fn stop_workers(&self) {
        self.jobs.close();
        let workers = std::mem::take(&mut *lock(&self.workers));
        for worker in workers {
            if worker.join().is_err() {
                tracing::error!("a precompute worker panicked");
            }
        }
    }

    /// The memory budgets every scene is taken from.
    pub fn budget(&self) -> &MemoryBudget {
        &self.budget
    }

    /// Adds a loaded scene under `id` (a new random id when `None`), deletable only with the
    /// token whose [`owner_digest`](crate::service::scene_store::owner_digest) is `owner` when there is
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
            self.max_lights,
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
            metrics::gauge!(crate::service::metrics::SCENES).set(scenes.len() as f64);
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
            self.max_lights,
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
        metrics::gauge!(crate::service::metrics::SCENES).set(scenes.len() as f64);
        Ok(())
    }

    /// Drops scene `id` if no session uses it (it was deleted from the scene store by
    /// another replica); returns whether it was dropped.
    pub fn forget(&self, id: &str) -> bool {
        let mut scenes = lock(&self.scenes);
        let unused = scenes.get(id).is_some_and(|e| e.in_use() == 0);
        if unused {
            scenes.remove(id);
            metrics::gauge!(crate::service::metrics::SCENES).set(scenes.len() as f64);
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
