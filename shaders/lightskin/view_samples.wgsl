// View samples for importance estimation (eq. 10): G-buffer positions and normals at N_VS
// Halton-distributed pixel positions.

// Mirrored by `ViewSample` in server/src/passes/importance.rs.
struct ViewSample {
    position: vec3<f32>,
    // 1 where the sample hit geometry, 0 on background.
    valid: f32,
    normal: vec3<f32>,
    pad0: f32,
}

// Radical inverse of `i` in `base`: the i-th element of the Halton sequence.
fn halton(i: u32, base: u32) -> f32 {
    var f = 1.0;
    var r = 0.0;
    var n = i;
    let inv = 1.0 / f32(base);
    loop {
        if n == 0u {
            break;
        }
        f *= inv;
        r += f * f32(n % base);
        n /= base;
    }
    return r;
}
