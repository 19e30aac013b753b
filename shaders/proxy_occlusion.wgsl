// Occlusion of each cache's two proxy lights by the disks of the other caches (double
// projection, see light_caches.wgsl); scales the proxies' flux by the visible fraction.

// Mirrored by `OcclusionParams` in server/src/passes/proxy_occlusion.rs.
struct OcclusionParams {
    cache_count: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> params: OcclusionParams;
@group(0) @binding(1) var<storage, read> caches: array<LightCache>;
@group(0) @binding(2) var<storage, read_write> lighting: array<CacheLighting>;

const TILE_CACHES: u32 = 64u;
var<workgroup> tile: array<LightCache, 64>;

@compute @workgroup_size(64)
fn occlude_proxies(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let i = id.x;
    let in_range = i < params.cache_count;
    var c = LightCache(vec3<f32>(0.0), 0.0, vec3<f32>(0.0, 1.0, 0.0), 0.0, vec3<f32>(0.0), 1.0, vec3<f32>(0.0), 0.0);
    var l = CacheLighting(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    if in_range {
        c = caches[i];
        l = lighting[i];
    }
    let frame = tangent_frame(c.normal);
    let square_d = proxy_square(frame, c, l.diffuse_position, l.diffuse_radius);
    let square_g = proxy_square(frame, c, l.glossy_position, l.glossy_radius);
    var covered_d = 0.0;
    var covered_g = 0.0;
    for (var base = 0u; base < params.cache_count; base += TILE_CACHES) {
        workgroupBarrier();
        let j = base + local;
        if j < params.cache_count {
            tile[local] = caches[j];
        } else {
            tile[local] = LightCache(vec3<f32>(0.0), 0.0, vec3<f32>(0.0, 1.0, 0.0), 0.0, vec3<f32>(0.0), 1.0, vec3<f32>(0.0), 0.0);
        }
        workgroupBarrier();
        if in_range {
            let count = min(TILE_CACHES, params.cache_count - base);
            for (var k = 0u; k < count; k++) {
                if base + k == i {
                    continue;
                }
                let o = tile[k];
                covered_d += overlap(square_d, occluder_square(frame, c, o, l.diffuse_position, l.diffuse_radius));
                covered_g += overlap(square_g, occluder_square(frame, c, o, l.glossy_position, l.glossy_radius));
            }
        }
    }
    if !in_range {
        return;
    }
    l.diffuse_flux *= visibility(square_d, covered_d);
    l.glossy_flux *= visibility(square_g, covered_g);
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
