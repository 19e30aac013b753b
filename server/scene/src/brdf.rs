//! The BRDF every pass shades with, and its CPU reference (mirrored by `shaders/brdf.wgsl`
//! and `shaders/brdf_eval.wgsl`): glTF 2.0's metallic-roughness model (the specification's
//! Appendix B) with a diffuse lobe that conserves energy.
//!
//! For base colour c, metallic m, roughness r (α = r²) and dielectric specular weight s
//! (`KHR_materials_specular`'s `specularFactor`, 1 without it):
//!
//! - specular: f_s = F(v·h) D(h) G(l, v) / (4 (n·l)(n·v)) with GGX's D, the separable Smith G
//!   of Appendix B and Schlick's Fresnel F = F0 + (F90 − F0)(1 − v·h)⁵, F0 = mix(0.04·s, c, m),
//!   F90 = mix(s, 1, m) (glTF's `mix(dielectric_brdf, metal_brdf, metallic)`, Schlick being
//!   linear in F0);
//! - diffuse: f_d = (1 − m) c/π · (1 − s·E(n·l)) (1 − s·E(n·v)) / (1 − s·Ē), where E(μ) is the
//!   directional albedo of a dielectric's specular lobe (F0 = 0.04, F90 = 1) and Ē its
//!   cosine-weighted mean 2∫E(μ)μ dμ.
//!
//! Appendix B weights the diffuse lobe by 1 − F(v·h) instead, which is not energy-conserving:
//! by quadrature a white smooth dielectric seen at grazing angles reflects up to 1.86 times
//! what it receives (`gltf_appendix_b_gains_energy` below). Weighting by the specular lobe's own
//! albedo (Kelemen & Szirmay-Kalos 2001's coupling; Kulla & Conty 2017's albedo scaling) gives
//! the diffuse lobe exactly what the specular one leaves: a white dielectric reflects all it
//! receives from every direction, the BRDF stays reciprocal, and s = 0 is exactly Lambertian.
//! Single-scattering GGX still loses energy at high roughness (a white metal at r = 1 keeps
//! 31 % at normal incidence), as in glTF's model and Mitsuba's `roughconductor`.

use crate::material::DiffuseGlossy;
use glam::Vec3;
use std::f32::consts::PI;
use std::sync::OnceLock;

/// Reflectance at normal incidence of a dielectric (glTF's fixed 4 %, an index of 1.5).
pub const DIELECTRIC_F0: f32 = 0.04;
/// Roughness below this is raised to it: GGX's peak 1/(πα²) stays finite in f32 and lobes
/// stay wider than a texel of the maps that sample them (Filament's limit).
pub const MIN_ROUGHNESS: f32 = 0.045;
/// Samples per axis of [`BrdfTable`]: cosines (i/(N−1))² and roughnesses j/(N−1).
pub const TABLE_SIZE: usize = 32;
/// Visible-normal samples per table entry (a Hammersley set).
const TABLE_SAMPLES: u32 = 4096;
/// Floor of the Phong lobe's albedo [`Brdf::lobes`] divides by (a sharp lobe about a mirror
/// direction on the horizon keeps about 1/√k of its light).
const MIN_LOBE_ALBEDO: f32 = 1e-4;
/// The Phong exponents the paper's lobes use (seed 004, eq. 3–4): k = 1 is a broad lobe, 4096
/// close to a mirror for the methods' maps.
const MIN_EXPONENT: f32 = 1.0;
const MAX_EXPONENT: f32 = 4096.0;

/// One surface point's BRDF parameters (mirrored by `SurfaceBrdf` in `shaders/brdf.wgsl`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Brdf {
    /// Linear base colour (textured).
    pub base: Vec3,
    pub metallic: f32,
    /// Perceptual roughness in [`MIN_ROUGHNESS`, 1]; GGX's α is its square.
    pub roughness: f32,
    /// Dielectric specular weight in [0, 1].
    pub specular: f32,
}

impl Brdf {
    /// Clamps glTF's factors into the model's ranges (as `surface_brdf` in WGSL does).
    pub fn new(base: Vec3, metallic: f32, roughness: f32, specular: f32) -> Self {
        Self {
            base: base.max(Vec3::ZERO),
            metallic: metallic.clamp(0.0, 1.0),
            roughness: roughness.clamp(MIN_ROUGHNESS, 1.0),
            specular: specular.clamp(0.0, 1.0),
        }
    }

    /// A Lambertian surface of albedo `albedo` (no specular lobe).
    pub fn lambertian(albedo: Vec3) -> Self {
        Self::new(albedo, 0.0, 1.0, 0.0)
    }

    /// Schlick's F0 and F90 per channel.
    fn fresnel_ends(&self) -> (Vec3, Vec3) {
        let f0 = Vec3::splat(DIELECTRIC_F0 * self.specular).lerp(self.base, self.metallic);
        let f90 = Vec3::splat(self.specular).lerp(Vec3::ONE, self.metallic);
        (f0, f90)
    }

    /// f_r for light arriving from `to_light` and leaving towards `to_viewer` (unit vectors,
    /// `n` the unit shading normal).
    pub fn eval(&self, n: Vec3, to_light: Vec3, to_viewer: Vec3) -> Vec3 {
        let nl = n.dot(to_light);
        if nl <= 0.0 {
            return Vec3::ZERO;
        }
        // A shading normal may face slightly away from the viewer; V stays finite at n·v = 0.
        let nv = n.dot(to_viewer).max(0.0);
        let a2 = alpha2(self.roughness);
        let diffuse = self.eval_diffuse(n, to_light, to_viewer);
        let h = (to_light + to_viewer).normalize_or_zero();
        if h == Vec3::ZERO {
            return diffuse;
        }
        let (f0, f90) = self.fresnel_ends();
        let w = schlick_weight(to_viewer.dot(h));
        diffuse + (f0 + (f90 - f0) * w) * (ggx_d(n.dot(h), a2) * smith_v(nl, nv, a2))
    }

    /// The diffuse lobe of [`Self::eval`] alone: Lambert × (1 − m) weighted by what the
    /// specular lobe leaves in both directions.
    pub fn eval_diffuse(&self, n: Vec3, to_light: Vec3, to_viewer: Vec3) -> Vec3 {
        let nl = n.dot(to_light);
        if nl <= 0.0 {
            return Vec3::ZERO;
        }
        let nv = n.dot(to_viewer).max(0.0);
        let table = BrdfTable::get();
        self.base
            * ((1.0 - self.metallic) / PI
                * (1.0 - self.specular * table.dielectric(nl, self.roughness))
                * (1.0 - self.specular * table.dielectric(nv, self.roughness))
                / (1.0 - self.specular * table.dielectric_mean(self.roughness)))
    }

    /// The paper's lobes (a Lambertian plus a normalised Phong lobe about the mirror
    /// direction, seed 004 eq. 3–4) fitted to this BRDF as seen from cosine `mu` off the
    /// normal, so that each reflects what its counterpart does towards the viewer: the diffuse
    /// albedo is the diffuse lobe's, (1 − m)·c·(1 − s·E(μ)) (exact for light from a
    /// cosine-weighted spread of directions); the glossy colour is the specular lobe's
    /// directional albedo F0·A + F90·B over the Phong lobe's own, P (about μ for a sharp lobe,
    /// more where the horizon cuts a broad one); the exponent follows the roughness. What the
    /// lobes' shapes still miss is measured by `examples/phong_fit.rs`. For the methods whose
    /// equations are written for Phong lobes.
    pub fn lobes(&self, mu: f32) -> DiffuseGlossy {
        let table = BrdfTable::get();
        let [a, b, _, phong] = table.terms(mu, self.roughness);
        let phong = phong.max(MIN_LOBE_ALBEDO);
        self.lobes_from(a / phong, b / phong, table.dielectric(mu, self.roughness))
    }

    /// [`Self::lobes`] for what a surface reflects towards no particular viewer (a light
    /// cache's or a surfel's reflectance): the diffuse albedo averaged over cosine-weighted
    /// directions, and the glossy colour whose lobe reflects over those directions what the
    /// specular lobe does (Ē over P̄, both cosine-weighted means).
    pub fn mean_lobes(&self) -> DiffuseGlossy {
        let table = BrdfTable::get();
        let [a, b, phong] = table.means(self.roughness);
        let phong = phong.max(MIN_LOBE_ALBEDO);
        self.lobes_from(a / phong, b / phong, table.dielectric_mean(self.roughness))
    }

    fn lobes_from(&self, a: f32, b: f32, dielectric: f32) -> DiffuseGlossy {
        let (f0, f90) = self.fresnel_ends();
        DiffuseGlossy {
            diffuse: self.base * ((1.0 - self.metallic) * (1.0 - self.specular * dielectric)),
            glossy: f0 * a + f90 * b,
            exponent: phong_exponent(self.roughness),
        }
    }

    /// The specular lobe's directional albedo for light arriving at cosine `mu`, F0·A + F90·B.
    pub fn specular_albedo(&self, mu: f32) -> Vec3 {
        let [a, b, _, _] = BrdfTable::get().terms(mu, self.roughness);
        let (f0, f90) = self.fresnel_ends();
        f0 * a + f90 * b
    }

    /// The share of what the surface reflects of light arriving at cosine `mu` that the
    /// specular lobe carries, by Rec. 709 luminance (0 for a black surface); by reciprocity
    /// also the share of what reaches a viewer at that cosine (`specular_share` in
    /// `shaders/brdf_eval.wgsl`, which sorts a comparison's receivers).
    pub fn specular_share(&self, mu: f32) -> f32 {
        let specular = crate::environment::luminance(self.specular_albedo(mu).into());
        let total = specular + crate::environment::luminance(self.diffuse_albedo(mu).into());
        if total > 0.0 {
            specular / total
        } else {
            0.0
        }
    }

    /// The diffuse lobe's albedo for light arriving at cosine `mu`: the fraction of the
    /// irradiance it reflects diffusely, whatever the direction it leaves in (what a reflective
    /// shadow map's texel sends on as a diffuse VAL).
    pub fn diffuse_albedo(&self, mu: f32) -> Vec3 {
        self.base
            * ((1.0 - self.metallic)
                * (1.0 - self.specular * BrdfTable::get().dielectric(mu, self.roughness)))
    }
}

/// The centres of `rings`² cells over the upper hemisphere (z up) that each carry the same
/// projected solid angle π/rings² (cos θ dω = ½ d(sin²θ) dφ: cells uniform in sin²θ and φ):
/// ∫ g(l) cos θ dω ≈ π/rings² · Σ g(l). A quadrature independent of the table's sampling, for
/// tests and `examples/phong_fit.rs`.
pub fn cosine_cells(rings: usize) -> impl Iterator<Item = Vec3> {
    (0..rings).flat_map(move |i| {
        let s2 = (i as f32 + 0.5) / rings as f32;
        let (sin_t, cos_t) = (s2.sqrt(), (1.0 - s2).sqrt());
        (0..rings).map(move |j| {
            let phi = 2.0 * PI * (j as f32 + 0.5) / rings as f32;
            Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
        })
    })
}

/// GGX's α² for perceptual roughness `roughness`.
fn alpha2(roughness: f32) -> f32 {
    let alpha = roughness * roughness;
    alpha * alpha
}

/// Schlick's (1 − cos)⁵.
fn schlick_weight(cos: f32) -> f32 {
    (1.0 - cos.clamp(0.0, 1.0)).powi(5)
}

/// GGX normal distribution D(h) for n·h.
fn ggx_d(nh: f32, a2: f32) -> f32 {
    if nh <= 0.0 {
        return 0.0;
    }
    let d = nh * nh * (a2 - 1.0) + 1.0;
    a2 / (PI * d * d)
}

/// Smith's separable G(l, v) / (4 (n·l)(n·v)) (glTF Appendix B), written so it stays finite
/// at n·v = 0 (G₁(v)/(n·v) = 2/(n·v + √(α² + (1 − α²)(n·v)²))).
fn smith_v(nl: f32, nv: f32, a2: f32) -> f32 {
    let lambda = |c: f32| c + (a2 + (1.0 - a2) * c * c).sqrt();
    1.0 / (lambda(nl) * lambda(nv))
}

/// The Phong exponent of the paper's lobe for a roughness: the Beckmann/Blinn-Phong
/// correspondence k_blinn = 2/α² − 2 (Walter et al. 2007), divided by 4 because the paper's
/// lobe is about the mirror direction, whose exponent is about a quarter of the half-vector's.
pub fn phong_exponent(roughness: f32) -> f32 {
    let a2 = alpha2(roughness.clamp(MIN_ROUGHNESS, 1.0));
    ((2.0 / a2 - 2.0) * 0.25).clamp(MIN_EXPONENT, MAX_EXPONENT)
}

/// The roughness whose [`phong_exponent`] is `k` (before its clamp): what the
/// `glossy_exponent` override sets every material's roughness to.
pub fn roughness_for_exponent(k: f32) -> f32 {
    (2.0 / (4.0 * k.max(0.0) + 2.0))
        .sqrt()
        .sqrt()
        .clamp(MIN_ROUGHNESS, 1.0)
}

/// What shading needs of the specular lobe, tabulated over the cosine μ of the view (at √μ =
/// i/(N−1): a smooth lobe's albedo changes fastest at grazing angles, where a uniform grid in
/// μ was off by up to 6 %) and the roughness: its directional albedo in Schlick's two parts,
/// A = ∫ (1 − (1 − v·h)⁵) D G/(4 n·l n·v) n·l dω_l and B the same with (1 − v·h)⁵, so a lobe
/// with Fresnel ends F0, F90 reflects F0·A + F90·B; a dielectric's cosine-weighted mean
/// Ē = 2∫(0.04·A + B) μ dμ of the row; and the albedo P of the paper's Phong lobe of the
/// roughness' exponent about the view's mirror direction (for [`Brdf::lobes`]). The means are
/// taken over the interpolant itself, so that the diffuse lobe's normalisation 1 − s·Ē matches
/// what the lookups return and a white dielectric's albedo is 1 to the table's precision.
/// `entries` go to the GPU as they are (`SceneBuffers::brdf_table`).
#[derive(Clone, Debug)]
pub struct BrdfTable {
    /// `[A, B, Ē, P]` at cosine (i/(N−1))² and roughness j/(N−1), index j·N + i.
    pub entries: Vec<[f32; 4]>,
    /// The cosine-weighted means `[Ā, B̄, P̄]` of each roughness' row (for [`Brdf::mean_lobes`]).
    means: Vec<[f32; 3]>,
}

impl BrdfTable {
    /// The table, computed on first use (about 8 M samples).
    pub fn get() -> &'static Self {
        static TABLE: OnceLock<BrdfTable> = OnceLock::new();
        TABLE.get_or_init(Self::compute)
    }

    fn compute() -> Self {
        let last = (TABLE_SIZE - 1) as f32;
        let mut entries = vec![[0.0; 4]; TABLE_SIZE * TABLE_SIZE];
        let mut means = Vec::with_capacity(TABLE_SIZE);
        for j in 0..TABLE_SIZE {
            let roughness = (j as f32 / last).max(MIN_ROUGHNESS);
            let exponent = phong_exponent(roughness);
            let row = &mut entries[j * TABLE_SIZE..(j + 1) * TABLE_SIZE];
            for (i, entry) in row.iter_mut().enumerate() {
                let x = i as f32 / last;
                let [a, b] = specular_albedo(x * x, roughness);
                *entry = [a, b, 0.0, phong_albedo(x * x, exponent)];
            }
            let mean = |k: usize| cosine_mean(&row.iter().map(|e| e[k]).collect::<Vec<_>>());
            let row_means = [mean(0), mean(1), mean(3)];
            for entry in row.iter_mut() {
                entry[2] = DIELECTRIC_F0 * row_means[0] + row_means[1];
            }
            means.push(row_means);
        }
        Self { entries, means }
    }

    /// Bilinear lookup at cosine `mu` and roughness `roughness`, in (√μ, roughness) (as
    /// `brdf_terms` in WGSL): `[A, B, Ē, P]`.
    pub fn terms(&self, mu: f32, roughness: f32) -> [f32; 4] {
        let last = (TABLE_SIZE - 1) as f32;
        let x = mu.clamp(0.0, 1.0).sqrt() * last;
        let (y0, fy) = row(roughness);
        let x0 = (x as usize).min(TABLE_SIZE - 2);
        let fx = x - x0 as f32;
        let at = |i: usize, j: usize| self.entries[j * TABLE_SIZE + i];
        let mut out = [0.0; 4];
        for (k, o) in out.iter_mut().enumerate() {
            let lo = lerp(at(x0, y0)[k], at(x0 + 1, y0)[k], fx);
            let hi = lerp(at(x0, y0 + 1)[k], at(x0 + 1, y0 + 1)[k], fx);
            *o = lerp(lo, hi, fy);
        }
        out
    }

    /// The rows' means `[Ā, B̄, P̄]` at `roughness`, linear between rows.
    fn means(&self, roughness: f32) -> [f32; 3] {
        let (y0, fy) = row(roughness);
        let (lo, hi) = (self.means[y0], self.means[y0 + 1]);
        [0, 1, 2].map(|k| lerp(lo[k], hi[k], fy))
    }

    /// A dielectric's specular albedo E(μ) = 0.04·A + B.
    pub fn dielectric(&self, mu: f32, roughness: f32) -> f32 {
        let [a, b, _, _] = self.terms(mu, roughness);
        DIELECTRIC_F0 * a + b
    }

    /// Its cosine-weighted mean Ē = 2∫E(μ)μ dμ.
    pub fn dielectric_mean(&self, roughness: f32) -> f32 {
        self.terms(1.0, roughness)[2]
    }
}

/// The table row below `roughness` and the weight of the next.
fn row(roughness: f32) -> (usize, f32) {
    let y = roughness.clamp(0.0, 1.0) * (TABLE_SIZE - 1) as f32;
    let y0 = (y as usize).min(TABLE_SIZE - 2);
    (y0, y - y0 as f32)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// The Hammersley point `k` of [`TABLE_SAMPLES`].
fn hammersley(k: u32) -> (f32, f32) {
    (
        (k as f32 + 0.5) / TABLE_SAMPLES as f32,
        k.reverse_bits() as f32 * (1.0 / 4_294_967_296.0),
    )
}

/// The albedo of the paper's Phong lobe (k+2)/2π·cosᵏα about the mirror direction r of a view
/// at cosine `mu`: ∫ (k+2)/2π·max(l·r, 0)ᵏ·max(n·l, 0) dω_l, μ for a lobe above the horizon.
/// Sampling cosᵏα about r, the estimator is (k+2)/(k+1)·max(n·l, 0).
fn phong_albedo(mu: f32, k: f32) -> f32 {
    let r = Vec3::new(-(1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let (t, b) = r.any_orthonormal_pair();
    let mut sum = 0.0f64;
    for s in 0..TABLE_SAMPLES {
        let (u1, u2) = hammersley(s);
        let cos_a = u1.powf(1.0 / (k + 1.0));
        let sin_a = (1.0 - cos_a * cos_a).max(0.0).sqrt();
        let phi = 2.0 * PI * u2;
        let l = r * cos_a + (t * phi.cos() + b * phi.sin()) * sin_a;
        sum += f64::from(l.z.max(0.0));
    }
    (k + 2.0) / (k + 1.0) * (sum / f64::from(TABLE_SAMPLES)) as f32
}

/// `[A, B]` at view cosine `mu` by sampling GGX's visible normals (Heitz 2018, "Sampling the
/// GGX Distribution of Visible Normals"): with density G₁(v)·D(h)·(v·h)/(n·v) per half
/// vector, the estimator of ∫ F D G/(4 n·l n·v) n·l dω_l is F·G₁(l), nearly constant, so 4,096
/// points give about 10⁻⁵ where sampling D·(n·h) gave 10⁻³ at grazing views.
fn specular_albedo(mu: f32, roughness: f32) -> [f32; 2] {
    let alpha = roughness * roughness;
    let a2 = alpha * alpha;
    let nv = mu.clamp(0.0, 1.0);
    let v = Vec3::new((1.0 - nv * nv).max(0.0).sqrt(), 0.0, nv);
    // The view in the hemisphere configuration of α = 1, and a basis around it.
    let vh = Vec3::new(alpha * v.x, alpha * v.y, v.z).normalize();
    let t1 = if vh.x * vh.x + vh.y * vh.y > 0.0 {
        Vec3::new(-vh.y, vh.x, 0.0).normalize()
    } else {
        Vec3::X
    };
    let t2 = vh.cross(t1);
    let (mut a, mut b) = (0.0f64, 0.0f64);
    for k in 0..TABLE_SAMPLES {
        let (u1, u2) = hammersley(k);
        let r = u1.sqrt();
        let phi = 2.0 * PI * u2;
        let p1 = r * phi.cos();
        let s = 0.5 * (1.0 + vh.z);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
        let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
        let h = Vec3::new(alpha * nh.x, alpha * nh.y, nh.z.max(0.0)).normalize();
        let vdh = v.dot(h);
        let l = 2.0 * vdh * h - v;
        if l.z <= 0.0 || vdh <= 0.0 {
            continue;
        }
        let g1 = 2.0 * l.z / (l.z + (a2 + (1.0 - a2) * l.z * l.z).sqrt());
        let fc = schlick_weight(vdh);
        a += f64::from((1.0 - fc) * g1);
        b += f64::from(fc * g1);
    }
    let n = f64::from(TABLE_SAMPLES);
    [(a / n) as f32, (b / n) as f32]
}

/// 2∫₀¹ f(μ)·μ dμ of the interpolant through `values` at √μ = i/(N−1), linear in √μ: with
/// x = √μ it is 4∫ f(x)·x³ dx, a quartic on each segment, which 3-point Gauss–Legendre
/// integrates exactly.
fn cosine_mean(values: &[f32]) -> f32 {
    let h = 1.0 / (values.len() - 1) as f64;
    let nodes = [
        (-(0.6f64).sqrt(), 5.0 / 9.0),
        (0.0, 8.0 / 9.0),
        ((0.6f64).sqrt(), 5.0 / 9.0),
    ];
    let sum: f64 = values
        .windows(2)
        .enumerate()
        .map(|(i, w)| {
            let (x0, mid) = (i as f64 * h, (i as f64 + 0.5) * h);
            nodes
                .iter()
                .map(|&(t, weight)| {
                    let x = mid + 0.5 * h * t;
                    let f = f64::from(w[0]) + (f64::from(w[1]) - f64::from(w[0])) * (x - x0) / h;
                    weight * 0.5 * h * f * x * x * x
                })
                .sum::<f64>()
        })
        .sum();
    (4.0 * sum) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The directional albedo ∫ f(l, v) n·l dω_l at view cosine `mu`, by a midpoint rule over
    /// the hemisphere in (cos θ², φ) (uniform in projected solid angle), independent of the
    /// table's importance sampling. `rings × rings` cells.
    fn albedo(brdf: &Brdf, mu: f32, rings: usize) -> Vec3 {
        let n = Vec3::Z;
        let v = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
        // f64 sums: a million f32 additions would drift by a few 0.1 %.
        let sum: glam::DVec3 = cosine_cells(rings)
            .map(|l| brdf.eval(n, l, v).as_dvec3())
            .sum();
        (sum * (std::f64::consts::PI / (rings * rings) as f64)).as_vec3()
    }

    #[test]
    fn the_table_matches_an_independent_quadrature() {
        // Midpoint quadrature of a rough lobe (no narrow peak to miss) against the table.
        for &(roughness, mu) in &[(1.0, 1.0), (0.6, 0.5), (0.8, 0.2)] {
            let metal = Brdf::new(Vec3::ONE * 0.5, 1.0, roughness, 1.0);
            let [a, b, _, _] = BrdfTable::get().terms(mu, roughness);
            let expected = 0.5 * a + b;
            let got = albedo(&metal, mu, 600).x;
            assert!(
                (got - expected).abs() < 2e-3,
                "r {roughness} μ {mu}: quadrature {got} vs table {expected}"
            );
        }
    }

    #[test]
    fn a_white_dielectric_reflects_all_it_receives() {
        for &roughness in &[0.5, 1.0] {
            for &mu in &[1.0, 0.5, 0.2] {
                let white = Brdf::new(Vec3::ONE, 0.0, roughness, 1.0);
                let a = albedo(&white, mu, 600).x;
                assert!((a - 1.0).abs() < 3e-3, "r {roughness} μ {mu}: {a}");
            }
        }
    }

    #[test]
    fn no_material_reflects_more_than_it_receives() {
        // Sharp lobes need fine cells: 800² cells resolve r = 0.3 (α = 0.09).
        for &metallic in &[0.0, 0.5, 1.0] {
            for &roughness in &[0.3, 0.6, 1.0] {
                for &mu in &[1.0, 0.5, 0.15, 0.03] {
                    let brdf = Brdf::new(Vec3::ONE, metallic, roughness, 1.0);
                    let a = albedo(&brdf, mu, 800).max_element();
                    assert!(a <= 1.0 + 5e-3, "m {metallic} r {roughness} μ {mu}: {a}");
                }
            }
        }
    }

    #[test]
    fn gltf_appendix_b_gains_energy() {
        // The weighting this model replaces, 1 − F(v·h) on the diffuse lobe: a white smooth
        // dielectric seen at grazing angles reflects far more than it receives.
        let a2 = alpha2(0.2);
        let v = Vec3::new((1.0f32 - 0.01).sqrt(), 0.0, 0.1);
        let rings = 800;
        let sum: f64 = cosine_cells(rings)
            .map(|l| {
                let h = (l + v).normalize();
                let f = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * schlick_weight(v.dot(h));
                f64::from((1.0 - f) / PI + f * ggx_d(h.z, a2) * smith_v(l.z, v.z, a2))
            })
            .sum();
        let albedo = sum * std::f64::consts::PI / (rings * rings) as f64;
        assert!(albedo > 1.3, "{albedo}");
    }

    #[test]
    fn without_specular_it_is_lambertian() {
        let s = Brdf::lambertian(Vec3::new(0.5, 0.25, 0.1));
        let n = Vec3::Z;
        let l = Vec3::new(0.6, 0.0, 0.8);
        let v = Vec3::new(-0.3, 0.4, (1.0f32 - 0.25).sqrt());
        assert!((s.eval(n, l, v) - Vec3::new(0.5, 0.25, 0.1) / PI).length() < 1e-6);
    }

    #[test]
    fn it_is_reciprocal() {
        let brdf = Brdf::new(Vec3::new(0.8, 0.5, 0.2), 0.3, 0.4, 0.7);
        let n = Vec3::Z;
        let l = Vec3::new(0.5, 0.1, 0.86).normalize();
        let v = Vec3::new(-0.7, 0.2, 0.3).normalize();
        let (a, b) = (brdf.eval(n, l, v), brdf.eval(n, v, l));
        assert!((a - b).length() < 1e-5 * a.length(), "{a} vs {b}");
    }

    #[test]
    fn a_metal_is_glossy_only_and_smoother_means_sharper() {
        let rough = Brdf::new(Vec3::new(1.0, 0.8, 0.3), 1.0, 0.6, 1.0).mean_lobes();
        let smooth = Brdf::new(Vec3::new(1.0, 0.8, 0.3), 1.0, 0.2, 1.0).mean_lobes();
        assert_eq!(rough.diffuse, Vec3::ZERO);
        assert!(smooth.exponent > rough.exponent * 10.0);
        assert!(phong_exponent(0.0) <= MAX_EXPONENT);
        assert!((roughness_for_exponent(phong_exponent(0.5)) - 0.5).abs() < 1e-4);
    }
}
