//! A held scene and the state of its precomputations: which sets exist, are wanted, are
//! being built or failed, what they hold of the budgets, and who still waits for them.

use super::*;

impl Demands {
    /// Whether nobody has held a demand for `key` for `grace` (a key never demanded, such as
    /// a comparison's BVH, is not unwanted).
    pub(super) fn unwanted(&self, key: &PrecomputeKey, grace: Duration) -> bool {
        lock(&self.0)
            .get(key)
            .is_some_and(|(holders, since)| *holders == 0 && since.elapsed() >= grace)
    }
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

impl Variant {
    /// Marks the set failed with `error` and gives its units back to the budget (it stays
    /// listed with the error, so that a request for it is answered at once, not rebuilt).
    pub(super) fn fail(&mut self, error: String) {
        self.state = PrecomputeState::Failed;
        self.error = Some(error);
        self.held = None;
    }

    pub(super) fn info(&self) -> Precomputed {
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

/// Decoded texture bytes of a scene, as the budgets count them: its textures and its
/// environment image.
pub fn texture_bytes(scene: &Scene) -> u64 {
    scene
        .textures
        .iter()
        .map(|t| t.rgba8.len() as u64)
        .sum::<u64>()
        + scene.environment_image.as_ref().map_or(0, |i| i.bytes())
}

impl SceneEntry {
    /// A scene with its texture bytes and triangles taken from `budget`, or 413 naming the
    /// budget it would overrun.
    pub(super) fn new(
        scene: Scene,
        source: String,
        id: String,
        load_ms: f64,
        owner: Option<String>,
        budget: &Arc<MemoryBudget>,
        max_lights: usize,
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
            default_lights: default_lights(&scene, max_lights.min(MAX_LIGHTS)),
            emitter_stand_in: emitter_stand_in(&scene),
            facts: SceneFacts::of(&scene),
            node_bounds: scene.node_bounds(),
            nodes: node_infos(&scene),
            animations: animation_infos(&scene),
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
            default_lights: self.default_lights.clone(),
            camera_region: s.camera_region.map(|r| Bounds {
                min: r.min.into(),
                max: r.max.into(),
            }),
            environment_image: s.environment_image.as_ref().map(|i| {
                lightcast_protocol::EnvironmentImageInfo {
                    name: i.name.clone(),
                    width: i.source_width,
                    height: i.source_height,
                    kept_width: i.width,
                    kept_height: i.height,
                }
            }),
            nodes: self.nodes.clone(),
            animations: self.animations.clone(),
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
        crate::service::cost::check_precompute(entry, gi, key, &self.facts, limits)
    }

    /// Refuses a new set whose estimated size exceeds the per-set limit or what is left of
    /// the total.
    pub(super) fn check_budget(
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
                        (budget.advice)(key, &self.facts, per_set)
                    ),
                ));
            }
        }
        self.reserve(entry, key).map(drop)
    }

    /// The pool a kind's units are taken from, with its flag.
    pub(super) fn pool(&self, pool: BudgetPool) -> Result<(&Arc<Pool>, &'static str), ApiError> {
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
    pub(super) fn per_set_limit(&self, pool: BudgetPool) -> Option<(u64, &'static str)> {
        match pool {
            BudgetPool::Declared {
                per_set: Some(limit),
                ..
            } => Some((self.budget.gi_limit(limit), limit.flag)),
            _ => None,
        }
    }

    /// Takes a new set's estimated units from its pool (nothing for unbudgeted kinds).
    pub(super) fn reserve(
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
                    (budget.advice)(key, &self.facts, pool.available())
                ),
            )
        })
    }

    /// Makes a built set's share of its pool its real size. The light caches' estimate is of
    /// flat geometry; curved or folded surfaces (or a small cache angle) can make more, and a
    /// set beyond the per-set limit or what is left of the total is refused, its memory freed.
    pub(super) fn hold_built(
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

    pub(super) fn update_variant(&self, key: &PrecomputeKey, f: &mut dyn FnMut(&mut Variant)) {
        if let Some(v) = lock(&self.variants).iter_mut().find(|v| v.key == *key) {
            f(v);
        }
    }

    /// Forgets precomputation `key`, cancelled because nobody waits for it (its units go back
    /// to the budget; a later request queues it afresh).
    pub(super) fn drop_cancelled(&self, key: &PrecomputeKey) {
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
    pub(super) fn unwanted(&self, key: &PrecomputeKey, grace: Duration) -> bool {
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

impl Drop for SceneLease {
    fn drop(&mut self) {
        self.0.sessions.fetch_sub(1, Ordering::Relaxed);
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

fn node_infos(scene: &Scene) -> Vec<lightcast_protocol::NodeInfo> {
    scene
        .nodes
        .iter()
        .zip(scene.node_bounds())
        .map(|(n, b)| lightcast_protocol::NodeInfo {
            id: n.id,
            name: n.name.clone(),
            parent: n.parent,
            movable: n.movable,
            bounds: b.map(|b| Bounds {
                min: b.min.into(),
                max: b.max.into(),
            }),
            translation: n.local.map(|t| t.translation.into()),
            rotation: n.local.map(|t| t.rotation.into()),
            scale: n.local.map(|t| t.scale.into()),
            world: n.rest_world.to_cols_array(),
        })
        .collect()
}

fn animation_infos(scene: &Scene) -> Vec<lightcast_protocol::AnimationInfo> {
    scene
        .animations
        .iter()
        .map(|a| {
            let mut nodes: Vec<u32> = a.channels.iter().map(|c| c.node).collect();
            nodes.sort_unstable();
            nodes.dedup();
            lightcast_protocol::AnimationInfo {
                name: a.name.clone(),
                duration: a.duration(),
                nodes,
            }
        })
        .collect()
}
