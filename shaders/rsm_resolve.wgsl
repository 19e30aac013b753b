// Resolves the RSM's visibility buffer (rsm_visibility.wgsl) into its targets, one thread per
// atlas texel: the texel's face projects its triangle as the rasteriser did, which gives the
// surface point at the texel's centre (visible_point.wgsl), lit as rsm.wgsl lights a fragment
// (rsm_texel.wgsl). Empty texels, those beyond the lights' faces among them (the raster drew
// none there; the emitter face is copied in afterwards), are cleared, as the fat raster's
// clear leaves them.

// The atlas's faces in order (a face is a square of the atlas's height).
@group(0) @binding(0) var<storage, read> faces: array<RsmFace>;
@group(0) @binding(1) var<storage, read> lights: Lights;
@group(0) @binding(2) var vis_id: texture_2d<u32>;
@group(0) @binding(3) var vis_base: texture_2d<f32>;
// The scene's triangle list and vertices (visible_point.wgsl).
@group(0) @binding(4) var<storage, read> indices: array<u32>;
@group(0) @binding(5) var<storage, read> vertices: array<f32>;
@group(0) @binding(6) var<storage, read> materials: array<MaterialGpu>;
@group(0) @binding(7) var out_position: texture_storage_2d<rgba32float, write>;
@group(0) @binding(8) var out_normal: texture_storage_2d<rgba16float, write>;
@group(0) @binding(9) var out_flux_area: texture_storage_2d<rgba32float, write>;
@group(0) @binding(10) var out_glossy: texture_storage_2d<rgba32uint, write>;
// `scene::brdf::BrdfTable` (brdf_eval.wgsl).
@group(0) @binding(11) var<storage, read> brdf_table: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn resolve(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(vis_id);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let base = textureLoad(vis_base, texel, 0);
    if base.a == 0.0 {
        textureStore(out_position, texel, vec4<f32>(0.0));
        textureStore(out_normal, texel, vec4<f32>(0.0));
        textureStore(out_flux_area, texel, vec4<f32>(0.0));
        textureStore(out_glossy, texel, vec4<u32>(0u));
        return;
    }
    let side = size.y;
    let face = faces[id.x / side];
    let local = vec2<u32>(id.x % side, id.y);
    let t = textureLoad(vis_id, texel, 0).x;
    let point = visible_point(t, texel_ndc(local, vec2<u32>(side)), face.view_proj);
    let m = materials[point.material];
    let brdf = surface_brdf(base.rgb, m.metallic, m.roughness, m.specular);
    let n = visible_normal(point, base);
    let out = rsm_texel(face, lights.list[face.light], point.world, n, brdf);
    textureStore(out_position, texel, out.position);
    textureStore(out_normal, texel, out.normal);
    textureStore(out_flux_area, texel, out.flux_area);
    textureStore(out_glossy, texel, out.glossy);
}
