//! Per-model precomputation of LightSkin light caches (seed paper 004, "LightSkin Overview" →
//! "Cache Distribution", steps 1–5, and "Occlusion" for the per-cache disk area).
//!
//! Two parameters control the distribution: `d_eps`, the largest distance between a surface
//! point and the cache that represents it, and `theta_eps`, the largest angle between their
//! normals. [`precompute`] runs the paper's steps on a point sampling of the surfaces:
//!
//! 1. sample every triangle (spacing ≤ d_eps/4) and bin the samples into voxels of edge
//!    d_eps/2;
//! 2. per voxel, bin the sample normals into a cube-map normal container;
//! 3. per voxel, repeatedly turn the bin with the largest area into a cache;
//! 4. snap caches that float off the surface onto their closest sample;
//! 5. join similar caches that came from neighbouring voxels.
//!
//! Afterwards every sample is handed to its nearest compatible cache, which gives each cache its
//! Voronoi area on the surface and its area-weighted material, and every scene vertex gets its
//! [`NEIGHBOURS`] nearest caches for interpolation.
//!
//! The paper distributes caches per model, in model space, so that a moving model's caches
//! move with it: every step here keeps to one model (`LightCache::model`: a movable node's
//! geometry, or the static rest of the scene). Voxels, joins, the samples a cache represents
//! and a vertex's neighbours never mix two models.
//!
//! The output is bit-identical for the same input whatever the thread count: parallel work is
//! split into fixed chunks whose results are concatenated in order, floating-point sums run
//! sequentially in a fixed order, and every sort has a total order with an index tie-break.

use crate::gi::common::kdtree::KdTree;
use crate::gi::common::triangles::{surface_area, triangle, triangle_area, triangle_normal};
use crate::scene::material::DiffuseGlossy;
use crate::scene::Scene;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::time::{Duration, Instant};

mod assignment;
mod clustering;
mod merging;
mod surface_samples;

use assignment::*;
use clustering::*;
use merging::*;
use surface_samples::*;

/// Nearest caches stored per scene vertex.
pub const NEIGHBOURS: usize = 16;

/// The nearest caches of a point, at most [`NEIGHBOURS`].
type Nearest = crate::gi::common::kdtree::Nearest<NEIGHBOURS>;
/// Refuse parameters that would create more caches than this (GPU buffers and the per-frame
/// passes are sized by the cache count).
pub const MAX_CACHES: u64 = 2_000_000;
/// Refuse parameters that would need more surface samples than this (32 bytes each).
pub const MAX_SAMPLES: u64 = 64_000_000;

/// [`CacheParams::for_scene`] aims at about this many caches on flat geometry.
const DEFAULT_CACHE_TARGET: f64 = 6000.0;
const DEFAULT_THETA_DEGREES: f32 = 30.0;
/// Sample spacing as a fraction of d_eps (step 1): every sample piece has its longest edge at
/// most d_eps/4, so each voxel face (d_eps/2) holds at least a handful of samples to average.
const SAMPLE_SPACING: f32 = 0.25;
/// Voxel edge as a fraction of d_eps (step 1).
const VOXEL_EDGE: f32 = 0.5;
/// Caches from different voxels closer than this fraction of d_eps are joined (step 5).
const MERGE_DISTANCE: f32 = 0.25;
/// A cache counts as floating (step 4) when it lies further than this fraction of d_eps off the
/// tangent plane of its closest sample; flat patches stay where the average put them.
const FLOATING_TOLERANCE: f32 = 0.01;
/// Longest-edge bisection stops here even if f32 rounding keeps an edge from shrinking.
const MAX_BISECTION_DEPTH: u32 = 48;
/// Parallel work is done in chunks of this many items, with a progress report after each.
const CHUNK: usize = 1 << 16;
/// Triangles per parallel sampling task.
const TRIANGLE_BLOCK: usize = 256;

/// The two control parameters of the cache distribution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CacheParams {
    /// Largest distance between a surface point and its cache (scene units).
    pub d_eps: f32,
    /// Largest angle between a surface normal and its cache's normal.
    pub theta_eps_degrees: f32,
}

impl CacheParams {
    /// Defaults derived from scene scale: d_eps = 2·sqrt(total surface area / 6000) rounded to
    /// 3 significant digits (≈6000 caches on flat geometry), theta_eps = 30°.
    ///
    /// On flat geometry each voxel face of area (d_eps/2)² holds one cache, so A / (d_eps/2)²
    /// caches cover area A.
    pub fn for_scene(scene: &Scene) -> Self {
        Self::for_area(surface_area(scene), scene.bounds.radius())
    }

    /// [`Self::for_scene`] for a scene of `area` square units within a sphere of `radius`.
    pub fn for_area(area: f64, radius: f32) -> Self {
        let d_eps = if area > 0.0 && area.is_finite() {
            2.0 * (area / DEFAULT_CACHE_TARGET).sqrt()
        } else {
            // Degenerate scene without area: any positive distance works; keep it in scale.
            let radius = f64::from(radius);
            if radius > 0.0 && radius.is_finite() {
                radius * 0.05
            } else {
                1.0
            }
        };
        Self {
            d_eps: round_significant(d_eps, 3) as f32,
            theta_eps_degrees: DEFAULT_THETA_DEGREES,
        }
    }

    /// Checks the parameters on their own: d_eps finite and > 0, theta_eps in (0°, 90°].
    pub fn validate(&self) -> Result<(), CacheError> {
        if !(self.d_eps.is_finite() && self.d_eps > 0.0) {
            return Err(CacheError::InvalidDistance(self.d_eps));
        }
        if !(self.theta_eps_degrees > 0.0 && self.theta_eps_degrees <= 90.0) {
            return Err(CacheError::InvalidAngle(self.theta_eps_degrees));
        }
        Ok(())
    }

    /// [`CacheParams::validate`] plus an estimate of the cache count from the scene's surface
    /// area ([`surface_area`]), so absurd parameters fail before any work is done.
    pub fn validate_for_area(&self, area: f64) -> Result<(), CacheError> {
        self.validate()?;
        let estimated = self.estimated_caches(area);
        if estimated > MAX_CACHES {
            return Err(CacheError::TooManyCaches {
                d_eps: self.d_eps,
                estimated,
                surface_area: area,
                min_d_eps: min_distance_for(area, MAX_CACHES),
            });
        }
        Ok(())
    }

    /// Flat-geometry cache count for `surface_area`: one cache per (d_eps/2)² of surface
    /// (step 1's voxel faces), known before any work is done.
    pub fn estimated_caches(&self, surface_area: f64) -> u64 {
        let h = f64::from(self.d_eps) * f64::from(VOXEL_EDGE);
        (surface_area / (h * h)).ceil().min(u64::MAX as f64) as u64
    }
}

/// The smallest d_eps whose [`CacheParams::estimated_caches`] for `surface_area` stays within
/// `max_caches`, rounded up to 3 significant digits.
pub fn min_distance_for(surface_area: f64, max_caches: u64) -> f32 {
    let min_d_eps = 2.0 * (surface_area / max_caches.max(1) as f64).sqrt();
    round_up_significant(min_d_eps, 3) as f32
}

/// Why the caches could not be computed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CacheError {
    #[error("d_eps must be a finite distance greater than 0 (scene units), got {0}")]
    InvalidDistance(f32),
    #[error("theta_eps_degrees must be greater than 0 and at most 90, got {0}")]
    InvalidAngle(f32),
    #[error(
        "d_eps = {d_eps} would create about {estimated} light caches for {surface_area:.6} square \
         units of surface, more than the maximum of {MAX_CACHES}; use d_eps >= {min_d_eps}"
    )]
    TooManyCaches {
        d_eps: f32,
        estimated: u64,
        surface_area: f64,
        min_d_eps: f32,
    },
    #[error(
        "d_eps = {d_eps} needs more than {MAX_SAMPLES} surface samples (one per d_eps/4 of \
         triangle edge and at least one per triangle); use a larger d_eps"
    )]
    TooManySamples { d_eps: f32 },
    #[error(
        "d_eps = {d_eps} with theta_eps_degrees = {theta_eps_degrees} created {count} light \
         caches, more than the maximum of {MAX_CACHES}; use a larger d_eps or theta_eps_degrees"
    )]
    TooManyCachesCreated {
        d_eps: f32,
        theta_eps_degrees: f32,
        count: u64,
    },
}

/// One light cache. Mirrored in WGSL; fields are grouped in 16-byte vec3+scalar blocks.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LightCache {
    pub position: [f32; 3],
    /// Surface area represented by the cache: its Voronoi cell on the surface.
    pub area: f32,
    pub normal: [f32; 3],
    /// Area of the disk that stands in for this cache when it occludes other caches (paper,
    /// "Occlusion": a disk per cache whose area comes from a Voronoi diagram computed after
    /// the distribution). Equal to `area`, which is exactly that Voronoi area.
    pub disk_area: f32,
    /// Area-weighted diffuse albedo ρ_d of the represented surface.
    pub diffuse: [f32; 3],
    /// Area-weighted Phong exponent k.
    pub exponent: f32,
    /// Area-weighted glossy colour ρ_g.
    pub glossy: [f32; 3],
    /// The model it belongs to and moves with (seed 004 §3: caches are distributed per model,
    /// in model space): the position in `Scene::nodes` of the innermost node of its surface
    /// when that node can move, [`STATIC`] for the static rest of the scene.
    pub model: u32,
}

/// [`LightCache::model`] of the scene's static geometry.
pub const STATIC: u32 = u32::MAX;

/// Per triangle, its model (see [`LightCache::model`]).
pub fn triangle_models(scene: &Scene) -> Vec<u32> {
    let vertices = vertex_models(scene);
    scene
        .indices
        .chunks_exact(3)
        .map(|t| vertices[t[0] as usize])
        .collect()
}

/// Per scene vertex, its model (see [`LightCache::model`]).
pub fn vertex_models(scene: &Scene) -> Vec<u32> {
    let moves = crate::scene::nodes::can_move(&scene.nodes);
    crate::scene::nodes::owners(&scene.nodes, scene.vertices.len() as u32)
        .into_iter()
        .map(|n| match moves.get(n as usize) {
            Some(true) => n,
            _ => STATIC,
        })
        .collect()
}

/// Wall-clock time of each step of [`precompute`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepTimings {
    /// Step 1, triangle sampling.
    pub sampling: Duration,
    /// Step 1, binning samples into voxels.
    pub voxelising: Duration,
    /// Steps 2–4.
    pub clustering: Duration,
    /// Step 5.
    pub merging: Duration,
    /// Voronoi areas and materials.
    pub assigning: Duration,
    /// Per-vertex nearest caches.
    pub neighbours: Duration,
    pub total: Duration,
}

/// Counts and timings of one [`precompute`] run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CacheStats {
    pub triangles: u64,
    /// Triangles without area, which get no samples.
    pub degenerate_triangles: u64,
    pub samples: u64,
    /// Occupied voxels.
    pub voxels: u64,
    /// Caches created by step 3.
    pub caches_before_merge: u64,
    /// Caches moved onto the surface by step 4 (counted again if a step-5 join floats).
    pub snapped: u64,
    /// Caches absorbed into another one by step 5.
    pub merged_away: u64,
    /// Caches left without any sample after the final assignment (every sample they averaged
    /// is closer to another compatible cache), which are dropped.
    pub dropped_empty: u64,
    /// Final cache count.
    pub caches: u64,
    /// Total triangle area of the scene (scene units squared).
    pub surface_area: f64,
    pub timings: StepTimings,
}

/// The light caches of one scene.
#[derive(Clone, Debug, PartialEq)]
pub struct CacheSet {
    pub params: CacheParams,
    /// What each cache sees (`cache_visibility`), traced after the caches are placed or
    /// loaded; never stored with them.
    pub visibility: Option<super::cache_visibility::CacheVisibility>,
    pub caches: Vec<LightCache>,
    /// Per scene vertex, indices of its 16 nearest caches (nearest first), padded with u32::MAX
    /// if fewer exist. Caches whose normal is within 90° of the vertex normal come first; only
    /// if fewer than 16 such caches exist in the whole scene do the nearest others follow.
    pub vertex_caches: Vec<[u32; NEIGHBOURS]>,
    pub stats: CacheStats,
}

/// Progress of [`precompute`]: `done` of `total` items of the named step.
pub use crate::gi::precompute::Progress;

/// A point sample of the surface (step 1).
#[derive(Clone, Copy, Debug)]
struct Sample {
    position: Vec3,
    /// Geometric normal of the triangle, oriented like its vertex normals.
    normal: Vec3,
    area: f32,
    material: u32,
    /// Its triangle's model: caches never gather samples of two models.
    model: u32,
}

/// A cache as steps 3–5 build it; `members` of the clustering output are its samples.
#[derive(Clone, Copy, Debug)]
struct Proto {
    position: Vec3,
    normal: Vec3,
    /// Area of the samples averaged into it (the weight for step 5 joins).
    area: f64,
    voxel: u32,
    first: u32,
    count: u32,
}

/// Derived constants shared by the steps.
struct Setup {
    d_eps: f32,
    cos_theta: f32,
    cos_half_theta: f32,
    normal_bins: u32,
}

impl Setup {
    fn new(params: &CacheParams) -> Self {
        let theta = params.theta_eps_degrees.to_radians();
        Self {
            d_eps: params.d_eps,
            cos_theta: theta.cos(),
            cos_half_theta: (theta * 0.5).cos(),
            normal_bins: normal_resolution(theta),
        }
    }
}

/// Computes the light caches of `scene` (paper steps 1–5, then areas, materials and per-vertex
/// neighbours). `progress` is called from this thread between chunks of work.
pub fn precompute(
    scene: &Scene,
    params: &CacheParams,
    progress: &mut dyn FnMut(Progress),
) -> Result<CacheSet, CacheError> {
    let area = surface_area(scene);
    params.validate_for_area(area)?;
    let start = Instant::now();
    let setup = Setup::new(params);
    let mut stats = CacheStats {
        triangles: scene.triangle_count() as u64,
        surface_area: area,
        ..CacheStats::default()
    };

    let t = Instant::now();
    let (samples, degenerate) = sample_surfaces(scene, params.d_eps, progress)?;
    stats.degenerate_triangles = degenerate;
    stats.samples = samples.len() as u64;
    stats.timings.sampling = t.elapsed();

    let t = Instant::now();
    let (voxel_order, voxels) = voxelise(&samples, params.d_eps * VOXEL_EDGE, progress);
    stats.voxels = voxels.len() as u64;
    stats.timings.voxelising = t.elapsed();

    let t = Instant::now();
    let (protos, members, snapped) = cluster(&samples, &voxel_order, &voxels, &setup, progress);
    drop(voxel_order);
    stats.caches_before_merge = protos.len() as u64;
    stats.snapped = snapped;
    if protos.len() as u64 > MAX_CACHES {
        return Err(CacheError::TooManyCachesCreated {
            d_eps: params.d_eps,
            theta_eps_degrees: params.theta_eps_degrees,
            count: protos.len() as u64,
        });
    }
    stats.timings.clustering = t.elapsed();

    let t = Instant::now();
    let (joined, owner, merge_snapped) = merge(&protos, &members, &samples, &setup, progress);
    stats.merged_away = (protos.len() - joined.len()) as u64;
    stats.snapped += merge_snapped;
    stats.timings.merging = t.elapsed();

    let t = Instant::now();
    let caches = assign(scene, &samples, &joined, &owner, &setup, progress);
    stats.dropped_empty = (joined.len() - caches.len()) as u64;
    stats.caches = caches.len() as u64;
    stats.timings.assigning = t.elapsed();

    let t = Instant::now();
    let vertex_caches = vertex_neighbours(scene, &caches, progress);
    stats.timings.neighbours = t.elapsed();
    stats.timings.total = start.elapsed();

    tracing::debug!(?stats, "light caches computed");
    Ok(CacheSet {
        params: *params,
        visibility: None,
        caches,
        vertex_caches,
        stats,
    })
}

// ---------------------------------------------------------------------------------------------
// Scene helpers
// ---------------------------------------------------------------------------------------------

/// The paper's lobes per material (`Brdf::mean_lobes`: a cache's light goes every way), with
/// base colour textures folded in as their mean linear colour (caches represent whole surface
/// patches, so a per-texel value is not needed). The lobes are affine in the base colour, so
/// scaling the base colour first is exact for the mean.
pub fn material_lobes(scene: &Scene) -> Vec<DiffuseGlossy> {
    let texture_means: Vec<Vec3> = scene
        .textures
        .par_iter()
        .map(|t| mean_linear_colour(&t.rgba8))
        .collect();
    scene
        .materials
        .iter()
        .map(|m| {
            let tint = m
                .base_color_texture
                .and_then(|t| texture_means.get(t).copied())
                .unwrap_or(Vec3::ONE);
            m.brdf_with(tint).mean_lobes()
        })
        .collect()
}

/// Mean linear RGB of sRGB-encoded RGBA8 pixels; an empty image is neutral white.
fn mean_linear_colour(rgba8: &[u8]) -> Vec3 {
    let lut: [f64; 256] = std::array::from_fn(|i| {
        let c = i as f64 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    });
    let pixels = rgba8.chunks_exact(4);
    let n = pixels.len();
    if n == 0 {
        return Vec3::ONE;
    }
    let sum = pixels.fold(DVec3::ZERO, |s, p| {
        s + DVec3::new(lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize])
    });
    (sum / n as f64).as_vec3()
}

fn round_significant(x: f64, digits: i32) -> f64 {
    if !(x > 0.0 && x.is_finite()) {
        return x;
    }
    let scale = 10f64.powi(x.log10().floor() as i32 - (digits - 1));
    (x / scale).round() * scale
}

fn round_up_significant(x: f64, digits: i32) -> f64 {
    if !(x > 0.0 && x.is_finite()) {
        return x;
    }
    let scale = 10f64.powi(x.log10().floor() as i32 - (digits - 1));
    (x / scale).ceil() * scale
}

/// Runs `f` over `0..n` in parallel, in chunks with a progress report after each; results keep
/// their order.
fn par_map_chunked<T: Send>(
    n: usize,
    step: &'static str,
    progress: &mut dyn FnMut(Progress),
    f: impl Fn(usize) -> T + Sync + Send,
) -> Vec<T> {
    let mut out = Vec::with_capacity(n);
    progress(Progress {
        step,
        done: 0,
        total: n as u64,
    });
    let mut start = 0;
    while start < n {
        let end = (start + CHUNK).min(n);
        out.par_extend((start..end).into_par_iter().map(&f));
        progress(Progress {
            step,
            done: end as u64,
            total: n as u64,
        });
        start = end;
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Step 1: sampling and voxelisation
// ---------------------------------------------------------------------------------------------

#[cfg(test)]
mod tests;
