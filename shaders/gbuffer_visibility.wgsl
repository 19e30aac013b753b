// The thin G-buffer raster (issue 36): a visibility buffer (visibility_out.wgsl).
// gbuffer_resolve.wgsl rebuilds the position, normal and material terms; the targets it fills
// are the fat G-buffer's (gbuffer.wgsl), so every later pass reads what it read before. 12
// bytes a pixel leave the rasteriser instead of 44.

@fragment
fn fs_main(
    in: SurfaceVaryings,
    @builtin(front_facing) front: bool,
    @builtin(primitive_index) primitive: u32,
) -> VisibilityOut {
    let m = sample_material(in.material, in.uv);
    if !m.covered {
        discard;
    }
    return visibility_out(in, m, front, primitive);
}
