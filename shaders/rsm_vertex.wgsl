// The RSM's vertex stage, face and lights (rsm.wgsl rasterises every target; rsm_visibility.wgsl
// only the triangle id and base colour, which rsm_resolve.wgsl turns into the rest).

@group(0) @binding(0) var<storage, read> face: RsmFace;
@group(0) @binding(1) var<storage, read> lights: Lights;

@vertex
fn vs_main(
    v: VertexInput,
    @builtin(vertex_index) vertex: u32,
    @builtin(instance_index) first_triangle: u32,
) -> SurfaceVaryings {
    return surface_varyings(v, vertex, first_triangle, face.view_proj);
}
