// Indirect light per pixel: the proxy lights of the 16 caches stored with the pixel's vertex
// are interpolated with the weights of eq. 8 (eq. 9) and applied with the surface's BRDF.

// Mirrored by `IndirectParams` in server/src/passes/indirect_light.rs.
struct IndirectParams {
    // 0 writes black (GI off).
    enabled: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> camera: CameraUniform;
@group(0) @binding(1) var<uniform> params: IndirectParams;
@group(0) @binding(2) var g_position: texture_2d<f32>;
@group(0) @binding(3) var g_normal_exponent: texture_2d<f32>;
@group(0) @binding(4) var g_diffuse: texture_2d<f32>;
@group(0) @binding(5) var g_glossy: texture_2d<f32>;
@group(0) @binding(6) var g_vertex: texture_2d<u32>;
@group(0) @binding(7) var<storage, read> caches: array<LightCache>;
@group(0) @binding(8) var<storage, read> lighting: array<CacheLighting>;
// 16 cache indices per scene vertex; u32::MAX pads lists of fewer caches.
@group(0) @binding(9) var<storage, read> vertex_caches: array<u32>;
@group(0) @binding(10) var indirect_out: texture_storage_2d<rgba16float, write>;

const NEIGHBOURS: u32 = 16u;
const NO_CACHE: u32 = 0xffffffffu;
const MIN_DIST2: f32 = 1e-4;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(indirect_out);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let position = textureLoad(g_position, texel, 0);
    if params.enabled == 0u || position.w == 0.0 {
        textureStore(indirect_out, texel, vec4<f32>(0.0));
        return;
    }
    let x = position.xyz;
    let ne = textureLoad(g_normal_exponent, texel, 0);
    let n = normalize(ne.xyz);
    let k = ne.w;
    let v = normalize(camera.position - x);
    let first = textureLoad(g_vertex, texel, 0).x * NEIGHBOURS;

    var d_max = 0.0;
    for (var j = 0u; j < NEIGHBOURS; j++) {
        let ci = vertex_caches[first + j];
        if ci != NO_CACHE {
            d_max = max(d_max, distance(x, caches[ci].position));
        }
    }
    var sum_d = 0.0;
    var sum_g = 0.0;
    var pos_d = vec3<f32>(0.0);
    var pos_g = vec3<f32>(0.0);
    var flux_d = vec3<f32>(0.0);
    var flux_g = vec3<f32>(0.0);
    for (var j = 0u; j < NEIGHBOURS; j++) {
        let ci = vertex_caches[first + j];
        if ci == NO_CACHE {
            continue;
        }
        let c = caches[ci];
        let l = lighting[ci];
        var a = 1.0;
        if d_max > 0.0 {
            a = 1.0 - distance(x, c.position) / d_max;
        }
        // Eq. 8: normals for the diffuse term, mirrored incident directions for the glossy one.
        let w_d = a * sqrt(max(dot(n, c.normal), 0.0));
        let r_x = mirror(n, normalize(l.glossy_position - x));
        let r_c = mirror(c.normal, normalize(l.glossy_position - c.position));
        let w_g = a * sqrt(max(dot(r_x, r_c), 0.0));
        sum_d += w_d;
        sum_g += w_g;
        pos_d += w_d * l.diffuse_position;
        pos_g += w_g * l.glossy_position;
        flux_d += w_d * l.diffuse_flux;
        flux_g += w_g * l.glossy_flux;
    }
    var radiance = vec3<f32>(0.0);
    if sum_d > 0.0 {
        // Eq. 9, then the interpolated proxy as a point light of intensity Φ/4π.
        let to_light = pos_d / sum_d - x;
        let d2 = max(dot(to_light, to_light), MIN_DIST2);
        let w = normalize(to_light);
        let diffuse = textureLoad(g_diffuse, texel, 0).rgb;
        radiance += diffuse / PI * (flux_d / sum_d) / (4.0 * PI * d2) * max(dot(n, w), 0.0);
    }
    if sum_g > 0.0 {
        let to_light = pos_g / sum_g - x;
        let d2 = max(dot(to_light, to_light), MIN_DIST2);
        let w = normalize(to_light);
        let glossy = textureLoad(g_glossy, texel, 0).rgb;
        let lobe = (k + 2.0) / (2.0 * PI) * pow(max(dot(mirror(n, w), v), 0.0), k);
        radiance += glossy * lobe * (flux_g / sum_g) / (4.0 * PI * d2) * max(dot(n, w), 0.0);
    }
    textureStore(indirect_out, texel, vec4<f32>(radiance, 1.0));
}
