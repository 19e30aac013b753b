// A surface point's BRDF parameters: glTF's metallic-roughness model, evaluated by
// brdf_eval.wgsl. Mirrored by `scene::brdf::Brdf` (see there for the model and its sources).

// Mirrored by `scene::brdf::MIN_ROUGHNESS`.
const MIN_ROUGHNESS: f32 = 0.045;

struct SurfaceBrdf {
    // Linear base colour (textured).
    base: vec3<f32>,
    metallic: f32,
    // Perceptual roughness; GGX's α is its square.
    roughness: f32,
    // Dielectric specular weight (KHR_materials_specular's specularFactor).
    specular: f32,
}

// `scene::brdf::Brdf::new`: the factors clamped into the model's ranges.
fn surface_brdf(base: vec3<f32>, metallic: f32, roughness: f32, specular: f32) -> SurfaceBrdf {
    return SurfaceBrdf(
        max(base, vec3<f32>(0.0)),
        clamp(metallic, 0.0, 1.0),
        clamp(roughness, MIN_ROUGHNESS, 1.0),
        clamp(specular, 0.0, 1.0),
    );
}
