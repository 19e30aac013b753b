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
//! The output is bit-identical for the same input whatever the thread count: parallel work is
//! split into fixed chunks whose results are concatenated in order, floating-point sums run
//! sequentially in a fixed order, and every sort has a total order with an index tie-break.

use crate::gi::common::kdtree::KdTree;
use crate::gi::common::triangles::{surface_area, triangle, triangle_area, triangle_normal};
use crate::scene::material::{split, DiffuseGlossy};
use crate::scene::Scene;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::time::{Duration, Instant};

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
    pub pad0: f32,
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
        caches,
        vertex_caches,
        stats,
    })
}

// ---------------------------------------------------------------------------------------------
// Scene helpers
// ---------------------------------------------------------------------------------------------

/// The paper's BRDF parameters per material, with base colour textures folded in as their mean
/// linear colour (caches represent whole surface patches, so a per-texel value is not needed).
/// The split is linear in the base colour, so scaling the base colour first is exact for the
/// mean.
pub fn material_splits(scene: &Scene) -> Vec<DiffuseGlossy> {
    let texture_means: Vec<Vec3> = scene
        .textures
        .par_iter()
        .map(|t| mean_linear_colour(&t.rgba8))
        .collect();
    scene
        .materials
        .iter()
        .map(|m| {
            let [r, g, b, _] = m.base_color;
            let tint = m
                .base_color_texture
                .and_then(|t| texture_means.get(t).copied())
                .unwrap_or(Vec3::ONE);
            split(Vec3::new(r, g, b) * tint, m.metallic, m.roughness)
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

/// Splits a triangle by longest-edge bisection until no piece has an edge longer than
/// `spacing`, calling `emit(centroid, area)` per piece, and returns the piece count (stopping
/// early once it passes `budget`). Bisection keeps pieces well shaped (the smallest angle at
/// most halves) and needs only O(area/spacing² + perimeter/spacing) pieces even for slivers,
/// and every surface point lies within `spacing` (the piece's longest edge) of its piece's
/// centroid sample.
fn bisect(
    corners: [Vec3; 3],
    area: f64,
    spacing: f32,
    budget: u64,
    stack: &mut Vec<([Vec3; 3], u32)>,
    emit: &mut impl FnMut(Vec3, f64),
) -> u64 {
    let spacing2 = spacing * spacing;
    let mut pieces = 0u64;
    stack.clear();
    stack.push((corners, 0));
    while let Some(([a, b, c], depth)) = stack.pop() {
        let edges = [
            (b - a).length_squared(),
            (c - b).length_squared(),
            (a - c).length_squared(),
        ];
        let longest = if edges[0] >= edges[1] && edges[0] >= edges[2] {
            0
        } else if edges[1] >= edges[2] {
            1
        } else {
            2
        };
        if edges[longest] <= spacing2 || depth >= MAX_BISECTION_DEPTH {
            emit((a + b + c) / 3.0, area / f64::from(depth).exp2());
            pieces += 1;
            if pieces > budget {
                return pieces;
            }
            continue;
        }
        // Rotate so the longest edge runs from p to q, with r opposite.
        let (p, q, r) = match longest {
            0 => (a, b, c),
            1 => (b, c, a),
            _ => (c, a, b),
        };
        let m = (p + q) * 0.5;
        stack.push(([m, q, r], depth + 1));
        stack.push(([p, m, r], depth + 1));
    }
    pieces
}

/// Step 1: area-weighted surface samples with geometric triangle normals (flat per triangle, so
/// a sample's normal is exactly the surface normal at the sample; vertex normals may be smoothed
/// across creases that the caches should respect). Returns the samples and the number of
/// triangles without area.
fn sample_surfaces(
    scene: &Scene,
    d_eps: f32,
    progress: &mut dyn FnMut(Progress),
) -> Result<(Vec<Sample>, u64), CacheError> {
    let spacing = d_eps * SAMPLE_SPACING;
    let triangles = scene.triangle_count();
    let blocks = triangles.div_ceil(TRIANGLE_BLOCK);
    let block_range = |b: usize| b * TRIANGLE_BLOCK..((b + 1) * TRIANGLE_BLOCK).min(triangles);

    // Count first so that memory is only committed once the total is known to be sane.
    let counts = par_map_chunked(blocks, "counting samples", progress, |b| {
        let mut stack = Vec::new();
        let mut count = 0u64;
        for t in block_range(b) {
            if let Some((_, corners)) = triangle_normal(scene, t) {
                count += bisect(
                    corners,
                    0.0,
                    spacing,
                    MAX_SAMPLES,
                    &mut stack,
                    &mut |_, _| {},
                );
                if count > MAX_SAMPLES {
                    break;
                }
            }
        }
        count
    });
    let total = counts
        .iter()
        .try_fold(0u64, |s, &c| s.checked_add(c).filter(|&s| s <= MAX_SAMPLES));
    let Some(total) = total else {
        return Err(CacheError::TooManySamples { d_eps });
    };

    let per_block = par_map_chunked(blocks, "sampling", progress, |b| {
        let mut stack = Vec::new();
        let mut out = Vec::new();
        let mut degenerate = 0u64;
        for t in block_range(b) {
            let Some((normal, corners)) = triangle_normal(scene, t) else {
                degenerate += 1;
                continue;
            };
            let material = scene.vertices[triangle(scene, t)[0] as usize].material;
            let area = triangle_area(scene, t);
            bisect(corners, area, spacing, u64::MAX, &mut stack, &mut |p, a| {
                out.push(Sample {
                    position: p,
                    normal,
                    // Keep every weight positive so weighted means never divide by zero.
                    area: (a as f32).max(f32::MIN_POSITIVE),
                    material,
                })
            });
        }
        (out, degenerate)
    });
    let mut samples = Vec::with_capacity(total as usize);
    let mut degenerate = 0;
    for (block, d) in per_block {
        samples.extend_from_slice(&block);
        degenerate += d;
    }
    Ok((samples, degenerate))
}

/// Step 1: bins samples into voxels of edge `h`. Returns the sample indices ordered by voxel and
/// each voxel's range in that order. Sorting by (voxel, sample) instead of filling a hash map
/// gives a deterministic voxel order for free.
fn voxelise(
    samples: &[Sample],
    h: f32,
    progress: &mut dyn FnMut(Progress),
) -> (Vec<u32>, Vec<(u32, u32)>) {
    let n = samples.len() as u64;
    progress(Progress {
        step: "voxelising",
        done: 0,
        total: n,
    });
    let h = f64::from(h);
    let mut keyed: Vec<([i64; 3], u32)> = samples
        .par_iter()
        .enumerate()
        .map(|(i, s)| {
            let p = s.position.as_dvec3() / h;
            // Saturating float-to-int casts keep absurd coordinates from wrapping.
            let key = [p.x.floor() as i64, p.y.floor() as i64, p.z.floor() as i64];
            (key, i as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    let mut voxels = Vec::new();
    let mut start = 0;
    for i in 1..=keyed.len() {
        if i == keyed.len() || keyed[i].0 != keyed[start].0 {
            voxels.push((start as u32, i as u32));
            start = i;
        }
    }
    progress(Progress {
        step: "voxelising",
        done: n,
        total: n,
    });
    (keyed.into_iter().map(|(_, i)| i).collect(), voxels)
}

// ---------------------------------------------------------------------------------------------
// Steps 2–4: normal containers, clustering, snapping
// ---------------------------------------------------------------------------------------------

/// Cells per cube-face side of the normal container (step 2). A cell at a face centre spans the
/// widest angle, whose half-diagonal is at most √2/N radians; N > √2/θ keeps every bin inside a
/// θ-cone around its centre, so the bin chosen in step 3 always contributes samples.
fn normal_resolution(theta: f32) -> u32 {
    ((std::f32::consts::SQRT_2 / theta).floor() as u32)
        .saturating_add(1)
        .clamp(1, 16384)
}

/// Cube-map bin of a unit normal: face (±X, ±Y, ±Z) then an N×N grid on that face.
fn normal_bin(n: Vec3, res: u32) -> u32 {
    let a = n.abs();
    let (face, u, v, major) = if a.x >= a.y && a.x >= a.z {
        (u32::from(n.x < 0.0), n.y, n.z, a.x)
    } else if a.y >= a.z {
        (2 + u32::from(n.y < 0.0), n.z, n.x, a.y)
    } else {
        (4 + u32::from(n.z < 0.0), n.x, n.y, a.z)
    };
    let cell = |c: f32| (((c / major + 1.0) * 0.5 * res as f32) as u32).min(res - 1);
    (face * res + cell(v)) * res + cell(u)
}

/// Centre direction of a [`normal_bin`] cell.
fn normal_bin_centre(bin: u32, res: u32) -> Vec3 {
    let face = bin / (res * res);
    let within = bin % (res * res);
    let coord = |i: u32| (i as f32 + 0.5) / res as f32 * 2.0 - 1.0;
    let (v, u) = (coord(within / res), coord(within % res));
    let sign = if face.is_multiple_of(2) { 1.0 } else { -1.0 };
    match face / 2 {
        0 => Vec3::new(sign, u, v),
        1 => Vec3::new(v, sign, u),
        _ => Vec3::new(u, v, sign),
    }
    .normalize()
}

/// Steps 2–4 for every voxel. Returns the caches, their member samples (each cache's
/// `first..first + count`) and how many caches were snapped.
fn cluster(
    samples: &[Sample],
    voxel_order: &[u32],
    voxels: &[(u32, u32)],
    setup: &Setup,
    progress: &mut dyn FnMut(Progress),
) -> (Vec<Proto>, Vec<u32>, u64) {
    let per_voxel = par_map_chunked(voxels.len(), "clustering", progress, |v| {
        let (start, end) = voxels[v];
        cluster_voxel(
            samples,
            &voxel_order[start as usize..end as usize],
            v as u32,
            setup,
        )
    });
    let mut protos = Vec::new();
    let mut members = Vec::with_capacity(samples.len());
    let mut snapped = 0;
    for (voxel_protos, voxel_members, voxel_snapped) in per_voxel {
        let base = members.len() as u32;
        protos.extend(voxel_protos.into_iter().map(|p| Proto {
            first: p.first + base,
            ..p
        }));
        members.extend_from_slice(&voxel_members);
        snapped += voxel_snapped;
    }
    (protos, members, snapped)
}

/// Steps 2–4 for one voxel's samples.
fn cluster_voxel(
    samples: &[Sample],
    voxel_samples: &[u32],
    voxel: u32,
    setup: &Setup,
) -> (Vec<Proto>, Vec<u32>, u64) {
    let res = setup.normal_bins;
    let cos = setup.cos_theta;
    // Step 2: the normal container, kept as (bin, sample) pairs sorted by bin.
    let mut remaining: Vec<(u32, u32)> = voxel_samples
        .iter()
        .map(|&s| (normal_bin(samples[s as usize].normal, res), s))
        .collect();
    remaining.sort_unstable();

    let mut protos = Vec::new();
    let mut members = Vec::new();
    let mut snapped = 0;
    while !remaining.is_empty() {
        // Step 3: the bin representing the largest surface (lowest bin id on ties).
        let mut best = (remaining[0].0, f64::NEG_INFINITY);
        let mut run_start = 0;
        for i in 1..=remaining.len() {
            if i == remaining.len() || remaining[i].0 != remaining[run_start].0 {
                let area: f64 = remaining[run_start..i]
                    .iter()
                    .map(|&(_, s)| f64::from(samples[s as usize].area))
                    .sum();
                if area > best.1 {
                    best = (remaining[run_start].0, area);
                }
                run_start = i;
            }
        }
        let centre = normal_bin_centre(best.0, res);
        // Samples deviating less than theta_eps from the bin centre; the bin's own samples
        // always count, which only matters when theta_eps is below the container resolution.
        let around_centre =
            |&(bin, s): &(u32, u32)| bin == best.0 || samples[s as usize].normal.dot(centre) > cos;

        let mut normal_sum = DVec3::ZERO;
        for entry in remaining.iter().filter(|e| around_centre(e)) {
            let s = &samples[entry.1 as usize];
            normal_sum += s.normal.as_dvec3() * f64::from(s.area);
        }
        let mut normal = normal_sum.as_vec3().try_normalize().unwrap_or(centre);
        // The cache represents (and removes) those samples that are also within theta_eps of
        // the averaged normal, so every sample ends up within theta_eps of its cache. For
        // normals inside a θ-cone the weighted mean always has one such sample: if all had
        // n·m̂ <= cos θ, then |m| = Σ wᵢ nᵢ·m̂ <= cos θ < Σ wᵢ nᵢ·c <= |m|.
        let mut taken: Vec<u32> = remaining
            .iter()
            .filter(|e| around_centre(e) && samples[e.1 as usize].normal.dot(normal) > cos)
            .map(|e| e.1)
            .collect();
        if taken.is_empty() {
            // Only reachable through the bin fallback above: take the best-aligned sample.
            let closest = remaining
                .iter()
                .filter(|e| around_centre(e))
                .max_by(|a, b| {
                    let da = samples[a.1 as usize].normal.dot(normal);
                    let db = samples[b.1 as usize].normal.dot(normal);
                    da.total_cmp(&db).then(b.1.cmp(&a.1))
                })
                .map_or(remaining[0].1, |e| e.1);
            normal = samples[closest as usize].normal;
            taken.push(closest);
        }
        taken.sort_unstable();

        let (mut position, area) = weighted_position(samples, &taken);
        if let Some(p) = snap(samples, &taken, position, setup.d_eps) {
            position = p;
            snapped += 1;
        }
        protos.push(Proto {
            position,
            normal,
            area,
            voxel,
            first: members.len() as u32,
            count: taken.len() as u32,
        });
        members.extend_from_slice(&taken);
        remaining.retain(|e| taken.binary_search(&e.1).is_err());
    }
    (protos, members, snapped)
}

/// Area-weighted mean position of samples, and their total area.
fn weighted_position(samples: &[Sample], ids: &[u32]) -> (Vec3, f64) {
    let mut sum = DVec3::ZERO;
    let mut area = 0.0;
    for &s in ids {
        let s = &samples[s as usize];
        let a = f64::from(s.area);
        sum += s.position.as_dvec3() * a;
        area += a;
    }
    ((sum / area).as_vec3(), area)
}

/// Step 4: an averaged position can float off a curved or bent surface. It counts as floating
/// when it lies off the tangent plane of its closest sample by more than a small fraction of
/// d_eps; then the cache moves onto that sample.
fn snap(samples: &[Sample], ids: &[u32], position: Vec3, d_eps: f32) -> Option<Vec3> {
    let closest = ids.iter().copied().min_by(|&a, &b| {
        let da = samples[a as usize].position.distance_squared(position);
        let db = samples[b as usize].position.distance_squared(position);
        da.total_cmp(&db).then(a.cmp(&b))
    })?;
    let s = &samples[closest as usize];
    let off_plane = (position - s.position).dot(s.normal).abs();
    (off_plane > FLOATING_TOLERANCE * d_eps).then_some(s.position)
}

// ---------------------------------------------------------------------------------------------
// Step 5: joining caches across voxels
// ---------------------------------------------------------------------------------------------

/// A cache after step 5.
#[derive(Clone, Copy, Debug)]
struct Joined {
    position: Vec3,
    normal: Vec3,
}

/// Step 5: caches from different voxels closer than d_eps/4 whose normals differ by less than
/// theta_eps/2 are joined (area-weighted position and normal). Larger caches absorb smaller
/// ones first, so the order (and the result) is fixed. A join is skipped if it would leave any
/// member sample more than theta_eps from the joined normal. Returns the joined caches, the
/// joined cache of every sample and how many joins had to be snapped (step 4 again).
fn merge(
    protos: &[Proto],
    members: &[u32],
    samples: &[Sample],
    setup: &Setup,
    progress: &mut dyn FnMut(Progress),
) -> (Vec<Joined>, Vec<u32>, u64) {
    let n = protos.len();
    progress(Progress {
        step: "merging",
        done: 0,
        total: n as u64,
    });
    let positions: Vec<Vec3> = protos.iter().map(|p| p.position).collect();
    let tree = KdTree::new(&positions);
    let radius = setup.d_eps * MERGE_DISTANCE;
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.par_sort_unstable_by(|&a, &b| {
        protos[b as usize]
            .area
            .total_cmp(&protos[a as usize].area)
            .then(a.cmp(&b))
    });
    let member_ids = |p: &Proto| &members[p.first as usize..(p.first + p.count) as usize];

    let mut taken = vec![false; n];
    // (anchor, group) in anchor order of processing; sorted by anchor afterwards.
    let mut groups: Vec<(u32, Vec<u32>)> = Vec::with_capacity(n);
    let mut candidates = Vec::new();
    for (done, &i) in order.iter().enumerate() {
        if done > 0 && done.is_multiple_of(CHUNK) {
            progress(Progress {
                step: "merging",
                done: done as u64,
                total: n as u64,
            });
        }
        if taken[i as usize] {
            continue;
        }
        taken[i as usize] = true;
        let anchor = &protos[i as usize];
        candidates.clear();
        tree.within(anchor.position, radius * radius, &mut |j| {
            let other = &protos[j as usize];
            if !taken[j as usize]
                && other.voxel != anchor.voxel
                && other.normal.dot(anchor.normal) > setup.cos_half_theta
            {
                candidates.push(j);
            }
        });
        candidates.sort_unstable();
        let mut group = vec![i];
        let mut normal_sum = anchor.normal.as_dvec3() * anchor.area;
        for &j in &candidates {
            let other = &protos[j as usize];
            let Some(normal) = (normal_sum + other.normal.as_dvec3() * other.area)
                .as_vec3()
                .try_normalize()
            else {
                continue;
            };
            let keeps_samples = group
                .iter()
                .chain(std::iter::once(&j))
                .flat_map(|&g| member_ids(&protos[g as usize]))
                .all(|&s| samples[s as usize].normal.dot(normal) > setup.cos_theta);
            if keeps_samples {
                group.push(j);
                taken[j as usize] = true;
                normal_sum += other.normal.as_dvec3() * other.area;
            }
        }
        groups.push((i, group));
    }
    groups.sort_unstable_by_key(|g| g.0);

    let mut owner = vec![u32::MAX; samples.len()];
    let mut snapped = 0;
    let joined = groups
        .iter()
        .enumerate()
        .map(|(index, (_, group))| {
            for &g in group {
                for &s in member_ids(&protos[g as usize]) {
                    owner[s as usize] = index as u32;
                }
            }
            let first = &protos[group[0] as usize];
            if group.len() == 1 {
                return Joined {
                    position: first.position,
                    normal: first.normal,
                };
            }
            let (mut position_sum, mut normal_sum, mut area) = (DVec3::ZERO, DVec3::ZERO, 0.0);
            for &g in group {
                let p = &protos[g as usize];
                position_sum += p.position.as_dvec3() * p.area;
                normal_sum += p.normal.as_dvec3() * p.area;
                area += p.area;
            }
            let mut position = (position_sum / area).as_vec3();
            let all_members: Vec<u32> = group
                .iter()
                .flat_map(|&g| member_ids(&protos[g as usize]).iter().copied())
                .collect();
            if let Some(p) = snap(samples, &all_members, position, setup.d_eps) {
                position = p;
                snapped += 1;
            }
            Joined {
                position,
                normal: normal_sum.as_vec3().try_normalize().unwrap_or(first.normal),
            }
        })
        .collect();
    progress(Progress {
        step: "merging",
        done: n as u64,
        total: n as u64,
    });
    (joined, owner, snapped)
}

// ---------------------------------------------------------------------------------------------
// Voronoi areas, materials, per-vertex neighbours
// ---------------------------------------------------------------------------------------------

/// Hands every sample to its nearest cache within d_eps whose normal is within theta_eps (else
/// to the cache that averaged it), so a cache's area is its Voronoi cell on the surface, and
/// averages the samples' materials per cache. Caches left without samples are dropped.
fn assign(
    scene: &Scene,
    samples: &[Sample],
    joined: &[Joined],
    owner: &[u32],
    setup: &Setup,
    progress: &mut dyn FnMut(Progress),
) -> Vec<LightCache> {
    let positions: Vec<Vec3> = joined.iter().map(|c| c.position).collect();
    let tree = KdTree::new(&positions);
    let d2 = setup.d_eps * setup.d_eps;
    let assigned = par_map_chunked(samples.len(), "assigning", progress, |i| {
        let s = &samples[i];
        let mut best = Nearest::new(1);
        tree.nearest(s.position, d2, &mut best, &|c| {
            joined[c as usize].normal.dot(s.normal) > setup.cos_theta
        });
        let nearest = best.ids().next();
        nearest.unwrap_or(owner[i])
    });

    let splits = material_splits(scene);
    #[derive(Clone, Copy, Default)]
    struct Sum {
        area: f64,
        diffuse: DVec3,
        glossy: DVec3,
        exponent: f64,
    }
    let mut sums = vec![Sum::default(); joined.len()];
    for (s, &c) in samples.iter().zip(&assigned) {
        let m = &splits[s.material as usize];
        let a = f64::from(s.area);
        let sum = &mut sums[c as usize];
        sum.area += a;
        sum.diffuse += m.diffuse.as_dvec3() * a;
        sum.glossy += m.glossy.as_dvec3() * a;
        sum.exponent += f64::from(m.exponent) * a;
    }
    joined
        .iter()
        .zip(&sums)
        .filter(|(_, s)| s.area > 0.0)
        .map(|(c, s)| {
            let area = s.area as f32;
            LightCache {
                position: c.position.to_array(),
                area,
                normal: c.normal.to_array(),
                disk_area: area,
                diffuse: (s.diffuse / s.area).as_vec3().to_array(),
                exponent: (s.exponent / s.area) as f32,
                glossy: (s.glossy / s.area).as_vec3().to_array(),
                pad0: 0.0,
            }
        })
        .collect()
}

/// The [`NEIGHBOURS`] nearest caches of every vertex among those facing the same hemisphere
/// (normal within 90°, so a wall's caches do not light the back of the wall), nearest first;
/// if the whole scene has fewer such caches, the nearest others follow, then u32::MAX.
fn vertex_neighbours(
    scene: &Scene,
    caches: &[LightCache],
    progress: &mut dyn FnMut(Progress),
) -> Vec<[u32; NEIGHBOURS]> {
    let positions: Vec<Vec3> = caches.iter().map(|c| Vec3::from(c.position)).collect();
    let normals: Vec<Vec3> = caches.iter().map(|c| Vec3::from(c.normal)).collect();
    let tree = KdTree::new(&positions);
    par_map_chunked(scene.vertices.len(), "neighbours", progress, |v| {
        let vertex = &scene.vertices[v];
        let p = Vec3::from(vertex.position);
        // A broken (non-finite) vertex normal faces every cache (dot 0) rather than none.
        let n = Some(Vec3::from(vertex.normal))
            .filter(|n| n.is_finite())
            .unwrap_or(Vec3::ZERO);
        let mut out = [u32::MAX; NEIGHBOURS];
        let mut facing = Nearest::new(NEIGHBOURS);
        tree.nearest(p, f32::INFINITY, &mut facing, &|c| {
            normals[c as usize].dot(n) >= 0.0
        });
        let mut len = 0;
        for id in facing.ids() {
            out[len] = id;
            len += 1;
        }
        if len < NEIGHBOURS {
            let mut others = Nearest::new(NEIGHBOURS - len);
            tree.nearest(p, f32::INFINITY, &mut others, &|c| {
                normals[c as usize].dot(n) < 0.0
            });
            for id in others.ids() {
                out[len] = id;
                len += 1;
            }
        }
        out
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic pseudo-random numbers for test inputs.
    struct SplitMix64(u64);

    impl SplitMix64 {
        fn next_f32(&mut self) -> f32 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
        }

        fn point(&mut self) -> Vec3 {
            Vec3::new(self.next_f32(), self.next_f32(), self.next_f32()) * 10.0 - 5.0
        }
    }

    #[test]
    fn bisection_covers_the_triangle_with_small_pieces() {
        // A sliver: 10 long, 0.01 high. Pieces must be short without squaring the count.
        let corners = [
            Vec3::ZERO,
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(4.0, 0.01, 0.0),
        ];
        let mut stack = Vec::new();
        let mut total = 0.0;
        let mut centroids = Vec::new();
        let count = bisect(corners, 0.05, 0.25, u64::MAX, &mut stack, &mut |p, a| {
            total += a;
            centroids.push(p);
        });
        assert_eq!(count as usize, centroids.len());
        assert!((total - 0.05).abs() < 1e-12, "areas sum to {total}");
        assert!(count < 400, "{count} pieces for a 40-spacing-long sliver");
        // Every point along the long edge is near a sample.
        for i in 0..=100 {
            let p = Vec3::new(i as f32 * 0.1, 0.0, 0.0);
            let d = centroids
                .iter()
                .map(|c| c.distance(p))
                .fold(f32::MAX, f32::min);
            assert!(d <= 0.25, "point {p} is {d} from its nearest sample");
        }
        // The budget stops the count early.
        assert_eq!(
            bisect(corners, 0.05, 0.001, 10, &mut stack, &mut |_, _| {}),
            11
        );
    }

    #[test]
    fn normal_bins_stay_within_theta_of_their_centre() {
        let mut rng = SplitMix64(9);
        for theta_deg in [90.0f32, 30.0, 10.0, 2.0] {
            let theta = theta_deg.to_radians();
            let res = normal_resolution(theta);
            for _ in 0..5000 {
                let Some(n) = rng.point().try_normalize() else {
                    continue;
                };
                let bin = normal_bin(n, res);
                assert!(bin < 6 * res * res);
                let angle = n.dot(normal_bin_centre(bin, res)).clamp(-1.0, 1.0).acos();
                assert!(angle < theta, "{n} is {angle} rad from its bin centre");
            }
        }
    }

    #[test]
    fn mean_linear_colour_decodes_srgb() {
        let white_black = [255, 255, 255, 255, 0, 0, 0, 255];
        assert_eq!(mean_linear_colour(&white_black), Vec3::splat(0.5));
        let mid = mean_linear_colour(&[128, 128, 128, 0]);
        assert!((mid.x - 0.2158).abs() < 1e-3, "{mid}");
        assert_eq!(mean_linear_colour(&[]), Vec3::ONE);
    }

    #[test]
    fn rounding_keeps_three_significant_digits() {
        assert!((round_significant(0.0141421, 3) - 0.0141).abs() < 1e-12);
        assert!((round_significant(45.678, 3) - 45.7).abs() < 1e-9);
        assert!((round_up_significant(45.612, 3) - 45.7).abs() < 1e-9);
    }
}
