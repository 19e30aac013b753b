// The reference's accumulated sums → the frame's indirect buffer, plus the convergence sums:
// per pixel the variance of its mean luminance, reduced over the image (server/gi/src/reference/
// resolve.rs; the CPU twin is `resolve` in server/gi/src/reference/mod.rs).

// Mirrored by `ResolveParams` in server/gi/src/reference/resolve.rs.
struct ResolveParams {
    width: u32,
    height: u32,
    samples: u32,
    partial_count: u32,
}

// Mirrored by `ProgressSums` in server/gi/src/mod.rs.
struct ProgressSums {
    variance_of_mean: f32,
    luminance: f32,
    pixels: f32,
    pad0: f32,
}

@group(0) @binding(0) var<storage, read> params: ResolveParams;
// Per pixel: radiance sums (rgb) and the sum of squared luminance (w).
@group(0) @binding(1) var<storage, read> accum: array<vec4<f32>>;
@group(0) @binding(2) var g_position: texture_2d<f32>;
@group(0) @binding(3) var indirect_out: texture_storage_2d<rgba16float, write>;
// Per workgroup of `resolve`: (variance of the mean, mean luminance) summed over its pixels.
@group(0) @binding(4) var<storage, read_write> partials: array<vec2<f32>>;
@group(0) @binding(5) var<storage, read_write> progress: ProgressSums;

var<workgroup> tile: array<vec2<f32>, 64>;
var<workgroup> total: array<vec2<f32>, 256>;

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

@compute @workgroup_size(8, 8)
fn resolve(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    var sums = vec2<f32>(0.0);
    if id.x < params.width && id.y < params.height {
        let s = accum[id.y * params.width + id.x];
        let n = f32(max(params.samples, 1u));
        let mean = s.xyz / n;
        let y = luminance(mean);
        var variance_of_mean = 0.0;
        if params.samples > 1u {
            // Unbiased sample variance of the luminance, divided by n for that of the mean.
            variance_of_mean = max((s.w / n - y * y) * n / (n - 1.0), 0.0) / n;
        }
        let covered = textureLoad(g_position, vec2<i32>(id.xy), 0).w;
        textureStore(indirect_out, vec2<i32>(id.xy), vec4<f32>(mean, covered));
        sums = vec2<f32>(variance_of_mean, y);
    }
    tile[local] = sums;
    workgroupBarrier();
    for (var stride = 32u; stride > 0u; stride = stride >> 1u) {
        if local < stride {
            tile[local] += tile[local + stride];
        }
        workgroupBarrier();
    }
    if local == 0u {
        partials[group.y * groups.x + group.x] = tile[0];
    }
}

@compute @workgroup_size(256)
fn reduce(@builtin(local_invocation_index) local: u32) {
    var sums = vec2<f32>(0.0);
    for (var i = local; i < params.partial_count; i += 256u) {
        sums += partials[i];
    }
    total[local] = sums;
    workgroupBarrier();
    for (var stride = 128u; stride > 0u; stride = stride >> 1u) {
        if local < stride {
            total[local] += total[local + stride];
        }
        workgroupBarrier();
    }
    if local == 0u {
        progress = ProgressSums(total[0].x, total[0].y, f32(params.width * params.height), 0.0);
    }
}
