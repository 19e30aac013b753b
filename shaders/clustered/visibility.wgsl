// The visibility of a VPL at a receiver (seed paper 003, §4): V_C(i)(x) of its VAL from the
// convolution soft shadow maps (§4.1–4.2), or V_i(x) from the VPL's own hard-shadow map.

@group(0) @binding(8) var<storage, read> centres: array<MapCentre>;
@group(0) @binding(9) var<storage, read> mapping: array<u32>;
@group(0) @binding(10) var depth_atlas: texture_depth_2d;
@group(0) @binding(11) var basis: texture_2d<f32>;
@group(0) @binding(12) var basis_sampler: sampler;

// Where a receiver falls in light j's map.
struct MapLookup {
    uv: vec2<f32>,
    // Its distance to the light over the scene's extent, less the slope bias.
    depth: f32,
    // Its distance over the extent.
    distance: f32,
    // tan θ of the angle between its normal and the direction to the light (at most 8).
    slope: f32,
    // False behind the map's reach (more than 109° from the normal), where the light sends
    // nothing anyway: visibility 1.
    inside: bool,
}

// The slope bias sized to the texel the receiver falls in: the paraboloid map is conformal,
// with dφ/du = 1 + cos φ at angle φ off its axis, so a texel (2/S of uv) spans
// τ = 2(1 + cos φ)/S radians, from 4/S at the centre to 1.3/S at the rim. The nearest texel's
// centre ray is at most τ/√2 away, where a receiver plane at angle θ from its normal lies
// d·tan θ·τ/√2 deeper: the bias takes d·τ·(tan θ + ½), √2 of margin on the slope term for
// curved surfaces and shading normals, and half a texel for the depth the map's rasteriser
// rounds (issue 34: the fixed d·(4/S)(1 + tan θ) ignored up to 56 % of the distance with
// 32² maps at grazing angles).
fn map_lookup(j: u32, x: vec3<f32>, n: vec3<f32>) -> MapLookup {
    var out: MapLookup;
    let centre = centres[j];
    let v = x - map_origin(params, centre);
    let d = length(v);
    out.inside = false;
    if d <= 1e-6 * params.extent {
        return out;
    }
    let w = v / d;
    let local = transpose(paraboloid_frame(centre.normal)) * w;
    if local.z < -1.0 / 3.0 {
        return out;
    }
    out.inside = true;
    out.uv = paraboloid_uv(local);
    out.distance = d / params.extent;
    let cos_r = max(abs(dot(n, w)), 1e-3);
    out.slope = min(sqrt(max(1.0 - cos_r * cos_r, 0.0)) / cos_r, 8.0);
    let texel_angle = 2.0 * (1.0 + local.z) / f32(params.map_size);
    out.depth = out.distance * (1.0 - texel_angle * (0.5 + out.slope));
    return out;
}

// V_i(x) of `vpl_shadows`: the nearest texel's depth against the receiver's.
fn hard_visibility(j: u32, x: vec3<f32>, n: vec3<f32>) -> f32 {
    let m = map_lookup(j, x, n);
    if !m.inside {
        return 1.0;
    }
    let origin = tile_origin(params, j);
    let last = origin + vec2<f32>(f32(params.map_size) - 1.0);
    let texel = clamp(floor(atlas_position(params, j, m.uv)), origin, last);
    return select(0.0, 1.0, m.depth <= textureLoad(depth_atlas, vec2<i32>(texel), 0));
}

// Basis band `band` of light j's map at uv, box-filtered over 2^lod texels (trilinear between
// levels), kept inside the map's tile at the coarser level.
fn sample_band(j: u32, uv: vec2<f32>, band: u32, lod: f32) -> vec4<f32> {
    let s = f32(params.map_size);
    let texel = exp2(ceil(lod));
    let origin = tile_origin(params, j);
    let p = clamp(atlas_position(params, j, uv), origin + 0.5 * texel, origin + s - 0.5 * texel);
    let height = f32(params.atlas_rows) * s;
    let size = vec2<f32>(f32(params.atlas_columns) * s, height * f32(CSSM_BANDS));
    return textureSampleLevel(basis, basis_sampler, (p + vec2<f32>(0.0, f32(band) * height)) / size, lod);
}

// The receiver-plane bias of a filter of level `lod`: across the kernel's half-width (π/S
// radians per texel, 2^lod texels) the receiver's own surface moves d·tan θ·angle in depth.
// Without it, a wide kernel on a slanted receiver counts the receiver's own surface nearer
// the light as blockers (on the Cornell box 30 VALs of 1,024 VPLs darkened the indirect
// light by 30 % where per-VPL shadows take 11 %).
fn kernel_bias(m: MapLookup, lod: f32) -> f32 {
    return m.distance * m.slope * 0.5 * PI * exp2(lod) / f32(params.map_size);
}

// The level whose texels span the angle `a` (radians): the paper's filter width a/π of the
// map (§4.2), in texels.
fn angle_lod(a: f32) -> f32 {
    let s = f32(params.map_size);
    return clamp(log2(max(s * a / PI, 1.0)), 0.0, log2(s));
}

// V_C(x) of VAL j (§4.1–4.2): the blocker search over the VAL's angular size seen from x,
// z_avg from the basis-z bands, the penumbra p·cos β = (d − z_avg)·Λ/z_avg (Fig. 3), its
// angle α = atan(p·cos β / d) as the filter, and the filtered step.
fn cssm_visibility(j: u32, x: vec3<f32>, n: vec3<f32>) -> f32 {
    let m = map_lookup(j, x, n);
    if !m.inside {
        return 1.0;
    }
    let terms = params.fourier_terms;
    let depth = m.depth - cssm_offset(terms);
    // Λ: the side of the VAL's bounding rectangle, over the extent.
    let side = sqrt(max(centres[j].area, 0.0)) / params.extent;
    let search = angle_lod(atan(side / m.distance));
    let d = depth - kernel_bias(m, search);
    let lit = 0.5 + fourier_sum(
        sample_band(j, m.uv, 0u, search),
        sample_band(j, m.uv, 1u, search),
        d,
        terms,
    );
    let blockers = 1.0 - lit;
    if blockers < 0.02 {
        return 1.0;
    }
    let blocker_depth_sum = 0.5 * sample_band(j, m.uv, 4u, search).x - fourier_sum(
        sample_band(j, m.uv, 2u, search),
        sample_band(j, m.uv, 3u, search),
        d,
        terms,
    );
    let z_avg = clamp(blocker_depth_sum / blockers, 1e-3 * m.distance, max(d, 1e-3 * m.distance));
    let penumbra = (d - z_avg) * side / z_avg;
    let lod = angle_lod(atan(penumbra / m.distance));
    return cssm_sharpen(0.5 + fourier_sum(
        sample_band(j, m.uv, 0u, lod),
        sample_band(j, m.uv, 1u, lod),
        depth - kernel_bias(m, lod),
        terms,
    ));
}

// V of VPL i at x with normal n for the frame's visibility mode.
fn vpl_visibility(i: u32, x: vec3<f32>, n: vec3<f32>) -> f32 {
    switch params.visibility {
        case VISIBILITY_CSSM: {
            let j = mapping[i];
            if j == NO_VAL {
                return 0.0;
            }
            return cssm_visibility(j, x, n);
        }
        case VISIBILITY_VPL_SHADOWS: {
            return hard_visibility(i, x, n);
        }
        default: {
            return 1.0;
        }
    }
}
