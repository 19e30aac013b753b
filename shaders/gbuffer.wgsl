// G-buffer: rasterises the scene from the camera into world position, normal + glossy
// exponent, diffuse albedo, glossy colour, emission and the id that finds the pixel's light
// caches. The fragment entry point comes from gbuffer_triangle_ids.wgsl (scene-wide triangle
// ids, needs the primitive_index extension) or gbuffer_vertex_ids.wgsl (provoking vertex).

@group(0) @binding(0) var<storage, read> camera: CameraUniform;

@vertex
fn vs_main(
    v: VertexInput,
    @builtin(vertex_index) vertex: u32,
    @builtin(instance_index) first_triangle: u32,
) -> SurfaceVaryings {
    return surface_varyings(v, vertex, first_triangle, camera.view_proj);
}

struct GBufferOut {
    @location(0) position: vec4<f32>,
    @location(1) normal_exponent: vec4<f32>,
    @location(2) diffuse: vec4<f32>,
    @location(3) glossy: vec4<f32>,
    @location(4) emissive: vec4<f32>,
    @location(5) id: u32,
}

fn write_gbuffer(in: SurfaceVaryings, front: bool, id: u32) -> GBufferOut {
    let m = sample_material(in.material, in.uv);
    if !m.covered {
        discard;
    }
    let n = facing_normal(in.normal, front);
    var out: GBufferOut;
    // w = 1 marks covered pixels; the clear value 0 marks background.
    out.position = vec4<f32>(in.world, 1.0);
    let k = select(m.brdf.exponent, camera.glossy_exponent, camera.glossy_exponent > 0.0);
    out.normal_exponent = vec4<f32>(n, k);
    out.diffuse = vec4<f32>(m.brdf.diffuse, 1.0);
    out.glossy = vec4<f32>(m.brdf.glossy, 1.0);
    // Emitters emit from the side their vertex normals face (scene/src/emitters.rs, the
    // reference's `surface_at`): seen from behind, a lamp quad is dark.
    let emits = dot(in.normal, camera.position - in.world) > 0.0;
    out.emissive = vec4<f32>(select(vec3<f32>(0.0), m.emissive, emits), 1.0);
    out.id = id;
    return out;
}
