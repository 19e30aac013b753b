// The G-buffer's vertex stage and camera (gbuffer.wgsl writes every target from the raster;
// gbuffer_visibility.wgsl only the triangle id and base colour, gbuffer_resolve.wgsl the rest).

@group(0) @binding(0) var<storage, read> camera: CameraUniform;

@vertex
fn vs_main(
    v: VertexInput,
    @builtin(vertex_index) vertex: u32,
    @builtin(instance_index) first_triangle: u32,
) -> SurfaceVaryings {
    return surface_varyings(v, vertex, first_triangle, camera.view_proj);
}
