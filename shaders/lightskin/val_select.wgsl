// Selection of N_sVAL VALs by inverting the cumulative importance with binary searches (BRSM),
// with each VAL's estimator weight 1 / (N_sVAL · P_VAL) for eq. 13–15.
//
// P_VAL mixes the importance distribution with a uniform one over all texels ("defensive"
// importance sampling): P = (1 − α)·I/ΣI + α/M. Importance comes from what the view samples
// see, yet every VAL lights every cache; a VAL that matters to some cache but got almost no
// importance would otherwise be drawn rarely with a huge weight 1/(N·P). α = 0 is the paper's
// plain BRSM.

// Mirrored by `SelectParams` in server/passes/src/passes/val_select.rs.
struct SelectParams {
    width: u32,
    height: u32,
    count: u32,
    // Threads per row of the dispatch grid (dispatches are 2D past 65535 workgroups).
    row_pitch: u32,
    // Offset of the stratified sample positions within their strata, in [0, 1).
    jitter: f32,
    // α of the defensive mixture, in [0, 1].
    defensive: f32,
    pad0: f32,
    pad1: f32,
}

@group(0) @binding(0) var<storage, read> params: SelectParams;
@group(0) @binding(1) var<storage, read> importance_map: array<f32>;
@group(0) @binding(2) var<storage, read> column_sums: array<f32>;
@group(0) @binding(3) var<storage, read> row_sums: array<f32>;
@group(0) @binding(4) var rsm_position: texture_2d<f32>;
@group(0) @binding(5) var rsm_normal: texture_2d<f32>;
@group(0) @binding(6) var rsm_flux_area: texture_2d<f32>;
@group(0) @binding(7) var<storage, read_write> vals: array<Val>;
@group(0) @binding(8) var rsm_glossy: texture_2d<u32>;

// Mixture CDF up to and including column `x` (texels in column-major order).
fn column_cdf(x: u32, alpha: f32, total: f32) -> f32 {
    var importance = 0.0;
    if total > 0.0 {
        importance = row_sums[x] / total;
    }
    return (1.0 - alpha) * importance + alpha * f32(x + 1u) / f32(params.width);
}

// Mixture probability of rows 0..=y within column `x`.
fn row_cdf(x: u32, y: u32, alpha: f32, total: f32) -> f32 {
    var importance = 0.0;
    if total > 0.0 {
        importance = column_sums[y * params.width + x] / total;
    }
    let texels = f32(params.width) * f32(params.height);
    return (1.0 - alpha) * importance + alpha * f32(y + 1u) / texels;
}

// First column whose cumulative probability exceeds `u`.
fn find_column(u: f32, alpha: f32, total: f32) -> u32 {
    var lo = 0u;
    var hi = params.width - 1u;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if column_cdf(mid, alpha, total) > u {
            hi = mid;
        } else {
            lo = mid + 1u;
        }
    }
    return lo;
}

// First row of column `x` whose cumulative probability exceeds `r`.
fn find_row(x: u32, r: f32, alpha: f32, total: f32) -> u32 {
    var lo = 0u;
    var hi = params.height - 1u;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if row_cdf(x, mid, alpha, total) > r {
            hi = mid;
        } else {
            lo = mid + 1u;
        }
    }
    return lo;
}

@compute @workgroup_size(64)
fn select_vals(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.y * params.row_pitch + id.x;
    if i >= params.count {
        return;
    }
    let total = row_sums[params.width - 1u];
    // Without any importance the uniform part alone remains.
    var alpha = clamp(params.defensive, 0.0, 1.0);
    if !(total > 0.0) {
        alpha = 1.0;
    }
    // Stratified positions along the cumulative distribution: each of the N strata of equal
    // probability gets exactly one sample.
    let u = (f32(i) + params.jitter) / f32(params.count);
    let x = find_column(u, alpha, total);
    var before = 0.0;
    if x > 0u {
        before = column_cdf(x - 1u, alpha, total);
    }
    let y = find_row(x, u - before, alpha, total);
    let texel = y * params.width + x;
    var importance = 0.0;
    if total > 0.0 {
        importance = importance_map[texel] / total;
    }
    let p = (1.0 - alpha) * importance + alpha / (f32(params.width) * f32(params.height));
    var weight = 0.0;
    if p > 0.0 {
        weight = 1.0 / (f32(params.count) * p);
    }
    let fa = textureLoad(rsm_flux_area, vec2<u32>(x, y), 0);
    vals[i] = Val(
        textureLoad(rsm_position, vec2<u32>(x, y), 0).xyz,
        fa.a,
        textureLoad(rsm_normal, vec2<u32>(x, y), 0).xyz,
        weight,
        fa.rgb,
        texel,
        decode_glossy(textureLoad(rsm_glossy, vec2<u32>(x, y), 0)),
    );
}
