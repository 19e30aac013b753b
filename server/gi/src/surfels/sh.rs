//! Real spherical harmonics up to degree 4 for the surfel links and cache lighting (eq. 3–8 and
//! appendix B, eq. 11–12).
//!
//! **Convention.** Real, orthonormal over the unit sphere (∫ y_i y_j dω = δ_ij), z up, index
//! i = l² + l + m, m < 0 ↔ sin(|m|φ), m > 0 ↔ cos(mφ): Sloan's layout ("Stupid Spherical Harmonics
//! Tricks", 2008) **without** the Condon–Shortley phase: every constant in [`eval`] is positive
//! (y_1,−1 = +√(3/4π)·y, y_1,1 = +√(3/4π)·x). Sloan's published evaluation code keeps (−1)^m, so
//! its odd-m functions have the opposite sign; copy constants from this file, not from that code.
//! The WGSL port mirrors [`eval`] line by line.
//!
//! Orthonormality is what makes eq. 5 (and the interpolate-then-dot of eq. 6) a plain [`dot`] of
//! coefficient vectors. The sign choice is otherwise free (dot products and zonal rotations do not
//! change if a basis function flips sign), but links, caches and shaders must all share it.

use glam::Vec3;
use std::f32::consts::PI;

/// Bands supported (l = 0..=4), so at most `MAX_BANDS²` = 25 coefficients.
pub const MAX_BANDS: u32 = 5;

/// Largest Phong exponent [`phong_zonal`] uses. There 1 − s_l(n) ≈ l(l+1)/(2n) ≤ 1e-5 for l ≤ 4:
/// the lobe is already a delta at these bands, and n = ∞ no longer gives ∞/∞ in the recurrence.
const MAX_PHONG_EXPONENT: f64 = 1.0e6;

/// Number of coefficients of `bands` bands (degrees 0..bands−1): bands².
pub fn coefficient_count(bands: u32) -> usize {
    let b = bands as usize;
    b.saturating_mul(b)
}

/// Zonal coefficients Â_l = 2π∫₀¹ t·P_l(t) dt of the clamped cosine max(cos θ, 0), for
/// [`project_lobe`]. Equal to π·[`phong_zonal`]`(1.0, ..)`: the diffuse D_SH of eq. 5 without ρ/π.
pub const COSINE_ZONAL: [f32; MAX_BANDS as usize] = [PI, 2.0 * PI / 3.0, PI / 4.0, 0.0, -PI / 24.0];

/// Evaluates y_i(d) for i < bands² into `out`. `d` must be unit length (the polynomials use
/// x² + y² + z² = 1 to drop terms, as in 3z² − 1). Writes `min(bands², out.len())` values with
/// `bands` clamped to [`MAX_BANDS`]; never panics.
pub fn eval(bands: u32, d: Vec3, out: &mut [f32]) {
    let count = coefficient_count(bands.min(MAX_BANDS)).min(out.len());
    let (x, y, z) = (d.x, d.y, d.z);
    let mut sh = [0.0f32; 25];
    // l = 0: 1/(2√π).
    sh[0] = 0.2820948;
    if count > 1 {
        // l = 1: √(3/4π)·(y, z, x).
        sh[1] = 0.48860252 * y;
        sh[2] = 0.48860252 * z;
        sh[3] = 0.48860252 * x;
    }
    if count > 4 {
        // l = 2: √(15/4π)·(xy, yz, ·, xz), √(5/16π)(3z² − 1), √(15/16π)(x² − y²).
        sh[4] = 1.0925485 * x * y;
        sh[5] = 1.0925485 * y * z;
        sh[6] = 0.31539157 * (3.0 * z * z - 1.0);
        sh[7] = 1.0925485 * x * z;
        sh[8] = 0.54627424 * (x * x - y * y);
    }
    if count > 9 {
        // l = 3: √(35/32π), √(105/4π), √(21/32π), √(7/16π), √(21/32π), √(105/16π), √(35/32π).
        sh[9] = 0.5900436 * y * (3.0 * x * x - y * y);
        sh[10] = 2.8906114 * x * y * z;
        sh[11] = 0.4570458 * y * (5.0 * z * z - 1.0);
        sh[12] = 0.37317634 * z * (5.0 * z * z - 3.0);
        sh[13] = 0.4570458 * x * (5.0 * z * z - 1.0);
        sh[14] = 1.4453057 * z * (x * x - y * y);
        sh[15] = 0.5900436 * x * (x * x - 3.0 * y * y);
    }
    if count > 16 {
        // l = 4: ¾√(35/π), ¾√(35/2π), ¾√(5/π), ¾√(5/2π), (3/16)√(1/π), ¾√(5/2π), (3/8)√(5/π),
        // ¾√(35/2π), (3/16)√(35/π).
        let z2 = z * z;
        sh[16] = 2.5033429 * x * y * (x * x - y * y);
        sh[17] = 1.7701308 * y * z * (3.0 * x * x - y * y);
        sh[18] = 0.9461747 * x * y * (7.0 * z2 - 1.0);
        sh[19] = 0.6690465 * y * z * (7.0 * z2 - 3.0);
        sh[20] = 0.10578555 * (35.0 * z2 * z2 - 30.0 * z2 + 3.0);
        sh[21] = 0.6690465 * x * z * (7.0 * z2 - 3.0);
        sh[22] = 0.47308734 * (x * x - y * y) * (7.0 * z2 - 1.0);
        sh[23] = 1.7701308 * x * z * (x * x - 3.0 * y * y);
        sh[24] = 0.6258357 * (x * x * (x * x - 3.0 * y * y) - y * y * (3.0 * x * x - y * y));
    }
    out[..count].copy_from_slice(&sh[..count]);
}

/// Zonal factors s_l(n) = (n+1)∫₀¹ tⁿ P_l(t) dt of the normalised Phong lobe (n+1)/(2π)·cosⁿθ
/// (eq. 7 scaled by √(4π/(2l+1)), i.e. eq. 11), for l < min(bands, [`MAX_BANDS`]); the rest are 0.
///
/// Appendix B's recurrence s_0 = 1, s_1 = (n+1)/(n+2), s_l = s_{l−2}·(n+2−l)/(n+1+l) is used as
/// extracted: it is the known ratio ∫₀¹tⁿP_l / ∫₀¹tⁿP_{l−2}, and the tests confirm it against
/// quadrature for integer and non-integer n (no extraction error). n = 1 gives Â_l/π.
/// `n` is clamped to [0, 1e6] (NaN → 0): below 0 the lobe is no longer a Phong lobe and n = −2
/// would divide by zero.
pub fn phong_zonal(n: f32, bands: u32) -> [f32; MAX_BANDS as usize] {
    let n = if n.is_nan() {
        0.0
    } else {
        f64::from(n).clamp(0.0, MAX_PHONG_EXPONENT)
    };
    let mut s = [1.0f64; MAX_BANDS as usize];
    s[1] = (n + 1.0) / (n + 2.0);
    for l in 2..s.len() {
        let lf = l as f64;
        s[l] = s[l - 2] * (n + 2.0 - lf) / (n + 1.0 + lf);
    }
    let mut out = [0.0f32; MAX_BANDS as usize];
    for (o, s) in out.iter_mut().zip(s).take(bands as usize) {
        *o = s as f32;
    }
    out
}

/// SH coefficients of a lobe that is rotationally symmetric about the unit axis `d` (eq. 8 / 12):
/// `out[l² + l + m] = zonal[l]·y_lm(d)`.
///
/// Normalisation: for a lobe g(ω·d), pass `zonal[l]` = 2π∫₋₁¹ g(t) P_l(t) dt (= √(4π/(2l+1))·c_l0,
/// c_l0 the projection of the z-aligned lobe onto y_l0, eq. 7/11). Then, by the Funk–Hecke theorem,
/// out_lm = ∫_{S²} g(ω·d) y_lm(ω) dω, the orthonormal projection of the rotated lobe. With
/// [`phong_zonal`]`(n)` that is the lobe (n+1)/(2π)·max(ω·d, 0)ⁿ (S_SH of eq. 5, unit integral);
/// with [`COSINE_ZONAL`] it is max(ω·d, 0); ρ·phong_zonal(1) gives D_SH = (ρ/π)·max(ω·n, 0).
/// Bands beyond `zonal.len()` are taken as 0; output length rules as for [`eval`].
pub fn project_lobe(zonal: &[f32], bands: u32, d: Vec3, out: &mut [f32]) {
    eval(bands, d, out);
    let count = coefficient_count(bands.min(MAX_BANDS)).min(out.len());
    for (i, c) in out.iter_mut().take(count).enumerate() {
        *c *= zonal.get(i.isqrt()).copied().unwrap_or(0.0);
    }
}

/// ⟨a, b⟩ = Σ a_i b_i over the common length: the integral of the product of the two represented
/// functions (eq. 5), because the basis is orthonormal. Both must use this module's convention.
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    const N: usize = 25;

    /// ∫ f(ω) y_i(ω) dω for all 25 i, on the Fibonacci sphere.
    fn project_numerically(f: impl Fn(Vec3) -> f64) -> [f64; N] {
        // 2¹⁶ points, each standing for 4π/2¹⁶ sr: equal-area, so plain sums are quadratures.
        let count = 1 << 16;
        let weight = 4.0 * std::f64::consts::PI / count as f64;
        let mut c = [0.0f64; N];
        let mut y = [0.0f32; N];
        for w in crate::scene::octahedral::fibonacci_sphere(count) {
            eval(MAX_BANDS, w, &mut y);
            let fw = f(w) * weight;
            for (c, y) in c.iter_mut().zip(y) {
                *c += fw * f64::from(y);
            }
        }
        c
    }

    /// Deterministic unit directions (xorshift64*, uniform on the sphere).
    fn random_dirs(count: usize, mut state: u64) -> Vec<Vec3> {
        let mut next = move || {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..count)
            .map(|_| {
                let z = 2.0 * next() - 1.0;
                let phi = 2.0 * std::f64::consts::PI * next();
                let r = (1.0 - z * z).sqrt();
                Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)
            })
            .collect()
    }

    #[test]
    fn orthonormal_on_fibonacci_sphere() {
        // 2¹⁶ points, each standing for 4π/2¹⁶ sr: equal-area, so plain sums are quadratures.
        let count = 1 << 16;
        let weight = 4.0 * std::f64::consts::PI / count as f64;
        let mut gram = [[0.0f64; N]; N];
        let mut y = [0.0f32; N];
        for w in crate::scene::octahedral::fibonacci_sphere(count) {
            eval(MAX_BANDS, w, &mut y);
            for (row, yi) in gram.iter_mut().zip(y) {
                for (g, yj) in row.iter_mut().zip(y) {
                    *g += f64::from(yi) * f64::from(yj) * weight;
                }
            }
        }
        let mut worst = 0.0f64;
        for (i, row) in gram.iter().enumerate() {
            for (j, g) in row.iter().enumerate() {
                worst = worst.max((g - if i == j { 1.0 } else { 0.0 }).abs());
            }
        }
        println!("orthonormality: max |G − I| = {worst:.2e}");
        assert!(worst < 1e-3, "max |G − I| = {worst}");
    }

    #[test]
    fn eval_matches_hand_values() {
        // +z: y_l0 = √((2l+1)/4π) = K_l^0, and every m ≠ 0 function vanishes exactly.
        let mut y = [0.0f32; N];
        eval(MAX_BANDS, Vec3::Z, &mut y);
        let axis = [0.2820948, 0.4886025, 0.6307831, 0.7463527, 0.8462844];
        for (i, v) in y.iter().enumerate() {
            let l = i.isqrt();
            let want = if i == l * l + l { axis[l] } else { 0.0 };
            assert!((v - want).abs() < 1e-6, "+z: y[{i}] = {v}, want {want}");
        }
        // d = (2, 3, 6)/7, every index: √2·K_l^|m|·P_l^|m|(cos θ)·{cos mφ, sin |m|φ} with P_l^m
        // lacking the (−1)^m factor, evaluated in f64 outside this file (e.g. y_1,−1 = √(3/4π)·3/7,
        // y_40 = (3/16)√(1/π)·(−357/2401)). Pins the sign and the m ↔ index order of every entry.
        let generic: [f32; N] = [
            0.2820948, 0.2094011, 0.4188022, 0.1396007, 0.1337814, 0.4013443, 0.3797572, 0.2675629,
            -0.0557423, 0.0154822, 0.3033878, 0.5236706, 0.2154196, 0.3491137, -0.1264116,
            -0.0791312, -0.0312788, 0.0398114, 0.4799837, 0.5266547, -0.0157290, 0.3511031,
            -0.1999932, -0.2034803, -0.0310181,
        ];
        eval(MAX_BANDS, Vec3::new(2.0, 3.0, 6.0) / 7.0, &mut y);
        for (i, (v, want)) in y.iter().zip(generic).enumerate() {
            assert!(
                (v - want).abs() < 1e-6,
                "(2,3,6)/7: y[{i}] = {v}, want {want}"
            );
        }
    }

    #[test]
    fn cosine_lobe_projection() {
        // c_l0 = ∫ max(ω·z, 0) y_l0(ω) dω = Â_l·√((2l+1)/4π): the same quantity three ways.
        let expected = [0.8862269, 1.0233267, 0.4954159, 0.0, -0.1107784];
        // (1) Quadrature through eval: midpoint in t = cos θ (4000) × uniform φ (64), which is
        // exact in φ for these degrees and O(h²) ≈ 1e-7 in t.
        let (nt, nphi) = (4000, 64);
        let mut c = [0.0f64; N];
        let mut y = [0.0f32; N];
        for it in 0..nt {
            let t = (it as f64 + 0.5) / nt as f64;
            for ip in 0..nphi {
                let phi = 2.0 * std::f64::consts::PI * ip as f64 / nphi as f64;
                let r = (1.0 - t * t).sqrt();
                let w = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, t as f32);
                eval(MAX_BANDS, w, &mut y);
                let weight = t / nt as f64 * 2.0 * std::f64::consts::PI / nphi as f64;
                for (c, y) in c.iter_mut().zip(y) {
                    *c += weight * f64::from(y);
                }
            }
        }
        // (2) project_lobe with COSINE_ZONAL along +z, (3) π·phong_zonal(1).
        let mut p = [0.0f32; N];
        project_lobe(&COSINE_ZONAL, MAX_BANDS, Vec3::Z, &mut p);
        let phong = phong_zonal(1.0, MAX_BANDS);
        for (l, want) in expected.into_iter().enumerate() {
            let i = l * l + l;
            println!("c_{l}0: quadrature {:.7}, project_lobe {:.7}", c[i], p[i]);
            assert!(
                (c[i] - f64::from(want)).abs() < 2e-6,
                "quadrature c_{l}0 = {}",
                c[i]
            );
            assert!((p[i] - want).abs() < 1e-6, "project_lobe c_{l}0 = {}", p[i]);
            assert!((phong[l] * PI - COSINE_ZONAL[l]).abs() < 1e-6);
            for m in 1..=l {
                assert!(c[i + m].abs() < 1e-6 && c[i - m].abs() < 1e-6 && p[i + m] == 0.0);
            }
        }
    }

    #[test]
    fn recurrence_matches_quadrature() {
        // (n+1)∫₀¹ tⁿ P_l(t) dt by the midpoint rule with 2·10⁵ points; P_l from Bonnet's
        // recursion, independent of eval.
        let legendre = |l: usize, t: f64| {
            let (mut p0, mut p1) = (1.0, t);
            for k in 1..=l {
                let kf = k as f64;
                (p0, p1) = (p1, ((2.0 * kf + 1.0) * t * p1 - kf * p0) / (kf + 1.0));
            }
            p0
        };
        let (points, mut worst) = (200_000, 0.0f64);
        for n in [1.0f32, 2.0, 2.5, 20.0] {
            let h = 1.0 / points as f64;
            for (l, s) in phong_zonal(n, MAX_BANDS).into_iter().enumerate() {
                let sum: f64 = (0..points)
                    .map(|k| (k as f64 + 0.5) * h)
                    .map(|t| t.powf(f64::from(n)) * legendre(l, t))
                    .sum();
                let err = (f64::from(s) - sum * h * (f64::from(n) + 1.0)).abs();
                worst = worst.max(err);
                assert!(err < 1e-6, "n = {n}, l = {l}: s = {s}, error {err}");
            }
        }
        println!("recurrence: max error {worst:.2e}");
        // Spot values from the spec table (closed forms 3/4, 7/9, 5/11, 7/39, 1/33, 21/22, ...).
        let table = [
            (2.0, [1.0, 0.75, 0.4, 0.125, 0.0]),
            (2.5, [1.0, 0.777778, 0.454545, 0.179487, 0.030303]),
            (20.0, [1.0, 0.9545455, 0.8695652, 0.7556818, 0.626087]),
        ];
        for (n, want) in table {
            let s = phong_zonal(n, MAX_BANDS);
            for (l, (s, want)) in s.iter().zip(want).enumerate() {
                assert!((s - want).abs() < 1e-6, "n = {n}, l = {l}: {s}");
            }
        }
    }

    #[test]
    fn rotated_lobe_matches_numerical_projection() {
        let mut analytic = [0.0f32; N];
        let mut worst = 0.0f64;
        for n in [1.0f32, 8.0, 20.0] {
            for d in random_dirs(3, 0x9e37_79b9_7f4a_7c15 ^ n.to_bits() as u64) {
                let norm = (f64::from(n) + 1.0) / (2.0 * std::f64::consts::PI);
                let numeric =
                    project_numerically(|w| norm * f64::from(w.dot(d)).max(0.0).powf(f64::from(n)));
                project_lobe(&phong_zonal(n, MAX_BANDS), MAX_BANDS, d, &mut analytic);
                for (a, q) in analytic.iter().zip(numeric) {
                    let err = (f64::from(*a) - q).abs();
                    worst = worst.max(err);
                    assert!(err < 2e-3, "n = {n}, d = {d}: {a} vs {q}");
                }
            }
        }
        println!("rotated lobe: max abs error {worst:.2e}");
    }

    #[test]
    fn white_furnace() {
        // L ≡ 1 has L_00 = 2√π and nothing else; ⟨L, D_SH⟩ = ρ and ⟨L, S_SH⟩ = 1 for any axis.
        let radiance = project_numerically(|_| 1.0).map(|c| c as f32);
        let rho = 0.7;
        let mut lobe = [0.0f32; N];
        let mut worst = 0.0f32;
        for axis in random_dirs(8, 7) {
            project_lobe(&phong_zonal(1.0, MAX_BANDS), MAX_BANDS, axis, &mut lobe);
            worst = worst.max((dot(&radiance, &lobe) - 1.0).abs());
            let diffuse = phong_zonal(1.0, MAX_BANDS).map(|s| rho * s);
            project_lobe(&diffuse, MAX_BANDS, axis, &mut lobe);
            worst = worst.max((dot(&radiance, &lobe) - rho).abs());
            project_lobe(&phong_zonal(20.0, MAX_BANDS), MAX_BANDS, axis, &mut lobe);
            worst = worst.max((dot(&radiance, &lobe) - 1.0).abs());
        }
        println!("white furnace: max error {worst:.2e}");
        assert!(worst < 1e-5, "furnace error {worst}");
    }

    #[test]
    fn out_of_range_arguments_are_clamped() {
        let d = Vec3::new(0.48, -0.6, 0.64);
        let mut full = [0.0f32; N];
        eval(MAX_BANDS, d, &mut full);
        // Too many bands: clamped to MAX_BANDS.
        let mut more = [0.0f32; N];
        eval(9, d, &mut more);
        assert_eq!(full, more);
        // Output shorter than bands²: only the prefix is written.
        let mut short = [-1.0f32; 6];
        eval(3, d, &mut short);
        assert_eq!(short, full[..6]);
        // Fewer bands than the output: the tail is untouched; missing zonal bands count as 0.
        let mut partial = [-1.0f32; N];
        project_lobe(&[1.0, 0.5], 3, d, &mut partial);
        assert_eq!(
            partial[..4],
            [full[0], full[1] * 0.5, full[2] * 0.5, full[3] * 0.5]
        );
        assert!(partial[4..9].iter().all(|c| *c == 0.0) && partial[9..].iter().all(|c| *c == -1.0));
        // NaN and negative exponents fall back to n = 0 (uniform hemisphere, s_1 = 1/2); +∞ to
        // the largest exponent, where every s_l ≈ 1.
        assert_eq!(phong_zonal(f32::NAN, 5), phong_zonal(0.0, 5));
        assert_eq!(phong_zonal(-3.0, 5)[1], 0.5);
        assert!(phong_zonal(f32::INFINITY, 5)
            .iter()
            .all(|s| (s - 1.0).abs() < 1e-4));
        assert_eq!(phong_zonal(2.0, 2)[2..], [0.0; 3]);
        assert_eq!(coefficient_count(4), 16);
    }
}
