// Indirect light from the VPLs (seed paper 003, §4 and §6 "Indirect Lighting"): the pixel at
// (x, y) is lit by the VPLs of its interleave class c = (y mod B)·B + (x mod B), the run
// c·N/B² ≤ i < (c+1)·N/B² of the Halton-ordered VPLs, weighted by N over the run's length so
// that the geometry-aware blur's average over a B×B block estimates the sum over all N. A run
// of consecutive Halton points covers the whole RSM; the residue class i ≡ c (mod B²) that
// this shader used before does not (those indices share their low bits, so their points
// shared one narrow strip of the RSM) and each class lit the scene from a different strip:
// a B-pixel pattern the blur could not hide (issue 31). Mirrors `cpu::class_vpls`. Each VPL's
// light is weighted by its visibility (clustered/visibility.wgsl).

@group(0) @binding(0) var<storage, read> params: ClusteredParams;
@group(0) @binding(1) var<storage, read> camera: CameraUniform;
@group(0) @binding(2) var g_position: texture_2d<f32>;
@group(0) @binding(3) var g_normal_roughness: texture_2d<f32>;
@group(0) @binding(4) var g_base_metallic: texture_2d<f32>;
@group(0) @binding(5) var g_emissive_specular: texture_2d<f32>;
@group(0) @binding(6) var<storage, read> vpls: array<Vpl>;
@group(0) @binding(7) var interleaved_out: texture_storage_2d<rgba32float, write>;
// Bindings 8–12 are visibility.wgsl's.
@group(0) @binding(13) var<storage, read> brdf_table: array<vec4<f32>>;
@group(0) @binding(14) var<storage, read> vpl_glossy: array<GlossySender>;

// L_i(x, ω_o) of §4 (vpl_light.wgsl).
fn vpl_radiance(i: u32, vpl: Vpl, x: vec3<f32>, s: ViewedBrdf) -> vec3<f32> {
    return vpl_light(vpl.position, vpl.normal, vpl.flux, vpl_glossy[i], vpl.area, vpl.area, x, s);
}

// The surface pixel `id` sees: its point and unit normal; `covered` false where no geometry
// is (the pixel's output is then cleared).
struct Receiver {
    x: vec3<f32>,
    n: vec3<f32>,
    covered: bool,
}

fn receiver(texel: vec2<i32>) -> Receiver {
    let position = textureLoad(g_position, texel, 0);
    let n = normalize(textureLoad(g_normal_roughness, texel, 0).xyz);
    return Receiver(position.xyz, n, position.w != 0.0);
}

@compute @workgroup_size(8, 8)
fn shade(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let r = receiver(texel);
    if !r.covered {
        textureStore(interleaved_out, texel, vec4<f32>(0.0));
        return;
    }
    let v = normalize(camera.position - r.x);
    let s = view_brdf(gbuffer_brdf(texel), r.n, v);
    let b = params.interleave;
    let classes = b * b;
    let own_class = (id.y % b) * b + id.x % b;
    // N ≥ 256 ≥ B² (the parameters' ranges): every run holds at least one VPL.
    let first = own_class * params.vpl_count / classes;
    let end = (own_class + 1u) * params.vpl_count / classes;
    var radiance = vec3<f32>(0.0);
    for (var i = first; i < end; i++) {
        let vpl = vpls[i];
        if vpl.lit != 0u {
            let l = vpl_radiance(i, vpl, r.x, s);
            if any(l > vec3<f32>(0.0)) {
                radiance += l * vpl_visibility(i, r.x, r.n);
            }
        }
    }
    textureStore(interleaved_out, texel, vec4<f32>(radiance * (f32(params.vpl_count) / f32(end - first)), 1.0));
}

// The `val-shadow` debug view: the visibility of light `shadow_light` (a VAL, or a VPL with
// per-VPL shadows) at every pixel's surface; alpha 0 where no geometry is, 0.5 where the
// light and the surface face away from each other.
@compute @workgroup_size(8, 8)
fn light_shadow(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let r = receiver(texel);
    let j = params.shadow_light;
    let to_light = map_origin(params, centres[j]) - r.x;
    if !r.covered {
        textureStore(interleaved_out, texel, vec4<f32>(0.0));
        return;
    }
    // Where the light and the surface do not face each other the light sends nothing, and
    // its visibility does not matter.
    if dot(r.n, to_light) <= 0.0 || dot(centres[j].normal, to_light) >= 0.0 {
        textureStore(interleaved_out, texel, vec4<f32>(0.0, 0.0, 0.0, 0.5));
        return;
    }
    var v = 1.0;
    switch params.visibility {
        case VISIBILITY_CSSM: {
            v = cssm_visibility(j, r.x, r.n);
        }
        case VISIBILITY_VPL_SHADOWS: {
            v = hard_visibility(j, r.x, r.n);
        }
        default: {}
    }
    textureStore(interleaved_out, texel, vec4<f32>(v, v, v, 1.0));
}
