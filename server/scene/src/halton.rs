//! The Halton sequence (radical inverses), mirrored by `shaders/halton.wgsl`: the low-discrepancy
//! positions of the methods' samples (points on triangles, texels of the RSM, emitter
//! samples).

/// Radical inverse of `i` in `base`: the i-th element of the Halton sequence.
pub fn halton(mut i: u32, base: u32) -> f32 {
    let inv = 1.0 / base as f32;
    let (mut f, mut r) = (1.0, 0.0);
    while i > 0 {
        f *= inv;
        r += f * (i % base) as f32;
        i /= base;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halton_is_the_radical_inverse() {
        assert_eq!(halton(1, 2), 0.5);
        assert_eq!(halton(3, 2), 0.75);
        assert_eq!(halton(1, 3), 1.0 / 3.0);
        assert!((halton(5, 3) - (2.0 / 3.0 + 1.0 / 9.0)).abs() < 1e-6);
    }
}
