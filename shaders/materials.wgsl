// Scene materials, bound as group 1 by every pass that rasterises the scene with materials
// (one bind group per material: its base colour texture, a sampler and the material table),
// shaded by material_model.wgsl.

@group(1) @binding(0) var base_color_texture: texture_2d<f32>;
@group(1) @binding(1) var base_color_sampler: sampler;
@group(1) @binding(2) var<storage, read> materials: array<MaterialGpu>;
// `scene::brdf::BrdfTable`, for brdf_eval.wgsl (the RSM evaluates the BRDF).
@group(1) @binding(3) var<storage, read> brdf_table: array<vec4<f32>>;

fn sample_material(index: u32, uv: vec2<f32>) -> MaterialSample {
    // Untextured materials are bound to a 1×1 white texture, so sampling stays uniform.
    let texel = textureSample(base_color_texture, base_color_sampler, uv);
    return shade_material(materials[index], texel);
}

// Mirrors `scene::Vertex`.
struct VertexInput {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) material: u32,
}

// What the rasterising passes interpolate from a scene vertex.
struct SurfaceVaryings {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) @interpolate(flat) material: u32,
    // The provoking vertex (its light caches serve the triangle when triangle ids are not
    // available).
    @location(4) @interpolate(flat) vertex: u32,
    // Index of the draw's first triangle in the scene (passed as the instance index), so that
    // it plus the primitive index is the scene-wide triangle id.
    @location(5) @interpolate(flat) first_triangle: u32,
}

fn surface_varyings(v: VertexInput, vertex: u32, first_triangle: u32, view_proj: mat4x4<f32>) -> SurfaceVaryings {
    return SurfaceVaryings(view_proj * vec4<f32>(v.position, 1.0), v.position, v.normal, v.uv, v.material, vertex, first_triangle);
}

