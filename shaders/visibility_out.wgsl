// What a visibility-buffer raster writes (issue 36; gbuffer_visibility.wgsl, rsm_visibility.wgsl):
// the scene-wide triangle id, and what a compute pass cannot read back from the scene's buffers
// alone: the base colour (the material's factor times its texture, sampled where each material
// has its bind group and the rasteriser its derivatives), with the facing in alpha (1 front,
// 0.5 back; the clear value 0 marks empty texels). 12 bytes a texel.

struct VisibilityOut {
    @location(0) id: u32,
    @location(1) base_facing: vec4<f32>,
}

fn visibility_out(in: SurfaceVaryings, m: MaterialSample, front: bool, primitive: u32) -> VisibilityOut {
    return VisibilityOut(in.first_triangle + primitive, vec4<f32>(m.brdf.base, select(0.5, 1.0, front)));
}
