//! The SH caches' positions (seed 001, "Cache Placement"): a uniform lattice over the scene's
//! bounds, interpolated trilinearly per pixel. The paper sets its resolution by hand; the
//! default here aims at about [`DEFAULT_CACHES`] caches, the paper's order of magnitude.
//!
//! The lattice is node-centred with a margin of at least [`MIN_MARGIN`] spacings around the
//! bounds: every point of the scene has its eight surrounding caches, and no layer of caches
//! lies exactly on a floor or wall that spans the bounds (a cache on a surface sees it at
//! grazing angles, and half of its rays would start inside it).

use glam::{UVec3, Vec3};

/// The default spacing aims at about this many caches.
pub const DEFAULT_CACHES: u32 = 8192;
/// Most caches a grid may have (each holds n_L links).
pub const MAX_CACHES: u64 = 1 << 20;
/// Least distance between the bounds and the outermost caches, in spacings.
const MIN_MARGIN: f32 = 0.05;

/// A lattice of caches; cache (x, y, z) is number x + dims.x·(y + dims.y·z).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CacheGrid {
    /// Position of cache (0, 0, 0).
    pub origin: Vec3,
    /// Distance between neighbouring caches, in scene units.
    pub spacing: f32,
    pub dims: UVec3,
}

/// Why a grid cannot be laid over the bounds.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum GridError {
    #[error("the cache spacing must be a finite distance > 0, got {0}")]
    Spacing(f32),
    #[error(
        "a cache spacing of {spacing} makes {caches} caches over these bounds, more than \
         {MAX_CACHES}; use a spacing of at least {min_spacing}"
    )]
    TooMany {
        spacing: f32,
        caches: u64,
        min_spacing: f32,
    },
}

impl CacheGrid {
    /// The default spacing for bounds of `extent`: about [`DEFAULT_CACHES`] over the volume,
    /// with a flat scene counted at least a sixteenth of its largest side thick (so that a
    /// plane gets a few layers rather than millions of caches), rounded to 3 significant
    /// digits.
    pub fn default_spacing(extent: Vec3) -> f32 {
        let largest = extent.max_element().max(f32::MIN_POSITIVE);
        let volume = extent.max(Vec3::splat(largest / 16.0));
        let spacing = (f64::from(volume.x) * f64::from(volume.y) * f64::from(volume.z)
            / f64::from(DEFAULT_CACHES))
        .cbrt();
        round_significant(spacing, 3) as f32
    }

    /// The lattice of `spacing` over bounds `min`..`min + extent`.
    pub fn new(min: Vec3, extent: Vec3, spacing: f32) -> Result<Self, GridError> {
        if !(spacing.is_finite() && spacing > 0.0) {
            return Err(GridError::Spacing(spacing));
        }
        let n = [extent.x, extent.y, extent.z].map(|e| per_axis(e, spacing));
        let caches = count(extent, spacing);
        if caches > MAX_CACHES {
            return Err(GridError::TooMany {
                spacing,
                caches,
                min_spacing: min_spacing(extent),
            });
        }
        let dims = UVec3::new(n[0] as u32, n[1] as u32, n[2] as u32);
        let margins = Vec3::new(
            margin(extent.x, n[0], spacing),
            margin(extent.y, n[1], spacing),
            margin(extent.z, n[2], spacing),
        );
        Ok(Self {
            origin: min - margins,
            spacing,
            dims,
        })
    }

    pub fn count(&self) -> usize {
        (self.dims.x * self.dims.y * self.dims.z) as usize
    }

    /// Position of cache number `i`.
    pub fn position(&self, i: usize) -> Vec3 {
        let (dx, dy) = (self.dims.x as usize, self.dims.y as usize);
        let cell = UVec3::new(
            (i % dx) as u32,
            ((i / dx) % dy) as u32,
            (i / (dx * dy)) as u32,
        );
        self.origin + cell.as_vec3() * self.spacing
    }

    /// Whether cache `cache` may light a surface at `surface` with normal `n`: it lies on the
    /// side the normal faces (up to [`BEHIND_TOLERANCE`] spacings behind, for caches in the
    /// surface's plane). A cache behind the surface sees its other side: interpolating it
    /// would light the back of a wall from the room the wall closes (seed 001 places caches
    /// to see the surfaces they light; eq. 6 sums the caches around a point with no regard to
    /// which side they are on). Mirrored in `shaders/surfels/caches.wgsl`.
    pub fn in_front(&self, cache: usize, surface: Vec3, n: Vec3) -> bool {
        (self.position(cache) - surface).dot(n) >= -BEHIND_TOLERANCE * self.spacing
    }

    /// The eight caches around `p` with their trilinear weights (the per-pixel interpolation
    /// of the shading pass); points outside the lattice take its border cells.
    pub fn trilinear(&self, p: Vec3) -> [(usize, f32); 8] {
        let last = (self.dims - UVec3::ONE).max(UVec3::ONE).as_vec3();
        let t = ((p - self.origin) / self.spacing).clamp(Vec3::ZERO, last);
        let base = t.floor().min(last - Vec3::ONE).max(Vec3::ZERO);
        let f = t - base;
        let b = base.as_uvec3();
        let index = |c: UVec3| {
            let c = c.min(self.dims - UVec3::ONE);
            (c.x + self.dims.x * (c.y + self.dims.y * c.z)) as usize
        };
        std::array::from_fn(|k| {
            let o = UVec3::new(k as u32 & 1, (k as u32 >> 1) & 1, (k as u32 >> 2) & 1);
            let w = Vec3::select(o.cmpeq(UVec3::ONE), f, Vec3::ONE - f);
            (index(b + o), w.x * w.y * w.z)
        })
    }
}

/// How far (in cache spacings) a cache may lie behind a surface and still light it: rounding
/// only, so caches in the surface's own plane stay in.
pub const BEHIND_TOLERANCE: f32 = 1e-3;

/// Caches along an axis of `extent`: enough to span it with at least [`MIN_MARGIN`] to spare
/// on both sides.
fn per_axis(extent: f32, spacing: f32) -> u64 {
    let n = (f64::from(extent) / f64::from(spacing)).floor().min(1e12) as u64 + 2;
    if margin(extent, n, spacing) < MIN_MARGIN * spacing {
        n + 1
    } else {
        n
    }
}

fn count(extent: Vec3, spacing: f32) -> u64 {
    [extent.x, extent.y, extent.z]
        .map(|e| per_axis(e, spacing))
        .iter()
        .fold(1u64, |n, &a| n.saturating_mul(a))
}

/// The smallest spacing (3 significant digits, rounded up) whose grid over `extent` stays
/// within [`MAX_CACHES`].
fn min_spacing(extent: Vec3) -> f32 {
    let volume = extent.max(Vec3::splat(f32::MIN_POSITIVE));
    let mut spacing = (f64::from(volume.x) * f64::from(volume.y) * f64::from(volume.z)
        / MAX_CACHES as f64)
        .cbrt();
    // The lattice adds up to three caches per axis: step up until it fits.
    while count(extent, round_up_significant(spacing, 3) as f32) > MAX_CACHES {
        spacing *= 1.01;
    }
    round_up_significant(spacing, 3) as f32
}

/// The margin on each side of an axis of `extent` with `n` caches of `spacing`.
fn margin(extent: f32, n: u64, spacing: f32) -> f32 {
    ((n - 1) as f32 * spacing - extent) * 0.5
}

fn round_significant(v: f64, digits: i32) -> f64 {
    if v <= 0.0 || !v.is_finite() {
        return v;
    }
    let scale = 10f64.powi(digits - 1 - v.log10().floor() as i32);
    (v * scale).round() / scale
}

fn round_up_significant(v: f64, digits: i32) -> f64 {
    if v <= 0.0 || !v.is_finite() {
        return v;
    }
    let scale = 10f64.powi(digits - 1 - v.log10().floor() as i32);
    (v * scale).ceil() / scale
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lattice_surrounds_the_bounds_with_a_margin() {
        let (min, extent) = (Vec3::new(-1.0, 0.0, 2.0), Vec3::new(2.0, 1.0, 0.5));
        let g = CacheGrid::new(min, extent, 0.25).expect("grid");
        // 2 / 0.25 = 8 spacings exactly: 10 caches, half a spacing beyond each side.
        assert_eq!(g.dims, UVec3::new(10, 6, 4));
        assert!(
            (g.origin - (min - Vec3::new(0.125, 0.125, 0.125)))
                .abs()
                .max_element()
                < 1e-6
        );
        let top = g.position(g.count() - 1);
        for axis in 0..3 {
            let low = min[axis] - g.origin[axis];
            let high = top[axis] - (min[axis] + extent[axis]);
            assert!(low >= MIN_MARGIN * 0.25 - 1e-6 && high >= MIN_MARGIN * 0.25 - 1e-6);
            assert!((low - high).abs() < 1e-5, "centred: {low} vs {high}");
        }
        assert_eq!(g.position(1), g.origin + Vec3::new(0.25, 0.0, 0.0));
        assert_eq!(g.position(10), g.origin + Vec3::new(0.0, 0.25, 0.0));
        assert_eq!(g.position(60), g.origin + Vec3::new(0.0, 0.0, 0.25));
    }

    #[test]
    fn trilinear_weights_sum_to_one_and_reproduce_a_linear_function() {
        let g = CacheGrid::new(Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), 0.3).expect("grid");
        let f = |p: Vec3| 2.0 * p.x - p.y + 0.5 * p.z + 1.0;
        for k in 0..200 {
            let u = Vec3::new(
                crate::gi::common::halton::halton(k + 1, 2),
                crate::gi::common::halton::halton(k + 1, 3),
                crate::gi::common::halton::halton(k + 1, 5),
            );
            let p = u * Vec3::new(1.0, 2.0, 3.0);
            let w = g.trilinear(p);
            let total: f32 = w.iter().map(|(_, w)| w).sum();
            assert!((total - 1.0).abs() < 1e-5, "{total}");
            let interpolated: f32 = w.iter().map(|&(i, w)| w * f(g.position(i))).sum();
            assert!(
                (interpolated - f(p)).abs() < 1e-4,
                "{p}: {interpolated} vs {}",
                f(p)
            );
        }
    }

    #[test]
    fn the_default_spacing_aims_at_the_default_count() {
        for extent in [
            Vec3::splat(1.0),
            Vec3::new(5.5, 5.5, 5.5),
            Vec3::new(2000.0, 30.0, 2000.0),
        ] {
            let spacing = CacheGrid::default_spacing(extent);
            let g = CacheGrid::new(Vec3::ZERO, extent, spacing).expect("grid");
            let n = g.count() as f32;
            assert!(
                (0.5..2.0).contains(&(n / DEFAULT_CACHES as f32)),
                "{extent}: {n} caches at spacing {spacing}"
            );
            assert!(g.dims.min_element() >= 2, "{extent}: {}", g.dims);
        }
        // A flat square gets a few layers, not millions of caches.
        let flat = Vec3::new(10.0, 0.0, 10.0);
        let g = CacheGrid::new(Vec3::ZERO, flat, CacheGrid::default_spacing(flat)).expect("grid");
        assert!(g.count() <= 2 * DEFAULT_CACHES as usize, "{}", g.dims);
    }

    #[test]
    fn bad_spacings_are_refused_with_what_would_fit() {
        assert_eq!(
            CacheGrid::new(Vec3::ZERO, Vec3::ONE, 0.0),
            Err(GridError::Spacing(0.0))
        );
        assert!(CacheGrid::new(Vec3::ZERO, Vec3::ONE, f32::NAN).is_err());
        let Err(GridError::TooMany { min_spacing, .. }) =
            CacheGrid::new(Vec3::ZERO, Vec3::splat(100.0), 0.1)
        else {
            panic!("a million and more caches");
        };
        let g = CacheGrid::new(Vec3::ZERO, Vec3::splat(100.0), min_spacing).expect("fits");
        assert!(g.count() as u64 <= MAX_CACHES, "{}", g.count());
    }
}
