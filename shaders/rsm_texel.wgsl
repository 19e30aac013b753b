// Reflective shadow map: every texel seen from the light becomes a virtual area light (VAL)
// with a position, a normal, the flux it reflects and its disk area (eq. 1), and the glossy
// lobe it sends on (rsm_glossy.wgsl). The faces of every light (six for a point light) lie
// side by side in one atlas, so later stages treat all the frame's lights as one 2D map. This
// file is what a texel holds for the surface point it shows; rsm.wgsl writes it from the
// raster, rsm_resolve.wgsl from a visibility buffer (rsm_visibility.wgsl).

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

// An RSM texel's targets.
struct RsmTexel {
    // w = 1 marks texels that hold a VAL.
    position: vec4<f32>,
    normal: vec4<f32>,
    // rgb: reflected flux Φ_l; a: disk area A_l (eq. 1).
    flux_area: vec4<f32>,
    // `encode_glossy` (rsm_glossy.wgsl).
    glossy: vec4<u32>,
}

// Whether `face` of `light` leaves the point at `world` to another face: a directional
// light's far cascade leaves what its near one covers to it, so that each surface point sends
// its light from one face (frame_uniforms::Coverage::View).
fn rsm_left_to_nearer_face(light: LightUniform, face: RsmFace, world: vec3<f32>) -> bool {
    if light.kind != LIGHT_DIRECTIONAL || face.index == 0u {
        return false;
    }
    let near = light.face_view_proj[0] * vec4<f32>(world, 1.0);
    return all(abs(near.xy / near.w) <= vec2<f32>(1.0));
}

// The texel of `face` (of `light`) showing the point at `world` with shading normal `n` and
// BRDF `brdf`.
fn rsm_texel(face: RsmFace, light: LightUniform, world: vec3<f32>, n: vec3<f32>, brdf: SurfaceBrdf) -> RsmTexel {
    var area = face.texel_area;
    // Cross-section of the texel's beam across the ray, which is what E⊥ falls on.
    var cross_section = area;
    if face.perspective != 0u {
        let to_texel = world - light.position;
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
    let incident = light_incident(light, world);
    let cos_l = dot(n, incident.to_light);
    let facing = select(0.0, 1.0, cos_l > 0.0);
    let flux_in = incident.irradiance * cross_section * facing;
    let lobes = phong_lobes(brdf, cos_l);
    return RsmTexel(
        vec4<f32>(world, 1.0),
        vec4<f32>(n, 0.0),
        vec4<f32>(lobes.diffuse * flux_in, area),
        encode_glossy(lobes.glossy * flux_in * f32(face.glossy), reflect(-incident.to_light, n), lobes.exponent),
    );
}
