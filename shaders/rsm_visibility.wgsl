// The thin RSM raster (issue 36): a visibility buffer, as the G-buffer's (gbuffer_visibility.wgsl):
// the scene-wide triangle id, and the base colour with the facing in alpha (1 front, 0.5 back,
// the clear value 0 marks empty texels). rsm_resolve.wgsl rebuilds the texel's targets from
// them. 12 bytes a texel leave the rasteriser instead of 56.

struct RsmVisibilityOut {
    @location(0) id: u32,
    @location(1) base_facing: vec4<f32>,
}

@fragment
fn fs_main(
    in: SurfaceVaryings,
    @builtin(front_facing) front: bool,
    @builtin(primitive_index) primitive: u32,
) -> RsmVisibilityOut {
    let m = sample_material(in.material, in.uv);
    if !m.covered || rsm_left_to_nearer_face(lights.list[face.light], face, in.world) {
        discard;
    }
    return RsmVisibilityOut(in.first_triangle + primitive, vec4<f32>(m.brdf.base, select(0.5, 1.0, front)));
}
