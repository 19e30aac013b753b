//! CPU reference of LightSkin's proxy lights (seed paper 004), used by tests to check the GPU
//! passes. It evaluates, in plain `f32` arithmetic, the project's chosen reading of
//!
//! * "Proxy Lights Generation": the VAL radiance at a cache (eq. 3–4, with the BRSM weights
//!   1/(N_sVAL·P_VAL) of eq. 14–15), the proxy position (eq. 5–6, weighted as in eq. 13), its
//!   extent (the 2σ bounding box of "Occlusion", turned into a sphere) and its flux (eq. 7);
//! * "Interpolation using the Proxy Lights": the weights of eq. 8, the interpolated proxy
//!   light of eq. 9 and the shading of a surface point by it.
//!
//! Occlusion is not modelled. Nothing here depends on the rest of the crate (only `glam`).
//!
//! Why the albedo ρ cancels: eq. 7 divides the cache's outgoing radiance by its BRDF,
//! Φ_p = 4π·L_o·‖x_p − c‖² / (f_r·(n_c·ω_i)⁺). For the diffuse proxy, L_o,d = ρ_d/π·E_d (eq. 3)
//! and f_r = ρ_d/π; for the glossy proxy, L_o,g = ρ_g(k+2)/(2π)·E_g (eq. 4, the cos^k θ_e of each
//! VAL already inside E_g) and f_r = ρ_g(k+2)/(2π)·cos^k θ_e(ω_p). In both the albedo factor is
//! the same above and below the fraction bar, so it cancels: a proxy light carries the incident
//! light at the cache, independent of any material there, and the shaded surface applies its
//! own ρ_d, ρ_g in [`shade`].

use crate::passes::rsm::GlossySender;
use glam::Vec3;
use std::f32::consts::PI;

/// ε_p of eq. 6 as a fraction of the largest form factor the VAL could have at its distance:
/// each position weight of eq. 5 is ε_p·F_max + F with F_max = A_l/(A_l + π d²), the form factor
/// of the VAL's disk facing the cache head-on (eq. 3's denominator without the cosines). Eq. 6's
/// ε_p only keeps the sums of eq. 5 non-zero; added as a plain constant it would outweigh the
/// form factors of a high-resolution RSM's many tiny VALs (F shrinks with the texel) and drag
/// every proxy to the mean of the whole RSM, and multiplied by A_l alone (as before) it had
/// units of length²: 1e-6·A_l outweighed F in a kilometre-sized scene. F_max is dimensionless
/// and shrinks with the VAL like F does, so ε_p stays a relative 10⁻⁶ at any scale and RSM size.
pub const EPS_P: f32 = 1e-6;
/// Floor of (n_c·ω_p)⁺ in the diffuse flux of eq. 7.
pub const MIN_COS_DIFFUSE: f32 = 1e-3;
/// Floor of (n_c·ω_p)⁺·cos^k θ_e in the glossy flux of eq. 7.
pub const MIN_COS_GLOSSY: f32 = 1e-2;
/// Floor of the squared proxy–cache distance in eq. 7 and of the squared proxy–surface
/// distance when eq. 9's interpolated proxy lights a point, per unit of the cache's surface
/// area A_c: (r_c/2)² for the cache's cell seen as a disk of radius r_c = √(A_c/π). A proxy
/// nearer than that is below the resolution of the cache distribution, and a floor in scene
/// units (it was 1 cm) would flatten all indirect light in a centimetre-sized model. The two
/// floors match, so a point at the cache still receives exactly the cache's irradiance.
pub const MIN_DIST2_PER_AREA: f32 = 1.0 / (4.0 * PI);
/// A light cache: a point on a surface with its unit normal and Phong exponent k.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefCache {
    pub position: Vec3,
    /// Unit normal n_c.
    pub normal: Vec3,
    /// Phong exponent k of the glossy lobe (eq. 4).
    pub exponent: f32,
    /// Surface area the cache stands for (its Voronoi cell): the scale of the distance floors
    /// ([`MIN_DIST2_PER_AREA`]).
    pub area: f32,
}

/// A virtual area light (VAL) taken from the reflective shadow map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefVal {
    /// x_l.
    pub position: Vec3,
    /// Unit normal n_l.
    pub normal: Vec3,
    /// Φ_l (rgb).
    pub flux: Vec3,
    /// Disk area A_l (eq. 1).
    pub area: f32,
    /// 1 for LightSkin; 1/(N_sVAL·P_VAL) for BRSM (eq. 13–15). VALs with weight ≤ 0 are skipped.
    pub weight: f32,
    /// The glossy lobe it sends besides Φ_l (`GlossySender`; beyond the paper).
    pub glossy: GlossySender,
}

/// A proxy point light with its extent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProxyLight {
    /// x_p (eq. 5 / 13).
    pub position: Vec3,
    /// Φ_p (eq. 7), rgb.
    pub flux: Vec3,
    /// Radius of the sphere replacing the 2σ bounding box of the averaged VAL positions.
    pub radius: f32,
}

impl ProxyLight {
    /// Without flux: its cache saw no VAL, so its position means nothing.
    pub fn is_unlit(&self) -> bool {
        self.flux.cmple(Vec3::ZERO).all()
    }
}

/// The two proxy lights of one cache.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProxyLights {
    pub diffuse: ProxyLight,
    pub glossy: ProxyLight,
}

/// A surface point to shade.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefSurface {
    pub position: Vec3,
    /// Unit normal n_x.
    pub normal: Vec3,
    /// ρ_d (rgb).
    pub diffuse: Vec3,
    /// ρ_g (rgb).
    pub glossy: Vec3,
    /// Phong exponent k.
    pub exponent: f32,
}

/// `w` mirrored about `n`: 2(n·w)n − w.
pub fn reflect_about(n: Vec3, w: Vec3) -> Vec3 {
    2.0 * n.dot(w) * n - w
}

/// cos^k θ_e: the Phong lobe around the reflection of `w` (pointing away from the surface) about
/// `n`, seen from `view`.
fn phong_lobe(n: Vec3, w: Vec3, view: Vec3, exponent: f32) -> f32 {
    reflect_about(n, w).dot(view).max(0.0).powf(exponent)
}

/// Weighted first and second moments of VAL positions (eq. 5 / 13 and the σ of "Occlusion").
#[derive(Default)]
/// Moments of the VAL positions relative to the cache, as the shader keeps them: about the
/// origin, E[x²] − E[x]² in f32 would lose the spread to cancellation in large scenes.
struct Moments {
    /// S = Σ a.
    sum: f32,
    /// P = Σ a·(x_l − c).
    first: Vec3,
    /// Q = Σ a·(x_l − c)² (componentwise).
    second: Vec3,
}

impl Moments {
    fn add(&mut self, a: f32, offset: Vec3) {
        self.sum += a;
        self.first += a * offset;
        self.second += a * offset * offset;
    }

    /// (x_p, radius) for the cache at `cache`, or `None` when nothing was accumulated.
    fn position_and_radius(&self, cache: Vec3) -> Option<(Vec3, f32)> {
        if self.sum <= 0.0 {
            return None;
        }
        let mean = self.first / self.sum;
        let sigma = (self.second / self.sum - mean * mean)
            .max(Vec3::ZERO)
            .map(f32::sqrt);
        // Box of extent 2σ → sphere whose radius matches its largest dimension.
        Some((cache + mean, 2.0 * sigma.max_element()))
    }
}

/// Builds a proxy light at the position given by `moments`; `flux_at` gives Φ_p from x_p.
fn proxy_light(cache: Vec3, moments: &Moments, flux_at: impl Fn(Vec3) -> Vec3) -> ProxyLight {
    match moments.position_and_radius(cache) {
        Some((position, radius)) => ProxyLight {
            position,
            flux: flux_at(position),
            radius,
        },
        None => ProxyLight {
            position: cache,
            flux: Vec3::ZERO,
            radius: 0.0,
        },
    }
}

/// The diffuse and glossy proxy lights of `cache`, lit by `vals`, for a camera at `camera`
/// (eq. 3–7, 13–15).
pub fn light_cache(cache: &RefCache, vals: &[RefVal], camera: Vec3) -> ProxyLights {
    light_cache_seen(cache, vals, camera, |_, _| 1.0)
}

/// [`light_cache`] with each VAL weighted by `visible(direction, distance)`, how much of it
/// the cache sees in that unit direction at that distance (`cache_visibility`).
pub fn light_cache_seen(
    cache: &RefCache,
    vals: &[RefVal],
    camera: Vec3,
    visible: impl Fn(Vec3, f32) -> f32,
) -> ProxyLights {
    let c = cache.position;
    let n_c = cache.normal;
    let k = cache.exponent;
    let view = (camera - c).normalize_or_zero();

    // E_d = Σ w·Φ_l·G and E_g = Σ w·Φ_l·G·cos^k θ_e: eq. 14 / 15 without the ρ factors.
    let mut e_d = Vec3::ZERO;
    let mut e_g = Vec3::ZERO;
    let mut m_d = Moments::default();
    let mut m_g = Moments::default();
    for val in vals {
        if val.weight <= 0.0 {
            continue;
        }
        let delta = val.position - c;
        let len2 = delta.length_squared();
        if len2 == 0.0 {
            continue;
        }
        let d = len2.sqrt();
        // Direction cache → VAL.
        let omega = delta / d;
        let cos_l = val.normal.dot(-omega).max(0.0);
        let cos_x = n_c.dot(omega).max(0.0);
        // Largest form factor of the VAL's disk at this distance (facing the cache); the
        // disk's own area keeps it finite at any distance, so no distance floor is needed.
        let f_max = val.area / (val.area + PI * len2);
        // Geometric factor of eq. 3 / 4 for the VAL's disk.
        let g = cos_l * cos_x / (val.area + PI * len2);
        // A VAL that cannot light the cache takes no part, not even through ε_p: summed over
        // the many VALs behind a cache, ε_p alone would drag the proxy far off, and eq. 9 then
        // interpolates that far proxy's large flux onto nearby points.
        if g <= 0.0 {
            continue;
        }
        // Form factor disk → point at c (eq. 6): F_max·cos_l·cos_x.
        let form_factor = val.area * g;
        // cos^k θ_e of eq. 4 with the cache's k.
        let lobe = phong_lobe(n_c, omega, view, k);
        let w = val.weight * visible(omega, d);
        // Φ_l of eq. 3/4 is what the VAL sends towards the cache: its glossy lobe's share too.
        let flux = val
            .glossy
            .sent_flux(val.flux, -omega, GlossySender::spread(val.area, len2));
        e_d += w * g * flux;
        e_g += w * g * lobe * flux;
        // Eq. 6 weights (ε_p relative to F_max, see [`EPS_P`]) times the BRSM weight
        // 1/(N_sVAL·P_VAL) of eq. 13.
        m_d.add(w * (EPS_P * f_max + form_factor), delta);
        m_g.add(w * (EPS_P * f_max + lobe * form_factor), delta);
    }

    let min_dist2 = MIN_DIST2_PER_AREA * cache.area;
    // Eq. 7 with L_o,d = ρ_d/π·E_d and f_r = ρ_d/π: ρ_d cancels.
    let diffuse = proxy_light(c, &m_d, |x_p| {
        let to_proxy = x_p - c;
        let d_p2 = to_proxy.length_squared().max(min_dist2);
        let cos_p = n_c.dot(to_proxy.normalize_or_zero());
        4.0 * PI * d_p2 * e_d / cos_p.max(MIN_COS_DIFFUSE)
    });
    // Eq. 7 with L_o,g = ρ_g(k+2)/(2π)·E_g and f_r = ρ_g(k+2)/(2π)·cos^k θ_e(ω_p): ρ_g(k+2)/(2π)
    // cancels.
    let glossy = proxy_light(c, &m_g, |x_p| {
        let to_proxy = x_p - c;
        let d_p2 = to_proxy.length_squared().max(min_dist2);
        let omega_p = to_proxy.normalize_or_zero();
        let cos_p = n_c.dot(omega_p);
        let lobe_p = phong_lobe(n_c, omega_p, view, k);
        4.0 * PI * d_p2 * e_g / (cos_p * lobe_p).max(MIN_COS_GLOSSY)
    });
    ProxyLights { diffuse, glossy }
}

/// Running sums of eq. 9 for one proxy kind: Σ w', Σ w'·Φ_p and Σ w'·A_c over all
/// neighbours, Σ w' and Σ w'·x_p over lit ones. Unlit neighbours dim the flux as they should,
/// but their proxy sits on their own cache, and averaging that position in would pull the light
/// onto the surface and brighten it by 1/d².
#[derive(Default)]
struct Interpolated {
    weight: f32,
    flux: Vec3,
    area: f32,
    lit_weight: f32,
    position: Vec3,
}

/// An interpolated proxy light (eq. 9) and the floor of its squared distance to the surface.
struct Interpolation {
    position: Vec3,
    flux: Vec3,
    /// [`MIN_DIST2_PER_AREA`] times the interpolated cache area, the floor eq. 7 used.
    min_dist2: f32,
}

impl Interpolated {
    fn add(&mut self, w: f32, cache: &RefCache, proxy: &ProxyLight) {
        self.weight += w;
        self.flux += w * proxy.flux;
        self.area += w * cache.area;
        if !proxy.is_unlit() {
            self.lit_weight += w;
            self.position += w * proxy.position;
        }
    }

    /// (x_v, Φ_v) of eq. 9, or `None` when no neighbour is lit.
    fn finish(&self) -> Option<Interpolation> {
        (self.lit_weight > 0.0).then(|| Interpolation {
            position: self.position / self.lit_weight,
            flux: self.flux / self.weight,
            min_dist2: MIN_DIST2_PER_AREA * self.area / self.weight,
        })
    }
}

/// Indirect radiance leaving `surface` towards `camera`, interpolated from the proxy lights of
/// its `neighbours` (eq. 8–9), without occlusion.
pub fn shade(surface: &RefSurface, camera: Vec3, neighbours: &[(RefCache, ProxyLights)]) -> Vec3 {
    let x = surface.position;
    let n_x = surface.normal;
    let k = surface.exponent;
    let view = (camera - x).normalize_or_zero();
    let d_max = neighbours
        .iter()
        .map(|(cache, _)| (x - cache.position).length())
        .fold(0.0_f32, f32::max);

    let mut diffuse = Interpolated::default();
    let mut glossy = Interpolated::default();
    for (cache, proxies) in neighbours {
        let c = cache.position;
        let a = if d_max > 0.0 {
            1.0 - (x - c).length() / d_max
        } else {
            1.0
        };
        // Eq. 8, diffuse: normal similarity.
        let w_d = a * n_x.dot(cache.normal).max(0.0).sqrt();
        // Eq. 8, glossy: similarity of the glossy proxy's direction mirrored at x and at c. An
        // unlit proxy has no direction and falls back to the normals.
        let w_g = if proxies.glossy.is_unlit() {
            w_d
        } else {
            let x_pg = proxies.glossy.position;
            let r_x = reflect_about(n_x, (x_pg - x).normalize_or_zero());
            let r_c = reflect_about(cache.normal, (x_pg - c).normalize_or_zero());
            a * r_x.dot(r_c).max(0.0).sqrt()
        };
        diffuse.add(w_d, cache, &proxies.diffuse);
        glossy.add(w_g, cache, &proxies.glossy);
    }

    let mut radiance = Vec3::ZERO;
    // A proxy on the surface point itself (possible only for caches without area) lights it
    // from no direction: no light rather than 0/0.
    if let Some(v) = diffuse.finish() {
        let to_light = v.position - x;
        let d2 = to_light.length_squared().max(v.min_dist2);
        if d2 > 0.0 {
            let cos = n_x.dot(to_light.normalize_or_zero()).max(0.0);
            radiance += surface.diffuse / PI * v.flux / (4.0 * PI * d2) * cos;
        }
    }
    if let Some(v) = glossy.finish() {
        let to_light = v.position - x;
        let d2 = to_light.length_squared().max(v.min_dist2);
        if d2 > 0.0 {
            let omega = to_light.normalize_or_zero();
            let cos = n_x.dot(omega).max(0.0);
            let lobe = phong_lobe(n_x, omega, view, k);
            radiance +=
                surface.glossy * (k + 2.0) / (2.0 * PI) * lobe * v.flux / (4.0 * PI * d2) * cos;
        }
    }
    radiance
}

#[cfg(test)]
mod tests {
    use super::*;

    const CACHE: RefCache = RefCache {
        position: Vec3::ZERO,
        normal: Vec3::Y,
        exponent: 8.0,
        area: 0.01,
    };

    fn val(position: Vec3, normal: Vec3, flux: Vec3) -> RefVal {
        RefVal {
            position,
            normal: normal.normalize(),
            flux,
            area: 0.1,
            weight: 1.0,
            glossy: GlossySender::default(),
        }
    }

    fn surface_at(cache: &RefCache, diffuse: Vec3, glossy: Vec3) -> RefSurface {
        RefSurface {
            position: cache.position,
            normal: cache.normal,
            diffuse,
            glossy,
            exponent: cache.exponent,
        }
    }

    /// Largest componentwise |a − b|, relative to the largest |b| component (absolute below 1).
    fn rel_err(a: Vec3, b: Vec3) -> f32 {
        (a - b).abs().max_element() / b.abs().max_element().max(1.0e-30)
    }

    fn assert_close(a: Vec3, b: Vec3, tol: f32) {
        assert!(rel_err(a, b) <= tol, "{a} vs {b}");
    }

    /// Eq. 3 + 4 (with the weights of eq. 14–15) evaluated directly from the VALs.
    fn direct_radiance(surface: &RefSurface, camera: Vec3, vals: &[RefVal]) -> Vec3 {
        let x = surface.position;
        let view = (camera - x).normalize();
        let mut out = Vec3::ZERO;
        for v in vals {
            let delta = v.position - x;
            let d2 = delta.length_squared();
            let omega = delta / d2.sqrt();
            let geom = v.normal.dot(-omega).max(0.0) * surface.normal.dot(omega).max(0.0)
                / (v.area + PI * d2);
            let cos_e = reflect_about(surface.normal, omega).dot(view).max(0.0);
            let k = surface.exponent;
            let brdf =
                surface.diffuse / PI + surface.glossy * (k + 2.0) / (2.0 * PI) * cos_e.powf(k);
            out += v.weight * v.flux * brdf * geom;
        }
        out
    }

    #[test]
    fn single_val_above_cache_is_reproduced() {
        let flux = Vec3::new(1.0, 0.5, 0.25);
        let vals = [val(Vec3::new(0.0, 2.0, 0.0), -Vec3::Y, flux)];
        let camera = Vec3::new(1.0, 5.0, 0.5);
        let proxies = light_cache(&CACHE, &vals, camera);

        // By hand: d² = 4, cos_l = cos_x = 1, G = 1/(A + 4π).
        let g = 1.0 / (0.1 + PI * 4.0);
        let e_d = flux * g;
        assert_close(proxies.diffuse.position, vals[0].position, 1e-6);
        assert_eq!(proxies.diffuse.radius, 0.0);
        assert_close(proxies.diffuse.flux, 4.0 * PI * 4.0 * e_d / 1.0, 1e-6);

        // The mirror direction is +Y; the lobe seen from the camera is > MIN_COS_GLOSSY.
        let lobe = camera.normalize().y.powf(CACHE.exponent);
        assert!(lobe > 0.5);
        let e_g = e_d * lobe;
        assert_close(proxies.glossy.position, vals[0].position, 1e-6);
        assert_close(proxies.glossy.flux, 4.0 * PI * 4.0 * e_g / lobe, 1e-5);

        // The proxies recreate the radiance the VAL gives at the cache.
        let rho_d = Vec3::new(0.8, 0.6, 0.4);
        let rho_g = Vec3::new(0.3, 0.2, 0.1);
        let neighbours = [(CACHE, proxies)];
        let only_d = shade(&surface_at(&CACHE, rho_d, Vec3::ZERO), camera, &neighbours);
        assert_close(only_d, rho_d / PI * e_d, 1e-5);
        let only_g = shade(&surface_at(&CACHE, Vec3::ZERO, rho_g), camera, &neighbours);
        let k = CACHE.exponent;
        assert_close(only_g, rho_g * (k + 2.0) / (2.0 * PI) * e_g, 1e-5);
        let both = surface_at(&CACHE, rho_d, rho_g);
        assert_close(shade(&both, camera, &neighbours), only_d + only_g, 1e-5);
        assert_close(
            shade(&both, camera, &neighbours),
            direct_radiance(&both, camera, &vals),
            1e-5,
        );
    }

    #[test]
    fn many_vals_are_reproduced_at_the_cache() {
        let cache = RefCache {
            position: Vec3::new(1.0, -0.5, 2.0),
            normal: Vec3::new(0.2, 1.0, -0.1).normalize(),
            exponent: 4.0,
            area: 0.01,
        };
        let vals = [
            val(
                cache.position + Vec3::new(0.3, 1.5, 0.1),
                Vec3::new(0.1, -1.0, 0.0),
                Vec3::new(1.0, 2.0, 0.5),
            ),
            RefVal {
                weight: 0.5,
                area: 0.02,
                ..val(
                    cache.position + Vec3::new(-0.4, 2.0, 0.3),
                    Vec3::new(0.0, -1.0, -0.3),
                    Vec3::new(0.2, 0.1, 3.0),
                )
            },
            val(
                cache.position + Vec3::new(0.1, 1.0, -0.5),
                Vec3::new(-0.2, -1.0, 0.4),
                Vec3::splat(0.7),
            ),
        ];
        let camera = cache.position + Vec3::new(-0.5, 4.0, 0.8);
        let proxies = light_cache(&cache, &vals, camera);
        let surface = surface_at(&cache, Vec3::new(0.8, 0.6, 0.4), Vec3::new(0.3, 0.2, 0.1));
        assert_close(
            shade(&surface, camera, &[(cache, proxies)]),
            direct_radiance(&surface, camera, &vals),
            1e-5,
        );
    }

    #[test]
    fn symmetric_pair_lies_on_the_normal() {
        let half = 0.5;
        let flux = Vec3::ONE;
        let vals = [
            val(Vec3::new(half, 2.0, 0.0), -Vec3::Y, flux),
            val(Vec3::new(-half, 2.0, 0.0), -Vec3::Y, flux),
        ];
        // Camera on the axis keeps the glossy weights equal too.
        let proxies = light_cache(&CACHE, &vals, Vec3::new(0.0, 5.0, 0.0));
        for proxy in [proxies.diffuse, proxies.glossy] {
            assert!((proxy.position - Vec3::new(0.0, 2.0, 0.0)).length() < 1e-6);
            assert!((proxy.radius - 2.0 * half).abs() < 1e-5, "{}", proxy.radius);
            assert!(proxy.flux.min_element() > 0.0);
        }
    }

    fn brsm_vals() -> Vec<RefVal> {
        vec![
            RefVal {
                weight: 0.25,
                ..val(
                    Vec3::new(0.5, 1.0, 0.0),
                    Vec3::new(-0.3, -1.0, 0.0),
                    Vec3::ONE,
                )
            },
            RefVal {
                weight: 2.0,
                ..val(
                    Vec3::new(-1.0, 2.0, 0.5),
                    Vec3::new(0.5, -1.0, 0.0),
                    Vec3::new(0.5, 1.0, 2.0),
                )
            },
            RefVal {
                weight: 1.5,
                ..val(Vec3::new(0.0, 0.5, -2.0), Vec3::new(0.0, 0.0, 1.0), Vec3::X)
            },
        ]
    }

    fn assert_proxies_close(a: &ProxyLights, b: &ProxyLights, flux_scale: f32) {
        for (p, q) in [(a.diffuse, b.diffuse), (a.glossy, b.glossy)] {
            assert_close(p.position, q.position, 1e-5);
            assert!((p.radius - q.radius).abs() <= 1e-4 * q.radius.max(1.0));
            assert_close(p.flux, q.flux * flux_scale, 1e-5);
        }
    }

    #[test]
    fn brsm_weights_are_consistent() {
        let camera = Vec3::new(0.5, 3.0, 2.0);
        let vals = brsm_vals();
        let base = light_cache(&CACHE, &vals, camera);
        assert!(base.diffuse.flux.max_element() > 0.0);
        assert!(base.glossy.flux.max_element() > 0.0);

        let doubled: Vec<RefVal> = vals
            .iter()
            .chain(&vals)
            .map(|v| RefVal {
                weight: v.weight * 0.5,
                ..*v
            })
            .collect();
        assert_proxies_close(&light_cache(&CACHE, &doubled, camera), &base, 1.0);

        let s = 3.0;
        let scaled: Vec<RefVal> = vals
            .iter()
            .map(|v| RefVal {
                weight: v.weight * s,
                ..*v
            })
            .collect();
        assert_proxies_close(&light_cache(&CACHE, &scaled, camera), &base, s);
    }

    #[test]
    fn degenerate_vals_are_skipped() {
        let camera = Vec3::new(0.0, 5.0, 0.0);
        let empty = light_cache(&CACHE, &[], camera);
        let skipped = light_cache(
            &CACHE,
            &[
                RefVal {
                    weight: 0.0,
                    ..val(Vec3::Y, -Vec3::Y, Vec3::ONE)
                },
                val(CACHE.position, Vec3::Y, Vec3::ONE),
            ],
            camera,
        );
        for proxies in [empty, skipped] {
            for proxy in [proxies.diffuse, proxies.glossy] {
                assert_eq!(proxy.position, CACHE.position);
                assert_eq!(proxy.flux, Vec3::ZERO);
                assert_eq!(proxy.radius, 0.0);
            }
        }
    }

    #[test]
    fn vals_behind_or_facing_away_give_no_flux() {
        let camera = Vec3::new(0.0, 5.0, 0.0);
        // Below the cache, facing it: cos_x = 0.
        let behind = [val(Vec3::new(0.2, -2.0, 0.0), Vec3::Y, Vec3::ONE)];
        // Above the cache, facing away: cos_l = 0.
        let away = [val(Vec3::new(0.0, 2.0, 0.0), Vec3::Y, Vec3::ONE)];
        for vals in [&behind, &away] {
            let proxies = light_cache(&CACHE, vals, camera);
            for proxy in [proxies.diffuse, proxies.glossy] {
                assert_eq!(proxy.flux, Vec3::ZERO);
                // No VAL takes part: the proxy sits at the cache.
                assert_close(proxy.position, CACHE.position, 1e-6);
            }
        }
    }

    #[test]
    fn unlit_neighbours_dim_but_do_not_move_the_interpolated_light() {
        let camera = Vec3::new(0.3, 4.0, 1.0);
        let vals = [val(Vec3::new(0.2, 2.0, -0.1), -Vec3::Y, Vec3::ONE)];
        let lit = light_cache(&CACHE, &vals, camera);
        // Same normal, no VAL in front: both proxies unlit, sitting on their caches.
        let dark = |x: f32| {
            let cache = RefCache {
                position: Vec3::new(x, 0.0, 0.0),
                ..CACHE
            };
            let proxies = light_cache(&cache, &[], camera);
            assert!(proxies.diffuse.is_unlit() && proxies.glossy.is_unlit());
            (cache, proxies)
        };
        let surface = surface_at(&CACHE, Vec3::new(0.8, 0.6, 0.4), Vec3::new(0.3, 0.2, 0.1));
        let alone = shade(&surface, camera, &[(CACHE, lit)]);
        assert!(alone.min_element() > 0.0);
        // Weights a = 1 (lit, at the surface), 0.5 and 0 (the farthest, which sets d_max): the
        // light stays where the lit proxy puts it, its flux averaged over weight 1.5.
        let mixed = shade(&surface, camera, &[(CACHE, lit), dark(0.5), dark(1.0)]);
        assert_close(mixed, alone / 1.5, 1e-5);
        assert_eq!(shade(&surface, camera, &[dark(0.0), dark(0.5)]), Vec3::ZERO);
    }

    #[test]
    fn interpolation_weights_fall_off_with_distance() {
        let camera = Vec3::new(0.3, 4.0, 1.0);
        let vals = [val(Vec3::new(0.2, 2.0, -0.1), -Vec3::Y, Vec3::ONE)];
        let near = RefCache {
            position: Vec3::new(0.5, 0.0, 0.0),
            ..CACHE
        };
        let far = RefCache {
            position: Vec3::new(-1.5, 0.0, 0.5),
            ..CACHE
        };
        let near_proxies = light_cache(&near, &vals, camera);
        let far_proxies = light_cache(&far, &vals, camera);
        let rho_d = Vec3::new(0.8, 0.6, 0.4);
        let rho_g = Vec3::new(0.3, 0.2, 0.1);
        let surface = surface_at(&CACHE, rho_d, rho_g);

        // The only neighbour defines d_max, so a = 0.
        assert_eq!(shade(&surface, camera, &[(far, far_proxies)]), Vec3::ZERO);

        // The farther one gets a = 0: its proxies do not matter.
        let both = shade(
            &surface,
            camera,
            &[(near, near_proxies), (far, far_proxies)],
        );
        assert!(both.min_element() > 0.0);
        let bright_far = ProxyLights {
            diffuse: ProxyLight {
                flux: far_proxies.diffuse.flux * 10.0,
                ..far_proxies.diffuse
            },
            glossy: ProxyLight {
                flux: far_proxies.glossy.flux * 10.0,
                ..far_proxies.glossy
            },
        };
        assert_eq!(
            shade(&surface, camera, &[(near, near_proxies), (far, bright_far)]),
            both
        );

        // Diffuse only, by hand from the nearer cache's proxy light.
        let diffuse_surface = surface_at(&CACHE, rho_d, Vec3::ZERO);
        let to_light = near_proxies.diffuse.position - surface.position;
        let expected = rho_d / PI * near_proxies.diffuse.flux
            / (4.0 * PI * to_light.length_squared())
            * surface.normal.dot(to_light.normalize());
        assert_close(
            shade(
                &diffuse_surface,
                camera,
                &[(near, near_proxies), (far, far_proxies)],
            ),
            expected,
            1e-5,
        );
    }

    #[test]
    fn shading_is_linear_in_val_flux() {
        let camera = Vec3::new(0.5, 3.0, 2.0);
        let caches = [
            CACHE,
            RefCache {
                position: Vec3::new(1.0, 0.0, 0.0),
                normal: Vec3::new(0.1, 1.0, 0.0).normalize(),
                exponent: 8.0,
                area: 0.01,
            },
            RefCache {
                position: Vec3::new(0.0, 0.0, 1.5),
                normal: Vec3::new(0.0, 1.0, 0.2).normalize(),
                exponent: 8.0,
                area: 0.01,
            },
        ];
        let surface = RefSurface {
            position: Vec3::new(0.3, 0.0, 0.4),
            normal: Vec3::Y,
            diffuse: Vec3::new(0.8, 0.6, 0.4),
            glossy: Vec3::new(0.3, 0.2, 0.1),
            exponent: 8.0,
        };
        let shade_with = |vals: &[RefVal]| {
            let neighbours: Vec<(RefCache, ProxyLights)> = caches
                .iter()
                .map(|c| (*c, light_cache(c, vals, camera)))
                .collect();
            shade(&surface, camera, &neighbours)
        };
        let vals = brsm_vals();
        let base = shade_with(&vals);
        assert!(base.max_element() > 0.0);
        let s = 3.0;
        let brighter: Vec<RefVal> = vals
            .iter()
            .map(|v| RefVal {
                flux: v.flux * s,
                ..*v
            })
            .collect();
        assert_close(shade_with(&brighter), base * s, 1e-5);
    }

    /// Every length times `s` (VAL areas s², VAL flux s² since E·A is reflected, cache areas
    /// s²): the proxies move with the scene, their flux grows by s² (eq. 7's 4π·d²·E) and the
    /// radiance leaving a surface is unchanged. Fails with a floor or ε_p in scene units.
    #[test]
    fn proxies_and_shading_are_invariant_under_a_change_of_length_unit() {
        let camera = Vec3::new(0.5, 3.0, 2.0);
        let caches = [
            CACHE,
            RefCache {
                position: Vec3::new(0.4, 0.0, 0.1),
                area: 0.02,
                ..CACHE
            },
            RefCache {
                position: Vec3::new(0.0, 0.0, 0.5),
                normal: Vec3::new(0.0, 1.0, 0.2).normalize(),
                ..CACHE
            },
        ];
        let surface = RefSurface {
            position: Vec3::new(0.1, 0.0, 0.2),
            normal: Vec3::Y,
            diffuse: Vec3::new(0.8, 0.6, 0.4),
            glossy: Vec3::new(0.3, 0.2, 0.1),
            exponent: 8.0,
        };
        let run = |s: f32| {
            let vals: Vec<RefVal> = brsm_vals()
                .iter()
                .map(|v| RefVal {
                    position: v.position * s,
                    area: v.area * s * s,
                    flux: v.flux * s * s,
                    ..*v
                })
                .collect();
            let neighbours: Vec<(RefCache, ProxyLights)> = caches
                .iter()
                .map(|c| {
                    let c = RefCache {
                        position: c.position * s,
                        area: c.area * s * s,
                        ..*c
                    };
                    (c, light_cache(&c, &vals, camera * s))
                })
                .collect();
            let at = RefSurface {
                position: surface.position * s,
                ..surface
            };
            let radiance = shade(&at, camera * s, &neighbours);
            (neighbours[0].1, radiance)
        };
        let (base_proxies, base) = run(1.0);
        assert!(base.min_element() > 0.0);
        for s in [1e-3, 1e3] {
            let (proxies, radiance) = run(s);
            for (p, q) in [
                (proxies.diffuse, base_proxies.diffuse),
                (proxies.glossy, base_proxies.glossy),
            ] {
                assert_close(p.position / s, q.position, 1e-4);
                assert_close(p.flux / (s * s), q.flux, 1e-4);
            }
            assert_close(radiance, base, 1e-4);
        }
    }
}

/// A cache as an occluder or occlusion target: position, unit normal and disk area.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OccluderDisk {
    pub position: Vec3,
    pub normal: Vec3,
    pub disk_area: f32,
}

/// Smallest side of a proxy's square on the unit base disk (a point proxy still has a
/// footprint that occluders can cover).
pub const MIN_PROXY_SIDE: f32 = 1e-3;

/// Occluders nearer to the target than this fraction of their own disk area (squared
/// distance), i.e. within 1/10⁴ of their radius, sit on the target itself: they have no
/// direction to project along. Relative to the disk so that it holds at any scene scale.
pub const MIN_OCCLUDER_DIST2_PER_AREA: f32 = 1e-8;

/// An axis-aligned square on the target cache's unit base disk: centre and side.
type Square = (glam::Vec2, f32);

fn tangent_frame(n: Vec3) -> (Vec3, Vec3) {
    let up = if n.y.abs() > 0.99 { Vec3::X } else { Vec3::Y };
    let t = n.cross(up).normalize();
    (t, n.cross(t))
}

fn overlap(a: Square, b: Square) -> f32 {
    let lo = (a.0 - glam::Vec2::splat(0.5 * a.1)).max(b.0 - glam::Vec2::splat(0.5 * b.1));
    let hi = (a.0 + glam::Vec2::splat(0.5 * a.1)).min(b.0 + glam::Vec2::splat(0.5 * b.1));
    let size = (hi - lo).max(glam::Vec2::ZERO);
    size.x * size.y
}

/// Visible fraction of a proxy sphere (`center`, `radius`) seen from `target`, by the paper's
/// double projection ("Occlusion"): the sphere and every occluder disk in front of the target,
/// nearer than the proxy and outside its sphere are projected onto the unit hemisphere and then onto the base
/// disk, where each covers π times its form factor — (r/d)²·cos θ for the sphere,
/// A·cos θ_c·cos θ_o / (π d² + A) for a disk — as a square of that area; the squares' overlap
/// with the proxy's square is the occluded fraction (clamped to 1).
pub fn proxy_visibility(
    target: &OccluderDisk,
    center: Vec3,
    radius: f32,
    occluders: &[OccluderDisk],
) -> f32 {
    let (t, b) = tangent_frame(target.normal);
    let square = |w: Vec3, form_factor: f32| -> Square {
        (
            glam::Vec2::new(w.dot(t), w.dot(b)),
            (PI * form_factor.max(0.0)).sqrt(),
        )
    };
    let to = center - target.position;
    let d2 = to.length_squared();
    let w = to.normalize_or_zero();
    let cos_c = target.normal.dot(w).max(0.0);
    // (r/d)², or the whole hemisphere from inside the sphere.
    let subtended = if d2 > radius * radius {
        radius * radius / d2
    } else {
        1.0
    };
    let mut proxy = square(w, subtended * cos_c);
    proxy.1 = proxy.1.max(MIN_PROXY_SIDE);
    let covered: f32 = occluders
        .iter()
        .filter_map(|o| {
            let to_o = o.position - target.position;
            let od2 = to_o.length_squared();
            // Caches inside the proxy's sphere carry its VALs: they are the light itself.
            let inside = (o.position - center).length_squared() < radius * radius;
            if od2 <= MIN_OCCLUDER_DIST2_PER_AREA * o.disk_area || od2 >= d2 || inside {
                return None;
            }
            let wo = to_o / od2.sqrt();
            let cos_t = target.normal.dot(wo).max(0.0);
            let cos_o = o.normal.dot(wo).abs();
            let form_factor = o.disk_area * cos_t * cos_o / (PI * od2 + o.disk_area);
            Some(overlap(proxy, square(wo, form_factor)))
        })
        .sum();
    1.0 - (covered / (proxy.1 * proxy.1)).min(1.0)
}

#[cfg(test)]
mod occlusion_tests {
    use super::*;

    fn disk(position: Vec3, normal: Vec3, disk_area: f32) -> OccluderDisk {
        OccluderDisk {
            position,
            normal,
            disk_area,
        }
    }

    #[test]
    fn a_wall_of_caches_between_cache_and_proxy_hides_it() {
        let target = disk(Vec3::ZERO, Vec3::Y, 0.01);
        // A 5×5 grid of 0.2 m caches at height 1 fully covers a proxy at height 2.
        let wall: Vec<OccluderDisk> = (-2..=2)
            .flat_map(|i| {
                (-2..=2).map(move |j| {
                    disk(
                        Vec3::new(i as f32 * 0.2, 1.0, j as f32 * 0.2),
                        Vec3::NEG_Y,
                        0.04,
                    )
                })
            })
            .collect();
        assert!(proxy_visibility(&target, Vec3::new(0.0, 2.0, 0.0), 0.05, &wall) < 0.01);
        // Without the wall, or with the wall behind the proxy, it is fully visible.
        assert_eq!(
            proxy_visibility(&target, Vec3::new(0.0, 2.0, 0.0), 0.05, &[]),
            1.0
        );
        assert_eq!(
            proxy_visibility(&target, Vec3::new(0.0, 0.5, 0.0), 0.05, &wall),
            1.0
        );
    }

    #[test]
    fn coplanar_caches_do_not_occlude_and_partial_cover_is_partial() {
        let target = disk(Vec3::ZERO, Vec3::Y, 0.01);
        let floor: Vec<OccluderDisk> = (1..5)
            .map(|i| disk(Vec3::new(i as f32 * 0.3, 0.0, 0.0), Vec3::Y, 0.09))
            .collect();
        assert_eq!(
            proxy_visibility(&target, Vec3::new(0.3, 1.0, 0.0), 0.3, &floor),
            1.0
        );
        // One small disk in front of a large proxy covers part of it.
        let one = [disk(Vec3::new(0.0, 0.5, 0.0), Vec3::NEG_Y, 0.01)];
        let v = proxy_visibility(&target, Vec3::new(0.0, 2.0, 0.0), 1.0, &one);
        assert!(v > 0.5 && v < 1.0, "visibility {v}");
    }

    /// Form factors are ratios of areas, so visibility cannot depend on the unit of length;
    /// a floor of squared distances in scene units (it was 10⁻⁸) would change a micro-scale
    /// model's. Two occluders at different distances cover a small proxy in part.
    #[test]
    fn visibility_is_invariant_under_a_change_of_length_unit() {
        let visibility = |s: f32| {
            let target = disk(Vec3::ZERO, Vec3::Y, 0.01 * s * s);
            let occluders = [
                disk(Vec3::new(0.02, 0.01, 0.0) * s, Vec3::NEG_Y, 1e-5 * s * s),
                disk(Vec3::new(-0.01, 0.05, 0.01) * s, Vec3::NEG_Y, 4e-4 * s * s),
            ];
            proxy_visibility(&target, Vec3::new(0.0, 0.1, 0.0) * s, 0.01 * s, &occluders)
        };
        let base = visibility(1.0);
        assert!(base > 0.1 && base < 0.9, "visibility {base}");
        for s in [1e-4, 1e4] {
            let v = visibility(s);
            assert!((v - base).abs() < 1e-4, "×{s}: {v} vs {base}");
        }
    }
}
