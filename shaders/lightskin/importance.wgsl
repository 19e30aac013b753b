// Bidirectional importance of every VAL (eq. 10–11): how strongly it lights what the camera
// sees, estimated from N_VS view samples. Two entry points: gather the view samples from the
// G-buffer, then one thread per RSM texel sums over all samples.

// Mirrored by `ImportanceParams` in server/passes/src/passes/importance.rs.
struct ImportanceParams {
    rsm_width: u32,
    rsm_height: u32,
    sample_count: u32,
    // 1: every texel gets importance 1, covered or not (turns the BRSM estimator into plain
    // stratified sampling: with one draw per texel it is exactly the full LightSkin sum).
    uniform_importance: u32,
    // This dispatch's first RSM row: rows are split into bands, one dispatch each, so no
    // dispatch runs long enough to trip a driver's watchdog.
    first_row: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<storage, read> params: ImportanceParams;
@group(0) @binding(1) var g_position: texture_2d<f32>;
@group(0) @binding(2) var g_normal_roughness: texture_2d<f32>;
@group(0) @binding(3) var<storage, read_write> samples: array<ViewSample>;
@group(0) @binding(4) var rsm_position: texture_2d<f32>;
@group(0) @binding(5) var rsm_normal: texture_2d<f32>;
@group(0) @binding(6) var rsm_flux_area: texture_2d<f32>;
@group(0) @binding(7) var<storage, read_write> importance: array<f32>;
@group(0) @binding(8) var rsm_glossy: texture_2d<u32>;

@compute @workgroup_size(64)
fn gather_view_samples(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.sample_count {
        return;
    }
    let size = textureDimensions(g_position);
    // Index 0 of the Halton sequence is the origin; start at 1.
    let h = vec2<f32>(halton(i + 1u, 2u), halton(i + 1u, 3u));
    let pixel = min(vec2<u32>(h * vec2<f32>(size)), size - vec2<u32>(1u));
    let p = textureLoad(g_position, pixel, 0);
    let n = textureLoad(g_normal_roughness, pixel, 0).xyz;
    samples[i] = ViewSample(p.xyz, p.w, n, 0.0);
}

const TILE_SAMPLES: u32 = 64u;
var<workgroup> tile: array<ViewSample, 64>;

@compute @workgroup_size(8, 8)
fn estimate_importance(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let texel = vec2<u32>(id.x, id.y + params.first_row);
    let inside = texel.x < params.rsm_width && texel.y < params.rsm_height;
    var val_position = vec3<f32>(0.0);
    var val_normal = vec3<f32>(0.0);
    var sent = 0.0;
    if inside {
        let p = textureLoad(rsm_position, texel, 0);
        val_position = p.xyz;
        val_normal = textureLoad(rsm_normal, texel, 0).xyz;
        // Eq. 10's Φ_VAL: all the VAL reflects, its glossy part as if it left diffusely. That
        // part is ρ_g·P·Φ_in (P the Phong lobe's albedo, which ρ_g divides out), and P ≈ cosθ_l
        // = n·r for the sharp lobes where it matters. The lobe's direction is left out: a
        // sharp lobe between the view samples would give a VAL that lights the caches brightly
        // no importance, and the few draws the defensive mixture gives it weights of hundreds.
        let g = decode_glossy(textureLoad(rsm_glossy, texel, 0));
        let all = textureLoad(rsm_flux_area, texel, 0).rgb + g.weight * max(dot(val_normal, g.mirror), 0.0);
        sent = p.w * dot(all, vec3<f32>(0.2126, 0.7152, 0.0722));
    }
    var sum = 0.0;
    // Samples are staged through workgroup memory, 64 at a time, shared by the 64 texels.
    for (var base = 0u; base < params.sample_count; base += TILE_SAMPLES) {
        workgroupBarrier();
        let s = base + local;
        if s < params.sample_count {
            tile[local] = samples[s];
        } else {
            tile[local] = ViewSample(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
        }
        workgroupBarrier();
        if sent > 0.0 {
            for (var k = 0u; k < TILE_SAMPLES; k++) {
                let vs = tile[k];
                let l = vs.position - val_position;
                let dist2 = dot(l, l);
                // Unit direction, zero for a view sample on the VAL itself (no floor in
                // scene units: eq. 11's clamp below keeps g finite).
                let d = select(vec3<f32>(0.0), l * inverseSqrt(dist2), dist2 > 0.0);
                // Eq. 11: the squared distance is clamped to at least 1.
                let g = max(dot(val_normal, d), 0.0) * max(dot(vs.normal, -d), 0.0) / max(dist2, 1.0);
                sum += vs.valid * g;
            }
        }
    }
    if inside {
        var value = sent * sum / f32(max(params.sample_count, 1u));
        if params.uniform_importance != 0u {
            value = 1.0;
        }
        importance[texel.y * params.rsm_width + texel.x] = value;
    }
}
