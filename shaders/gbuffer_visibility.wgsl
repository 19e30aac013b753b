// The thin G-buffer raster (issue 36): a visibility buffer. The fragment writes the scene-wide
// triangle id and what a compute pass cannot read back from the scene's buffers alone: the
// base colour (the material's factor times its texture, sampled here where each material has
// its bind group and the rasteriser its derivatives), with the facing in alpha (1 front, 0.5
// back; the clear value 0 marks background). gbuffer_resolve.wgsl rebuilds the position,
// normal and material terms; the targets it fills are the fat G-buffer's (gbuffer.wgsl), so
// every later pass reads what it read before. 12 bytes a pixel leave the rasteriser instead
// of 44.

struct VisibilityOut {
    @location(0) id: u32,
    @location(1) base_facing: vec4<f32>,
}

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
    return VisibilityOut(in.first_triangle + primitive, vec4<f32>(m.brdf.base, select(0.5, 1.0, front)));
}
