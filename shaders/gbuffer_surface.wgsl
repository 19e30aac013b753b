// The G-buffer's material at a pixel as the BRDF's parameters (gbuffer.wgsl writes them). The
// including shader binds the G-buffer's `g_normal_roughness`, `g_base_metallic` and
// `g_emissive_specular`.

fn gbuffer_brdf(texel: vec2<i32>) -> SurfaceBrdf {
    let base_metallic = textureLoad(g_base_metallic, texel, 0);
    return SurfaceBrdf(
        base_metallic.rgb,
        base_metallic.a,
        textureLoad(g_normal_roughness, texel, 0).w,
        textureLoad(g_emissive_specular, texel, 0).a,
    );
}
