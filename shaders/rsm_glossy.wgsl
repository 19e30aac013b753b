// The glossy part of what a reflective-shadow-map texel sends on, beyond the seed papers: their
// VALs and VPLs reflect diffusely (seed 004 eq. 3, seed 003 §4), so the sun's reflection off a
// glass façade onto the street (a quarter of the street's indirect light, issue 34) is lost.
// A texel keeps the paper's own glossy lobe (seed 004 eq. 4, the Phong lobe fitted to the
// BRDF: `phong_lobes`) about the mirror direction of the light it receives, and sends
//     I(ω) = (Φ_d/π + ρ_g·(k+2)/2π·max(r·ω, 0)^k·Φ_in)·cosθ_ω
// into direction ω: Φ_d the diffuse flux of `flux_area`, ρ_g the lobe's colour at the incident
// cosine, Φ_in the flux arriving at the texel. Mirrored by `GlossySender` in
// server/passes/src/passes/rsm.rs.

struct GlossySender {
    // ρ_g·Φ_in; zero where the texel sends nothing glossy (`senders: diffuse`, emitters).
    weight: vec3<f32>,
    // Phong exponent k (at least 1).
    exponent: f32,
    // Unit mirror direction r of the light the texel receives.
    mirror: vec3<f32>,
    pad0: f32,
}

// A light without a glossy lobe.
fn no_glossy() -> GlossySender {
    return GlossySender(vec3<f32>(0.0), 1.0, vec3<f32>(0.0, 0.0, 1.0), 0.0);
}

// The texel layout (an Rgba32Uint target): the weight's f32 bits in xyz; in w the mirror
// direction in octahedral coordinates (11 bits each: 0.1° at worst, a tenth of the narrowest
// lobe's width at k = 4,096) and log2 k over [0, 12] in 10 bits (k within 0.4 %).
const GLOSSY_OCT_BITS: u32 = 11u;
const GLOSSY_EXPONENT_BITS: u32 = 10u;
const GLOSSY_MAX_LOG2_EXPONENT: f32 = 12.0;

fn quantize(x: f32, bits: u32) -> u32 {
    let top = f32((1u << bits) - 1u);
    return u32(round(clamp(x, 0.0, 1.0) * top));
}

fn dequantize(q: u32, bits: u32) -> f32 {
    return f32(q & ((1u << bits) - 1u)) / f32((1u << bits) - 1u);
}

fn encode_glossy(weight: vec3<f32>, mirror: vec3<f32>, exponent: f32) -> vec4<u32> {
    let oct = octahedral_encode(mirror) * 0.5 + vec2<f32>(0.5);
    let k = log2(max(exponent, 1.0)) / GLOSSY_MAX_LOG2_EXPONENT;
    let packed = quantize(oct.x, GLOSSY_OCT_BITS)
        | (quantize(oct.y, GLOSSY_OCT_BITS) << GLOSSY_OCT_BITS)
        | (quantize(k, GLOSSY_EXPONENT_BITS) << (2u * GLOSSY_OCT_BITS));
    return vec4<u32>(bitcast<vec3<u32>>(max(weight, vec3<f32>(0.0))), packed);
}

fn decode_glossy(texel: vec4<u32>) -> GlossySender {
    let oct = vec2<f32>(
        dequantize(texel.w, GLOSSY_OCT_BITS),
        dequantize(texel.w >> GLOSSY_OCT_BITS, GLOSSY_OCT_BITS),
    );
    let k = exp2(dequantize(texel.w >> (2u * GLOSSY_OCT_BITS), GLOSSY_EXPONENT_BITS) * GLOSSY_MAX_LOG2_EXPONENT);
    return GlossySender(bitcast<vec3<f32>>(texel.xyz), k, octahedral_decode(oct * 2.0 - vec2<f32>(1.0)), 0.0);
}

// The flux a light (VAL, VPL) with diffuse flux `flux` sends towards unit `toward`, in the
// units of a diffuse flux (its intensity is this times cosθ/π): Φ_d + ρ_g·(k'+2)/2·max(r·ω, 0)^k'·Φ_in.
// A light standing for texels over an area A, seen from distance d, sends their lobes from
// points up to √(A/π) apart: its lobe is theirs widened by the disk's angular size. With
// cos^k α ≈ exp(−kα²/2) the lobe's variance per axis is 1/k, and a disk of angular radius
// ρ = √(A/π)/d adds ρ²/4 = A/(4π d²) (`spread`): k' = 1/(1/k + spread). Without it a VPL
// standing for a thousand texels of glass throws their whole flux into a lobe of one texel's
// width: a few bright spots instead of the reflection's wide patch.
fn sent_flux(flux: vec3<f32>, g: GlossySender, toward: vec3<f32>, spread: f32) -> vec3<f32> {
    let c = dot(g.mirror, toward);
    if c <= 0.0 {
        return flux;
    }
    let k = g.exponent / (1.0 + g.exponent * spread);
    return flux + g.weight * (0.5 * (k + 2.0) * pow(c, k));
}

// 1/4π (this file is also part of modules without common.wgsl's PI).
const GLOSSY_INV_4PI: f32 = 0.0795774715459477;

// `spread` for a light standing for area `area` at squared distance `d2`.
fn glossy_spread(area: f32, d2: f32) -> f32 {
    return GLOSSY_INV_4PI * area / d2;
}
