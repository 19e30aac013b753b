// Reflective shadow map: every texel seen from the light becomes a virtual area light (VAL)
// with a position, a normal, the flux it reflects and its disk area (eq. 1), and the glossy
// lobe it sends on (rsm_glossy.wgsl). The faces of every light (six for a point light) lie
// side by side in one atlas, so later stages treat all the frame's lights as one 2D map.

// Mirrored by `RsmFace` in server/passes/src/passes/rsm.rs.
struct RsmFace {
    view_proj: mat4x4<f32>,
    // The face's viewing axis (unit), for the view-space depth z of eq. 1.
    axis: vec3<f32>,
    // Eq. 1 without z²: w_near·h_near / (z_near²·w_RSM·h_RSM) for perspective faces; the
    // constant texel area (w·h of the orthographic box / texel count) for directional lights.
    texel_area: f32,
    perspective: u32,
    // The face's light in `lights`.
    light: u32,
    // The face's index among its light's: a cube face, or a directional light's cascade.
    index: u32,
    // 1: texels send on the glossy part of what they reflect (`senders: full`); 0: the
    // paper's diffuse VALs alone.
    glossy: u32,
}

@group(0) @binding(0) var<storage, read> face: RsmFace;
@group(0) @binding(1) var<storage, read> lights: Lights;

@vertex
fn vs_main(
    v: VertexInput,
    @builtin(vertex_index) vertex: u32,
    @builtin(instance_index) first_triangle: u32,
) -> SurfaceVaryings {
    return surface_varyings(v, vertex, first_triangle, face.view_proj);
}

struct RsmOut {
    // w = 1 marks texels that hold a VAL.
    @location(0) position: vec4<f32>,
    @location(1) normal: vec4<f32>,
    // rgb: reflected flux Φ_l; a: disk area A_l (eq. 1).
    @location(2) flux_area: vec4<f32>,
    // `encode_glossy` (rsm_glossy.wgsl).
    @location(3) glossy: vec4<u32>,
}

@fragment
fn fs_main(in: SurfaceVaryings, @builtin(front_facing) front: bool) -> RsmOut {
    let m = sample_material(in.material, in.uv);
    if !m.covered {
        discard;
    }
    let n = facing_normal(in.normal, front);
    let light = lights.list[face.light];
    // A directional light's far cascade leaves what its near one covers to it: each surface
    // point sends its light from one face (frame_uniforms::Coverage::View).
    if light.kind == LIGHT_DIRECTIONAL && face.index > 0u {
        let near = light.face_view_proj[0] * vec4<f32>(in.world, 1.0);
        if all(abs(near.xy / near.w) <= vec2<f32>(1.0)) {
            discard;
        }
    }
    var area = face.texel_area;
    // Cross-section of the texel's beam across the ray, which is what E⊥ falls on.
    var cross_section = area;
    if face.perspective != 0u {
        let to_texel = in.world - light.position;
        let z = dot(to_texel, face.axis);
        area *= z * z;
        // A_disk (eq. 1) lies across the face's axis; tilted by θ off the axis, the beam's
        // cross-section is A_disk·cosθ (so the texel receives I·Ω with Ω = texel_area·cos³θ).
        cross_section = area * z / max(length(to_texel), 1e-20);
    }
    // The texel receives E⊥ times its beam's cross-section, Φ_in, and sends on what its diffuse
    // lobe reflects of that, in whatever direction (the VAL emits diffusely, eq. 3): the
    // diffuse lobe's albedo for light arriving at the texel's cosine. Its specular lobe's part
    // leaves as the Phong lobe of eq. 4 about the light's mirror direction, with the colour
    // that lobe has for light arriving at that cosine (reciprocity).
    let incident = light_incident(light, in.world);
    let cos_l = dot(n, incident.to_light);
    let facing = select(0.0, 1.0, cos_l > 0.0);
    let flux_in = incident.irradiance * cross_section * facing;
    let lobes = phong_lobes(m.brdf, cos_l);
    var out: RsmOut;
    out.position = vec4<f32>(in.world, 1.0);
    out.normal = vec4<f32>(n, 0.0);
    out.flux_area = vec4<f32>(lobes.diffuse * flux_in, area);
    out.glossy = encode_glossy(
        lobes.glossy * flux_in * f32(face.glossy),
        reflect(-incident.to_light, n),
        lobes.exponent,
    );
    return out;
}
