// Visibility of the surfels from a batch of caches: V of eq. 3 (seed 001), one shadow ray per
// cache and surfel, one bit each. Prefixed by `bvh.wgsl` (group 1, the scene's BVH).
// CPU port: the `occluded` test in `links::cache_links`, which this replaces on a GPU.

// Mirrored by `LinkRayParams` in server/gi/src/surfels/link_rays.rs.
struct LinkRayParams {
    surfels: u32,
    caches: u32,
    // u32 words of bits per cache: ceil(surfels / 32).
    words: u32,
    // Ray offset at the surfel's end, relative to the scene (`links::cache_links`).
    epsilon: f32,
}

@group(0) @binding(0) var<storage, read> params: LinkRayParams;
// Cache positions of the batch in xyz.
@group(0) @binding(1) var<storage, read> caches: array<vec4<f32>>;
// Two vec4 per surfel in the hierarchy's leaf order: position, normal.
@group(0) @binding(2) var<storage, read> surfels: array<vec4<f32>>;
// Bit k of word c·words + k/32: surfel k faces cache c and nothing lies between them.
@group(0) @binding(3) var<storage, read_write> visible: array<atomic<u32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    let c = id.y;
    if k >= params.surfels || c >= params.caches {
        return;
    }
    let p = caches[c].xyz;
    let to = surfels[2u * k].xyz - p;
    let d = length(to);
    if d <= params.epsilon {
        return;
    }
    let dir = to / d;
    // Only senders facing the cache are traced; the others count zero in eq. 3 anyway.
    if dot(surfels[2u * k + 1u].xyz, dir) >= 0.0 {
        return;
    }
    // The surfel's own triangle ends the ray at d: stop just short of it.
    if !occluded(p, dir, d - params.epsilon) {
        atomicOr(&visible[c * params.words + k / 32u], 1u << (k % 32u));
    }
}

// Geometry only, as the CPU links (`SceneBvh::occluded` has no alpha test).
fn hit_masked(triangle: u32, b: vec2<f32>) -> bool {
    return false;
}
