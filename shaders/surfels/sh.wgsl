// Real spherical harmonics of up to 4 bands (16 coefficients) in the convention of
// server/gi/src/surfels/sh.rs (orthonormal, z up, no Condon–Shortley phase): `sh_eval`
// mirrors `sh::eval` line by line, `zonal_cosine` is `sh::COSINE_ZONAL` and `zonal_phong` is
// `sh::phong_zonal` (appendix B's recurrence, eq. 11).

const SH_COEFFICIENTS: u32 = 16u;

fn sh_eval(d: vec3<f32>) -> array<f32, 16> {
    let x = d.x;
    let y = d.y;
    let z = d.z;
    var sh: array<f32, 16>;
    sh[0] = 0.2820948;
    sh[1] = 0.48860252 * y;
    sh[2] = 0.48860252 * z;
    sh[3] = 0.48860252 * x;
    sh[4] = 1.0925485 * x * y;
    sh[5] = 1.0925485 * y * z;
    sh[6] = 0.31539157 * (3.0 * z * z - 1.0);
    sh[7] = 1.0925485 * x * z;
    sh[8] = 0.54627424 * (x * x - y * y);
    sh[9] = 0.5900436 * y * (3.0 * x * x - y * y);
    sh[10] = 2.8906114 * x * y * z;
    sh[11] = 0.4570458 * y * (5.0 * z * z - 1.0);
    sh[12] = 0.37317634 * z * (5.0 * z * z - 3.0);
    sh[13] = 0.4570458 * x * (5.0 * z * z - 1.0);
    sh[14] = 1.4453057 * z * (x * x - y * y);
    sh[15] = 0.5900436 * x * (x * x - 3.0 * y * y);
    return sh;
}

// Band l of coefficient i (l² ≤ i < (l+1)²).
fn sh_band(i: u32) -> u32 {
    return u32(floor(sqrt(f32(i) + 0.5)));
}

// Zonal factors 2π∫ t·P_l(t) dt of the clamped cosine (irradiance, eq. 5's D_SH without ρ/π).
fn zonal_cosine(l: u32) -> f32 {
    switch l {
        case 0u: { return PI; }
        case 1u: { return 2.0 * PI / 3.0; }
        case 2u: { return PI / 4.0; }
        default: { return 0.0; }
    }
}

// s_l(n) of the normalised Phong lobe (n+1)/(2π)·cosⁿ (eq. 11): s_0 = 1,
// s_1 = (n+1)/(n+2), s_l = s_{l−2}·(n+2−l)/(n+1+l).
fn zonal_phong(exponent: f32) -> vec4<f32> {
    let n = clamp(exponent, 0.0, 1.0e6);
    let s1 = (n + 1.0) / (n + 2.0);
    let s2 = n / (n + 3.0);
    let s3 = s1 * (n - 1.0) / (n + 4.0);
    return vec4<f32>(1.0, s1, s2, s3);
}
