// The paper's reflectance model (eq. 3–4): Lambert diffuse plus a normalised Phong lobe around
// the mirror direction, and the metallic/roughness → diffuse/glossy split used to feed it.

struct SurfaceBrdf {
    diffuse: vec3<f32>,
    glossy: vec3<f32>,
    exponent: f32,
}

// Mirror of `scene::material::split` (see there for the derivation of the exponent).
fn split_material(base: vec3<f32>, metallic_in: f32, roughness_in: f32) -> SurfaceBrdf {
    let metallic = clamp(metallic_in, 0.0, 1.0);
    let roughness = clamp(roughness_in, 0.0, 1.0);
    let alpha = max(roughness * roughness, 1e-3);
    let k_blinn = 2.0 / (alpha * alpha) - 2.0;
    return SurfaceBrdf(
        base * (1.0 - metallic),
        mix(vec3<f32>(0.04), base, metallic),
        clamp(k_blinn * 0.25, 1.0, 4096.0),
    );
}

// f_r for light arriving from `to_light` and leaving towards `to_viewer` (all unit vectors).
// The glossy lobe's (k+2)/2π keeps it energy-normalised; θ_e is the angle between the view
// direction and the light's mirror reflection (eq. 4).
fn eval_brdf(s: SurfaceBrdf, n: vec3<f32>, to_light: vec3<f32>, to_viewer: vec3<f32>) -> vec3<f32> {
    let mirrored = reflect(-to_light, n);
    let cos_e = max(dot(mirrored, to_viewer), 0.0);
    let lobe = (s.exponent + 2.0) / (2.0 * PI) * pow(cos_e, s.exponent);
    return s.diffuse / PI + s.glossy * lobe;
}
