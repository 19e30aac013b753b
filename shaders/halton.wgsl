// The Halton sequence, shared by the passes that place samples at low-discrepancy positions.

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
