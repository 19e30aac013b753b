// The scene's two-level BVH (group 1), built on the CPU by `gi::common::bvh`, and ray
// traversal: a top level over instances, each a bottom level (the triangles of one movable
// node, or the static rest) placed by its node's pose. `SceneBvh::intersect` in
// server/gi/src/common/bvh.rs is the CPU port of `trace`, without
// the alpha test: hits `hit_masked(triangle, barycentrics)` rejects are skipped, and the module
// that includes this file defines it (the path tracer's alpha masks in surfaces.wgsl; false in
// the geometry-only traversal test).

// Mirrored by `BvhNode` in server/gi/src/common/bvh.rs. An inner node (`prim_count` 0) has
// its children at `first_index` and `first_index + 1`; a leaf's triangles are
// `first_index .. first_index + prim_count` of `bvh_triangles`.
struct BvhNode {
    min: vec3<f32>,
    prim_count: u32,
    max: vec3<f32>,
    first_index: u32,
}

// Mirrored by `BvhInstance`: the rows of the affine map from the world into the bottom
// level's rest pose (which keeps a ray's parameter, so hits' t are the world's) and its root.
struct BvhInstance {
    row0: vec4<f32>,
    row1: vec4<f32>,
    row2: vec4<f32>,
    root: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

// Deepest stacks the traversal keeps (`bvh::MAX_STACK`, `MAX_TOP_STACK`; deeper trees are
// refused on the CPU).
const BVH_STACK: u32 = 48u;
const TLAS_STACK: u32 = 32u;
const NO_HIT: u32 = 0xffffffffu;
// Whether any triangle of the scene is alpha-tested, set per scene when the pipeline is
// created: without masks the test compiles away, which matters where divergent branches run
// masked rather than skipped (lavapipe runs the untaken test and is then ~2× slower).
override ALPHA_TESTED: bool = true;

@group(1) @binding(0) var<storage, read> bvh_nodes: array<BvhNode>;
// Three vec4 per triangle in leaf order: vertices in xyz; the first w holds the bits of the
// triangle's index in the scene, the second's 1 when its material has an alpha mask.
@group(1) @binding(1) var<storage, read> bvh_triangles: array<vec4<f32>>;
// The top level: nodes whose leaves hold instances, and the instances in leaf order.
@group(1) @binding(2) var<storage, read> tlas_nodes: array<BvhNode>;
@group(1) @binding(3) var<storage, read> bvh_instances: array<BvhInstance>;

struct RayHit {
    t: f32,
    // Index into the scene's triangles, NO_HIT when nothing was hit.
    triangle: u32,
    // Barycentric coordinates of the hit for the second and third vertex.
    uv: vec2<f32>,
}

// Entry distance into the node's box, or a huge value when the ray misses it or enters it
// beyond `t_max`.
fn bvh_slab(node: BvhNode, origin: vec3<f32>, inv_dir: vec3<f32>, t_max: f32) -> f32 {
    let t0 = (node.min - origin) * inv_dir;
    let t1 = (node.max - origin) * inv_dir;
    let t_enter = max(max(max(min(t0.x, t1.x), min(t0.y, t1.y)), min(t0.z, t1.z)), 0.0);
    let t_exit = min(min(min(max(t0.x, t1.x), max(t0.y, t1.y)), max(t0.z, t1.z)), t_max);
    return select(3.4e38, t_enter, t_enter <= t_exit);
}

// Möller–Trumbore, two-sided. Writes `best` when the hit is nearer and not masked away; the
// mask is tested last, only for hits that would be the nearest so far on triangles flagged as
// alpha-tested.
fn bvh_triangle(i: u32, origin: vec3<f32>, dir: vec3<f32>, best: ptr<function, RayHit>) {
    let a = bvh_triangles[3u * i];
    let b = bvh_triangles[3u * i + 1u];
    let v0 = a.xyz;
    let e1 = b.xyz - v0;
    let e2 = bvh_triangles[3u * i + 2u].xyz - v0;
    let p = cross(dir, e2);
    let det = dot(e1, p);
    if abs(det) < 1e-12 {
        return;
    }
    let inv_det = 1.0 / det;
    let s = origin - v0;
    let u = dot(s, p) * inv_det;
    if u < 0.0 || u > 1.0 {
        return;
    }
    let q = cross(s, e1);
    let v = dot(dir, q) * inv_det;
    if v < 0.0 || u + v > 1.0 {
        return;
    }
    let t = dot(e2, q) * inv_det;
    if t > 0.0 && t < (*best).t {
        let triangle = bitcast<u32>(a.w);
        if !ALPHA_TESTED || bitcast<u32>(b.w) == 0u || !hit_masked(triangle, vec2<f32>(u, v)) {
            *best = RayHit(t, triangle, vec2<f32>(u, v));
        }
    }
}

// The nearest unmasked hit with t in (0, t_max).
fn trace(origin: vec3<f32>, dir: vec3<f32>, t_max: f32) -> RayHit {
    return bvh_traverse(origin, dir, t_max, false);
}

// Whether any unmasked triangle lies on the ray with t in (0, t_max): a shadow ray, which
// stops at the first hit (`SceneBvh::occluded`).
fn occluded(origin: vec3<f32>, dir: vec3<f32>, t_max: f32) -> bool {
    return bvh_traverse(origin, dir, t_max, true).triangle != NO_HIT;
}

// The top level's instances the ray's box test reaches, nearer first, each traced in its
// bottom level; with `any_hit`, the first hit found ends it.
fn bvh_traverse(origin: vec3<f32>, dir: vec3<f32>, t_max: f32, any_hit: bool) -> RayHit {
    var best = RayHit(t_max, NO_HIT, vec2<f32>(0.0));
    if arrayLength(&bvh_nodes) == 0u || arrayLength(&tlas_nodes) == 0u {
        return best;
    }
    let inv_dir = 1.0 / dir;
    var stack: array<u32, TLAS_STACK>;
    var depth = 0u;
    var node = 0u;
    loop {
        let n = tlas_nodes[node];
        var next = false;
        if n.prim_count > 0u {
            for (var i = n.first_index; i < n.first_index + n.prim_count; i++) {
                let inst = bvh_instances[i];
                let o = vec3<f32>(
                    dot(inst.row0.xyz, origin) + inst.row0.w,
                    dot(inst.row1.xyz, origin) + inst.row1.w,
                    dot(inst.row2.xyz, origin) + inst.row2.w,
                );
                let d = vec3<f32>(dot(inst.row0.xyz, dir), dot(inst.row1.xyz, dir), dot(inst.row2.xyz, dir));
                blas_traverse(inst.root, o, d, any_hit, &best);
                if any_hit && best.triangle != NO_HIT {
                    return best;
                }
            }
        } else {
            let a = n.first_index;
            let b = a + 1u;
            let ta = bvh_slab(tlas_nodes[a], origin, inv_dir, best.t);
            let tb = bvh_slab(tlas_nodes[b], origin, inv_dir, best.t);
            let near = select(b, a, ta <= tb);
            let far = select(a, b, ta <= tb);
            if min(ta, tb) < 3.4e38 {
                if max(ta, tb) < 3.4e38 && depth < TLAS_STACK {
                    stack[depth] = far;
                    depth++;
                }
                node = near;
                next = true;
            }
        }
        if !next {
            if depth == 0u {
                break;
            }
            depth--;
            node = stack[depth];
        }
    }
    return best;
}

// One bottom level from `root`, for a ray in its rest pose: nearer child first, the other on
// a stack; with `any_hit`, the first hit found ends it.
fn blas_traverse(root: u32, origin: vec3<f32>, dir: vec3<f32>, any_hit: bool, best: ptr<function, RayHit>) {
    let inv_dir = 1.0 / dir;
    var stack: array<u32, BVH_STACK>;
    var depth = 0u;
    var node = root;
    loop {
        let n = bvh_nodes[node];
        var next = false;
        if n.prim_count > 0u {
            for (var i = n.first_index; i < n.first_index + n.prim_count; i++) {
                bvh_triangle(i, origin, dir, best);
            }
            if any_hit && (*best).triangle != NO_HIT {
                break;
            }
        } else {
            let a = n.first_index;
            let b = a + 1u;
            let ta = bvh_slab(bvh_nodes[a], origin, inv_dir, (*best).t);
            let tb = bvh_slab(bvh_nodes[b], origin, inv_dir, (*best).t);
            let near = select(b, a, ta <= tb);
            let far = select(a, b, ta <= tb);
            if min(ta, tb) < 3.4e38 {
                if max(ta, tb) < 3.4e38 && depth < BVH_STACK {
                    stack[depth] = far;
                    depth++;
                }
                node = near;
                next = true;
            }
        }
        if !next {
            if depth == 0u {
                break;
            }
            depth--;
            node = stack[depth];
        }
    }
}
