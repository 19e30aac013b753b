// Punctual lights and their shadow maps. The shadow map is one depth array for every light of
// the frame: one layer for a directional (orthographic) or spot (perspective) light, six cube
// faces for a point light, two cascades (near, far) for a directional light fitted to the view
// (`frame_uniforms::Coverage::View`), each light's layers from its `first_layer` on.

const LIGHT_DIRECTIONAL: u32 = 0u;
const LIGHT_SPOT: u32 = 1u;
const LIGHT_POINT: u32 = 2u;
// Mirrors `MAX_LIGHTS` in server/passes/src/passes/frame_uniforms.rs.
const MAX_LIGHTS: u32 = 16u;

// Mirrored by `LightUniform` in server/passes/src/passes/frame_uniforms.rs.
struct LightUniform {
    face_view_proj: array<mat4x4<f32>, 6>,
    position: vec3<f32>,
    kind: u32,
    // Direction the light travels (unit).
    direction: vec3<f32>,
    cos_inner: f32,
    // Colour × intensity: illuminance (directional) or intensity (spot, point).
    radiance: vec3<f32>,
    cos_outer: f32,
    // 1 / shadow map resolution.
    shadow_texel: f32,
    // Offset along the normal before the lookup, against self-shadowing: world units for
    // directional lights, world units per metre from the light for spot and point lights
    // (their texels grow with distance).
    normal_bias: f32,
    // The light's first layer in the frame's shadow-map array.
    first_layer: u32,
    // Its layers: 6 for a point light, 2 for a directional light's cascades, else 1.
    face_count: u32,
}

// Every light of a frame: the first `punctual` its punctual lights, the rest the directional
// lights a real-time method splits the environment into. Mirrored by `LightsUniform` in
// frame_uniforms.rs.
struct Lights {
    count: u32,
    punctual: u32,
    pad1: u32,
    pad2: u32,
    list: array<LightUniform, MAX_LIGHTS>,
}

struct Incident {
    to_light: vec3<f32>,
    // Irradiance on a surface facing the light, before the cosine and shadowing.
    irradiance: vec3<f32>,
}

fn light_incident(light: LightUniform, p: vec3<f32>) -> Incident {
    if light.kind == LIGHT_DIRECTIONAL {
        return Incident(-light.direction, light.radiance);
    }
    let d = light.position - p;
    let dist2 = max(dot(d, d), 1e-8);
    let l = d * inverseSqrt(dist2);
    var e = light.radiance / dist2;
    if light.kind == LIGHT_SPOT {
        e *= smoothstep(light.cos_outer, light.cos_inner, dot(-l, light.direction));
    }
    return Incident(l, e);
}

// Whether `p` lies inside the near cascade of a directional light (with its filter's
// footprint), whose face is the finer of the two wherever it reaches.
fn in_near_cascade(light: LightUniform, p: vec3<f32>) -> bool {
    let clip = light.face_view_proj[0] * vec4<f32>(p, 1.0);
    return all(abs(clip.xy / clip.w) <= vec2<f32>(1.0 - 4.0 * light.shadow_texel));
}

// Length of the first row of an orthographic face's matrix: 2 / the face's side.
fn ortho_scale(m: mat4x4<f32>) -> f32 {
    return length(vec3<f32>(m[0].x, m[1].x, m[2].x));
}

// `bias` (in the first face's texels for a directional light) in face `face`'s: the far
// cascade's texels are larger.
fn bias_in(light: LightUniform, face: u32, bias: f32) -> f32 {
    if light.kind == LIGHT_DIRECTIONAL && face > 0u {
        return bias * ortho_scale(light.face_view_proj[0]) / ortho_scale(light.face_view_proj[face]);
    }
    return bias;
}

// `q` in face `face`'s normalised device coordinates (w = 1), or w = 0 where it lies behind a
// perspective face's eye.
fn shadow_ndc(light: LightUniform, face: u32, q: vec3<f32>) -> vec4<f32> {
    let clip = light.face_view_proj[face] * vec4<f32>(q, 1.0);
    if clip.w <= 0.0 {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(clip.xyz / clip.w, 1.0);
}

// The face whose map holds `p`: the cube face (+X, -X, +Y, -Y, +Z, -Z) of a point light, the
// cascade of a directional light fitted to the view.
fn shadow_face(light: LightUniform, p: vec3<f32>) -> u32 {
    if light.kind == LIGHT_DIRECTIONAL && light.face_count > 1u {
        return select(1u, 0u, in_near_cascade(light, p));
    }
    if light.kind != LIGHT_POINT {
        return 0u;
    }
    let d = p - light.position;
    let a = abs(d);
    if a.x >= a.y && a.x >= a.z {
        return select(1u, 0u, d.x >= 0.0);
    }
    if a.y >= a.z {
        return select(3u, 2u, d.y >= 0.0);
    }
    return select(5u, 4u, d.z >= 0.0);
}

// Fraction of the light reaching `p` (3×3 PCF on hardware-filtered depth comparisons).
// `cos_x` is the cosine between the normal `n` and the direction to the light.
fn shadow_visibility(
    light: LightUniform,
    shadow_map: texture_depth_2d_array,
    shadow_sampler: sampler_comparison,
    p: vec3<f32>,
    n: vec3<f32>,
    cos_x: f32,
) -> f32 {
    var face = shadow_face(light, p);
    var bias = light.normal_bias;
    if light.kind != LIGHT_DIRECTIONAL {
        bias *= distance(p, light.position);
    }
    // A texel's footprint on a surface grows as 1/cos towards grazing light; so does the
    // depth error the offset has to clear (capped, or the shadow detaches entirely).
    bias *= min(1.0 / max(cos_x, 1e-3), 4.0);
    var ndc = shadow_ndc(light, face, p + n * bias_in(light, face, bias));
    var uv = ndc.xy * vec2<f32>(0.5, -0.5) + vec2<f32>(0.5);
    // Near a directional light's near cascade's edge the offset point may leave it: the far
    // cascade holds it.
    let outside = any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0));
    if outside && light.kind == LIGHT_DIRECTIONAL && face == 0u && light.face_count > 1u {
        face = 1u;
        ndc = shadow_ndc(light, face, p + n * bias_in(light, face, bias));
        uv = ndc.xy * vec2<f32>(0.5, -0.5) + vec2<f32>(0.5);
    }
    if ndc.w == 0.0 {
        return 0.0;
    }
    if any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0)) || ndc.z > 1.0 {
        return 1.0;
    }
    var lit = 0.0;
    for (var y = -1; y <= 1; y++) {
        for (var x = -1; x <= 1; x++) {
            let offset = vec2<f32>(f32(x), f32(y)) * light.shadow_texel;
            lit += textureSampleCompareLevel(shadow_map, shadow_sampler, uv + offset, light.first_layer + face, ndc.z);
        }
    }
    return lit / 9.0;
}
