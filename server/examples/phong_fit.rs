//! How far the paper's lobes (a Lambertian plus a normalised Phong lobe about the mirror
//! direction, seed 004 eq. 3–4), fitted to the BRDF by `Brdf::lobes`, are from the BRDF they
//! stand for. For a view at cosine μ and light from every direction of the hemisphere (a
//! cosine-weighted quadrature), it prints the light each reflects towards the viewer relative
//! to the BRDF's (energy) and the relative L1 difference of the two over light directions
//! (shape). `lightskin`/`brsm` (the proxies' glossy term and the pixels' diffuse one) and
//! `surfels` (the SH lobes) shade with these lobes and carry this error on top of their own;
//! `clustered` and `rsm_gather` evaluate the BRDF itself at the receiver.
//!
//! `cargo run --release -p lightcast-server --example phong_fit > bench/results/phong-fit.md`

use glam::{DVec3, Vec3};
use lightcast_server::scene::brdf::{cosine_cells, Brdf};
use std::f32::consts::PI;

/// Cells per axis of the quadrature (uniform in sin²θ and φ, each of solid angle × cos π/N²).
const RINGS: usize = 1200;

fn main() {
    println!("# The paper's Phong lobes against the BRDF they are fitted to");
    println!();
    println!("`cargo run --release -p lightcast-server --example phong_fit`: base colour 0.8,");
    println!("light from every direction (cosine-weighted), a {RINGS}² quadrature. energy: light");
    println!(
        "the lobes reflect towards the viewer / the BRDF's; shape: ∫|f_lobes − f| cos / ∫ f cos."
    );
    println!();
    println!("| metallic | roughness | view cos μ | energy | shape |");
    println!("|---|---|---|---|---|");
    for metallic in [0.0, 1.0] {
        for roughness in [0.2, 0.35, 0.5, 0.75, 1.0] {
            for mu in [1.0f32, 0.7, 0.4, 0.15] {
                let brdf = Brdf::new(Vec3::splat(0.8), metallic, roughness, 1.0);
                let (energy, shape) = compare(&brdf, mu);
                println!(
                    "| {metallic} | {roughness} | {mu} | {:.3} | {:.1} % |",
                    energy,
                    shape * 100.0
                );
            }
        }
    }
}

/// (∫ f_lobes cos / ∫ f cos, ∫ |f_lobes − f| cos / ∫ f cos) at view cosine `mu`.
fn compare(brdf: &Brdf, mu: f32) -> (f64, f64) {
    let n = Vec3::Z;
    let v = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
    let lobes = brdf.lobes(mu);
    let k = lobes.exponent;
    let (mut exact, mut fitted, mut diff) = (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
    for l in cosine_cells(RINGS) {
        let f = brdf.eval(n, l, v);
        let mirrored = 2.0 * n.dot(l) * n - l;
        let cos_e = mirrored.dot(v).max(0.0);
        let g = lobes.diffuse / PI + lobes.glossy * (k + 2.0) / (2.0 * PI) * cos_e.powf(k);
        exact += f.as_dvec3();
        fitted += g.as_dvec3();
        diff += (g - f).abs().as_dvec3();
    }
    let lum = |c: DVec3| c.dot(DVec3::new(0.2126, 0.7152, 0.0722));
    (lum(fitted) / lum(exact), lum(diff) / lum(exact))
}
