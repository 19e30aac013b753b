// Test entry point: the nearest hit of each ray in `rays` (origin.xyz + t_max, dir.xyz) into
// `hits` (t, triangle bits, u, v). Used to check the WGSL traversal against the CPU.

@group(0) @binding(0) var<storage, read> rays: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read_write> hits: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&hits) {
        return;
    }
    let o = rays[2u * i];
    let d = rays[2u * i + 1u];
    let hit = trace(o.xyz, d.xyz, o.w);
    hits[i] = vec4<f32>(hit.t, bitcast<f32>(hit.triangle), hit.uv);
}

// Geometry only, like the CPU traversal it is checked against (`SceneBvh::intersect`).
fn hit_masked(triangle: u32, b: vec2<f32>) -> bool {
    return false;
}
