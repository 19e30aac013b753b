//! LightSkin light caches fed by Bidirectional Reflective Shadow Maps (seed paper 004), the
//! `lightskin` and `brsm` methods. Per model, [`caches`] are precomputed once and kept by
//! [`cache_store`]; per frame, [`sampling`] runs the BRSM stages (RSM, [`importance`],
//! [`cumulative_sums`], [`val_select`]), [`cache_lighting`] lights every cache from the VALs,
//! [`proxy_occlusion`] dims hidden proxies and [`indirect_light`] interpolates them per pixel.
//! [`cache_buffers`] holds the caches on the GPU; [`cpu`] is the CPU reference of the equations.

pub mod bench;
pub mod cache_buffers;
pub mod cache_lighting;
pub mod cache_store;
pub mod cache_visibility;
pub mod caches;
pub mod cpu;
pub mod cumulative_sums;
pub mod importance;
pub mod indirect_light;
pub mod limits;
pub mod params;
pub mod proxy_occlusion;
pub mod sampling;
pub mod shaders;
pub mod shared;
pub mod stages;
pub mod val_select;
pub mod views;

use super::common::bvh::SceneBvh;
use super::common::params::{emitters, roughness_override};
use super::cost::{self, Cost, FrameShape, Knob};
use super::precompute::{BudgetPool, Built, PrecomputeEntry, PrecomputeKey, SceneData, UnitBudget};
use super::{
    DebugCapture, DebugData, FrameInputs, GiError, InvalidSetting, Method, MethodEntry,
    ProgressBuffer, SceneResources,
};
use crate::gpu::readback::{read_buffer, stage_buffer, PendingMap};
use crate::gpu::{timing::FrameStages, GpuContext, GpuError};
use crate::passes::gbuffer::GBuffer;
use crate::passes::ShaderPass;
use cache_buffers::CacheBuffers;
use cache_lighting::{CacheLighting, CacheLightingPass, ValSource};
use cache_store::CacheStore;
use cache_visibility::CacheVisibility;
use caches::{CacheParams, CacheSet};
use indirect_light::{CacheInputs, IndirectLightPass};
use lightcast_protocol::{GiMethod, GiParams, View};
use params::CACHE_VISIBILITY;
use proxy_occlusion::ProxyOcclusionPass;
use sampling::{SamplingReadback, ValSampling};
use shared::{Plan, Sharer, Sharing};
use std::any::{Any, TypeId};
use std::sync::Arc;

/// LightSkin: every RSM texel is a VAL (eq. 3–7).
pub const LIGHTSKIN: GiMethod = GiMethod::new("lightskin");
/// BRSM: an importance-sampled subset of the VALs (eq. 10–15).
pub const BRSM: GiMethod = GiMethod::new("brsm");

use crate::passes::rsm::max_rsm_size;
pub use crate::passes::rsm::MAX_RSM_SIZE;
pub use params::Settings;

/// Every module with its pipeline's bind groups (see [`ShaderPass`]).
const PASSES: &[ShaderPass] = &[
    ShaderPass::new(&shaders::IMPORTANCE, &[&importance::GROUP]),
    ShaderPass::new(&shaders::CUMULATIVE_SUMS, &[&cumulative_sums::GROUP]),
    ShaderPass::new(&shaders::VAL_SELECT, &[&val_select::GROUP]),
    ShaderPass::new(&shaders::CACHE_LIGHTING, &[&cache_lighting::GROUP]),
    ShaderPass::new(&shaders::INDIRECT_LIGHT, &[&indirect_light::GROUP]),
    ShaderPass::new(&shaders::PROXY_OCCLUSION, &[&proxy_occlusion::GROUP]),
];

pub const ENTRY: MethodEntry = MethodEntry {
    tables: &[params::LIGHTSKIN, params::BRSM],
    type_id: TypeId::of::<LightSkin>,
    validate,
    check_table: |gi| Settings::of(gi).map(drop),
    create: |r| Ok(Box::new(LightSkin::new(r))),
    precompute: Some(&PRECOMPUTE),
    cost,
    knobs: &[
        Knob::lower(&params::VAL_COUNT),
        Knob::lower(&params::VIEW_SAMPLES),
        Knob::lower(&crate::gi::common::params::RSM_SIZE),
    ],
    shaders: PASSES,
    stages: stages::ALL,
    limits: limits::LIMITS,
    downscales: true,
    samples_environment: false,
    follows_moved_nodes,
    bench: Some(&bench::SWEEP),
};

/// One frame's stages (`set_units` are the light caches C): the RSM, BRSM's importance
/// (N_VS view samples per texel) and VAL draw, cache lighting (C × VALs, every RSM texel for
/// `lightskin`), proxy occlusion (C²) and the per-pixel interpolation. Weights in reference
/// ns per item, measured on the Cornell box (6,596 caches, 64×48): 16 per cache·VAL
/// (val_count 512 … 16,384, LightSkin RSM 64² … 256²), 4.5 per texel·view sample, 200 per
/// texel for BRSM's cumulative sums and draw (RSM 1024² and 2048², besides the RSM's own
/// 100), 13 per cache pair, 1 µs per interpolated pixel.
fn cost(gi: &GiParams, shape: &FrameShape, cost: &mut Cost) {
    cost::rsm(gi, shape, cost);
    let texels = shape.rsm_texels(gi);
    let pixels = shape.reduced_pixels(gi);
    let brsm = gi.method == crate::gi::lightskin::BRSM;
    let Ok(gi) = Settings::of(gi) else {
        return;
    };
    let caches = caches_in(shape.set_units, gi.cache_visibility) as f64;
    if brsm {
        cost.add(
            "importance (faces × rsm_size² × view_samples)",
            texels * f64::from(gi.view_samples),
            4.5,
        );
        cost.add("VAL selection (faces × rsm_size²)", texels, 200.0);
        cost.add(
            "cache lighting (caches × val_count)",
            caches * f64::from(gi.val_count),
            16.0,
        );
    } else {
        cost.add(
            "cache lighting (caches × faces × rsm_size²)",
            caches * texels,
            16.0,
        );
    }
    if gi.occlusion {
        cost.add("proxy occlusion (caches²)", caches * caches, 13.0);
    }
    cost.add(
        "cache interpolation (pixels / indirect_downscale²)",
        pixels,
        1000.0,
    );
}

/// The light caches (paper §3), one set per scene and (d_eps, θ_eps), kept in the store.
pub static PRECOMPUTE: PrecomputeEntry = PrecomputeEntry {
    kind: lightcast_protocol::LIGHT_CACHES,
    label: "light caches",
    key: |gi, facts| {
        let gi = Settings::of(gi)?;
        let defaults = CacheParams::for_area(facts.surface_area, facts.radius);
        let params = CacheParams {
            d_eps: gi.cache_distance.unwrap_or(defaults.d_eps),
            theta_eps_degrees: gi.cache_angle.unwrap_or(defaults.theta_eps_degrees),
        };
        // The count is checked against the service's budgets, which are within the format's
        // own cap (`validate_for_area`, which the precomputation applies too).
        params.validate().map_err(|e| {
            let field = match e {
                caches::CacheError::InvalidAngle(_) => "cache_angle",
                _ => "cache_distance",
            };
            InvalidSetting::new(field, e.to_string())
        })?;
        Ok(cache_key(&params, gi.cache_visibility))
    },
    budget: Some(UnitBudget {
        pool: BudgetPool::Declared {
            total: &limits::MAX_TOTAL_CACHES,
            per_set: Some(&limits::MAX_CACHES_PER_SET),
        },
        unit: "light caches",
        field: "cache_distance",
        advice: |key, facts, allowed| {
            let side = visibility_side(key);
            let distance = caches::min_distance_for(facts.surface_area, caches_in(allowed, side));
            if side == 0 {
                format!("use cache_distance >= {distance}")
            } else {
                format!(
                    "each cache's visibility map counts as {} caches more: use a smaller \
                     cache_visibility, or cache_distance >= {distance}",
                    cache_visibility::vertices(side).div_ceil(16)
                )
            }
        },
    }),
    estimate: |key, facts| {
        budget_units(
            cache_params(key).estimated_caches(facts.surface_area),
            visibility_side(key),
        )
    },
    // Placement samples the surface at a quarter of d_eps (about 8 per cache) plus every
    // triangle, each a nearest-neighbour query: 1.5 µs per sample on the Cornell box.
    cost: |key, facts, cost| {
        let caches = cache_params(key).estimated_caches(facts.surface_area) as f64;
        cost.add(
            "cache placement (8 × caches + triangles samples)",
            8.0 * caches + facts.triangles as f64,
            1500.0,
        );
        let side = f64::from(visibility_side(key));
        if side > 0.0 {
            let levels = (facts.triangles.max(2) as f64).log2().max(10.0);
            cost.add(
                "cache visibility rays (caches × (cache_visibility + 1)²)",
                caches * (side + 1.0) * (side + 1.0),
                VISIBILITY_NS_PER_RAY_LEVEL * levels,
            );
            cost.add(
                "BVH build (triangles)",
                facts.triangles as f64,
                super::common::bvh::BUILD_NS_PER_TRIANGLE,
            );
        }
    },
    knobs: &[],
    build: |scene, key, env| {
        let mut caches = CacheStore::new(&env.store.dir);
        if let Some(max) = env.store.max_bytes {
            caches = caches.with_max_bytes(max);
        }
        let (mut set, from_store) = caches
            .load_or_compute(scene, &cache_params(key), env.progress)
            .map_err(|e| e.to_string())?;
        let side = visibility_side(key);
        if side > 0 {
            let bvh = SceneBvh::build(scene).map_err(|e| e.to_string())?;
            // Rays leave a ten-thousandth of the scene's radius off the cache's surface and
            // count as reaching the far side of the scene when they hit nothing.
            let radius = scene.bounds.radius();
            set.visibility = Some(CacheVisibility::build(
                &bvh,
                &set.caches,
                side,
                (1e-4 * radius, 4.0 * radius),
                env.progress,
                env.cancelled,
            )?);
        }
        Ok(Built {
            units: budget_units(set.caches.len() as u64, side),
            data: Arc::new(set),
            from_store,
        })
    },
    extension: Some(cache_store::EXTENSION),
};

/// Reference ns per visibility ray and BVH level, traced on the CPU (`cache_visibility`): the
/// 4-block street's 2.17 M rays (7,511 caches at 16², 1,088 triangles) took 0.33 s on this
/// machine's 2 cores, 150 ns a ray at the 10 levels `cost` assumes for small scenes.
const VISIBILITY_NS_PER_RAY_LEVEL: f64 = 15.0;

/// [`MethodEntry::follows_moved_nodes`]: the caches of a movable model move with it (seed 004
/// §3), but visibility maps are traced with every node at rest.
fn follows_moved_nodes(gi: &GiParams) -> Result<(), InvalidSetting> {
    if CACHE_VISIBILITY.u32(gi) > 0 {
        return Err(InvalidSetting {
            field: CACHE_VISIBILITY.name,
            reason: "visibility maps are traced with every node at rest; set 0 to move nodes"
                .into(),
        });
    }
    Ok(())
}

/// The key of the light caches for `params`, with visibility maps of `visibility`² cells
/// ((visibility + 1)² rays) per cache (none for 0, which keeps the key the sets had before
/// the maps existed).
pub fn cache_key(params: &CacheParams, visibility: u32) -> PrecomputeKey {
    let mut params = vec![
        ("cache_distance", params.d_eps),
        ("cache_angle", params.theta_eps_degrees),
    ];
    if visibility > 0 {
        params.push((CACHE_VISIBILITY.name, visibility as f32));
    }
    PrecomputeKey {
        kind: PRECOMPUTE.kind,
        params,
    }
}

/// What `caches` caches with visibility maps of `side` cells per side count against the
/// cache budgets: a cache is 64 bytes, its map (side + 1)² floats of 4, so a map counts as
/// ⌈(side + 1)²/16⌉ caches more (20 in all at 16², 70 at 32²).
fn budget_units(caches: u64, side: u32) -> u64 {
    if side == 0 {
        return caches;
    }
    caches * (1 + cache_visibility::vertices(side).div_ceil(16))
}

/// The caches `units` of the cache budgets hold with visibility maps of `side` (the inverse
/// of [`budget_units`]).
fn caches_in(units: u64, side: u32) -> u64 {
    if side == 0 {
        return units;
    }
    units / (1 + cache_visibility::vertices(side).div_ceil(16))
}

/// The side of the visibility maps a [`PRECOMPUTE`] key asks for (0: none).
pub fn visibility_side(key: &PrecomputeKey) -> u32 {
    key.param(CACHE_VISIBILITY.name).map_or(0, |s| s as u32)
}

/// The cache parameters of a [`PRECOMPUTE`] key (NaN, which no set is built for, if not).
pub fn cache_params(key: &PrecomputeKey) -> CacheParams {
    CacheParams {
        d_eps: key.param("cache_distance").unwrap_or(f32::NAN),
        theta_eps_degrees: key.param("cache_angle").unwrap_or(f32::NAN),
    }
}

/// Checks the parameters the two methods read.
/// What the tables cannot say: the RSM within the light's faces.
fn validate(gi: &GiParams, faces: u32) -> Result<(), InvalidSetting> {
    let g = Settings::of(gi)?;
    InvalidSetting::check_range("rsm_size", g.rsm_size, 16, max_rsm_size(faces))
}

/// How `frame` shares the light-side stages (`shared`'s rule): `None` where it does not.
fn sharer(frame: &FrameInputs, cache_sets: u64) -> Option<Sharer> {
    let (session, inputs) = frame.history.zip(frame.shared)?;
    if frame.debug_view != View::FINAL {
        return None;
    }
    let mut key = serde_json::to_vec(frame.settings).ok()?;
    key.extend_from_slice(inputs);
    key.extend_from_slice(&cache_sets.to_le_bytes());
    let mut view = serde_json::to_vec(frame.camera).ok()?;
    view.extend_from_slice(&frame.width.to_le_bytes());
    view.extend_from_slice(&frame.height.to_le_bytes());
    Some(Sharer {
        session,
        key,
        view,
        camera: frame.camera.position,
    })
}

impl DebugCapture for sampling::SamplingCapture {
    fn read(
        self: Box<Self>,
        ctx: &GpuContext,
        submission: Option<&wgpu::SubmissionIndex>,
    ) -> Result<DebugData, GpuError> {
        Ok(DebugData(Arc::new((*self).read(ctx, submission)?)))
    }
}

/// The proxy lights of every cache, staged for the `caches` view.
struct LightingCapture {
    staged: wgpu::Buffer,
    count: usize,
}

impl DebugCapture for LightingCapture {
    fn read(
        self: Box<Self>,
        ctx: &GpuContext,
        submission: Option<&wgpu::SubmissionIndex>,
    ) -> Result<DebugData, GpuError> {
        let map = PendingMap::new(&self.staged);
        ctx.wait_for(submission)?;
        let mut lighting: Vec<CacheLighting> = bytemuck::pod_collect_to_vec(&map.finish()?);
        lighting.truncate(self.count);
        Ok(DebugData(Arc::new(lighting)))
    }
}

/// Per-scene state of the `lightskin` and `brsm` methods.
pub struct LightSkin {
    ctx: GpuContext,
    sampling: ValSampling,
    cache_pass: CacheLightingPass,
    occlusion_pass: ProxyOcclusionPass,
    indirect_pass: IndirectLightPass,
    caches: Option<CacheBuffers>,
    vertices: usize,
    /// Whether the last frame ran the sampling stages (their buffers hold its results).
    sampled: bool,
    /// Sessions sharing the light-side stages (`shared`).
    sharing: Sharing,
    /// Counts the cache sets loaded: a sharing key names the one its proxies were made for.
    cache_sets: u64,
    /// The lighting buffer the last frame's proxies are in (`CacheBuffers::lighting_at`).
    lighting: usize,
}

impl LightSkin {
    pub fn new(r: &SceneResources) -> Self {
        let device = &r.ctx.device;
        Self {
            ctx: r.ctx.clone(),
            sampling: ValSampling::new(device, &r.lights, &r.material_layout),
            cache_pass: CacheLightingPass::new(device),
            occlusion_pass: ProxyOcclusionPass::new(device),
            indirect_pass: IndirectLightPass::new(device),
            caches: None,
            vertices: r.scene.vertices.len(),
            sampled: false,
            sharing: Sharing::default(),
            cache_sets: 0,
            lighting: 0,
        }
    }

    /// Uploads the scene's light caches (the per-model precomputation, see [`cache_store`]).
    pub fn set_caches(&mut self, set: &CacheSet) -> Result<(), GiError> {
        if set.vertex_caches.len() != self.vertices {
            return Err(GiError::Scene(format!(
                "light caches were computed for {} vertices, but the scene has {}",
                set.vertex_caches.len(),
                self.vertices
            )));
        }
        self.caches = Some(CacheBuffers::new(&self.ctx.device, set));
        self.cache_sets += 1;
        Ok(())
    }

    /// Proxy lights of every cache from the last frame (blocking; for tests and debugging).
    pub fn read_cache_lighting(&self) -> Result<Option<Vec<CacheLighting>>, GpuError> {
        let Some(caches) = self.caches.as_ref().filter(|_| self.sampled) else {
            return Ok(None);
        };
        let mut lighting: Vec<CacheLighting> = bytemuck::pod_collect_to_vec(&read_buffer(
            &self.ctx,
            caches.lighting_at(self.lighting),
        )?);
        lighting.truncate(caches.count as usize);
        Ok(Some(lighting))
    }

    /// The sampling stages' results of the last frame, if it ran them (blocking readback).
    pub fn read_sampling(&self) -> Result<Option<SamplingReadback>, GpuError> {
        if !self.sampled {
            return Ok(None);
        }
        self.sampling.read_back(&self.ctx).map(Some)
    }
}

impl Method for LightSkin {
    fn set_scene_data(&mut self, data: &SceneData) -> Result<(), GiError> {
        let set = data.downcast_ref::<CacheSet>().ok_or_else(|| {
            GiError::Scene("LightSkin's scene data must be its light caches".into())
        })?;
        self.set_caches(set)
    }

    fn encode(
        &mut self,
        frame: &FrameInputs,
        stages: &mut FrameStages,
    ) -> Result<Option<ProgressBuffer>, GiError> {
        let r = frame.resources;
        let sharer = sharer(frame, self.cache_sets);
        let plan = self.sharing.plan(sharer.as_ref(), frame.camera.position);
        let lighting = match &plan {
            Plan::Reuse { lighting, .. } => *lighting,
            Plan::Make(pool) => pool.lighting,
        };
        self.lighting = lighting;
        let caches = self.caches.as_mut().ok_or_else(|| {
            GiError::Scene(
                "LightSkin needs the scene's light caches; call LightSkin::set_caches first".into(),
            )
        })?;
        caches.set_poses(&r.ctx.queue, &r.scene.nodes, frame.poses);
        caches.ensure_lighting(&r.ctx.device, lighting);
        let caches = &*caches;
        let method = frame.settings.method;
        let gi = &Settings::of(frame.settings)?;
        let queue = &r.ctx.queue;
        let device = &r.ctx.device;
        self.sampling.prepare(
            &r.ctx,
            frame.gbuffer,
            frame.light_faces,
            (&r.scene, emitters(frame.settings)),
            gi,
            frame.visibility_buffer,
        );
        let source = match method {
            crate::gi::lightskin::BRSM => ValSource::Selected {
                count: gi.val_count,
            },
            _ => ValSource::EveryTexel,
        };
        self.indirect_pass
            .prepare(queue, true, r.ctx.primitive_index);
        let indirect_group = self.indirect_pass.bind(
            device,
            &r.camera,
            frame.gbuffer,
            &CacheInputs {
                caches: &caches.caches,
                lighting: caches.lighting_at(lighting),
                vertex_caches: &caches.vertex_caches,
                scene: &r.scene_buffers,
            },
            frame.indirect,
        );
        // What the sampling buffers and proxies hold is this frame's only where it makes them.
        self.sampled = matches!(plan, Plan::Make(_));
        let brsm = method == crate::gi::lightskin::BRSM;
        let sampling = &self.sampling;
        if brsm {
            let sharing = &mut self.sharing;
            stages.stage(stages::VIEW_SAMPLES, |e| {
                sampling.encode_gather(e, gi);
                if let Some(s) = &sharer {
                    sharing.keep_samples(device, e, s.session, sampling.samples(), gi.view_samples);
                }
            })?;
        }
        // The light-side stages this frame's method and parameters run.
        let mut light_side = vec![crate::passes::stages::RSM];
        if sampling.rsm().visibility() {
            light_side.push(crate::passes::stages::RSM_RESOLVE);
        }
        if brsm {
            light_side.extend([
                stages::IMPORTANCE,
                stages::CUMULATIVE_SUMS,
                stages::VAL_SELECT,
            ]);
        }
        light_side.push(stages::CACHE_LIGHTING);
        if gi.occlusion {
            light_side.push(stages::PROXY_OCCLUSION);
        }
        let sessions = match &plan {
            Plan::Reuse { sessions, .. } => *sessions,
            Plan::Make(pool) => pool.sessions,
        };
        for &stage in light_side.iter().filter(|_| sessions > 1) {
            stages.shared(stage, sessions.min(usize::from(u16::MAX)) as u16);
        }
        match plan {
            // Another session's frame made them this tick for the same inputs.
            Plan::Reuse { .. } => {
                for stage in light_side {
                    stages.reused(stage);
                }
            }
            Plan::Make(pool) => {
                let lighting_chunks = self.cache_pass.prepare(
                    queue,
                    &pool.cameras,
                    caches,
                    sampling.rsm(),
                    source,
                    // The exponent the pixels' lobes take from the overridden roughness (within
                    // [1, 4096]), so caches and pixels agree.
                    roughness_override(frame.settings).map(crate::scene::brdf::phong_exponent),
                );
                let occlusion_chunks = self.occlusion_pass.prepare(queue, caches.count);
                let lighting_group = self.cache_pass.bind(
                    device,
                    (caches, lighting),
                    sampling.vals(),
                    sampling.rsm(),
                );
                let occlusion_group = self.occlusion_pass.bind(
                    device,
                    &caches.caches,
                    caches.lighting_at(lighting),
                    &caches.coverage,
                );
                sampling.encode_rsm(stages, &r.scene_buffers, frame.shared)?;
                if brsm {
                    let ranges = self.sharing.sample_ranges(&pool);
                    stages.stage(stages::IMPORTANCE, |e| {
                        sampling.encode_importance(e, gi, ranges.as_deref())
                    })?;
                    stages.stage(stages::CUMULATIVE_SUMS, |e| {
                        sampling.encode_cumulative_sums(e)
                    })?;
                    stages.stage(stages::VAL_SELECT, |e| sampling.encode_selection(e, gi))?;
                }
                stages.stage(stages::CACHE_LIGHTING, |e| {
                    self.cache_pass
                        .encode(e, &lighting_group, caches.count, lighting_chunks)
                })?;
                if gi.occlusion {
                    stages.stage(stages::PROXY_OCCLUSION, |e| {
                        self.occlusion_pass.encode(
                            e,
                            &occlusion_group,
                            caches.count,
                            occlusion_chunks,
                        )
                    })?;
                }
            }
        }
        stages.stage(stages::INDIRECT_LIGHT, |e| {
            self.indirect_pass
                .encode(e, &indirect_group, frame.width, frame.height)
        })?;
        Ok(None)
    }

    fn capture_debug(
        &self,
        view: View,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Option<Box<dyn DebugCapture>> {
        if [
            views::RSM_FLUX.name,
            views::IMPORTANCE.name,
            views::SELECTED_VALS.name,
        ]
        .contains(&view)
        {
            return Some(Box::new(self.sampling.capture(device, encoder)));
        }
        if view == views::CACHES.name {
            let caches = self.caches.as_ref()?;
            return Some(Box::new(LightingCapture {
                staged: stage_buffer(device, encoder, caches.lighting_at(self.lighting)),
                count: caches.count as usize,
            }));
        }
        None
    }

    fn retain_targets(&mut self, live: &[&GBuffer]) {
        self.sampling.retain_gbuffers(live.iter().copied());
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[cfg(test)]
mod visibility_key_tests {
    use super::*;

    const PARAMS: CacheParams = CacheParams {
        d_eps: 0.25,
        theta_eps_degrees: 30.0,
    };

    /// Without maps the key is the one stored sets were made with.
    #[test]
    fn keys_without_maps_are_unchanged() {
        let key = cache_key(&PARAMS, 0);
        assert_eq!(
            key.params,
            vec![("cache_distance", 0.25), ("cache_angle", 30.0)]
        );
        assert_eq!(visibility_side(&key), 0);
        assert_eq!(visibility_side(&cache_key(&PARAMS, 16)), 16);
        assert_eq!(cache_params(&cache_key(&PARAMS, 16)), PARAMS);
    }

    /// Budget units and the caches they hold invert each other.
    #[test]
    fn maps_count_as_caches() {
        assert_eq!(budget_units(1000, 0), 1000);
        assert_eq!(budget_units(1000, 16), 20_000);
        assert_eq!(budget_units(1000, 32), 70_000);
        assert_eq!(budget_units(1000, 1), 2000);
        for side in [0, 1, 4, 16, 32] {
            assert_eq!(caches_in(budget_units(7511, side), side), 7511);
        }
    }
}
