// LightSkin light caches and the two proxy lights each one carries per frame.

// Mirrored by `LightCache` in server/gi/src/caches.rs.
struct LightCache {
    position: vec3<f32>,
    area: f32,
    normal: vec3<f32>,
    disk_area: f32,
    diffuse: vec3<f32>,
    exponent: f32,
    glossy: vec3<f32>,
    // The model it moves with (unused on the GPU: the CPU places moved caches).
    model: u32,
}

// Mirrored by `CacheLighting` in server/passes/src/passes/cache_lighting.rs. Each proxy light is a
// point light of the given flux at the given position; the radius is its extent (2σ of the
// VAL positions), kept for occlusion.
struct CacheLighting {
    diffuse_position: vec3<f32>,
    diffuse_radius: f32,
    diffuse_flux: vec3<f32>,
    pad0: f32,
    glossy_position: vec3<f32>,
    glossy_radius: f32,
    glossy_flux: vec3<f32>,
    pad1: f32,
}

// Floor of the squared proxy–cache distance (eq. 7) and proxy–surface distance (eq. 9's point
// light) per unit of cache area A_c: (r_c/2)² for the cache's cell as a disk of radius
// √(A_c/π). Relative to the cache distribution's own resolution, so it holds at any scene
// scale (a floor in scene units flattened a centimetre-sized model's indirect light). Mirrored
// by `MIN_DIST2_PER_AREA` in server/gi/src/lightskin/cpu.rs.
const MIN_DIST2_PER_AREA: f32 = 1.0 / (4.0 * PI);

// 2(n·w)n − w: `w` mirrored about `n` (both unit, `w` pointing away from the surface).
fn mirror(n: vec3<f32>, w: vec3<f32>) -> vec3<f32> {
    return 2.0 * dot(n, w) * n - w;
}

// `v` normalised, or zero for a zero vector (`normalize` would give NaN, which `max` may or
// may not swallow: SPIR-V leaves that undefined).
fn direction(v: vec3<f32>) -> vec3<f32> {
    let len2 = dot(v, v);
    return select(vec3<f32>(0.0), v * inverseSqrt(len2), len2 > 0.0);
}

// A proxy light without flux: its cache saw no VAL, so its position means nothing.
fn unlit(flux: vec3<f32>) -> bool {
    return all(flux <= vec3<f32>(0.0));
}

// Proxy-light occlusion by double projection (paper, "Occlusion"): the proxy's bounding sphere
// and the occluding caches' disks are projected onto the unit hemisphere around the target
// cache and from there onto its unit base disk (Nusselt's analogue: the projected area is π
// times the form factor), turned into axis-aligned squares of the same area, and the covered
// fraction of the proxy's square is its occlusion.

// Smallest side of a proxy's square on the unit base disk.
const MIN_PROXY_SIDE: f32 = 1e-3;
// Occluders nearer to the target than this fraction of their disk area (squared distance) sit
// on the target itself and have no direction; mirrored by `MIN_OCCLUDER_DIST2_PER_AREA` in
// server/gi/src/lightskin/cpu.rs.
const MIN_OCCLUDER_DIST2_PER_AREA: f32 = 1e-8;

struct Square {
    center: vec2<f32>,
    side: f32,
}

// Tangent axes of the target cache's base disk.
fn tangent_frame(n: vec3<f32>) -> mat2x3<f32> {
    var up = vec3<f32>(0.0, 1.0, 0.0);
    if abs(n.y) > 0.99 {
        up = vec3<f32>(1.0, 0.0, 0.0);
    }
    let t = normalize(cross(n, up));
    return mat2x3<f32>(t, cross(n, t));
}

// Square of area π·F on the base disk, centred where direction `w` lands.
fn projected_square(frame: mat2x3<f32>, w: vec3<f32>, form_factor: f32) -> Square {
    return Square(vec2<f32>(dot(w, frame[0]), dot(w, frame[1])), sqrt(PI * max(form_factor, 0.0)));
}

fn overlap(a: Square, b: Square) -> f32 {
    let lo = max(a.center - 0.5 * a.side, b.center - 0.5 * b.side);
    let hi = min(a.center + 0.5 * a.side, b.center + 0.5 * b.side);
    let size = max(hi - lo, vec2<f32>(0.0));
    return size.x * size.y;
}

// Square of a proxy sphere (centre, radius) seen from the cache; side 0 if below its horizon.
// The sphere's form factor is (r/d)²·cos θ.
fn proxy_square(frame: mat2x3<f32>, c: LightCache, center: vec3<f32>, radius: f32) -> Square {
    let to = center - c.position;
    let d2 = dot(to, to);
    let w = direction(to);
    let cos_c = max(dot(c.normal, w), 0.0);
    // (r/d)², or the whole hemisphere from inside the sphere.
    var subtended = 1.0;
    if d2 > radius * radius {
        subtended = radius * radius / d2;
    }
    let square = projected_square(frame, w, subtended * cos_c);
    // A point-like proxy still needs a footprint for the overlap test to see it covered.
    return Square(square.center, max(square.side, MIN_PROXY_SIDE));
}

// Square of occluder cache `o` seen from cache `c`, if `o` lies in front of `c`, nearer than
// the proxy sphere (`center`, `radius`) and outside it: caches inside the sphere carry the VALs
// the proxy stands for, so they are the light, not something in front of it. The disk's form
// factor is A·cos θ_c·cos θ_o / (π d² + A).
fn occluder_square(frame: mat2x3<f32>, c: LightCache, o: LightCache, center: vec3<f32>, radius: f32) -> Square {
    let to = o.position - c.position;
    let d2 = dot(to, to);
    let to_proxy = center - c.position;
    let from_proxy = o.position - center;
    if d2 <= MIN_OCCLUDER_DIST2_PER_AREA * o.disk_area || d2 >= dot(to_proxy, to_proxy) || dot(from_proxy, from_proxy) < radius * radius {
        return Square(vec2<f32>(0.0), 0.0);
    }
    let w = to * inverseSqrt(d2);
    let cos_c = max(dot(c.normal, w), 0.0);
    let cos_o = abs(dot(o.normal, w));
    let form_factor = o.disk_area * cos_c * cos_o / (PI * d2 + o.disk_area);
    return projected_square(frame, w, form_factor);
}
