// Every surfel's radiosity B = ρ·(E_direct + E_indirect) + B_emitted (seed 001, "Flux in
// Surfels and Hierarchy"): direct light through the frame's shadow map, emission, and, for
// multi-bounce frames, the irradiance of the previous bounce's caches half a cache spacing
// above the surfel (one more bounce per pass). Written as the leaves of the flux array, in
// surfel units (Φ̃ = B, see `pull_flux`). Mirrors `cpu::frame`'s first step.

// Mirrored by `SurfelGpu` in server/gi/src/surfels/passes.rs.
struct SurfelGpu {
    position: vec3<f32>,
    pad0: f32,
    normal: vec3<f32>,
    pad1: f32,
    albedo: vec3<f32>,
    pad2: f32,
    emitted: vec3<f32>,
    pad3: f32,
}

// Mirrored by `LightParams` in server/gi/src/surfels/passes.rs.
struct LightParams {
    surfel_count: u32,
    // 1: add the irradiance of `cache_light` (the previous bounce).
    feedback: u32,
    // Distance above the surfel at which the caches are read.
    offset: f32,
    // 1: add the surfel's emission (emissive surfaces as area lights, §3).
    emitters: u32,
}

@group(0) @binding(0) var<storage, read> params: LightParams;
@group(0) @binding(1) var<storage, read> lights: Lights;
@group(0) @binding(2) var shadow_map: texture_depth_2d_array;
@group(0) @binding(3) var shadow_sampler: sampler_comparison;
@group(0) @binding(4) var<storage, read> surfels: array<SurfelGpu>;
@group(0) @binding(5) var<storage, read> grid: GridUniform;
@group(0) @binding(6) var<storage, read> cache_usable: array<u32>;
@group(0) @binding(7) var<storage, read> cache_light: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read_write> flux: array<vec4<f32>>;
// 1 for a surfel on a node the frame moved away from where its links were traced: a moving
// object sends no light (seed 001 §5: dynamic geometry receives from the caches only).
@group(0) @binding(9) var<storage, read> moved: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= params.surfel_count {
        return;
    }
    if moved[k] != 0u {
        flux[k] = vec4<f32>(0.0);
        return;
    }
    let s = surfels[k];
    var direct = vec3<f32>(0.0);
    for (var i = 0u; i < lights.count; i++) {
        let light = lights.list[i];
        let incident = light_incident(light, s.position);
        let cos_x = max(dot(s.normal, incident.to_light), 0.0);
        if cos_x > 0.0 {
            let v = shadow_visibility(light, shadow_map, shadow_sampler, s.position, s.normal, cos_x);
            direct += incident.irradiance * cos_x * v;
        }
    }
    var indirect = vec3<f32>(0.0);
    if params.feedback != 0u {
        let around = interpolate_caches(s.position + params.offset * s.normal, s.position, s.normal);
        indirect = irradiance_from(around, s.normal);
    }
    flux[k] = vec4<f32>(s.albedo * (direct + indirect) + s.emitted * f32(params.emitters), 0.0);
}
