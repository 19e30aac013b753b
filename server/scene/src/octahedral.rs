//! Octahedral mapping of unit directions to the square [-1, 1]² (Cigolle et al. 2014, "A
//! Survey of Efficient Representations for Independent Unit Vectors"): continuous over the
//! sphere, nearly uniform texel solid angles. Mirrored by `octahedral_encode`/`_decode` in
//! `shaders/octahedral.wgsl`.

use glam::{Vec2, Vec3};

/// The point of [-1, 1]² of unit direction `d`.
pub fn encode(d: Vec3) -> Vec2 {
    let p = Vec2::new(d.x, d.y) / (d.x.abs() + d.y.abs() + d.z.abs());
    if d.z >= 0.0 {
        return p;
    }
    let sign = Vec2::new(
        if p.x >= 0.0 { 1.0 } else { -1.0 },
        if p.y >= 0.0 { 1.0 } else { -1.0 },
    );
    (Vec2::ONE - Vec2::new(p.y.abs(), p.x.abs())) * sign
}

/// `count` Fibonacci-sphere points: nearly equal-area unit directions, the same every call
/// (for quadratures and tests over all directions).
pub fn fibonacci_sphere(count: usize) -> impl Iterator<Item = Vec3> {
    let golden = std::f64::consts::PI * (3.0 - 5.0f64.sqrt());
    (0..count).map(move |i| {
        let z = 1.0 - (2.0 * i as f64 + 1.0) / count as f64;
        let r = (1.0 - z * z).sqrt();
        let phi = golden * i as f64;
        Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32).normalize()
    })
}

/// The unit direction of point `e` of [-1, 1]².
pub fn decode(e: Vec2) -> Vec3 {
    let mut d = Vec3::new(e.x, e.y, 1.0 - e.x.abs() - e.y.abs());
    let t = (-d.z).max(0.0);
    d.x += if d.x >= 0.0 { -t } else { t };
    d.y += if d.y >= 0.0 { -t } else { t };
    d.normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_round_trip() {
        for d in fibonacci_sphere(1000) {
            let e = encode(d);
            assert!(e.abs().max_element() <= 1.0 + 1e-6, "{d} → {e}");
            assert!((decode(e) - d).length() < 1e-5, "{d} → {e} → {}", decode(e));
        }
    }
}
