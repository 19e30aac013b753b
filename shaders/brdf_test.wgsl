// Test harness (server/tests/integration/gpu_brdf.rs): eval_brdf, eval_diffuse and phong_lobes of
// brdf_eval.wgsl for a list of cases, compared with their CPU reference `scene::brdf`.

// Mirrored by `BrdfCase` in gpu_brdf.rs.
struct BrdfCase {
    base: vec3<f32>,
    metallic: f32,
    n: vec3<f32>,
    roughness: f32,
    to_light: vec3<f32>,
    specular: f32,
    to_viewer: vec3<f32>,
    pad0: f32,
}

@group(0) @binding(0) var<storage, read> cases: array<BrdfCase>;
// Four per case: f_r (rgb), the lobes' diffuse (rgb) and exponent (w), their glossy (rgb), the
// diffuse lobe of f_r (rgb).
@group(0) @binding(1) var<storage, read_write> results: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> brdf_table: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= arrayLength(&cases) {
        return;
    }
    let c = cases[id.x];
    let s = surface_brdf(c.base, c.metallic, c.roughness, c.specular);
    let lobes = phong_lobes(s, max(dot(c.n, c.to_viewer), 0.0));
    results[4u * id.x] = vec4<f32>(eval_brdf(s, c.n, c.to_light, c.to_viewer), 0.0);
    results[4u * id.x + 1u] = vec4<f32>(lobes.diffuse, lobes.exponent);
    results[4u * id.x + 2u] = vec4<f32>(lobes.glossy, 0.0);
    results[4u * id.x + 3u] = vec4<f32>(eval_diffuse(s, c.n, c.to_light, c.to_viewer), 0.0);
}
