// Eq. 4 in flux form: every cache's incident radiance in SH, L_i = Σ_s Φ̃_s·g_{s,i}, over its
// n_L links to hierarchy nodes (`links::cache_lighting` on the CPU). One thread per cache and
// coefficient.

// Mirrored by `CacheLightParams` in server/gi/src/surfels/passes.rs.
struct CacheLightParams {
    caches: u32,
    per_cache: u32,
    coefficients: u32,
    pad0: u32,
}

const NO_NODE: u32 = 0xffffffffu;

@group(0) @binding(0) var<storage, read> params: CacheLightParams;
@group(0) @binding(1) var<storage, read> link_nodes: array<u32>;
@group(0) @binding(2) var<storage, read> link_coeffs: array<f32>;
@group(0) @binding(3) var<storage, read> flux: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> cache_light: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let total = params.caches * params.coefficients;
    if id.x >= total {
        return;
    }
    let cache = id.x / params.coefficients;
    let i = id.x % params.coefficients;
    var sum = vec3<f32>(0.0);
    for (var j = 0u; j < params.per_cache; j++) {
        let slot = cache * params.per_cache + j;
        let node = link_nodes[slot];
        if node == NO_NODE {
            continue;
        }
        sum += flux[node].rgb * link_coeffs[slot * params.coefficients + i];
    }
    cache_light[id.x] = vec4<f32>(sum, 0.0);
}
