// Light from one virtual point light (a reflective-shadow-map texel: Dachsbacher & Stamminger
// 2005; seed paper 003, §4), shared by the VPL methods. Mirrored by
// `gi::common::vpl::vpl_light`.

// L(x, ω_o) from a VPL at `position` with unit `normal`, diffuse flux Φ, glossy lobe `glossy`
// (rsm_glossy.wgsl) and disk area A: f_r·Φ(ω)·cosθ_i·cosθ_x / (π d²), Φ(ω) the flux it sends
// towards x (Φ itself for a diffuse VPL) with its lobe widened by the `footprint` area it
// stands for, and A added to π d² — the irradiance of a disk of area A on its axis,
// Φ/(A + π d²) — which keeps the 1/d² singularity finite without a distance clamp in scene
// units.
fn vpl_light(
    position: vec3<f32>,
    normal: vec3<f32>,
    flux: vec3<f32>,
    glossy: GlossySender,
    area: f32,
    footprint: f32,
    x: vec3<f32>,
    s: ViewedBrdf,
) -> vec3<f32> {
    let to_vpl = position - x;
    let d2 = dot(to_vpl, to_vpl);
    if d2 <= 0.0 {
        return vec3<f32>(0.0);
    }
    let w = to_vpl * inverseSqrt(d2);
    let cos_x = max(dot(s.n, w), 0.0);
    let cos_i = max(dot(normal, -w), 0.0);
    return eval_viewed(s, w) * sent_flux(flux, glossy, -w, glossy_spread(footprint, d2)) * (cos_i * cos_x / (area + PI * d2));
}
