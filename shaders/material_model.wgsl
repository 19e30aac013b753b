// The material model every pass shades with: a material's factors times its base-colour
// texel, cut by its alpha mask, as the BRDF's parameters (brdf.wgsl). The rasterising passes sample
// the texel with a sampler (materials.wgsl); the reference path tracer filters it by hand
// (reference/surfaces.wgsl), so both share this function and cannot drift apart.

// Mirrored by `MaterialGpu` in server/passes/src/passes/scene_buffers.rs.
struct MaterialGpu {
    base_color: vec4<f32>,
    emissive: vec3<f32>,
    metallic: f32,
    roughness: f32,
    // Alpha below this is discarded; 0 for opaque materials (glTF BLEND is loaded as opaque).
    alpha_cutoff: f32,
    // Dielectric specular weight (KHR_materials_specular's specularFactor).
    specular: f32,
    pad0: f32,
}

struct MaterialSample {
    brdf: SurfaceBrdf,
    emissive: vec3<f32>,
    // False where an alpha mask cuts the surface away.
    covered: bool,
}

// Material `m` where its base-colour texture reads `texel` (linear colour and alpha; white for
// untextured materials).
fn shade_material(m: MaterialGpu, texel: vec4<f32>) -> MaterialSample {
    let base = m.base_color * texel;
    return MaterialSample(
        surface_brdf(base.rgb, m.metallic, m.roughness, m.specular),
        m.emissive,
        base.a >= m.alpha_cutoff,
    );
}

// The shading normal: back faces (glTF allows double-sided materials) use the flipped one.
fn facing_normal(normal: vec3<f32>, front: bool) -> vec3<f32> {
    let n = normalize(normal);
    return select(-n, n, front);
}
