// Paraboloid maps around a VAL's (or a VPL's) normal and the convolution soft shadow maps
// built from them (seed paper 003, §4.1–4.2): the projection, the atlas that holds one map
// per light, the Fourier basis of the depth test and its reconstruction. Shared by the map,
// basis and shading passes; mirrored by server/gi/src/clustered/cpu.rs.

const VISIBILITY_OFF: u32 = 0u;
const VISIBILITY_CSSM: u32 = 1u;
const VISIBILITY_VPL_SHADOWS: u32 = 2u;

// K is at most 4 (the paper's choice), so the basis fits five RGBA bands: cos/sin of terms
// 0–1 and 2–3, the same times z, and z alone (for the blocker average's constant term).
const FOURIER_MAX_TERMS: u32 = 4u;
const CSSM_BANDS: u32 = 5u;

// A VPL or a VAL as the maps see it: `Vpl` and `Val` share these first 32 bytes and their
// 48-byte stride (checked by a layout test), so the same passes take either buffer.
struct MapCentre {
    position: vec3<f32>,
    area: f32,
    normal: vec3<f32>,
    // Non-zero for a lit VPL or a VAL with VPLs; a map of an unused centre stays empty.
    used: u32,
    rest: vec4<u32>,
}

// Maps look out from a thousandth of the extent above their light's surface: a VPL lies on
// its surface (from the RSM, within rounding either side), where that surface and the walls
// meeting it in a corner would fill the map with depth 0.
const MAP_LIFT: f32 = 1e-3;

fn map_origin(p: ClusteredParams, c: MapCentre) -> vec3<f32> {
    return c.position + c.normal * (MAP_LIFT * p.extent);
}

// Columns tangent, bitangent, n.
fn paraboloid_frame(n: vec3<f32>) -> mat3x3<f32> {
    let t = tangent_basis(n);
    return mat3x3<f32>(t[0], t[1], n);
}

// A unit direction in the frame's coordinates to the map's plane: the hemisphere around the
// normal lands in the unit disc, and directions down to 109° from it in the square's corners.
fn paraboloid_uv(local: vec3<f32>) -> vec2<f32> {
    return local.xy / (1.0 + local.z);
}

// The inverse of `paraboloid_uv`.
fn paraboloid_direction(uv: vec2<f32>) -> vec3<f32> {
    let r2 = dot(uv, uv);
    return vec3<f32>(2.0 * uv, 1.0 - r2) / (1.0 + r2);
}

// Top-left texel of light j's map in the atlas.
fn tile_origin(p: ClusteredParams, j: u32) -> vec2<f32> {
    return vec2<f32>(f32(j % p.atlas_columns), f32(j / p.atlas_columns)) * f32(p.map_size);
}

// The atlas position (in level-0 texels) of map coordinates uv ∈ [-1, 1]² of light j.
fn atlas_position(p: ClusteredParams, j: u32, uv: vec2<f32>) -> vec2<f32> {
    return tile_origin(p, j) + (uv * 0.5 + 0.5) * f32(p.map_size);
}

// c_k = π(2k + 1): the odd harmonics of the square wave of period 2 in z − d (§4.1).
fn fourier_c(k: u32) -> f32 {
    return PI * f32(2u * k + 1u);
}

// Band b of the basis of depth z: (cos c_k z, sin c_k z) pairs for k = 2(b mod 2) and the
// next term, times z in bands 2–3, and z in band 4.
fn cssm_basis(z: f32, band: u32) -> vec4<f32> {
    if band == 4u {
        return vec4<f32>(z, 0.0, 0.0, 0.0);
    }
    let k = (band % 2u) * 2u;
    let a = fourier_c(k) * z;
    let b = fourier_c(k + 1u) * z;
    let v = vec4<f32>(cos(a), sin(a), cos(b), sin(b));
    return select(v, v * z, band >= 2u);
}

// 2 Σ_k (1/c_k)(cos(c_k d)·E[sin c_k z] − sin(c_k d)·E[cos c_k z]) over the first `terms`
// terms, E[·] being the filtered bands `lo` (terms 0–1) and `hi` (terms 2–3): the oscillating
// part of the step H(z − d) ≈ 1/2 + 2 Σ sin(c_k (z − d))/c_k, convolved with the filter.
fn fourier_sum(lo: vec4<f32>, hi: vec4<f32>, d: f32, terms: u32) -> f32 {
    var sum = 0.0;
    for (var k = 0u; k < terms; k++) {
        let e = select(hi, lo, k < 2u);
        let i = (k % 2u) * 2u;
        let c = fourier_c(k);
        sum += 2.0 / c * (cos(c * d) * e[i + 1u] - sin(c * d) * e[i]);
    }
    return sum;
}

// The depth offset of the test for K terms: a quarter of the truncated step's rise (about
// 1/K), so that a receiver at its own depth reads as lit.
fn cssm_offset(terms: u32) -> f32 {
    return 0.25 / f32(terms);
}

// The filtered step made twice as steep around 1/2 and clamped: halves the penumbra the
// truncated series adds to every shadow and removes its ringing (our choice; the series
// alone overshoots by 9 % and needs 1/K of depth to fall from lit to shadowed).
fn cssm_sharpen(step: f32) -> f32 {
    return clamp(2.0 * step - 0.5, 0.0, 1.0);
}
