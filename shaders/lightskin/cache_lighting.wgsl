// Cache lighting: per light cache, the diffuse and glossy proxy lights built from the VALs
// (eq. 3–7 for LightSkin over every RSM texel; eq. 13–15 for the BRSM subset, where each VAL
// carries its weight 1 / (N_sVAL · P_VAL)). One thread per cache; VALs are staged through
// workgroup memory 64 at a time. The VALs are split into chunks, one dispatch each, whose sums
// add up in `accum`; a last dispatch turns the sums into proxy lights.

// Mirrored by `CacheLightingParams` in server/passes/src/passes/cache_lighting.rs.
struct CacheLightingParams {
    camera: vec3<f32>,
    cache_count: u32,
    // Selected VALs (BRSM) or RSM texels (LightSkin).
    val_count: u32,
    // 0: VALs from the selection buffer; 1: every RSM texel is a VAL with weight 1.
    every_texel: u32,
    rsm_width: u32,
    // This dispatch's VALs: [first_val, end_val).
    first_val: u32,
    end_val: u32,
    // Phong exponent k for every cache, overriding the materials'; 0 keeps their own.
    glossy_exponent: f32,
    // Side of each cache's visibility map (`cache_visibility`); 0: none.
    visibility_side: u32,
    // Cameras in `views` the proxies are shared by (server/gi/src/lightskin/shared.rs); 0 or 1:
    // `camera` alone.
    view_count: u32,
}

@group(0) @binding(0) var<storage, read> params: CacheLightingParams;
@group(0) @binding(1) var<storage, read> caches: array<LightCache>;
@group(0) @binding(2) var<storage, read> vals: array<Val>;
@group(0) @binding(3) var rsm_position: texture_2d<f32>;
@group(0) @binding(4) var rsm_normal: texture_2d<f32>;
@group(0) @binding(5) var rsm_flux_area: texture_2d<f32>;
@group(0) @binding(6) var<storage, read_write> lighting: array<CacheLighting>;
@group(0) @binding(7) var<storage, read_write> accum: array<Accum>;
@group(0) @binding(8) var rsm_glossy: texture_2d<u32>;
// Per cache, (visibility_side + 1)² octahedral grid vertices: how far the cache sees in each
// direction (server/gi/src/lightskin/cache_visibility.rs).
@group(0) @binding(9) var<storage, read> visibility: array<f32>;
// The camera positions (xyz) of the sessions sharing these proxies: `view_count` of them.
@group(0) @binding(10) var<storage, read> views: array<vec4<f32>>;

// The direction v towards the viewer that eq. 14/15's glossy lobe is taken about: the camera,
// or for proxies shared by sessions seeing the cache from several cameras the mean of their
// unit directions (the rule of server/gi/src/lightskin/shared.rs; zero, so no glossy proxy,
// where they cancel).
fn view_direction(c: LightCache) -> vec3<f32> {
    if params.view_count <= 1u {
        return direction(params.camera - c.position);
    }
    var sum = vec3<f32>(0.0);
    for (var j = 0u; j < params.view_count; j++) {
        sum += direction(views[j].xyz - c.position);
    }
    return direction(sum);
}

// Mirrored by `cache_visibility::{SLACK, RAMP}`.
const VISIBILITY_SLACK: f32 = 0.25;
const VISIBILITY_RAMP: f32 = 0.25;

// Whether cache `ci` sees a point at `distance` in unit direction `dir`: 1 up to its map's
// distance there (bilinear between its cell's vertices) and a quarter beyond, falling to 0 at
// half beyond (`CacheVisibility::visibility`); 1 without maps.
fn cache_visibility(ci: u32, dir: vec3<f32>, distance: f32) -> f32 {
    let side = params.visibility_side;
    if side == 0u {
        return 1.0;
    }
    let uv = (octahedral_encode(dir) * 0.5 + vec2<f32>(0.5)) * f32(side);
    let cell = clamp(floor(uv), vec2<f32>(0.0), vec2<f32>(f32(side - 1u)));
    let f = uv - cell;
    let row = side + 1u;
    let base = ci * row * row + u32(cell.y) * row + u32(cell.x);
    let bottom = mix(visibility[base], visibility[base + 1u], f.x);
    let top = mix(visibility[base + row], visibility[base + row + 1u], f.x);
    let seen = mix(bottom, top, f.y);
    return clamp((seen * (1.0 + VISIBILITY_SLACK + VISIBILITY_RAMP) - distance) / (VISIBILITY_RAMP * seen), 0.0, 1.0);
}

// ε_p of eq. 6 as a fraction of F_max = A_l / (A_l + π d²), the largest form factor the VAL's
// disk could have at its distance (facing the cache): eq. 6's weight becomes ε_p·F_max + F.
// Dimensionless, and it shrinks with the VAL as F does: a constant ε_p summed over a million
// tiny VALs of a high-resolution RSM would outweigh their form factors and drag every proxy to
// the mean of the whole RSM, and ε_p·A_l (length²) outweighed them in kilometre-sized scenes.
// Mirrored by `EPS_P` in server/gi/src/lightskin/cpu.rs, which says more.
const EPS_P: f32 = 1e-6;
// Floors of eq. 7's denominator: a proxy at grazing incidence (or outside the glossy lobe)
// would otherwise get an unbounded flux.
const MIN_COS_DIFFUSE: f32 = 1e-3;
const MIN_COS_GLOSSY: f32 = 1e-2;
const TILE_VALS: u32 = 64u;

var<workgroup> tile: array<Val, 64>;

fn load_val(index: u32) -> Val {
    if index >= params.val_count {
        return Val(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0u, no_glossy());
    }
    if params.every_texel == 0u {
        return vals[index];
    }
    let texel = vec2<u32>(index % params.rsm_width, index / params.rsm_width);
    let p = textureLoad(rsm_position, texel, 0);
    let fa = textureLoad(rsm_flux_area, texel, 0);
    // Uncovered texels get weight 0.
    let glossy = decode_glossy(textureLoad(rsm_glossy, texel, 0));
    return Val(p.xyz, fa.a, textureLoad(rsm_normal, texel, 0).xyz, p.w, fa.rgb, index, glossy);
}

// Mirrored by `CacheAccum` in server/passes/src/passes/cache_lighting.rs.
fn cache_exponent(c: LightCache) -> f32 {
    return select(c.exponent, params.glossy_exponent, params.glossy_exponent > 0.0);
}

struct Accum {
    // Σ w·Φ_l·G (diffuse) and Σ w·Φ_l·G·cos^k θ_e (glossy): eq. 14/15 without ρ.
    e_d: vec3<f32>,
    // Σ a with a the eq. 6 weight times the VAL's weight (eq. 13), diffuse and glossy.
    s_d: f32,
    e_g: vec3<f32>,
    s_g: f32,
    // Σ a·x_l and Σ a·x_l², for the proxy positions and extents.
    p_d: vec3<f32>,
    pad0: f32,
    p_g: vec3<f32>,
    pad1: f32,
    q_d: vec3<f32>,
    pad2: f32,
    q_g: vec3<f32>,
    pad3: f32,
}

fn accumulate(acc: ptr<function, Accum>, ci: u32, c: LightCache, v: vec3<f32>, val: Val) {
    let delta = val.position - c.position;
    let len2 = dot(delta, delta);
    if val.weight <= 0.0 || len2 <= 0.0 {
        return;
    }
    let w_dir = delta * inverseSqrt(len2);
    let cos_l = max(dot(val.normal, -w_dir), 0.0);
    let cos_x = max(dot(c.normal, w_dir), 0.0);
    // Geometric factor of eq. 3/4 with the VAL's disk area (which keeps it finite at any
    // distance); A·G is the disk-to-point form factor of eq. 6, at most F_max.
    let g = cos_l * cos_x / (val.area + PI * len2);
    let f_max = val.area / (val.area + PI * len2);
    // A VAL that cannot light the cache takes no part, not even through ε_p: summed over the
    // many VALs behind a cache, ε_p alone would drag the proxy far off, and eq. 9 then
    // interpolates that far proxy's large flux onto nearby points.
    if g <= 0.0 {
        return;
    }
    // A VAL the cache cannot see lights it with nothing and takes no part in its proxies.
    let weight = val.weight * cache_visibility(ci, w_dir, sqrt(len2));
    if weight <= 0.0 {
        return;
    }
    let form_factor = val.area * g;
    let lobe = pow(max(dot(mirror(c.normal, w_dir), v), 0.0), cache_exponent(c));
    // Φ_l of eq. 3/4 is what the VAL sends towards the cache: its glossy lobe's share too.
    let flux = sent_flux(val.flux, val.glossy, -w_dir, glossy_spread(val.area, len2));
    (*acc).e_d += weight * flux * g;
    (*acc).e_g += weight * flux * g * lobe;
    let a_d = weight * (EPS_P * f_max + form_factor);
    let a_g = weight * (EPS_P * f_max + lobe * form_factor);
    (*acc).s_d += a_d;
    (*acc).s_g += a_g;
    // Moments about the cache rather than the origin: E[x²] − E[x]² in f32 loses the spread
    // to cancellation when coordinates are large next to it (open-world scenes in metres).
    (*acc).p_d += a_d * delta;
    (*acc).p_g += a_g * delta;
    (*acc).q_d += a_d * delta * delta;
    (*acc).q_g += a_g * delta * delta;
}

struct Proxy {
    position: vec3<f32>,
    radius: f32,
}

// Eq. 5/13 position and the extent 2σ of the weighted VAL positions (largest axis); `p` and
// `q` are moments of the offsets from the cache.
fn proxy(c: LightCache, s: f32, p: vec3<f32>, q: vec3<f32>) -> Proxy {
    if s <= 0.0 {
        return Proxy(c.position, 0.0);
    }
    let mean = p / s;
    let sigma = sqrt(max(q / s - mean * mean, vec3<f32>(0.0)));
    return Proxy(c.position + mean, 2.0 * max(sigma.x, max(sigma.y, sigma.z)));
}

fn zero_accum() -> Accum {
    return Accum(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
}

fn load_cache(i: u32) -> LightCache {
    if i < params.cache_count {
        return caches[i];
    }
    return LightCache(vec3<f32>(0.0), 0.0, vec3<f32>(0.0, 1.0, 0.0), 0.0, vec3<f32>(0.0), 1.0, vec3<f32>(0.0), 0xffffffffu);
}

@compute @workgroup_size(64)
fn accumulate_vals(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let i = id.x;
    let in_range = i < params.cache_count;
    let c = load_cache(i);
    let v = view_direction(c);
    var acc = zero_accum();
    if in_range && params.first_val > 0u {
        acc = accum[i];
    }
    for (var base = params.first_val; base < params.end_val; base += TILE_VALS) {
        workgroupBarrier();
        tile[local] = load_val(base + local);
        workgroupBarrier();
        if in_range {
            let count = min(TILE_VALS, params.end_val - base);
            for (var k = 0u; k < count; k++) {
                accumulate(&acc, i, c, v, tile[k]);
            }
        }
    }
    if in_range {
        accum[i] = acc;
    }
}

@compute @workgroup_size(64)
fn finish_proxies(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.cache_count {
        return;
    }
    let c = caches[i];
    let v = view_direction(c);
    var acc = zero_accum();
    if params.val_count > 0u {
        acc = accum[i];
    }
    // Eq. 7 with eq. 3/4 (or 14/15) plugged in as L_o: the cache's ρ_d/π (ρ_g·(k+2)/2π) appears
    // in L_o and in f_r and cancels, so the proxies carry incident light only and any
    // surface near the cache can apply its own BRDF to them.
    let min_dist2 = MIN_DIST2_PER_AREA * c.area;
    let pd = proxy(c, acc.s_d, acc.p_d, acc.q_d);
    let to_d = pd.position - c.position;
    let dist2_d = max(dot(to_d, to_d), min_dist2);
    let cos_d = dot(c.normal, direction(to_d));
    let flux_d = 4.0 * PI * dist2_d * acc.e_d / max(cos_d, MIN_COS_DIFFUSE);

    let pg = proxy(c, acc.s_g, acc.p_g, acc.q_g);
    let to_g = pg.position - c.position;
    let dist2_g = max(dot(to_g, to_g), min_dist2);
    let w_g = direction(to_g);
    let lobe_g = pow(max(dot(mirror(c.normal, w_g), v), 0.0), cache_exponent(c));
    let flux_g = 4.0 * PI * dist2_g * acc.e_g / max(dot(c.normal, w_g) * lobe_g, MIN_COS_GLOSSY);

    lighting[i] = CacheLighting(pd.position, pd.radius, flux_d, 0.0, pg.position, pg.radius, flux_g, 0.0);
}
