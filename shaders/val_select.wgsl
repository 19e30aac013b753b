// Selection of N_sVAL VALs by inverting the cumulative importance with binary searches (BRSM),
// with each VAL's estimator weight 1 / (N_sVAL · P_VAL) for eq. 13–15.

// Mirrored by `SelectParams` in server/src/passes/val_select.rs.
struct SelectParams {
    width: u32,
    height: u32,
    count: u32,
    // Threads per row of the dispatch grid (dispatches are 2D past 65535 workgroups).
    row_pitch: u32,
    // Offset of the stratified sample positions within their strata, in [0, 1).
    jitter: f32,
    pad0: f32,
    pad1: f32,
    pad2: f32,
}

@group(0) @binding(0) var<uniform> params: SelectParams;
@group(0) @binding(1) var<storage, read> importance: array<f32>;
@group(0) @binding(2) var<storage, read> column_sums: array<f32>;
@group(0) @binding(3) var<storage, read> row_sums: array<f32>;
@group(0) @binding(4) var rsm_position: texture_2d<f32>;
@group(0) @binding(5) var rsm_normal: texture_2d<f32>;
@group(0) @binding(6) var rsm_flux_area: texture_2d<f32>;
@group(0) @binding(7) var<storage, read_write> vals: array<Val>;

// First column whose cumulative total exceeds `u`.
fn find_column(u: f32) -> u32 {
    var lo = 0u;
    var hi = params.width - 1u;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if row_sums[mid] > u {
            hi = mid;
        } else {
            lo = mid + 1u;
        }
    }
    return lo;
}

// First row of column `x` whose cumulative sum exceeds `r`.
fn find_row(x: u32, r: f32) -> u32 {
    var lo = 0u;
    var hi = params.height - 1u;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if column_sums[mid * params.width + x] > r {
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
    if !(total > 0.0) {
        vals[i] = Val(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0u);
        return;
    }
    // Stratified positions along the cumulative distribution (texels in column-major order):
    // each of the N strata of equal probability gets exactly one sample.
    let u = (f32(i) + params.jitter) / f32(params.count) * total;
    let x = find_column(u);
    var before = 0.0;
    if x > 0u {
        before = row_sums[x - 1u];
    }
    let y = find_row(x, u - before);
    let texel = y * params.width + x;
    let p = importance[texel] / total;
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
    );
}
