//! What each light cache sees (`cache_visibility`, issue 34 part 4; beyond seed 004, whose
//! only occlusion is the double projection of proxy lights against cache disks, which on the
//! street removes none of the light that reaches a cache through buildings).
//!
//! Per cache, an octahedral grid of `side`² cells over the sphere holds, at its (side + 1)²
//! vertices, how far the cache sees in that direction: the nearest hit of one ray against
//! the scene's BVH, traced once per scene on the precompute worker (the scene is static, the
//! light may move). Cache lighting interpolates the distance bilinearly at a VAL's direction
//! ω and weighs the VAL at distance d by 1 up to it (with [`SLACK`]), falling linearly to 0
//! over [`RAMP`] beyond it. On a plane the distance varies smoothly with the direction, so a VAL on a surface the
//! cache sees lies at the interpolated distance, and a VAL behind a wall that fills the cell
//! lies beyond it; a cell across an occluder's edge interpolates between near and far and
//! lets part of the light through. (Kept per cell instead, the farthest of a cell's rays let
//! a third of the directions of a cache in the Cornell box see half again past the wall they
//! hit, and DDGI's per-texel mean and variance with Chebyshev's bound (Majercik et al. 2019)
//! cut a tenth or more of the light off 1,123 of its 1,267 caches, both for walls seen at
//! grazing angles, whose distance varies across a cell.)
//! Mirrored by `cache_visibility` in `shaders/lightskin/cache_lighting.wgsl`.

use super::caches::LightCache;
use crate::gi::common::bvh::SceneBvh;
use crate::gi::precompute::Progress;
use crate::scene::octahedral;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Elevation (radians, about) above the cache's surface at which the vertices below it look.
const HORIZON: f32 = 0.01;
/// Most grid vertices over all caches: 4 bytes each, 64 MiB.
pub const MAX_VERTICES: u64 = 1 << 24;
/// How far beyond the interpolated distance a VAL still counts as seen, as a share of it: a
/// cell's bilinear distance is below the true one by more than a tenth in 15 % of the
/// directions of a cache on the Cornell box's floor (16² cells), by more than a quarter in
/// 2–5 % (edges of the blocks, cells across the octahedron's folds).
pub const SLACK: f32 = 0.25;
/// Beyond the slack, how far visibility takes to fall from 1 to 0, as a share of the distance.
pub const RAMP: f32 = 0.25;

/// The visibility maps of a scene's caches (see the module).
#[derive(Clone, Debug, PartialEq)]
pub struct CacheVisibility {
    /// Cells per side of each cache's octahedral grid.
    pub side: u32,
    /// Per cache, (`side` + 1)² grid vertices row-major: the distance to the nearest hit in
    /// that direction, `far` where nothing was hit or the direction is below the cache's
    /// surface.
    pub distances: Vec<f32>,
}

/// Grid vertices per cache for `side` cells per side.
pub fn vertices(side: u32) -> u64 {
    u64::from(side + 1) * u64::from(side + 1)
}

/// The distance the grid `map` of `side` cells per side holds in unit direction `d`,
/// bilinear between the vertices of its cell.
pub fn interpolate(map: &[f32], side: u32, d: Vec3) -> f32 {
    let uv = (octahedral::encode(d) * 0.5 + Vec2::splat(0.5)) * side as f32;
    let cell = uv
        .floor()
        .min(Vec2::splat((side - 1) as f32))
        .max(Vec2::ZERO);
    let f = uv - cell;
    let at = |x: u32, y: u32| map[(y * (side + 1) + x) as usize];
    let (x, y) = (cell.x as u32, cell.y as u32);
    let bottom = at(x, y) * (1.0 - f.x) + at(x + 1, y) * f.x;
    let top = at(x, y + 1) * (1.0 - f.x) + at(x + 1, y + 1) * f.x;
    bottom * (1.0 - f.y) + top * f.y
}

/// The visibility of a point at `distance` in a direction that sees as far as `seen`.
pub fn ramp(seen: f32, distance: f32) -> f32 {
    ((seen * (1.0 + SLACK + RAMP) - distance) / (RAMP * seen)).clamp(0.0, 1.0)
}

impl CacheVisibility {
    /// Traces the maps of `caches` in `bvh`, `side`² cells each; rays start `offset` off
    /// each cache's surface and count as hitting at `far` when they hit nothing. Gives up
    /// between chunks of caches once `cancelled` says nobody can use the maps.
    pub fn build(
        bvh: &SceneBvh,
        caches: &[LightCache],
        side: u32,
        (offset, far): (f32, f32),
        progress: &mut dyn FnMut(Progress),
        cancelled: &dyn Fn() -> bool,
    ) -> Result<Self, String> {
        let total = caches.len() as u64 * vertices(side);
        if total > MAX_VERTICES {
            return Err(format!(
                "cache visibility of {} caches at {side}² directions is {total} rays, over the \
                 {MAX_VERTICES} a scene may hold: use a smaller cache_visibility or a larger \
                 cache_distance",
                caches.len()
            ));
        }
        let per_cache = vertices(side) as usize;
        let mut distances = vec![0.0f32; caches.len() * per_cache];
        // Progress per chunk of caches: the rays of a large scene take seconds.
        let chunk = 256;
        for (done, (maps, caches)) in distances
            .chunks_mut(per_cache * chunk)
            .zip(caches.chunks(chunk))
            .enumerate()
        {
            if cancelled() {
                return Err("cancelled: the scene was deleted, or nobody waits for the set".into());
            }
            progress(Progress {
                step: "cache visibility",
                done: (done * chunk) as u64,
                total: caches.len() as u64,
            });
            maps.par_chunks_mut(per_cache)
                .zip(caches.par_iter())
                .for_each(|(map, cache)| trace_map(bvh, cache, side, offset, far, map));
        }
        progress(Progress {
            step: "cache visibility",
            done: caches.len() as u64,
            total: caches.len() as u64,
        });
        Ok(Self { side, distances })
    }

    /// The visibility from cache `cache` of a point at `distance` in unit direction `dir`.
    pub fn visibility(&self, cache: usize, dir: Vec3, distance: f32) -> f32 {
        let per_cache = vertices(self.side) as usize;
        let map = &self.distances[cache * per_cache..(cache + 1) * per_cache];
        ramp(interpolate(map, self.side, dir), distance)
    }
}

fn trace_map(
    bvh: &SceneBvh,
    cache: &LightCache,
    side: u32,
    offset: f32,
    far: f32,
    map: &mut [f32],
) {
    let normal = Vec3::from(cache.normal);
    let origin = Vec3::from(cache.position) + normal * offset;
    for (i, seen) in map.iter_mut().enumerate() {
        let (x, y) = (i as u32 % (side + 1), i as u32 / (side + 1));
        let dir = octahedral::decode(Vec2::new(x as f32, y as f32) / side as f32 * 2.0 - Vec2::ONE);
        // Below its surface a cache receives nothing (cos θ_x = 0), and a ray there meets the
        // surface itself a hair away: that distance, interpolated into the cells across the
        // horizon, would hide the VALs just above it. Such a vertex holds what the cache sees
        // just above the horizon in its azimuth instead (straight down: `far`), so that the
        // cells across the horizon interpolate between distances above it.
        let below = dir.dot(normal);
        let dir = if below > 0.0 {
            dir
        } else {
            (dir - normal * below).normalize_or_zero() + normal * HORIZON
        };
        *seen = if dir.length_squared() < HORIZON * HORIZON * 2.0 {
            far
        } else {
            bvh.intersect(origin, dir.normalize(), far)
                .map_or(far, |h| h.t)
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::procedural;

    #[test]
    fn the_ramp_falls_from_a_quarter_to_half_beyond_the_seen_distance() {
        assert_eq!(ramp(2.0, 1.0), 1.0);
        assert_eq!(ramp(2.0, 2.5), 1.0);
        assert!((ramp(2.0, 2.75) - 0.5).abs() < 1e-5);
        assert_eq!(ramp(2.0, 3.0), 0.0);
        assert_eq!(ramp(2.0, 5.0), 0.0);
    }

    /// A cache on the Cornell box's floor sees up to whatever is above it and not twice as
    /// far, except in a few cells across an edge (the blocks', the lamp's): measured 22 and 58
    /// of 362 directions.
    #[test]
    fn a_cache_sees_as_far_as_the_nearest_surface() {
        let scene = procedural::cornell_box();
        let bvh = SceneBvh::build(&scene).expect("bvh");
        let (lo, hi) = (scene.bounds.min, scene.bounds.max);
        let centre = (lo + hi) * 0.5;
        let cache = LightCache {
            position: [centre.x + 0.05, lo.y + 0.01, centre.z - 0.05],
            normal: [0.0, 1.0, 0.0],
            ..bytemuck::Zeroable::zeroed()
        };
        let r = scene.bounds.radius();
        let maps = CacheVisibility::build(
            &bvh,
            &[cache],
            16,
            (1e-4 * r, 4.0 * r),
            &mut |_| {},
            &|| false,
        )
        .expect("fits");
        assert_eq!(maps.distances.len(), 17 * 17);
        let origin = Vec3::from(cache.position) + Vec3::Y * 1e-4 * r;
        // Over directions up from the cache that hit something: a point on that surface is
        // seen, one twice as far is not.
        let (mut hits, mut hidden, mut leaks) = (0, 0, 0);
        for dir in octahedral::fibonacci_sphere(800).filter(|d| d.y > 0.0) {
            let Some(hit) = bvh.intersect(origin, dir, 4.0 * r) else {
                continue;
            };
            hits += 1;
            hidden += usize::from(maps.visibility(0, dir, hit.t) < 1.0);
            leaks += usize::from(maps.visibility(0, dir, 2.0 * hit.t) > 0.0);
        }
        eprintln!("of {hits} directions: {hidden} hide their surface, {leaks} see twice as far");
        assert!(hits > 300);
        assert!(
            hidden * 10 < hits,
            "{hidden} of {hits} hide the surface they hit"
        );
        assert!(
            leaks * 5 < hits,
            "{leaks} of {hits} see twice as far as the surface"
        );
    }

    /// At a grid vertex's own direction the interpolation is that vertex's distance, and no
    /// vertex below the cache's surface sees its own surface.
    #[test]
    fn the_grid_holds_its_rays_distances() {
        let scene = procedural::cornell_box();
        let bvh = SceneBvh::build(&scene).expect("bvh");
        let cache = LightCache {
            position: [0.3, 0.01, 0.4],
            normal: [0.0, 1.0, 0.0],
            ..bytemuck::Zeroable::zeroed()
        };
        let side = 8;
        let maps =
            CacheVisibility::build(&bvh, &[cache], side, (1e-4, 10.0), &mut |_| {}, &|| false)
                .expect("fits");
        for (i, &seen) in maps.distances.iter().enumerate() {
            let (x, y) = (i as u32 % (side + 1), i as u32 / (side + 1));
            let uv = Vec2::new(x as f32, y as f32) / side as f32 * 2.0 - Vec2::ONE;
            let dir = octahedral::decode(uv);
            let at = interpolate(&maps.distances, side, dir);
            assert!(
                (at - seen).abs() <= 1e-4 * seen,
                "vertex {i}: {at} vs {seen}"
            );
            // Below the surface a vertex holds what the cache sees just above the horizon.
            if dir.y <= 0.0 {
                assert!(seen > 0.1, "vertex {i} below the surface sees {seen}");
            }
        }
    }

    fn cornell_bvh() -> SceneBvh {
        SceneBvh::build(&procedural::cornell_box()).expect("bvh")
    }

    #[test]
    fn a_cancelled_build_gives_up() {
        let bvh = cornell_bvh();
        let caches = vec![bytemuck::Zeroable::zeroed(); 10];
        let e = CacheVisibility::build(&bvh, &caches, 4, (1e-4, 10.0), &mut |_| {}, &|| true);
        assert!(e.is_err_and(|e| e.starts_with("cancelled")));
    }

    #[test]
    fn maps_over_the_budget_are_refused() {
        let bvh = cornell_bvh();
        let caches = vec![bytemuck::Zeroable::zeroed(); 20_000];
        let e = CacheVisibility::build(&bvh, &caches, 32, (1e-4, 10.0), &mut |_| {}, &|| false);
        assert!(e.is_err_and(|e| e.contains("cache_visibility")));
    }
}
