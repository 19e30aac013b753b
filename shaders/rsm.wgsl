// The fat RSM raster: every target of a texel (rsm_texel.wgsl) from the fragment's varyings.

struct RsmOut {
    @location(0) position: vec4<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) flux_area: vec4<f32>,
    @location(3) glossy: vec4<u32>,
}

@fragment
fn fs_main(in: SurfaceVaryings, @builtin(front_facing) front: bool) -> RsmOut {
    let m = sample_material(in.material, in.uv);
    let light = lights.list[face.light];
    if !m.covered || rsm_left_to_nearer_face(light, face, in.world) {
        discard;
    }
    let t = rsm_texel(face, light, in.world, facing_normal(in.normal, front), m.brdf);
    return RsmOut(t.position, t.normal, t.flux_area, t.glossy);
}
