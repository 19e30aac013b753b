// Occlusion of each cache's two proxy lights by the disks of the other caches (double
// projection, see light_caches.wgsl); scales the proxies' flux by the visible fraction. The
// occluders are split into chunks, one dispatch each, whose covered areas add up in
// `coverage`; a last dispatch applies them.

// Mirrored by `OcclusionParams` in server/passes/src/passes/proxy_occlusion.rs.
struct OcclusionParams {
    cache_count: u32,
    // This dispatch's occluders: [first_occluder, end_occluder).
    first_occluder: u32,
    end_occluder: u32,
    pad0: u32,
}

@group(0) @binding(0) var<storage, read> params: OcclusionParams;
@group(0) @binding(1) var<storage, read> caches: array<LightCache>;
@group(0) @binding(2) var<storage, read_write> lighting: array<CacheLighting>;
// Covered area of the diffuse (x) and glossy (y) proxy squares so far.
@group(0) @binding(3) var<storage, read_write> coverage: array<vec2<f32>>;

const TILE_CACHES: u32 = 64u;
var<workgroup> tile: array<LightCache, 64>;

fn empty_cache() -> LightCache {
    return LightCache(vec3<f32>(0.0), 0.0, vec3<f32>(0.0, 1.0, 0.0), 0.0, vec3<f32>(0.0), 1.0, vec3<f32>(0.0), 0xffffffffu);
}

@compute @workgroup_size(64)
fn accumulate_coverage(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let i = id.x;
    let in_range = i < params.cache_count;
    var c = empty_cache();
    var l = CacheLighting(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    var covered = vec2<f32>(0.0);
    if in_range {
        c = caches[i];
        l = lighting[i];
        if params.first_occluder > 0u {
            covered = coverage[i];
        }
    }
    let frame = tangent_frame(c.normal);
    let square_d = proxy_square(frame, c, l.diffuse_position, l.diffuse_radius);
    let square_g = proxy_square(frame, c, l.glossy_position, l.glossy_radius);
    for (var base = params.first_occluder; base < params.end_occluder; base += TILE_CACHES) {
        workgroupBarrier();
        let j = base + local;
        if j < params.end_occluder {
            tile[local] = caches[j];
        } else {
            tile[local] = empty_cache();
        }
        workgroupBarrier();
        if in_range {
            let count = min(TILE_CACHES, params.end_occluder - base);
            for (var k = 0u; k < count; k++) {
                if base + k == i {
                    continue;
                }
                let o = tile[k];
                covered.x += overlap(square_d, occluder_square(frame, c, o, l.diffuse_position, l.diffuse_radius));
                covered.y += overlap(square_g, occluder_square(frame, c, o, l.glossy_position, l.glossy_radius));
            }
        }
    }
    if in_range {
        coverage[i] = covered;
    }
}

@compute @workgroup_size(64)
fn apply_occlusion(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.cache_count {
        return;
    }
    let c = caches[i];
    var l = lighting[i];
    let covered = coverage[i];
    let frame = tangent_frame(c.normal);
    l.diffuse_flux *= visibility(proxy_square(frame, c, l.diffuse_position, l.diffuse_radius), covered.x);
    l.glossy_flux *= visibility(proxy_square(frame, c, l.glossy_position, l.glossy_radius), covered.y);
    lighting[i] = l;
}

// Unoccluded fraction of a proxy's square; overlapping occluders may double count, hence the clamp.
fn visibility(proxy: Square, covered: f32) -> f32 {
    let area = proxy.side * proxy.side;
    if area <= 0.0 {
        return 1.0;
    }
    return 1.0 - min(covered / area, 1.0);
}
