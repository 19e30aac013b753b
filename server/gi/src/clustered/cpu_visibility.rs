//! CPU reference of `clustered`'s visibility (seed paper 003, §4.1–4.2), mirroring
//! `shaders/clustered/paraboloid.wgsl`, `paraboloid_maps.wgsl`, `cssm_basis.wgsl`,
//! `cssm_mips.wgsl` and `visibility.wgsl` in plain `f32`:
//!
//! * the paraboloid projection around a light's normal ([`frame`], [`uv_of`],
//!   [`direction_of`]) and the exact per-texel depth of a map by ray casting ([`map_depth`]);
//! * the truncated Fourier series of the depth test H(z − d) ([`fourier_step`]) and its
//!   basis ([`basis`]);
//! * the basis's mip chain and its trilinear lookups ([`CssmMaps`]), the blocker search, the
//!   penumbra estimate of Figure 3 and the filtered test ([`CssmMaps::visibility`]), and the
//!   hard test of the per-VPL baseline ([`hard_visibility`]).

use super::passes::{AtlasLayout, CSSM_BANDS};
use glam::{Mat3, Vec2, Vec3, Vec4};
use std::f32::consts::PI;

/// `MAP_LIFT`: maps look out from this fraction of the extent above their light's surface.
pub const MAP_LIFT: f32 = 1e-3;

/// Columns tangent, bitangent, n, as `paraboloid_frame`.
pub fn frame(n: Vec3) -> Mat3 {
    let (t, b) = super::cpu::tangent_basis(n);
    Mat3::from_cols(t, b, n)
}

/// The map coordinates of a unit direction given in the frame's coordinates.
pub fn uv_of(local: Vec3) -> Vec2 {
    Vec2::new(local.x, local.y) / (1.0 + local.z)
}

/// The unit direction (frame coordinates) of map coordinates `uv`.
pub fn direction_of(uv: Vec2) -> Vec3 {
    let r2 = uv.length_squared();
    Vec3::new(2.0 * uv.x, 2.0 * uv.y, 1.0 - r2) / (1.0 + r2)
}

/// Map coordinates of the centre of texel (x, y) of a map of side `size`.
pub fn texel_uv(x: u32, y: u32, size: u32) -> Vec2 {
    (Vec2::new(x as f32 + 0.5, y as f32 + 0.5) / size as f32) * 2.0 - 1.0
}

/// Distance from the origin along unit `d` to triangle abc (either side), Möller–Trumbore.
pub fn ray_triangle(d: Vec3, [a, b, c]: [Vec3; 3]) -> Option<f32> {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() <= 1e-9 * e1.length() * e2.length() {
        return None;
    }
    let s = -a;
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    let tolerance = 1e-6;
    if u < -tolerance || v < -tolerance || u + v > 1.0 + tolerance {
        return None;
    }
    Some(e2.dot(q) / det).filter(|&t| t > 0.0)
}

/// The depth a map of the light at `centre` with normal `normal` stores at `uv`: the nearest
/// triangle along the texel's ray, over `extent`, 1 where nothing is hit.
pub fn map_depth(
    triangles: &[[Vec3; 3]],
    centre: Vec3,
    normal: Vec3,
    uv: Vec2,
    extent: f32,
) -> f32 {
    let d = frame(normal) * direction_of(uv);
    triangles
        .iter()
        .filter_map(|t| ray_triangle(d, t.map(|p| p - centre)))
        .fold(f32::INFINITY, f32::min)
        .min(extent)
        / extent
}

/// c_k = π(2k + 1).
pub fn fourier_c(k: u32) -> f32 {
    PI * (2 * k + 1) as f32
}

/// S_K(t) = 1/2 + 2 Σ_{k<K} sin(c_k t)/c_k: the first K odd harmonics of the unit step H(t)
/// (period 2), the depth test H(z − d) of §4.1 with t = z − d.
pub fn fourier_step(t: f32, terms: u32) -> f32 {
    0.5 + (0..terms)
        .map(|k| 2.0 * (fourier_c(k) * t).sin() / fourier_c(k))
        .sum::<f32>()
}

/// The five basis bands of depth z, as `cssm_basis`.
pub fn basis(z: f32) -> [Vec4; CSSM_BANDS as usize] {
    let pair = |k: u32| {
        let (a, b) = (fourier_c(k) * z, fourier_c(k + 1) * z);
        Vec4::new(a.cos(), a.sin(), b.cos(), b.sin())
    };
    let (lo, hi) = (pair(0), pair(2));
    [lo, hi, lo * z, hi * z, Vec4::new(z, 0.0, 0.0, 0.0)]
}

/// 2 Σ_k (1/c_k)(cos(c_k d)·E[sin c_k z] − sin(c_k d)·E[cos c_k z]), as `fourier_sum`.
pub fn fourier_sum(lo: Vec4, hi: Vec4, d: f32, terms: u32) -> f32 {
    (0..terms)
        .map(|k| {
            let e = if k < 2 { lo } else { hi };
            let i = ((k % 2) * 2) as usize;
            let c = fourier_c(k);
            2.0 / c * ((c * d).cos() * e[i + 1] - (c * d).sin() * e[i])
        })
        .sum()
}

/// The test's depth offset for K terms (`cssm_offset`).
pub fn offset(terms: u32) -> f32 {
    0.25 / terms as f32
}

/// `cssm_sharpen`.
pub fn sharpen(step: f32) -> f32 {
    (2.0 * step - 0.5).clamp(0.0, 1.0)
}

/// A light as the maps see it.
#[derive(Clone, Copy, Debug)]
pub struct MapLight {
    pub position: Vec3,
    pub normal: Vec3,
    /// The VAL's bounding-rectangle area (0 for a VPL).
    pub area: f32,
}

impl MapLight {
    /// `map_origin`: where its map looks out from.
    pub fn origin(&self, extent: f32) -> Vec3 {
        self.position + self.normal * (MAP_LIFT * extent)
    }
}

/// Where a receiver falls in a light's map (`map_lookup`): `None` behind its reach.
struct Lookup {
    uv: Vec2,
    depth: f32,
    distance: f32,
    slope: f32,
}

fn lookup(light: &MapLight, x: Vec3, n: Vec3, map_size: u32, extent: f32) -> Option<Lookup> {
    let v = x - light.origin(extent);
    let d = v.length();
    if d <= 1e-6 * extent {
        return None;
    }
    let w = v / d;
    let local = frame(light.normal).transpose() * w;
    if local.z < -1.0 / 3.0 {
        return None;
    }
    let cos_r = n.dot(w).abs().max(1e-3);
    let slope = ((1.0 - cos_r * cos_r).max(0.0).sqrt() / cos_r).min(8.0);
    let distance = d / extent;
    Some(Lookup {
        uv: uv_of(local),
        distance,
        slope,
        // `map_lookup`'s bias: the texel's angle at the receiver times (tan θ + ½).
        depth: distance * (1.0 - 2.0 * (1.0 + local.z) / map_size as f32 * (0.5 + slope)),
    })
}

/// The paraboloid depth maps of a frame, read back, with the CSSM basis built from them.
pub struct CssmMaps {
    pub layout: AtlasLayout,
    pub extent: f32,
    /// Level 0 depths, row-major over the atlas.
    pub depth: Vec<f32>,
    /// Per mip level: (width, height, texels) of the basis texture (all bands stacked).
    levels: Vec<(u32, u32, Vec<Vec4>)>,
}

impl CssmMaps {
    /// The basis of every texel and its 2×2 box mip chain (`cssm_basis`, `cssm_mips`).
    pub fn new(layout: AtlasLayout, extent: f32, depth: Vec<f32>) -> Self {
        let (w, h) = (layout.width(), layout.height());
        let mut level0 = vec![Vec4::ZERO; (w * layout.basis_height()) as usize];
        for (i, &z) in depth.iter().enumerate() {
            let (x, y) = (i as u32 % w, i as u32 / w);
            for (band, value) in (0..).zip(basis(z)) {
                level0[((y + band * h) * w + x) as usize] = value;
            }
        }
        let mut levels = vec![(w, layout.basis_height(), level0)];
        for _ in 1..layout.mip_levels() {
            let (fw, _, finer) = levels.last().expect("level 0");
            let (cw, ch) = (fw / 2, levels.last().expect("level 0").1 / 2);
            let at = |x: u32, y: u32| finer[(y * fw + x) as usize];
            let coarser = (0..cw * ch)
                .map(|i| {
                    let (x, y) = (2 * (i % cw), 2 * (i / cw));
                    (at(x, y) + at(x + 1, y) + at(x, y + 1) + at(x + 1, y + 1)) * 0.25
                })
                .collect();
            levels.push((cw, ch, coarser));
        }
        Self {
            layout,
            extent,
            depth,
            levels,
        }
    }

    fn tile_origin(&self, j: u32) -> Vec2 {
        let l = &self.layout;
        Vec2::new((j % l.columns) as f32, (j / l.columns) as f32) * l.map_size as f32
    }

    fn atlas_position(&self, j: u32, uv: Vec2) -> Vec2 {
        self.tile_origin(j) + (uv * 0.5 + 0.5) * self.layout.map_size as f32
    }

    /// Bilinear lookup of level `l` at normalised coordinates, clamp-to-edge.
    fn bilinear(&self, l: usize, p: Vec2) -> Vec4 {
        let (w, h, texels) = &self.levels[l];
        let q = p * Vec2::new(*w as f32, *h as f32) - 0.5;
        let (x0, y0) = (q.x.floor(), q.y.floor());
        let (fx, fy) = (q.x - x0, q.y - y0);
        let at = |x: f32, y: f32| {
            let x = (x.max(0.0) as u32).min(w - 1);
            let y = (y.max(0.0) as u32).min(h - 1);
            texels[(y * w + x) as usize]
        };
        let top = at(x0, y0).lerp(at(x0 + 1.0, y0), fx);
        let bottom = at(x0, y0 + 1.0).lerp(at(x0 + 1.0, y0 + 1.0), fx);
        top.lerp(bottom, fy)
    }

    /// `sample_band`: band `band` of map j at uv, trilinear at `lod`, kept in the tile.
    pub fn sample_band(&self, j: u32, uv: Vec2, band: u32, lod: f32) -> Vec4 {
        let s = self.layout.map_size as f32;
        let texel = lod.ceil().exp2();
        let origin = self.tile_origin(j);
        let p = self
            .atlas_position(j, uv)
            .clamp(origin + 0.5 * texel, origin + s - 0.5 * texel);
        let height = self.layout.height() as f32;
        let size = Vec2::new(self.layout.width() as f32, height * CSSM_BANDS as f32);
        let p = (p + Vec2::new(0.0, band as f32 * height)) / size;
        let (l0, f) = (lod.floor(), lod - lod.floor());
        let a = self.bilinear(l0 as usize, p);
        if f == 0.0 {
            a
        } else {
            a.lerp(self.bilinear(l0 as usize + 1, p), f)
        }
    }

    /// `kernel_bias`: the receiver's own depth change across half the kernel of level `lod`.
    fn kernel_bias(&self, m: &Lookup, lod: f32) -> f32 {
        m.distance * m.slope * 0.5 * PI * lod.exp2() / self.layout.map_size as f32
    }

    fn angle_lod(&self, a: f32) -> f32 {
        let s = self.layout.map_size as f32;
        (s * a / PI).max(1.0).log2().clamp(0.0, s.log2())
    }

    /// V_C(x) of VAL j (`cssm_visibility`): blocker search over the VAL's angular size,
    /// z_avg, the penumbra p·cos β = (d − z_avg)·Λ/z_avg (Figure 3), its angle as the filter,
    /// and the sharpened filtered test, each with the receiver-plane bias of its kernel.
    pub fn visibility(&self, j: u32, light: &MapLight, x: Vec3, n: Vec3, terms: u32) -> f32 {
        let Some(m) = lookup(light, x, n, self.layout.map_size, self.extent) else {
            return 1.0;
        };
        let depth = m.depth - offset(terms);
        let side = light.area.max(0.0).sqrt() / self.extent;
        let search = self.angle_lod((side / m.distance).atan());
        let d = depth - self.kernel_bias(&m, search);
        let band = |b, lod| self.sample_band(j, m.uv, b, lod);
        let lit = 0.5 + fourier_sum(band(0, search), band(1, search), d, terms);
        let blockers = 1.0 - lit;
        if blockers < 0.02 {
            return 1.0;
        }
        let blocker_depth_sum =
            0.5 * band(4, search).x - fourier_sum(band(2, search), band(3, search), d, terms);
        let z_avg =
            (blocker_depth_sum / blockers).clamp(1e-3 * m.distance, d.max(1e-3 * m.distance));
        let penumbra = (d - z_avg) * side / z_avg;
        let lod = self.angle_lod((penumbra / m.distance).atan());
        let d = depth - self.kernel_bias(&m, lod);
        sharpen(0.5 + fourier_sum(band(0, lod), band(1, lod), d, terms))
    }
}

/// V_i(x) of `vpl_shadows`: the nearest texel of map j against the receiver's depth.
pub fn hard_visibility(maps: &CssmMaps, j: u32, light: &MapLight, x: Vec3, n: Vec3) -> f32 {
    let size = maps.layout.map_size;
    let Some(m) = lookup(light, x, n, size, maps.extent) else {
        return 1.0;
    };
    let origin = maps.tile_origin(j);
    let p = maps
        .atlas_position(j, m.uv)
        .floor()
        .clamp(origin, origin + (size - 1) as f32);
    let z = maps.depth[(p.y as u32 * maps.layout.width() + p.x as u32) as usize];
    if m.depth <= z {
        1.0
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mean |S_K − H| over t ∈ [−1, 1] (the whole period of the depth difference).
    fn step_error(terms: u32) -> f32 {
        let n = 4000;
        (0..n)
            .map(|i| {
                let t = -1.0 + 2.0 * (i as f32 + 0.5) / n as f32;
                (fourier_step(t, terms) - if t >= 0.0 { 1.0 } else { 0.0 }).abs()
            })
            .sum::<f32>()
            / n as f32
    }

    #[test]
    fn the_step_reconstruction_error_falls_with_k() {
        let errors: Vec<f32> = (1..=8).map(step_error).collect();
        eprintln!("mean |S_K - H| for K = 1..8: {errors:?}");
        assert!(errors.windows(2).all(|w| w[1] < w[0]), "{errors:?}");
        // Measured: each doubling of K takes off about 40 % (0.172, 0.109, 0.066, 0.039 at
        // K = 1, 2, 4, 8).
        assert!(
            errors[3] < 0.65 * errors[1] && errors[7] < 0.65 * errors[3],
            "{errors:?}"
        );
        assert!((0.15..0.2).contains(&errors[0]), "K = 1: {}", errors[0]);
    }

    #[test]
    fn the_sharpened_test_is_lit_at_the_receiver_and_dark_one_kth_nearer() {
        for terms in 1..=4 {
            let at_self = sharpen(fourier_step(offset(terms), terms));
            assert!(at_self > 0.99, "K = {terms}: {at_self}");
            // A blocker 1/(2K) of the extent in front of the receiver shadows it fully.
            let blocked = sharpen(fourier_step(offset(terms) - 0.5 / terms as f32, terms));
            assert!(blocked < 0.01, "K = {terms}: {blocked}");
            // Ringing is clamped away on both sides. (Near |t| = 1 the series wraps to its
            // next period; a receiver's own surface keeps z ≤ d there, so t stays below δ.)
            for i in 0..100 {
                let t = 0.3 + 0.4 * i as f32 / 100.0;
                assert_eq!(sharpen(fourier_step(t, terms)), 1.0, "K = {terms}, t = {t}");
                assert_eq!(
                    sharpen(fourier_step(-t, terms)),
                    0.0,
                    "K = {terms}, t = -{t}"
                );
            }
        }
    }

    #[test]
    fn the_filtered_basis_reconstructs_the_filtered_step() {
        // The mean of the basis over depths z_i, put through fourier_sum, equals the mean of
        // S_K(z_i − d): the convolution commutes with the expansion (§4.1).
        let depths = [0.1f32, 0.35, 0.4, 0.8, 0.95];
        let mean = |band: usize| {
            depths.iter().map(|&z| basis(z)[band]).sum::<Vec4>() / depths.len() as f32
        };
        for d in [0.05f32, 0.3, 0.5, 0.9] {
            let want = depths.iter().map(|&z| fourier_step(z - d, 4)).sum::<f32>() / 5.0;
            let got = 0.5 + fourier_sum(mean(0), mean(1), d, 4);
            assert!((want - got).abs() < 1e-5, "d = {d}: {got} vs {want}");
            // And the blocker-weighted depth sum: mean of z·(1 − S_K(z − d)).
            let want_z = depths
                .iter()
                .map(|&z| z * (1.0 - fourier_step(z - d, 4)))
                .sum::<f32>()
                / 5.0;
            let got_z = 0.5 * mean(4).x - fourier_sum(mean(2), mean(3), d, 4);
            assert!(
                (want_z - got_z).abs() < 1e-5,
                "d = {d}: {got_z} vs {want_z}"
            );
        }
    }

    #[test]
    fn the_paraboloid_projection_round_trips_and_covers_the_hemisphere() {
        for n in [Vec3::Z, -Vec3::Z, Vec3::new(0.3, -0.8, 0.2).normalize()] {
            let f = frame(n);
            assert!(
                (f.col(0).cross(f.col(1)) - n).length() < 1e-5,
                "right-handed"
            );
            assert!(f.col(0).dot(n).abs() < 1e-6 && f.col(1).dot(n).abs() < 1e-6);
        }
        for uv in [Vec2::ZERO, Vec2::new(0.5, -0.25), Vec2::new(1.0, 0.0)] {
            let d = direction_of(uv);
            assert!((d.length() - 1.0).abs() < 1e-6);
            assert!((uv_of(d) - uv).length() < 1e-6);
        }
        // The unit circle is the horizon, the corners reach 109.5° from the normal.
        assert!(direction_of(Vec2::new(0.0, 1.0)).z.abs() < 1e-6);
        assert!((direction_of(Vec2::ONE).z + 1.0 / 3.0).abs() < 1e-6);
    }

    #[test]
    fn a_ray_hits_a_triangle_inside_and_misses_outside() {
        let t = [
            Vec3::new(-1.0, -1.0, 2.0),
            Vec3::new(1.0, -1.0, 2.0),
            Vec3::new(0.0, 1.0, 2.0),
        ];
        assert!((ray_triangle(Vec3::Z, t).expect("hit") - 2.0).abs() < 1e-6);
        assert_eq!(ray_triangle(-Vec3::Z, t), None, "behind the origin");
        assert_eq!(ray_triangle(Vec3::new(0.9, 0.9, 1.0).normalize(), t), None);
    }
}
