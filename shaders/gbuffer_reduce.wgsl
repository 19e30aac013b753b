// The G-buffer at 1/factor of the output's width and height, for GI methods that compute
// indirect light at a reduced resolution (`gi.indirect_downscale`). Every reduced pixel copies
// one full-resolution pixel of its factor×factor block, never an average: a blend of two
// surfaces at an edge would be a point on neither. The block's centre is preferred so the
// upsample knows where each sample sits; the first covered pixel stands in where the centre
// sees background.

// Mirrored by `ReduceParams` in server/passes/src/passes/indirect_resolution.rs.
struct ReduceParams {
    factor: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<storage, read> params: ReduceParams;
@group(0) @binding(1) var g_position: texture_2d<f32>;
@group(0) @binding(2) var g_normal_roughness: texture_2d<f32>;
@group(0) @binding(3) var g_base_metallic: texture_2d<f32>;
@group(0) @binding(4) var g_emissive_specular: texture_2d<f32>;
@group(0) @binding(5) var g_id: texture_2d<u32>;
@group(0) @binding(6) var out_position: texture_storage_2d<rgba32float, write>;
@group(0) @binding(7) var out_normal_roughness: texture_storage_2d<rgba16float, write>;
@group(0) @binding(8) var out_base_metallic: texture_storage_2d<rgba16float, write>;
@group(0) @binding(9) var out_emissive_specular: texture_storage_2d<rgba16float, write>;
@group(0) @binding(10) var out_id: texture_storage_2d<r32uint, write>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let reduced = textureDimensions(out_position);
    if id.x >= reduced.x || id.y >= reduced.y {
        return;
    }
    let full = vec2<i32>(textureDimensions(g_position));
    let f = i32(params.factor);
    let corner = vec2<i32>(id.xy) * f;
    var pick = min(corner + vec2<i32>(f / 2), full - vec2<i32>(1));
    if textureLoad(g_position, pick, 0).w == 0.0 {
        var found = false;
        for (var y = 0; y < f && !found; y++) {
            for (var x = 0; x < f && !found; x++) {
                let candidate = min(corner + vec2<i32>(x, y), full - vec2<i32>(1));
                if textureLoad(g_position, candidate, 0).w != 0.0 {
                    pick = candidate;
                    found = true;
                }
            }
        }
    }
    let texel = vec2<i32>(id.xy);
    textureStore(out_position, texel, textureLoad(g_position, pick, 0));
    textureStore(out_normal_roughness, texel, textureLoad(g_normal_roughness, pick, 0));
    textureStore(out_base_metallic, texel, textureLoad(g_base_metallic, pick, 0));
    textureStore(out_emissive_specular, texel, textureLoad(g_emissive_specular, pick, 0));
    textureStore(out_id, texel, textureLoad(g_id, pick, 0));
}
