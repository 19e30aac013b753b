// Resolves the visibility buffer (gbuffer_visibility.wgsl) into the G-buffer's targets, one
// thread per pixel: the pixel's triangle, projected as the rasteriser projected it, gives the
// surface point at the pixel's centre (visible_point.wgsl); the material terms come from the
// material table (write_gbuffer in gbuffer.wgsl does the same
// from varyings).

@group(0) @binding(0) var<storage, read> camera: CameraUniform;
@group(0) @binding(1) var vis_id: texture_2d<u32>;
@group(0) @binding(2) var vis_base: texture_2d<f32>;
// The scene's triangle list and vertices (visible_point.wgsl).
@group(0) @binding(3) var<storage, read> indices: array<u32>;
@group(0) @binding(4) var<storage, read> vertices: array<f32>;
@group(0) @binding(5) var<storage, read> materials: array<MaterialGpu>;
@group(0) @binding(6) var out_position: texture_storage_2d<rgba32float, write>;
@group(0) @binding(7) var out_normal_roughness: texture_storage_2d<rgba16float, write>;
@group(0) @binding(8) var out_base_metallic: texture_storage_2d<rgba16float, write>;
@group(0) @binding(9) var out_emissive_specular: texture_storage_2d<rgba16float, write>;

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
        textureStore(out_normal_roughness, texel, vec4<f32>(0.0));
        textureStore(out_base_metallic, texel, vec4<f32>(0.0));
        textureStore(out_emissive_specular, texel, vec4<f32>(0.0));
        return;
    }
    let t = textureLoad(vis_id, texel, 0).x;
    let point = visible_point(t, texel_ndc(id.xy, size), camera.view_proj);
    let world = point.world;
    let normal = point.normal;
    let m = materials[point.material];
    let brdf = surface_brdf(base.rgb, m.metallic, m.roughness, m.specular);
    let roughness = select(brdf.roughness, camera.roughness, camera.roughness > 0.0);
    let n = visible_normal(point, base);
    // Emitters emit from the side their vertex normals face, as in write_gbuffer.
    let emits = dot(normal, camera.position - world) > 0.0;
    textureStore(out_position, texel, vec4<f32>(world, 1.0));
    textureStore(out_normal_roughness, texel, vec4<f32>(n, roughness));
    textureStore(out_base_metallic, texel, vec4<f32>(brdf.base, brdf.metallic));
    textureStore(out_emissive_specular, texel, vec4<f32>(select(vec3<f32>(0.0), m.emissive, emits), brdf.specular));
}
