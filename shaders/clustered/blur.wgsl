// Geometry-aware blur (seed paper 003, §6, after Laine et al.): each pixel averages the
// interleaved shading of the B×B block around it — one pixel of every interleave class — over
// the neighbours whose surface point lies within `blur_distance` of its own and whose normal
// is within `blur_normal` (cosine) of its own, so light does not bleed across edges.

@group(0) @binding(0) var<storage, read> params: ClusteredParams;
@group(0) @binding(1) var g_position: texture_2d<f32>;
@group(0) @binding(2) var g_normal_roughness: texture_2d<f32>;
@group(0) @binding(3) var interleaved: texture_2d<f32>;
@group(0) @binding(4) var indirect_out: texture_storage_2d<rgba16float, write>;

@compute @workgroup_size(8, 8)
fn blur(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let position = textureLoad(g_position, texel, 0);
    if position.w == 0.0 {
        textureStore(indirect_out, texel, vec4<f32>(0.0));
        return;
    }
    let n = normalize(textureLoad(g_normal_roughness, texel, 0).xyz);
    let b = i32(params.interleave);
    let first = texel - vec2<i32>(b / 2);
    let size = vec2<i32>(i32(params.width), i32(params.height));
    var sum = vec3<f32>(0.0);
    var count = 0.0;
    for (var dy = 0; dy < b; dy++) {
        for (var dx = 0; dx < b; dx++) {
            let q = first + vec2<i32>(dx, dy);
            if any(q < vec2<i32>(0)) || any(q >= size) {
                continue;
            }
            let pq = textureLoad(g_position, q, 0);
            let nq = normalize(textureLoad(g_normal_roughness, q, 0).xyz);
            let apart = pq.w == 0.0 || distance(pq.xyz, position.xyz) > params.blur_distance || dot(nq, n) < params.blur_normal;
            if apart && any(q != texel) {
                continue;
            }
            sum += textureLoad(interleaved, q, 0).rgb;
            count += 1.0;
        }
    }
    // The pixel itself always counts, so count ≥ 1.
    textureStore(indirect_out, texel, vec4<f32>(sum / count, 1.0));
}
