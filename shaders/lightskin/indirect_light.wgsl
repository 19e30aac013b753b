// Indirect light per pixel: the proxy lights of the 16 caches stored with a vertex are
// interpolated with the weights of eq. 8 (eq. 9) and applied with the surface's BRDF. With
// triangle ids in the G-buffer the results for the triangle's three vertices are blended by
// the pixel's barycentric coordinates (smooth across triangles); without, the provoking
// vertex serves the whole triangle. The surface reflects with the paper's lobes (eq. 3–4)
// fitted to its BRDF as seen from the camera (brdf_eval.wgsl `phong_lobes`): the specular
// lobe as a Phong lobe is this method's approximation of it. Mirrors `cpu::shade`.

// Mirrored by `IndirectParams` in server/passes/src/passes/indirect_light.rs.
struct IndirectParams {
    // 0 writes black (GI off).
    enabled: u32,
    // 1: `g_id` holds triangle ids; 0: provoking-vertex ids.
    triangle_ids: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<storage, read> camera: CameraUniform;
@group(0) @binding(1) var<storage, read> params: IndirectParams;
@group(0) @binding(2) var g_position: texture_2d<f32>;
@group(0) @binding(3) var g_normal_roughness: texture_2d<f32>;
@group(0) @binding(4) var g_base_metallic: texture_2d<f32>;
@group(0) @binding(5) var g_emissive_specular: texture_2d<f32>;
@group(0) @binding(6) var g_id: texture_2d<u32>;
@group(0) @binding(7) var<storage, read> caches: array<LightCache>;
@group(0) @binding(8) var<storage, read> lighting: array<CacheLighting>;
// 16 cache indices per scene vertex; u32::MAX pads lists of fewer caches.
@group(0) @binding(9) var<storage, read> vertex_caches: array<u32>;
@group(0) @binding(10) var indirect_out: texture_storage_2d<rgba16float, write>;
// The scene's triangle list and vertex positions (9 floats per vertex, position first).
@group(0) @binding(11) var<storage, read> indices: array<u32>;
@group(0) @binding(12) var<storage, read> vertices: array<f32>;
@group(0) @binding(13) var<storage, read> brdf_table: array<vec4<f32>>;

const NEIGHBOURS: u32 = 16u;
const NO_CACHE: u32 = 0xffffffffu;
const VERTEX_FLOATS: u32 = 9u;

struct Surface {
    x: vec3<f32>,
    n: vec3<f32>,
    v: vec3<f32>,
    lobes: PhongLobes,
}

// Indirect radiance at the surface from the 16 caches of `vertex` (eq. 8–9).
fn shade_from_vertex(s: Surface, vertex: u32) -> vec3<f32> {
    let first = vertex * NEIGHBOURS;
    var d_max = 0.0;
    for (var j = 0u; j < NEIGHBOURS; j++) {
        let ci = vertex_caches[first + j];
        if ci != NO_CACHE {
            d_max = max(d_max, distance(s.x, caches[ci].position));
        }
    }
    // Eq. 9 averages flux over all neighbours, so unlit ones dim the result as they should, but
    // positions only over lit ones: an unlit proxy sits on its own cache, and averaging it in
    // would pull the light onto the surface and brighten it by 1/d².
    var sum_d = 0.0;
    var sum_g = 0.0;
    var lit_d = 0.0;
    var lit_g = 0.0;
    var pos_d = vec3<f32>(0.0);
    var pos_g = vec3<f32>(0.0);
    var flux_d = vec3<f32>(0.0);
    var flux_g = vec3<f32>(0.0);
    // Σ w'·A_c: the interpolated cache area sets the distance floor, as A_c did in eq. 7.
    var area_d = 0.0;
    var area_g = 0.0;
    for (var j = 0u; j < NEIGHBOURS; j++) {
        let ci = vertex_caches[first + j];
        if ci == NO_CACHE {
            continue;
        }
        let c = caches[ci];
        let l = lighting[ci];
        var a = 1.0;
        if d_max > 0.0 {
            a = 1.0 - distance(s.x, c.position) / d_max;
        }
        // Eq. 8: normals for the diffuse term, mirrored incident directions for the glossy one.
        // An unlit glossy proxy has no incident direction and falls back to the normals.
        let w_d = a * sqrt(max(dot(s.n, c.normal), 0.0));
        var w_g = w_d;
        if !unlit(l.glossy_flux) {
            let r_x = mirror(s.n, direction(l.glossy_position - s.x));
            let r_c = mirror(c.normal, direction(l.glossy_position - c.position));
            w_g = a * sqrt(max(dot(r_x, r_c), 0.0));
            lit_g += w_g;
            pos_g += w_g * l.glossy_position;
        }
        if !unlit(l.diffuse_flux) {
            lit_d += w_d;
            pos_d += w_d * l.diffuse_position;
        }
        sum_d += w_d;
        sum_g += w_g;
        flux_d += w_d * l.diffuse_flux;
        flux_g += w_g * l.glossy_flux;
        area_d += w_d * c.area;
        area_g += w_g * c.area;
    }
    var radiance = vec3<f32>(0.0);
    // A proxy on the surface point itself (possible only for caches without area) lights it
    // from no direction: no light rather than 0/0.
    if lit_d > 0.0 {
        // Eq. 9, then the interpolated proxy as a point light of intensity Φ/4π.
        let to_light = pos_d / lit_d - s.x;
        let d2 = max(dot(to_light, to_light), MIN_DIST2_PER_AREA * area_d / sum_d);
        let w = direction(to_light);
        if d2 > 0.0 {
            radiance += s.lobes.diffuse / PI * (flux_d / sum_d) / (4.0 * PI * d2) * max(dot(s.n, w), 0.0);
        }
    }
    if lit_g > 0.0 {
        let to_light = pos_g / lit_g - s.x;
        let d2 = max(dot(to_light, to_light), MIN_DIST2_PER_AREA * area_g / sum_g);
        let w = direction(to_light);
        let k = s.lobes.exponent;
        let lobe = (k + 2.0) / (2.0 * PI) * pow(max(dot(mirror(s.n, w), s.v), 0.0), k);
        if d2 > 0.0 {
            radiance += s.lobes.glossy * lobe * (flux_g / sum_g) / (4.0 * PI * d2) * max(dot(s.n, w), 0.0);
        }
    }
    return radiance;
}

fn vertex_position(i: u32) -> vec3<f32> {
    let b = i * VERTEX_FLOATS;
    return vec3<f32>(vertices[b], vertices[b + 1u], vertices[b + 2u]);
}

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
    let n = normalize(textureLoad(g_normal_roughness, texel, 0).xyz);
    let v = normalize(camera.position - position.xyz);
    let s = Surface(position.xyz, n, v, phong_lobes(gbuffer_brdf(texel), max(dot(n, v), 0.0)));
    let g = textureLoad(g_id, texel, 0).x;
    var radiance = vec3<f32>(0.0);
    if params.triangle_ids == 0u {
        radiance = shade_from_vertex(s, g);
    } else {
        let tri = vec3<u32>(indices[3u * g], indices[3u * g + 1u], indices[3u * g + 2u]);
        let a = vertex_position(tri.x);
        let e1 = vertex_position(tri.y) - a;
        let e2 = vertex_position(tri.z) - a;
        // Barycentric coordinates of the pixel's position in its triangle.
        let d = s.x - a;
        let d11 = dot(e1, e1);
        let d12 = dot(e1, e2);
        let d22 = dot(e2, e2);
        let denom = d11 * d22 - d12 * d12;
        var b = vec3<f32>(1.0, 0.0, 0.0);
        if denom > 0.0 {
            let u = clamp((d22 * dot(d, e1) - d12 * dot(d, e2)) / denom, 0.0, 1.0);
            let w = clamp((d11 * dot(d, e2) - d12 * dot(d, e1)) / denom, 0.0, 1.0 - u);
            b = vec3<f32>(1.0 - u - w, u, w);
        }
        radiance = b.x * shade_from_vertex(s, tri.x) + b.y * shade_from_vertex(s, tri.y) + b.z * shade_from_vertex(s, tri.z);
    }
    textureStore(indirect_out, texel, vec4<f32>(radiance, 1.0));
}
