// G-buffer: rasterises the scene from the camera into world position, normal + roughness,
// base colour + metallic, emission + specular weight (the material's factors, which every
// pass turns into the BRDF with gbuffer_surface.wgsl) and the id that finds the pixel's light
// caches. The fragment entry point comes from gbuffer_triangle_ids.wgsl (scene-wide triangle
// ids, needs the primitive_index extension) or gbuffer_vertex_ids.wgsl (provoking vertex).

struct GBufferOut {
    @location(0) position: vec4<f32>,
    @location(1) normal_roughness: vec4<f32>,
    @location(2) base_metallic: vec4<f32>,
    @location(3) emissive_specular: vec4<f32>,
    @location(4) id: u32,
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
    let roughness = select(m.brdf.roughness, camera.roughness, camera.roughness > 0.0);
    out.normal_roughness = vec4<f32>(n, roughness);
    out.base_metallic = vec4<f32>(m.brdf.base, m.brdf.metallic);
    // Emitters emit from the side their vertex normals face (scene/src/emitters.rs, the
    // reference's `surface_at`): seen from behind, a lamp quad is dark.
    let emits = dot(in.normal, camera.position - in.world) > 0.0;
    out.emissive_specular = vec4<f32>(select(vec3<f32>(0.0), m.emissive, emits), m.brdf.specular);
    out.id = id;
    return out;
}
