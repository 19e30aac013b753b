// Reflective shadow maps (Dachsbacher & Stamminger 2005, §3): every pixel gathers a fixed
// pattern of RSM texels around the texel it projects to, each a pixel light (vpl_light.wgsl),
// weighted by the texels it stands for, without visibility. The pattern, its weights and the
// projection are explained in server/gi/src/rsm_gather/pattern.rs, whose `gather` is the CPU
// reference of this pass.

// Mirrored by `GatherParams` in server/gi/src/rsm_gather/passes.rs.
struct GatherParams {
    width: u32,
    height: u32,
    // Side of one face of the RSM atlas, in texels.
    rsm_size: u32,
    faces: u32,
    sample_count: u32,
    // r_max in texels.
    radius: f32,
    // The pixel whose gather the `gather-samples` view shows.
    probe_x: u32,
    probe_y: u32,
}

// The `light` of the face holding the emitters' samples (pattern.rs `EMITTER_FACE`).
const EMITTER_FACE: u32 = 0xffffffffu;

// Mirrored by `GatherFace` in server/gi/src/rsm_gather/passes.rs.
struct GatherFace {
    view_proj: mat4x4<f32>,
    // The face's light: a light's faces follow each other in the atlas.
    light: u32,
    // The emitter face's samples, in its first texels (pattern.rs `emitter_texels`).
    emitter_samples: u32,
    pad1: u32,
    pad2: u32,
}

// Mirrored by `GatherSample` in server/gi/src/rsm_gather/pattern.rs.
struct GatherSample {
    // ξ1·(sin 2πξ2, cos 2πξ2): the offset in units of r_max.
    offset: vec2<f32>,
    // 2π·ξ1/N: the texels it stands for, in units of r_max².
    weight: f32,
    pad0: f32,
}

@group(0) @binding(0) var<storage, read> params: GatherParams;
@group(0) @binding(1) var<storage, read> camera: CameraUniform;
@group(0) @binding(2) var g_position: texture_2d<f32>;
@group(0) @binding(3) var g_normal_roughness: texture_2d<f32>;
@group(0) @binding(4) var g_base_metallic: texture_2d<f32>;
@group(0) @binding(5) var g_emissive_specular: texture_2d<f32>;
@group(0) @binding(6) var rsm_position: texture_2d<f32>;
@group(0) @binding(7) var rsm_normal: texture_2d<f32>;
@group(0) @binding(8) var rsm_flux_area: texture_2d<f32>;
// Each face's view-projection, as the RSM was rendered with, and its light.
@group(0) @binding(9) var<storage, read> faces: array<GatherFace>;
@group(0) @binding(10) var<storage, read> samples: array<GatherSample>;
// The probe pixel's face of the first light, its texel coordinates within it, and 1 where it
// has a surface.
@group(0) @binding(11) var<storage, read_write> probe: vec4<f32>;
@group(0) @binding(12) var indirect_out: texture_storage_2d<rgba16float, write>;
@group(0) @binding(13) var<storage, read> brdf_table: array<vec4<f32>>;
@group(0) @binding(14) var rsm_glossy: texture_2d<u32>;

// L at x from atlas texel `t` as a pixel light (vpl_light.wgsl) standing for `texels` texels
// (its glossy lobe widened by their footprint); nothing where it is empty.
fn texel_light(t: vec2<i32>, texels: f32, x: vec3<f32>, s: ViewedBrdf) -> vec3<f32> {
    let light_position = textureLoad(rsm_position, t, 0);
    if light_position.w == 0.0 {
        return vec3<f32>(0.0);
    }
    let flux_area = textureLoad(rsm_flux_area, t, 0);
    let normal = textureLoad(rsm_normal, t, 0).xyz;
    let glossy = decode_glossy(textureLoad(rsm_glossy, t, 0));
    return vpl_light(light_position.xyz, normal, flux_area.rgb, glossy, flux_area.a, flux_area.a * texels, x, s) * texels;
}

// Where `x` projects in face `f`: texel coordinates (clamped to the face) and whether it lies
// inside the face's frustum (pattern.rs `project`).
struct Projection {
    st: vec2<f32>,
    inside: bool,
}

fn project(f: u32, x: vec3<f32>) -> Projection {
    let clip = faces[f].view_proj * vec4<f32>(x, 1.0);
    let size = f32(params.rsm_size);
    if clip.w <= 0.0 {
        let xy = clip.xy;
        let len = length(xy);
        var d = vec2<f32>(0.0);
        if len > 0.0 {
            d = xy / len * vec2<f32>(1.0, -1.0);
        }
        let uv = clamp(vec2<f32>(0.5) + d * 2.0, vec2<f32>(0.0), vec2<f32>(1.0));
        return Projection(uv * size, false);
    }
    let ndc = clip.xy / clip.w;
    let inside = abs(ndc.x) <= 1.0 && abs(ndc.y) <= 1.0;
    let uv = clamp(vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5), vec2<f32>(0.0), vec2<f32>(1.0));
    return Projection(uv * size, inside);
}

@compute @workgroup_size(8, 8)
fn gather(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let position = textureLoad(g_position, texel, 0);
    let is_probe = id.x == params.probe_x && id.y == params.probe_y;
    if position.w == 0.0 {
        textureStore(indirect_out, texel, vec4<f32>(0.0));
        if is_probe {
            probe = vec4<f32>(0.0);
        }
        return;
    }
    let x = position.xyz;
    let n = normalize(textureLoad(g_normal_roughness, texel, 0).xyz);
    let v = normalize(camera.position - x);
    let s = view_brdf(gbuffer_brdf(texel), n, v);
    var radiance = vec3<f32>(0.0);
    // Each light's faces in turn (pattern.rs `light_runs`): every light is gathered from.
    var first = 0u;
    while first < params.faces {
        var end = first + 1u;
        while end < params.faces && faces[end].light == faces[first].light {
            end++;
        }
        if faces[first].light == EMITTER_FACE {
            radiance += gather_emitters(first, x, s);
            first = end;
            continue;
        }
        // Every face of the light, around where x projects in it (its nearest border point
        // where x lies outside the face): a point light's six faces see disjoint surfaces, so
        // a wall lit from the floor gathers from the floor's face (pattern.rs `gather`). The
        // probe shows the first face whose frustum holds x, else the first face.
        var face = first;
        var centre = project(first, x).st;
        var found = false;
        for (var f = first; f < end; f++) {
            let p = project(f, x);
            if p.inside && !found {
                face = f;
                centre = p.st;
                found = true;
            }
            radiance += gather_face(f, p.st, x, s);
        }
        if is_probe && first == 0u {
            probe = vec4<f32>(f32(face), centre, 1.0);
        }
        first = end;
    }
    textureStore(indirect_out, texel, vec4<f32>(radiance, 1.0));
}

// Emitter face `face` whole: every (S/N)-th of its S samples, each standing for S/N of them
// (pattern.rs `emitter_texels`).
fn gather_emitters(face: u32, x: vec3<f32>, s: ViewedBrdf) -> vec3<f32> {
    let texels = faces[face].emitter_samples;
    let m = max(min(params.sample_count, texels), 1u);
    let weight = f32(texels) / f32(m);
    var radiance = vec3<f32>(0.0);
    for (var i = 0u; i < m; i++) {
        // ⌊i·texels/m⌋ without overflowing u32: i·q + ⌊i·r/m⌋ for texels = q·m + r, where
        // i·r < m² stays small (m ≤ gather_samples).
        let k = i * (texels / m) + (i * (texels % m)) / m;
        let t = vec2<i32>(i32(face * params.rsm_size + k % params.rsm_size), i32(k / params.rsm_size));
        radiance += texel_light(t, weight, x, s);
    }
    return radiance;
}

// The pattern around `centre` in atlas face `face`: Σ weight × the pixel light's L.
fn gather_face(face: u32, centre: vec2<f32>, x: vec3<f32>, s: ViewedBrdf) -> vec3<f32> {
    let size = f32(params.rsm_size);
    let r2 = params.radius * params.radius;
    var radiance = vec3<f32>(0.0);
    for (var i = 0u; i < params.sample_count; i++) {
        let sample = samples[i];
        let p = centre + params.radius * sample.offset;
        if p.x < 0.0 || p.y < 0.0 || p.x >= size || p.y >= size {
            continue;
        }
        let t = vec2<i32>(vec2<u32>(p) + vec2<u32>(face * params.rsm_size, 0u));
        radiance += texel_light(t, sample.weight * r2, x, s);
    }
    return radiance;
}
