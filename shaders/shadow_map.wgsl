// Depth of the scene from one light face (dynamic offset selects the face). Opaque materials
// are drawn depth-only; alpha-masked ones (glTF MASK) take a second pipeline whose fragment
// stage discards the texels their mask cuts away, as the G-buffer, the RSM and the reference
// do, so light passes through the holes of a masked leaf or fence.

@group(0) @binding(0) var<storage, read> face_view_proj: mat4x4<f32>;

@vertex
fn vs_main(@location(0) position: vec3<f32>) -> @builtin(position) vec4<f32> {
    return face_view_proj * vec4<f32>(position, 1.0);
}

@vertex
fn vs_masked(
    v: VertexInput,
    @builtin(vertex_index) vertex: u32,
    @builtin(instance_index) first_triangle: u32,
) -> SurfaceVaryings {
    return surface_varyings(v, vertex, first_triangle, face_view_proj);
}

@fragment
fn fs_masked(in: SurfaceVaryings) {
    if !sample_material(in.material, in.uv).covered {
        discard;
    }
}
