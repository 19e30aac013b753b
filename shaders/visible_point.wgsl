// A visibility buffer's texel back to the surface point it shows (issue 36): the resolves of
// the G-buffer (gbuffer_resolve.wgsl) and of the RSM (rsm_resolve.wgsl) use it. The including
// shader binds the scene's triangle list `indices` and vertices `vertices` (`scene::Vertex`,
// 9 words: position, normal, uv, material).

const VERTEX_WORDS: u32 = 9u;

fn vertex_vec3(i: u32, offset: u32) -> vec3<f32> {
    let b = i * VERTEX_WORDS + offset;
    return vec3<f32>(vertices[b], vertices[b + 1u], vertices[b + 2u]);
}

struct VisiblePoint {
    world: vec3<f32>,
    // Interpolated vertex normal (not normalised, not flipped for back faces).
    normal: vec3<f32>,
    // The triangle's material (the provoking vertex's, as flat varyings take it).
    material: u32,
}

// Triangle `t` at the centre of the texel whose normalised device coordinates are `ndc`, as
// drawn with `view_proj`: the rasteriser's perspective-correct interpolation there. A point
// Σ b_k·p_k of the triangle lies at clip position Σ b_k·c_k, so the centre's (x, y, 1) is
// proportional to M·b with M's columns (c_k.x, c_k.y, c_k.w), and b to adj(M)·(x, y, 1). No
// division by w: vertices behind the eye (a triangle cut by the near plane) need no care, and
// an orthographic projection (w = 1) is the same formula.
fn visible_point(t: u32, ndc: vec2<f32>, view_proj: mat4x4<f32>) -> VisiblePoint {
    let i = vec3<u32>(indices[3u * t], indices[3u * t + 1u], indices[3u * t + 2u]);
    let p = array<vec3<f32>, 3>(vertex_vec3(i.x, 0u), vertex_vec3(i.y, 0u), vertex_vec3(i.z, 0u));
    let q = vec3<f32>(ndc, 1.0);
    let c0 = (view_proj * vec4<f32>(p[0], 1.0)).xyw;
    let c1 = (view_proj * vec4<f32>(p[1], 1.0)).xyw;
    let c2 = (view_proj * vec4<f32>(p[2], 1.0)).xyw;
    let raw = vec3<f32>(dot(q, cross(c1, c2)), dot(q, cross(c2, c0)), dot(q, cross(c0, c1)));
    let sum = raw.x + raw.y + raw.z;
    // A triangle seen edge-on (no area on screen, yet drawn under a texel centre) takes its
    // centroid; the centre lies in the triangle up to rounding, so weights are kept in it.
    var w = vec3<f32>(1.0 / 3.0);
    if sum != 0.0 {
        w = max(raw / sum, vec3<f32>(0.0));
        w /= w.x + w.y + w.z;
    }
    return VisiblePoint(
        w.x * p[0] + w.y * p[1] + w.z * p[2],
        w.x * vertex_vec3(i.x, 3u) + w.y * vertex_vec3(i.y, 3u) + w.z * vertex_vec3(i.z, 3u),
        bitcast<u32>(vertices[i.x * VERTEX_WORDS + 8u]),
    );
}

// The shading normal of `point` as the raster's `facing_normal` makes it, the facing read from
// the visibility buffer's base-colour texel (visibility_out.wgsl: alpha 1 front, 0.5 back).
fn visible_normal(point: VisiblePoint, base_facing: vec4<f32>) -> vec3<f32> {
    return facing_normal(point.normal, base_facing.a > 0.75);
}

// Normalised device coordinates of texel `texel`'s centre in a viewport of `size` texels.
fn texel_ndc(texel: vec2<u32>, size: vec2<u32>) -> vec2<f32> {
    return vec2<f32>(
        (f32(texel.x) + 0.5) / f32(size.x) * 2.0 - 1.0,
        1.0 - (f32(texel.y) + 0.5) / f32(size.y) * 2.0,
    );
}
