// G-buffer fragment stage without the primitive_index extension: the provoking vertex's light
// caches serve the whole triangle.

@fragment
fn fs_main(in: SurfaceVaryings, @builtin(front_facing) front: bool) -> GBufferOut {
    return write_gbuffer(in, front, in.vertex);
}
