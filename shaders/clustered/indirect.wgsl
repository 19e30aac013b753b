// Indirect light from the VPLs (seed paper 003, §4 and §6 "Indirect Lighting"): the pixel at
// (x, y) is lit by the VPLs i ≡ (y mod B)·B + (x mod B) (mod B²) of interleaved sampling with
// B×B blocks, weighted by B² so that the geometry-aware blur's average over a block estimates
// the sum over all N. Visibility is off: every VPL sees every point (the paper's "without
// visibility" baseline).

@group(0) @binding(0) var<storage, read> params: ClusteredParams;
@group(0) @binding(1) var<storage, read> camera: CameraUniform;
@group(0) @binding(2) var g_position: texture_2d<f32>;
@group(0) @binding(3) var g_normal_exponent: texture_2d<f32>;
@group(0) @binding(4) var g_diffuse: texture_2d<f32>;
@group(0) @binding(5) var g_glossy: texture_2d<f32>;
@group(0) @binding(6) var<storage, read> vpls: array<Vpl>;
@group(0) @binding(7) var interleaved_out: texture_storage_2d<rgba32float, write>;

// L_i(x, ω_o) of §4: f_r·Φ_i·cosθ_i·cosθ_x / (π d²) for a diffusely emitting VPL, with the
// VPL's disk area A_i added to π d² — the irradiance of a disk of area A_i on its axis,
// Φ/(A + π d²) — which keeps the 1/d² singularity finite without a distance clamp in scene
// units.
fn vpl_radiance(vpl: Vpl, x: vec3<f32>, n: vec3<f32>, v: vec3<f32>, s: SurfaceBrdf) -> vec3<f32> {
    let to_vpl = vpl.position - x;
    let d2 = dot(to_vpl, to_vpl);
    if d2 <= 0.0 {
        return vec3<f32>(0.0);
    }
    let w = to_vpl * inverseSqrt(d2);
    let cos_x = max(dot(n, w), 0.0);
    let cos_i = max(dot(vpl.normal, -w), 0.0);
    return eval_brdf(s, n, w, v) * vpl.flux * (cos_i * cos_x / (vpl.area + PI * d2));
}

@compute @workgroup_size(8, 8)
fn shade(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let position = textureLoad(g_position, texel, 0);
    if position.w == 0.0 {
        textureStore(interleaved_out, texel, vec4<f32>(0.0));
        return;
    }
    let ne = textureLoad(g_normal_exponent, texel, 0);
    let x = position.xyz;
    let n = normalize(ne.xyz);
    let v = normalize(camera.position - x);
    let s = SurfaceBrdf(textureLoad(g_diffuse, texel, 0).rgb, textureLoad(g_glossy, texel, 0).rgb, ne.w);
    let b = params.interleave;
    let stride = b * b;
    var radiance = vec3<f32>(0.0);
    for (var i = (id.y % b) * b + id.x % b; i < params.vpl_count; i += stride) {
        let vpl = vpls[i];
        if vpl.lit != 0u {
            radiance += vpl_radiance(vpl, x, n, v, s);
        }
    }
    textureStore(interleaved_out, texel, vec4<f32>(radiance * f32(stride), 1.0));
}
