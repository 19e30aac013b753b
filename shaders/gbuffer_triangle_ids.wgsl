// G-buffer fragment stage with scene-wide triangle ids (the indirect pass then blends the
// light caches of all three vertices).

@fragment
fn fs_main(
    in: SurfaceVaryings,
    @builtin(front_facing) front: bool,
    @builtin(primitive_index) primitive: u32,
) -> GBufferOut {
    return write_gbuffer(in, front, in.first_triangle + primitive);
}
