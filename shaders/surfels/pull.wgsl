// Flux pulled up one level of the surfel hierarchy: every internal node of the level gets
// the sum of its two children (seed 001, "Flux in Surfels and Hierarchy"; `pull_flux` on the
// CPU). One dispatch per level, leaves first, so children are final before their parents.

// Mirrored by `PullLevel` in server/gi/src/surfels/passes.rs.
struct PullLevel {
    first: u32,
    count: u32,
    // n, the first internal node's id.
    leaves: u32,
    pad0: u32,
}

@group(0) @binding(0) var<storage, read> level: PullLevel;
@group(0) @binding(1) var<storage, read> children: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read> by_level: array<u32>;
@group(0) @binding(3) var<storage, read_write> flux: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= level.count {
        return;
    }
    let node = by_level[level.first + id.x];
    let c = children[node - level.leaves];
    flux[node] = flux[c.x] + flux[c.y];
}
