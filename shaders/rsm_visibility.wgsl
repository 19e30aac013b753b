// The thin RSM raster (issue 36): a visibility buffer (visibility_out.wgsl), with the fat
// raster's discards (rsm.wgsl). rsm_resolve.wgsl rebuilds the texel's targets from it. 12
// bytes a texel leave the rasteriser instead of 56.

@fragment
fn fs_main(
    in: SurfaceVaryings,
    @builtin(front_facing) front: bool,
    @builtin(primitive_index) primitive: u32,
) -> VisibilityOut {
    let m = sample_material(in.material, in.uv);
    if !m.covered || rsm_left_to_nearer_face(lights.list[face.light], face, in.world) {
        discard;
    }
    return visibility_out(in, m, front, primitive);
}
