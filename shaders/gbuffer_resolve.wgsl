// Resolves the visibility buffer (gbuffer_visibility.wgsl) into the G-buffer's targets, one
// thread per pixel: the pixel's triangle, projected as the rasteriser projected it, gives the
// perspective-correct barycentrics of the pixel's centre, which interpolate the scene's
// vertex positions and normals as the rasteriser interpolates its varyings there; the
// material terms come from the material table (write_gbuffer in gbuffer.wgsl does the same
// from varyings).

@group(0) @binding(0) var<storage, read> camera: CameraUniform;
@group(0) @binding(1) var vis_id: texture_2d<u32>;
@group(0) @binding(2) var vis_base: texture_2d<f32>;
// The scene's triangle list and vertices (`scene::Vertex`, 9 words: position, normal, uv,
// material).
@group(0) @binding(3) var<storage, read> indices: array<u32>;
@group(0) @binding(4) var<storage, read> vertices: array<f32>;
@group(0) @binding(5) var<storage, read> materials: array<MaterialGpu>;
@group(0) @binding(6) var out_position: texture_storage_2d<rgba32float, write>;
@group(0) @binding(7) var out_normal_roughness: texture_storage_2d<rgba16float, write>;
@group(0) @binding(8) var out_base_metallic: texture_storage_2d<rgba16float, write>;
@group(0) @binding(9) var out_emissive_specular: texture_storage_2d<rgba16float, write>;

const VERTEX_WORDS: u32 = 9u;

fn vertex_vec3(i: u32, offset: u32) -> vec3<f32> {
    let b = i * VERTEX_WORDS + offset;
    return vec3<f32>(vertices[b], vertices[b + 1u], vertices[b + 2u]);
}

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
    let i = vec3<u32>(indices[3u * t], indices[3u * t + 1u], indices[3u * t + 2u]);
    let p = array<vec3<f32>, 3>(vertex_vec3(i.x, 0u), vertex_vec3(i.y, 0u), vertex_vec3(i.z, 0u));
    // The rasteriser's interpolation at the pixel's centre (perspective-correct): a point
    // Σ b_k·p_k of the triangle lies at clip position Σ b_k·c_k, so the centre's (x, y, 1) is
    // proportional to M·b with M's columns (c_k.x, c_k.y, c_k.w), and b to adj(M)·(x, y, 1).
    // No division by w: vertices behind the camera (a triangle cut by the near plane) need no
    // care.
    let q = vec3<f32>(
        (f32(id.x) + 0.5) / f32(size.x) * 2.0 - 1.0,
        1.0 - (f32(id.y) + 0.5) / f32(size.y) * 2.0,
        1.0,
    );
    let c0 = (camera.view_proj * vec4<f32>(p[0], 1.0)).xyw;
    let c1 = (camera.view_proj * vec4<f32>(p[1], 1.0)).xyw;
    let c2 = (camera.view_proj * vec4<f32>(p[2], 1.0)).xyw;
    let raw = vec3<f32>(dot(q, cross(c1, c2)), dot(q, cross(c2, c0)), dot(q, cross(c0, c1)));
    let sum = raw.x + raw.y + raw.z;
    // A triangle seen edge-on (no area on screen, yet drawn under a pixel centre) takes its
    // centroid; the centre lies in the triangle up to rounding, so weights are kept in it.
    var w = vec3<f32>(1.0 / 3.0);
    if sum != 0.0 {
        w = max(raw / sum, vec3<f32>(0.0));
        w /= w.x + w.y + w.z;
    }
    let world = w.x * p[0] + w.y * p[1] + w.z * p[2];
    let normal = w.x * vertex_vec3(i.x, 3u) + w.y * vertex_vec3(i.y, 3u) + w.z * vertex_vec3(i.z, 3u);
    // Flat varyings take the provoking (first) vertex's material, as the raster did.
    let m = materials[bitcast<u32>(vertices[i.x * VERTEX_WORDS + 8u])];
    let brdf = surface_brdf(base.rgb, m.metallic, m.roughness, m.specular);
    let roughness = select(brdf.roughness, camera.roughness, camera.roughness > 0.0);
    let n = facing_normal(normal, base.a > 0.75);
    // Emitters emit from the side their vertex normals face, as in write_gbuffer.
    let emits = dot(normal, camera.position - world) > 0.0;
    textureStore(out_position, texel, vec4<f32>(world, 1.0));
    textureStore(out_normal_roughness, texel, vec4<f32>(n, roughness));
    textureStore(out_base_metallic, texel, vec4<f32>(brdf.base, brdf.metallic));
    textureStore(out_emissive_specular, texel, vec4<f32>(select(vec3<f32>(0.0), m.emissive, emits), brdf.specular));
}
