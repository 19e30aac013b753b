// LightSkin light caches and the two proxy lights each one carries per frame.

// Mirrored by `LightCache` in server/src/gi/caches.rs.
struct LightCache {
    position: vec3<f32>,
    area: f32,
    normal: vec3<f32>,
    disk_area: f32,
    diffuse: vec3<f32>,
    exponent: f32,
    glossy: vec3<f32>,
    pad0: f32,
}

// Mirrored by `CacheLighting` in server/src/passes/cache_lighting.rs. Each proxy light is a
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

// 2(n·w)n − w: `w` mirrored about `n` (both unit, `w` pointing away from the surface).
fn mirror(n: vec3<f32>, w: vec3<f32>) -> vec3<f32> {
    return 2.0 * dot(n, w) * n - w;
}
