// Automatic exposure: the geometric mean luminance of lit pixels is mapped to middle grey.
// Two stages: per-tile partial sums, then one workgroup reduces the tiles.

// Mirrored by `ExposureParams` in server/passes/src/passes/exposure.rs.
struct ExposureParams {
    tile_count: u32,
    // Target for the mean luminance after exposure (middle grey).
    key: f32,
    min_scale: f32,
    max_scale: f32,
}

@group(0) @binding(0) var<storage, read> params: ExposureParams;
@group(0) @binding(1) var hdr: texture_2d<f32>;
@group(0) @binding(2) var<storage, read_write> tiles: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> result: ExposureResult;

const TILE: u32 = 16u;
const FINISH_THREADS: u32 = 256u;
// Pixels darker than this (fully shadowed, no ambient) would drag a log average to -inf.
const MIN_LUMINANCE: f32 = 1e-6;

var<workgroup> partial: array<vec2<f32>, 256>;

fn reduce_partial(local: u32) {
    for (var stride = 128u; stride > 0u; stride >>= 1u) {
        if local < stride {
            partial[local] += partial[local + stride];
        }
        workgroupBarrier();
    }
}

@compute @workgroup_size(16, 16)
fn reduce_tiles(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let size = textureDimensions(hdr);
    var value = vec2<f32>(0.0);
    if id.x < size.x && id.y < size.y {
        let c = textureLoad(hdr, vec2<i32>(id.xy), 0);
        let lum = dot(c.rgb, vec3<f32>(0.2126, 0.7152, 0.0722));
        if c.a > 0.0 && lum > MIN_LUMINANCE {
            value = vec2<f32>(log2(lum), 1.0);
        }
    }
    partial[local] = value;
    workgroupBarrier();
    reduce_partial(local);
    if local == 0u {
        tiles[group.y * groups.x + group.x] = partial[0];
    }
}

@compute @workgroup_size(256)
fn finish(@builtin(local_invocation_index) local: u32) {
    var sum = vec2<f32>(0.0);
    for (var i = local; i < params.tile_count; i += FINISH_THREADS) {
        sum += tiles[i];
    }
    partial[local] = sum;
    workgroupBarrier();
    reduce_partial(local);
    if local == 0u {
        let total = partial[0];
        var mean = 0.0;
        var scale = 1.0;
        if total.y > 0.0 {
            mean = total.x / total.y;
            scale = clamp(params.key / exp2(mean), params.min_scale, params.max_scale);
        }
        result = ExposureResult(scale, mean, total.y, 0.0);
    }
}
