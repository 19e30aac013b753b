//! `surfels` (seed paper 001, issue 12): indirect light from surfels, a flux hierarchy over
//! them, precomputed light-transport links from SH caches to hierarchy nodes and per-pixel
//! spherical-harmonics shading, with progressive multi-bounce.
//!
//! The per-scene precomputation ([`PRECOMPUTE`], kind `surfel_links`) is built on the CPU and
//! tested against independent answers; the per-frame GPU passes ([`passes`]) against [`cpu`]:
//!
//! - [`sampling`]: n_S surfels of equal area over every triangle ("Surfel Placement").
//! - [`hierarchy`]: the binary tree over the surfels by agglomerative clustering with the
//!   paper's tree metric ("Surfel Clustering and Tree Metric"), up which flux is pulled.
//! - [`links`]: every cache's n_L most important hierarchy nodes with their SH form factors
//!   (eq. 3), and the cache lighting over them (eq. 4).
//! - [`cpu`]: the CPU reference of the per-frame steps (surfel radiosity with one more bounce
//!   per frame, pull-up, cache lighting, interpolated irradiance and shading) the GPU passes
//!   are compared with.
//! - [`passes`]: the GPU passes (surfel light, pull-up, cache lighting, shading).
//! - [`grid`]: the lattice of SH caches over the scene's bounds ("Cache Placement").
//! - [`sh`]: real spherical harmonics and the zonal projections of the diffuse and normalised
//!   Phong lobes (eq. 5–8, appendix B) the links and the shading are expressed in.

pub mod bench;
pub mod cpu;
pub mod grid;
pub mod hierarchy;
pub mod limits;
pub mod link_rays;
pub mod links;
pub mod params;
pub mod passes;
pub mod sampling;
pub mod senders;
pub mod sh;
pub mod shaders;
pub mod stages;
pub mod store;
pub mod views;

use crate::gi::common::bvh::SceneBvh;
use crate::gi::common::params::{emitters, BOUNCES};
use crate::gi::cost::{Cost, FrameShape, Knob};
use crate::gi::precompute::{
    BudgetPool, BuildEnv, Built, PrecomputeEntry, PrecomputeKey, Progress, SceneData, SceneFacts,
    UnitBudget,
};
use crate::gi::{
    DebugCapture, DebugData, FrameInputs, GiError, InvalidSetting, Method, MethodEntry,
    ProgressBuffer, SceneResources,
};
use crate::gpu::readback::{stage_buffer, PendingMap};
use crate::gpu::timing::FrameStages;
use crate::gpu::GpuContext;
use crate::passes::ShaderPass;
use crate::scene::Scene;
use glam::Vec3;
use grid::{CacheGrid, GridError};
use hierarchy::{ClusterWeights, HierarchyError, Leaf, Tree};
use lightcast_protocol::{GiMethod, GiParams, Light, View};
use links::{LinkError, SurfelLinks};
pub use params::{Settings, LINK_RANGE, MAX_SURFELS, MIN_BANDS, MIN_SURFELS};

/// The method's name.
pub const SURFELS: GiMethod = GiMethod::new("surfels");
use passes::{Bounce, SurfelBuffers, SurfelPasses};
use sampling::{SamplingError, Surfel};
use std::any::{Any, TypeId};
use std::sync::Arc;

/// Most bytes of link coefficients a request may make: wgpu's default storage binding size,
/// which every adapter the server accepts offers (larger GPUs bind more, but a request must
/// not depend on the machine it lands on).
pub const MAX_LINK_BYTES: u64 = 128 << 20;
/// Image histories (sessions) whose bounces a scene's surfels keep at once.
const MAX_HISTORIES: usize = 4;

/// Every module with its pipeline's bind groups (see [`ShaderPass`]).
const PASSES: &[ShaderPass] = &[
    ShaderPass::new(&shaders::SURFEL_LIGHT, &[&passes::LIGHT_GROUP]),
    ShaderPass::new(&shaders::SURFEL_PULL, &[&passes::PULL_GROUP]),
    ShaderPass::new(&shaders::SURFEL_CACHE_LIGHT, &[&passes::CACHE_LIGHT_GROUP]),
    ShaderPass::new(&shaders::SURFEL_SHADE, &[&passes::SHADE_GROUP]),
    ShaderPass::new(&shaders::SURFEL_CACHE_SH_VIEW, &[&passes::SH_VIEW_GROUP]),
    ShaderPass::new(
        &shaders::SURFEL_LINK_RAYS,
        &[&link_rays::RAY_GROUP, &link_rays::BVH_GROUP],
    ),
];

pub const ENTRY: MethodEntry = MethodEntry {
    tables: &[params::TABLE],
    type_id: TypeId::of::<Surfels>,
    validate: |gi, _| Settings::of(gi).map(drop),
    check_table: |gi| Settings::of(gi).map(drop),
    create: |r| Ok(Box::new(Surfels::new(r))),
    precompute: Some(&PRECOMPUTE),
    cost,
    knobs: &[
        Knob::lower(&params::SURFEL_LINKS),
        Knob::lower(&BOUNCES),
        Knob::lower(&params::SH_BANDS),
        Knob::lower(&params::SURFEL_COUNT),
    ],
    shaders: PASSES,
    stages: stages::ALL,
    limits: limits::LIMITS,
    downscales: true,
    samples_environment: false,
    follows_moved_nodes: super::follows_every_pose,
    bench: Some(&bench::SWEEP),
};

/// One frame's stages (`set_units` are the links, caches × `surfel_links`): per bounce the
/// surfel light and pull-up (per surfel) and the cache lighting of eq. 4 (per link and SH
/// coefficient), then the per-pixel SH shading. Weights in reference ns per item, measured
/// with one-shot renders of 1 … 16 bounces on the Cornell box (8,192 surfels, 681,472 links,
/// 3 bands: 55 ms a bounce): 16 per link·coefficient (twice what that run took; the
/// paper-grid bench's wall-clock stages gave up to 50 at 32,768 surfels), 1.5 µs per surfel,
/// 100 per pixel·coefficient.
fn cost(gi: &GiParams, shape: &FrameShape, cost: &mut Cost) {
    let pixels = shape.reduced_pixels(gi);
    let Ok(gi) = Settings::of(gi) else {
        return;
    };
    let steps = f64::from(if shape.all_bounces {
        gi.bounces.max(1)
    } else {
        1
    });
    let coefficients = f64::from(gi.sh_bands).powi(2);
    cost.add(
        "cache lighting (bounces × caches × surfel_links × sh_bands²)",
        steps * shape.set_units as f64 * coefficients,
        16.0,
    );
    cost.add(
        "surfel light and pull-up (bounces × surfel_count)",
        steps * f64::from(gi.surfel_count),
        1500.0,
    );
    cost.add(
        "SH shading (pixels × sh_bands²)",
        pixels * coefficients,
        100.0,
    );
}

/// Kind of the surfels' precomputation.
pub const SURFEL_LINKS: &str = "surfel_links";

/// The surfels, their hierarchy, the cache lattice and every cache's links, one set per scene
/// and parameter set. Built on the precompute worker with progress and cancellation, and kept
/// in the store ([`store`], `<key>.lsl`) so a scene is built once per parameter set.
pub static PRECOMPUTE: PrecomputeEntry = PrecomputeEntry {
    kind: SURFEL_LINKS,
    label: "surfel links",
    key: |gi, facts| Ok(surfel_key(&surfel_params(gi, facts)?)),
    budget: Some(UnitBudget {
        pool: BudgetPool::Declared {
            total: &limits::MAX_TOTAL_SURFEL_LINKS,
            per_set: None,
        },
        unit: "surfel links",
        field: "surfel_links",
        advice: |_, _, allowed| {
            format!(
                "use fewer surfel_links or a larger surfel_cache_spacing (at most {allowed} \
                 caches × links)"
            )
        },
    }),
    estimate: |key, facts| {
        let links = key.param("surfel_links").unwrap_or(0.0) as u64;
        let spacing = key.param("surfel_cache_spacing").unwrap_or(f32::NAN);
        CacheGrid::new(Vec3::ZERO, facts.extent, spacing)
            .map_or(u64::MAX, |g| g.count() as u64 * links)
    },
    // Every cache traces a ray to every surfel and sums its SH projection (eq. 3), whatever
    // the links kept: 0.31 µs per cache·surfel on 2 cores (8,192 surfels × 10,648 caches of
    // the Cornell box: 27 s), the surfel sampling and hierarchy besides.
    cost: |key, facts, cost| {
        let surfels = f64::from(key.param("surfel_count").unwrap_or(0.0));
        let spacing = key.param("surfel_cache_spacing").unwrap_or(f32::NAN);
        let caches = CacheGrid::new(Vec3::ZERO, facts.extent, spacing)
            .map_or(f64::INFINITY, |g| g.count() as f64);
        cost.add(
            "link rays and SH sums (caches × surfel_count)",
            caches * surfels,
            310.0,
        );
    },
    knobs: &[Knob::lower(&params::SURFEL_COUNT)],
    build: |scene, key, env| {
        let params = SurfelParams {
            surfels: key.param("surfel_count").unwrap_or(0.0) as u32,
            cache_spacing: key.param("surfel_cache_spacing"),
            links: key.param("surfel_links").unwrap_or(0.0) as u32,
            bands: key.param("sh_bands").unwrap_or(0.0) as u32,
        };
        let store = env.store;
        let (set, from_store) =
            store::load_or_compute(store, scene, &params, env).map_err(|e| e.to_string())?;
        Ok(Built {
            units: (set.grid.count() as u64) * u64::from(set.links.per_cache),
            data: Arc::new(set),
            from_store,
        })
    },
    extension: Some(store::EXTENSION),
};

/// The precomputation's parameters of a request, checked, with the default spacing resolved
/// for the scene.
fn surfel_params(gi: &GiParams, facts: &SceneFacts) -> Result<SurfelParams, InvalidSetting> {
    let gi = Settings::of(gi)?;
    let spacing = gi
        .surfel_cache_spacing
        .unwrap_or_else(|| CacheGrid::default_spacing(facts.extent));
    // The lattice's own limits (at most `grid::MAX_CACHES`) before anything is queued.
    let grid = CacheGrid::new(Vec3::ZERO, facts.extent, spacing)
        .map_err(|e| InvalidSetting::new("surfel_cache_spacing", e.to_string()))?;
    // The links' coefficients are bound as one buffer; refused here rather than by the GPU
    // after minutes of precomputation.
    let bytes = passes::link_coefficient_bytes(grid.count() as u64, gi.surfel_links, gi.sh_bands);
    if bytes > MAX_LINK_BYTES {
        return Err(InvalidSetting::new(
            "surfel_links",
            format!(
                "{} caches × {} links × {} SH coefficients take {} MiB, more than the {} MiB \
                 a GPU binds at once; use fewer surfel_links or sh_bands, or a larger \
                 surfel_cache_spacing",
                grid.count(),
                gi.surfel_links,
                gi.sh_bands * gi.sh_bands,
                bytes.div_ceil(1 << 20),
                MAX_LINK_BYTES >> 20
            ),
        ));
    }
    Ok(SurfelParams {
        surfels: gi.surfel_count,
        cache_spacing: Some(spacing),
        links: gi.surfel_links,
        bands: gi.sh_bands,
    })
}

/// The key of the surfel set for `params` (the spacing resolved).
fn surfel_key(params: &SurfelParams) -> PrecomputeKey {
    PrecomputeKey {
        kind: SURFEL_LINKS,
        params: vec![
            ("surfel_count", params.surfels as f32),
            (
                "surfel_cache_spacing",
                params.cache_spacing.unwrap_or(f32::NAN),
            ),
            ("surfel_links", params.links as f32),
            ("sh_bands", params.bands as f32),
        ],
    }
}

/// What the precomputation is built from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfelParams {
    /// n_S.
    pub surfels: u32,
    /// Distance between neighbouring SH caches in scene units (`None`: from the extent, see
    /// [`CacheGrid::default_spacing`]).
    pub cache_spacing: Option<f32>,
    /// n_L, links per cache.
    pub links: u32,
    /// SH bands l of the links' form factors (l² coefficients).
    pub bands: u32,
}

impl Default for SurfelParams {
    /// The table's defaults (the paper's 32k surfels and 128 links, 3 bands), so the service,
    /// the offline tools and the bench cannot disagree (issue 32: they were written twice).
    fn default() -> Self {
        let none = GiParams::new(crate::gi::surfels::SURFELS);
        Self {
            surfels: params::SURFEL_COUNT.u32(&none),
            cache_spacing: None,
            links: params::SURFEL_LINKS.u32(&none),
            bands: params::SH_BANDS.u32(&none),
        }
    }
}

/// A scene's surfels, their hierarchy and the cache lattice.
#[derive(Clone, Debug)]
pub struct SurfelSet {
    /// In the hierarchy's leaf order: surfel k is leaf k of [`Self::tree`], so every node's
    /// surfels are one contiguous range.
    pub surfels: Vec<Surfel>,
    /// Area of each surfel (square scene units); they sum to the scene's triangle area.
    pub surfel_area: f64,
    pub tree: Tree,
    pub grid: CacheGrid,
    /// Every cache's links ([`links`]), in the grid's cache order.
    pub links: SurfelLinks,
}

/// Why no surfel set was built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SurfelError {
    #[error("surfel_count {0} is outside 1..={MAX_SURFELS}")]
    Count(u32),
    #[error(transparent)]
    Sampling(#[from] SamplingError),
    #[error(transparent)]
    Hierarchy(#[from] HierarchyError),
    #[error(transparent)]
    Grid(#[from] GridError),
    #[error(transparent)]
    Links(#[from] LinkError),
    #[error("{0}")]
    Bvh(String),
}

/// Builds the surfels ([`sampling`]), their hierarchy ([`hierarchy`]), the cache lattice
/// ([`grid`]) and every cache's links ([`links`]) of `scene`, reporting the steps `surfels`,
/// `relaxing`, `clustering`, `bvh` and `links`.
pub fn precompute(
    scene: &Scene,
    params: &SurfelParams,
    env: &mut BuildEnv,
) -> Result<SurfelSet, SurfelError> {
    if !(1..=MAX_SURFELS).contains(&params.surfels) {
        return Err(SurfelError::Count(params.surfels));
    }
    let extent = scene.bounds.max - scene.bounds.min;
    let spacing = params
        .cache_spacing
        .unwrap_or_else(|| CacheGrid::default_spacing(extent));
    // The lattice first: a bad spacing is refused before the long steps.
    let grid = CacheGrid::new(scene.bounds.min, extent, spacing)?;
    let sampled = sampling::sample(
        scene,
        params.surfels,
        sampling::RELAX_STEPS,
        env.progress,
        env.cancelled,
    )?;
    let leaves: Vec<Leaf> = sampled
        .surfels
        .iter()
        .map(|s| Leaf {
            position: s.position,
            normal: s.normal,
            area: sampled.area as f32,
        })
        .collect();
    // Ē, the diagonal of the bounds (at least a surfel's size, for a scene of one point).
    let diagonal = f64::from(extent.length()).max(sampled.area.sqrt());
    let progress = &mut *env.progress;
    let tree = hierarchy::build(
        &leaves,
        diagonal,
        ClusterWeights::default(),
        &mut |done, total| {
            progress(Progress {
                step: "clustering",
                done,
                total,
            })
        },
        env.cancelled,
    )?;
    let surfels: Vec<Surfel> = tree
        .leaf_order
        .iter()
        .map(|&i| sampled.surfels[i as usize])
        .collect();
    progress(Progress {
        step: "bvh",
        done: 0,
        total: 1,
    });
    let bvh = SceneBvh::build(scene).map_err(|e| SurfelError::Bvh(e.to_string()))?;
    let positions: Vec<Vec3> = (0..grid.count()).map(|i| grid.position(i)).collect();
    let senders = links::Senders {
        surfels: &surfels,
        area: sampled.area,
        tree: &tree,
        bvh: &bvh,
        scene,
        extent: extent.length(),
    };
    let links = links::build(
        &senders,
        &positions,
        params.links,
        params.bands,
        links::RayDevice::for_adapter(env.gpu),
        &mut |done, total| {
            progress(Progress {
                step: "links",
                done,
                total,
            })
        },
        env.cancelled,
    )?;
    Ok(SurfelSet {
        surfels,
        surfel_area: sampled.area,
        tree,
        grid,
        links,
    })
}

/// What a history's caches were lit by: a change restarts its bounces.
#[derive(Clone, Debug, PartialEq)]
struct LitBy {
    lights: Vec<Light>,
    shadow_map_size: u32,
    bounces: u32,
    emitters: bool,
    poses: crate::scene::nodes::Poses,
}

/// One image history's caches: two cache-light buffers a bounce reads and writes in turn.
struct History {
    id: Option<u64>,
    lit_by: LitBy,
    /// Bounces the caches in `buffers[latest]` hold.
    done: u32,
    latest: usize,
    buffers: [wgpu::Buffer; 2],
}

/// The history `id` of `histories` (most recently used first), moved to the front; restarted
/// when its caches were lit otherwise, created (dropping the least recently used beyond
/// [`MAX_HISTORIES`]) when it is new.
fn history_for<'h>(
    histories: &'h mut Vec<History>,
    device: &wgpu::Device,
    id: Option<u64>,
    lit_by: LitBy,
    set: &SurfelBuffers,
) -> &'h mut History {
    if let Some(i) = histories.iter().position(|h| h.id == id) {
        let mut h = histories.remove(i);
        if h.lit_by != lit_by {
            h.lit_by = lit_by;
            h.done = 0;
        }
        histories.insert(0, h);
    } else {
        histories.truncate(MAX_HISTORIES - 1);
        let buffer = || set.cache_light_buffer(device);
        histories.insert(
            0,
            History {
                id,
                lit_by,
                done: 0,
                latest: 0,
                buffers: [buffer(), buffer()],
            },
        );
    }
    &mut histories[0]
}

/// A history's cache lighting as read back.
#[derive(Clone, Debug, PartialEq)]
pub struct CacheLight {
    /// Bounces it holds.
    pub bounces: u32,
    /// RGB(A) SH coefficients, `sh_bands²` per cache.
    pub coefficients: Vec<[f32; 4]>,
}

/// Per-scene state of the `surfels` method.
pub struct Surfels {
    ctx: GpuContext,
    scene: Arc<Scene>,
    passes: SurfelPasses,
    set: Option<SurfelBuffers>,
    /// Most recently used first.
    histories: Vec<History>,
    /// The last frame's `cache-sh` debug view (width, height, one RGBA value per pixel).
    sh_view: Option<(u32, u32, wgpu::Buffer)>,
}

impl Surfels {
    pub fn new(r: &SceneResources) -> Self {
        Self {
            ctx: r.ctx.clone(),
            scene: Arc::clone(&r.scene),
            passes: SurfelPasses::new(&r.ctx.device),
            set: None,
            histories: Vec::new(),
            sh_view: None,
        }
    }

    /// Uploads the scene's surfel set (the per-scene precomputation).
    pub fn set_surfels(&mut self, set: &SurfelSet) -> Result<(), GiError> {
        let buffers = SurfelBuffers::new(&self.ctx.device, &self.scene, set)
            .map_err(|e| GiError::Scene(e.to_string()))?;
        self.passes
            .prepare(&self.ctx.device, &self.ctx.queue, &buffers);
        self.set = Some(buffers);
        self.histories.clear();
        Ok(())
    }

    /// The cache lighting the last frame of `history` shaded with (blocking; for tests).
    pub fn read_cache_light(
        &self,
        history: Option<u64>,
    ) -> Result<Option<CacheLight>, crate::gpu::GpuError> {
        let Some(h) = self.histories.iter().find(|h| h.id == history) else {
            return Ok(None);
        };
        let bytes = crate::gpu::readback::read_buffer(&self.ctx, &h.buffers[h.latest])?;
        Ok(Some(CacheLight {
            bounces: h.done,
            coefficients: bytemuck::pod_collect_to_vec(&bytes),
        }))
    }

    /// The flux of every hierarchy node after the last bounce (blocking; for tests).
    pub fn read_flux(&self) -> Result<Option<Vec<[f32; 4]>>, crate::gpu::GpuError> {
        let Some(set) = &self.set else {
            return Ok(None);
        };
        let bytes = crate::gpu::readback::read_buffer(&self.ctx, &set.flux)?;
        Ok(Some(bytemuck::pod_collect_to_vec(&bytes)))
    }
}

impl Method for Surfels {
    fn set_scene_data(&mut self, data: &SceneData) -> Result<(), GiError> {
        let set = data.downcast_ref::<SurfelSet>().ok_or_else(|| {
            GiError::Scene("the surfels method's scene data must be its surfel set".into())
        })?;
        self.set_surfels(set)
    }

    fn encode(
        &mut self,
        frame: &FrameInputs,
        stages: &mut FrameStages,
    ) -> Result<Option<ProgressBuffer>, GiError> {
        let mut set = self.set.take().ok_or_else(|| {
            GiError::Scene(
                "surfels needs the scene's surfel set; call Surfels::set_surfels first".into(),
            )
        })?;
        set.set_poses(&self.ctx.queue, &self.scene, frame.poses);
        let result = self.encode_with(&set, frame, stages);
        self.set = Some(set);
        result.map(|()| None)
    }

    fn capture_debug(
        &self,
        view: View,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Option<Box<dyn DebugCapture>> {
        let staged = match view {
            v if v == views::SURFEL_RADIOSITY.name => {
                let set = self.set.as_ref()?;
                SurfelCapture::Radiosity {
                    surfels: set.surfel_count as usize,
                    staged: stage_buffer(device, encoder, &set.flux),
                }
            }
            v if v == views::CACHE_SH.name => {
                let (width, height, buffer) = self.sh_view.as_ref()?;
                SurfelCapture::CacheSh {
                    width: *width,
                    height: *height,
                    staged: stage_buffer(device, encoder, buffer),
                }
            }
            _ => return None,
        };
        Some(Box::new(staged))
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// What the surfels' debug views read back with a frame.
#[derive(Clone, Debug, PartialEq)]
pub enum SurfelView {
    /// `surfels`: every surfel's radiosity, in the set's surfel order.
    Radiosity(Vec<Vec3>),
    /// `cache-sh`: the caches' SH radiance along each pixel's normal (alpha 0 where no
    /// geometry is), row-major at the method's resolution.
    CacheSh {
        width: u32,
        height: u32,
        radiance: Vec<[f32; 4]>,
    },
}

/// The staged copies behind a [`SurfelView`].
enum SurfelCapture {
    Radiosity {
        surfels: usize,
        staged: wgpu::Buffer,
    },
    CacheSh {
        width: u32,
        height: u32,
        staged: wgpu::Buffer,
    },
}

impl DebugCapture for SurfelCapture {
    fn read(
        self: Box<Self>,
        ctx: &GpuContext,
        submission: Option<&wgpu::SubmissionIndex>,
    ) -> Result<DebugData, crate::gpu::GpuError> {
        let (pending, capture) = match *self {
            Self::Radiosity { surfels, staged } => (PendingMap::new(&staged), Ok(surfels)),
            Self::CacheSh {
                width,
                height,
                staged,
            } => (PendingMap::new(&staged), Err((width, height))),
        };
        ctx.wait_for(submission)?;
        let bytes = pending.finish()?;
        let view = match capture {
            // A node's flux in surfel units is the sum of its surfels' radiosities, so a leaf's
            // is its surfel's radiosity; the leaves come first.
            Ok(surfels) => SurfelView::Radiosity(
                bytemuck::pod_collect_to_vec::<u8, [f32; 4]>(&bytes)
                    .iter()
                    .take(surfels)
                    .map(|f| Vec3::new(f[0], f[1], f[2]))
                    .collect(),
            ),
            Err((width, height)) => SurfelView::CacheSh {
                width,
                height,
                radiance: bytemuck::pod_collect_to_vec(&bytes),
            },
        };
        Ok(DebugData(Arc::new(view)))
    }
}

impl Surfels {
    fn encode_with(
        &mut self,
        set: &SurfelBuffers,
        frame: &FrameInputs,
        stages: &mut FrameStages,
    ) -> Result<(), GiError> {
        let r = frame.resources;
        let wanted = Settings::of(frame.settings)?.bounces.max(1);
        let lit_by = LitBy {
            lights: frame.lights.to_vec(),
            shadow_map_size: frame.shadow.size,
            bounces: wanted,
            emitters: emitters(frame.settings),
            poses: frame.poses.clone(),
        };
        // A render, and a session's still, show every bounce.
        let one_shot = frame.history.is_none() || frame.still;
        let device = &self.ctx.device;
        let passes = &self.passes;
        let history = history_for(&mut self.histories, device, frame.history, lit_by, set);
        // A render computes every bounce; a session adds one per frame until it has them all
        // (the paper's progressive multi-bounce).
        let steps = if one_shot {
            wanted - history.done.min(wanted)
        } else {
            u32::from(history.done < wanted)
        };
        // The paper's rows (surfel lighting, pull, cache lighting) are timed apart; a frame that
        // adds several bounces reports each stage's sum.
        for _ in 0..steps {
            let previous = (history.done > 0).then_some(history.latest);
            let target = if history.done > 0 {
                1 - history.latest
            } else {
                0
            };
            stages.stage(stages::SURFEL_LIGHT, |e| {
                passes.encode_light(
                    device,
                    e,
                    set,
                    &Bounce {
                        lights: &r.lights,
                        shadow: frame.shadow,
                        previous: previous.map(|i| &history.buffers[i]),
                        emitters: emitters(frame.settings),
                    },
                )
            })?;
            stages.stage(stages::SURFEL_PULL, |e| passes.encode_pull(device, e, set))?;
            stages.stage(stages::SURFEL_CACHE_LIGHT, |e| {
                passes.encode_cache_light(device, e, set, &history.buffers[target])
            })?;
            history.latest = target;
            history.done += 1;
        }
        stages.stage(stages::SURFEL_SHADE, |e| {
            passes.encode_shade(
                device,
                e,
                &r.camera,
                frame.gbuffer,
                set,
                &history.buffers[history.latest],
                frame.indirect,
                (frame.width, frame.height),
                &r.scene_buffers.brdf_table,
            );
            if frame.debug_view == views::CACHE_SH.name {
                let size = (frame.width, frame.height);
                if !matches!(&self.sh_view, Some((w, h, _)) if (*w, *h) == size) {
                    let buffer = passes::sh_view_buffer(device, size.0, size.1);
                    self.sh_view = Some((size.0, size.1, buffer));
                }
                if let Some((_, _, out)) = &self.sh_view {
                    passes.encode_sh_view(
                        device,
                        e,
                        frame.gbuffer,
                        set,
                        &history.buffers[history.latest],
                        out,
                    );
                }
            }
        })?;
        Ok(())
    }
}

/// The flux of every hierarchy node from its surfels' (eq. 4's senders are nodes): leaves
/// carry their surfel's, and each internal node the sum of its children's, in the order the
/// per-frame pull runs (children before parents).
pub fn pull_flux(tree: &Tree, leaf_flux: &[Vec3]) -> Vec<Vec3> {
    let leaves = leaf_flux.len();
    let mut flux = leaf_flux.to_vec();
    flux.extend(tree.children.iter().map(|_| Vec3::ZERO));
    for (k, [a, b]) in tree.children.iter().enumerate() {
        flux[leaves + k] = flux[*a as usize] + flux[*b as usize];
    }
    flux
}

/// Small scenes the surfel tests share.
#[cfg(test)]
pub(crate) mod test_scenes {
    use crate::scene::{Material, Scene, Vertex};
    use glam::Vec3;

    /// One quad per entry, corners counter-clockwise seen from its front, uv (0,0), (1,0),
    /// (1,1), (0,1) at the corners.
    pub fn quads(quads: &[[Vec3; 4]]) -> Scene {
        let (mut vertices, mut indices) = (Vec::new(), Vec::new());
        for corners in quads {
            let n = (corners[1] - corners[0])
                .cross(corners[2] - corners[0])
                .normalize();
            let base = vertices.len() as u32;
            let uvs = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
            for (p, uv) in corners.iter().zip(uvs) {
                vertices.push(Vertex {
                    position: p.to_array(),
                    normal: n.to_array(),
                    uv,
                    material: 0,
                });
            }
            indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
        Scene::new(
            "quads",
            vertices,
            indices,
            vec![Material::default()],
            vec![],
            vec![],
            vec![],
        )
        .expect("scene")
    }

    /// A closed box of side 2 around the origin whose walls face inwards.
    pub fn closed_box() -> Scene {
        let wall = |n: Vec3| {
            let t1 = n.any_orthonormal_vector();
            let t2 = n.cross(t1);
            [-t1 - t2, t1 - t2, t1 + t2, -t1 + t2].map(|c| c - n)
        };
        quads(&[Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z].map(wall))
    }

    /// The surfel set of `scene`, built without progress or cancellation.
    pub fn surfel_set(scene: &Scene, params: &super::SurfelParams) -> super::SurfelSet {
        let store = crate::gi::precompute::Store::new(std::env::temp_dir());
        let mut env = crate::gi::precompute::BuildEnv {
            store: &store,
            progress: &mut |_| {},
            cancelled: &|| false,
            gpu: None,
        };
        super::precompute(scene, params, &mut env).expect("surfel set")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::precompute::Store;
    use crate::scene::procedural;

    fn build(scene: &Scene, params: &SurfelParams) -> Result<SurfelSet, SurfelError> {
        let store = Store::new(std::env::temp_dir());
        let mut steps = Vec::new();
        let mut env = BuildEnv {
            store: &store,
            progress: &mut |p: Progress| steps.push(p.step),
            cancelled: &|| false,
            gpu: None,
        };
        let set = precompute(scene, params, &mut env);
        if set.is_ok() {
            steps.dedup();
            assert_eq!(steps, ["surfels", "relaxing", "clustering", "bvh", "links"]);
        }
        set
    }

    #[test]
    fn the_cornell_box_gets_surfels_a_hierarchy_over_them_and_a_cache_lattice() {
        let scene = procedural::cornell_box();
        let params = SurfelParams {
            surfels: 3000,
            cache_spacing: Some(1.0),
            links: 16,
            bands: 2,
        };
        let set = build(&scene, &params).expect("surfel set");
        let n = set.surfels.len();
        assert_eq!(n, 3000);
        assert_eq!(set.tree.children.len(), n - 1);
        let root = 2 * n - 2;
        let area = crate::gi::common::triangles::surface_area(&scene);
        let root_area = f64::from(set.tree.area[root]);
        assert!(
            ((root_area - area) / area).abs() < 1e-4,
            "{root_area} vs {area}"
        );
        assert_eq!(
            (set.tree.first_leaf[root], set.tree.leaf_count[root]),
            (0, n as u32)
        );
        // Leaf k is surfel k: every node's surfels are its leaf range.
        for (k, s) in set.surfels.iter().enumerate() {
            assert_eq!(set.tree.centre[k], s.position, "leaf {k}");
        }
        let bounds = scene.bounds;
        for corner in bounds.corners() {
            let weights = set.grid.trilinear(corner);
            assert!(weights.iter().all(|&(i, _)| i < set.grid.count()));
        }
        assert!(set.grid.position(0).cmplt(bounds.min).all());
        assert!(set
            .grid
            .position(set.grid.count() - 1)
            .cmpgt(bounds.max)
            .all());
        // Caches in the room see the walls around them: at most the whole sphere, Σ c₀ ≤ 2/√π,
        // and most see all but the open front (caches inside a block see almost nothing).
        let full = 2.0 / std::f32::consts::PI.sqrt();
        assert_eq!(set.links.visible.len(), set.grid.count());
        let inside: Vec<f32> = (0..set.grid.count())
            .filter(|&i| {
                let p = set.grid.position(i);
                (p - bounds.center())
                    .abs()
                    .cmplt((bounds.max - bounds.min) * 0.3)
                    .all()
            })
            .map(|i| set.links.visible[i])
            .collect();
        eprintln!("Σ c₀ of the caches in the room: {inside:?} (whole sphere {full})");
        assert!(inside.iter().all(|&v| v <= 1.02 * full), "{inside:?}");
        let open = inside.iter().filter(|&&v| v > 0.7 * full).count();
        assert!(2 * open >= inside.len(), "{inside:?}");
    }

    /// A set whose link coefficients would not fit one GPU binding is refused with the
    /// request, naming `surfel_links`; the same lattice with fewer links or bands passes.
    #[test]
    fn link_coefficients_beyond_one_binding_are_refused_before_precomputing() {
        let facts = SceneFacts::of(&procedural::cornell_box());
        let gi = |links: u32, bands: u32| {
            GiParams::new(crate::gi::surfels::SURFELS)
                .with("surfel_cache_spacing", 0.05)
                .with("surfel_links", links)
                .with("sh_bands", bands)
        };
        // Some 80,000 caches 0.05 apart: 64 links × 9 coefficients × 4 bytes each exceed
        // 128 MiB, 32 links or 4 coefficients do not.
        let refused = surfel_params(&gi(64, 3), &facts).expect_err("too large");
        assert_eq!(refused.field, "surfel_links");
        assert!(refused.reason.contains("128 MiB"), "{}", refused.reason);
        assert!(surfel_params(&gi(32, 3), &facts).is_ok());
        assert!(surfel_params(&gi(64, 2), &facts).is_ok());
    }

    /// How long the precomputation takes at the defaults (`cargo test --release -- --ignored
    /// surfel_precompute_time --nocapture`); not a test of speed, which benches measure.
    #[test]
    #[ignore]
    fn surfel_precompute_time() {
        let scene = procedural::cornell_box();
        let store = Store::new(std::env::temp_dir());
        let started = std::time::Instant::now();
        let mut last = "";
        let mut env = BuildEnv {
            store: &store,
            progress: &mut |p: Progress| {
                if p.step != last {
                    eprintln!("{:>8.2} s  {}", started.elapsed().as_secs_f64(), p.step);
                    last = p.step;
                }
            },
            cancelled: &|| false,
            gpu: None,
        };
        let set = precompute(&scene, &SurfelParams::default(), &mut env).expect("set");
        eprintln!(
            "{:>8.2} s  done: {} surfels, {} caches × {} links",
            started.elapsed().as_secs_f64(),
            set.surfels.len(),
            set.grid.count(),
            set.links.per_cache
        );
    }

    #[test]
    fn the_root_flux_is_the_sum_of_the_leaves() {
        let scene = procedural::cornell_box();
        let set = build(
            &scene,
            &SurfelParams {
                surfels: 500,
                cache_spacing: Some(2.0),
                links: 4,
                bands: 1,
            },
        )
        .expect("surfel set");
        let leaf_flux: Vec<Vec3> = (0..500)
            .map(|k| Vec3::new(k as f32, 1.0, (k % 7) as f32 * 0.5))
            .collect();
        let flux = pull_flux(&set.tree, &leaf_flux);
        let root = *flux.last().expect("a root");
        let sum: Vec3 = leaf_flux.iter().sum();
        assert!(
            (root - sum).abs().max_element() < 1e-3 * sum.max_element(),
            "{root} vs {sum}"
        );
        // Every node holds the flux of exactly its leaf range.
        for (node, f) in flux.iter().enumerate() {
            let (first, count) = (set.tree.first_leaf[node], set.tree.leaf_count[node]);
            let range: Vec3 = leaf_flux[first as usize..(first + count) as usize]
                .iter()
                .sum();
            assert!((*f - range).abs().max_element() <= 1e-3 * range.max_element().max(1.0));
        }
    }

    #[test]
    fn bad_parameters_are_refused_before_any_work() {
        let scene = procedural::cornell_box();
        let refused = |params: SurfelParams| build(&scene, &params).err();
        assert_eq!(
            refused(SurfelParams {
                surfels: 0,
                ..SurfelParams::default()
            }),
            Some(SurfelError::Count(0))
        );
        assert!(matches!(
            refused(SurfelParams {
                surfels: 100,
                cache_spacing: Some(1e-4),
                ..SurfelParams::default()
            }),
            Some(SurfelError::Grid(GridError::TooMany { .. }))
        ));
        let store = Store::new(std::env::temp_dir());
        let mut env = BuildEnv {
            store: &store,
            progress: &mut |_| {},
            cancelled: &|| true,
            gpu: None,
        };
        assert_eq!(
            precompute(&scene, &SurfelParams::default(), &mut env).err(),
            Some(SurfelError::Sampling(SamplingError::Cancelled))
        );
    }
}
