// The SH caches around a point (seed 001, eq. 6): trilinear weights over the lattice's eight
// nearest caches, leaving out those inside geometry or outside a closed scene (they see mostly
// back faces or nothing, the paper's Fig. 7a) and those behind the lit surface (they see its
// other side: a wall's back would be lit from the room it closes), and renormalising. Mirrors
// `CacheGrid::trilinear`, `CacheGrid::in_front` and `cpu::irradiance`. The including pass declares `grid`,
// `cache_usable` and `cache_light`.

// Mirrored by `GridUniform` in server/gi/src/surfels/passes.rs.
struct GridUniform {
    origin: vec3<f32>,
    spacing: f32,
    dims: vec3<u32>,
    // l², the coefficients per cache.
    coefficients: u32,
}

struct Interpolated {
    radiance: array<vec3<f32>, 16>,
    total: f32,
}

// Mirrors `grid::BEHIND_TOLERANCE`.
const BEHIND_TOLERANCE: f32 = 1e-3;

// The caches around `p` in front of the surface at `surface` with normal `n`.
fn interpolate_caches(p: vec3<f32>, surface: vec3<f32>, n: vec3<f32>) -> Interpolated {
    var out: Interpolated;
    out.total = 0.0;
    for (var i = 0u; i < SH_COEFFICIENTS; i++) {
        out.radiance[i] = vec3<f32>(0.0);
    }
    let dims = grid.dims;
    let last = vec3<f32>(max(dims - vec3<u32>(1u), vec3<u32>(1u)));
    let t = clamp((p - grid.origin) / grid.spacing, vec3<f32>(0.0), last);
    let base = max(min(floor(t), last - vec3<f32>(1.0)), vec3<f32>(0.0));
    let f = t - base;
    let b = vec3<u32>(base);
    for (var k = 0u; k < 8u; k++) {
        let o = vec3<u32>(k & 1u, (k >> 1u) & 1u, (k >> 2u) & 1u);
        let wv = select(vec3<f32>(1.0) - f, f, o == vec3<u32>(1u));
        let w = wv.x * wv.y * wv.z;
        let c = min(b + o, dims - vec3<u32>(1u));
        let cache = c.x + dims.x * (c.y + dims.y * c.z);
        let cache_position = grid.origin + vec3<f32>(c) * grid.spacing;
        let behind = dot(cache_position - surface, n) < -BEHIND_TOLERANCE * grid.spacing;
        if w <= 0.0 || cache_usable[cache] == 0u || behind {
            continue;
        }
        out.total += w;
        for (var i = 0u; i < grid.coefficients; i++) {
            out.radiance[i] += w * cache_light[cache * grid.coefficients + i].rgb;
        }
    }
    return out;
}

// Irradiance on a surface with normal `n` from interpolated cache radiance (eq. 5–6).
fn irradiance_from(r: Interpolated, n: vec3<f32>) -> vec3<f32> {
    if r.total <= 0.0 {
        return vec3<f32>(0.0);
    }
    let y = sh_eval(n);
    var e = vec3<f32>(0.0);
    for (var i = 0u; i < grid.coefficients; i++) {
        e += r.radiance[i] * (zonal_cosine(sh_band(i)) * y[i]);
    }
    return e / r.total;
}
