//! The scene's triangles in a two-level bounding volume hierarchy, for the reference path
//! tracer and the precomputations' visibility rays.
//!
//! Bottom levels: the triangles of each node that can move (issue 35: its innermost node is
//! movable or under a movable one), and one for everything else, each built on the CPU with
//! `obvhs` (PLOC with reinsertion: a well-kept builder made for GPU traversal, and faster
//! than a hand-written binned SAH) in the rest pose, then flattened into 32-byte nodes the
//! WGSL traversal (`shaders/bvh.wgsl`) reads, one array for all levels. The top level places
//! each bottom level by its node's pose ([`BvhInstance`]: the inverse of its change from
//! rest) in a small BVH over their posed bounds, rebuilt whenever the poses change
//! ([`SceneBvh::top_level`]): a moved object costs that, not a rebuild of its triangles.
//! Triangles are stored in leaf order so a leaf's triangles are contiguous.
//! [`SceneBvh::intersect`] is the CPU port of the traversal and
//! [`SceneBvh::intersect_brute_force`] the independent check it is tested against. Both are
//! geometry only: the WGSL traversal also skips hits on alpha-masked texels, which needs the
//! materials and textures (`shaders/reference/surfaces.wgsl`).

use crate::scene::nodes::{can_move, owners, Node};
use crate::scene::Scene;
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};

/// Mirrors `BvhNode` in `shaders/bvh.wgsl`. An inner node (`prim_count` 0) has its
/// children at `first_index` and `first_index + 1`; a leaf's triangles are
/// `first_index .. first_index + prim_count` of [`SceneBvh::triangles`] (in the top level:
/// of its instances).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BvhNode {
    pub min: [f32; 3],
    pub prim_count: u32,
    pub max: [f32; 3],
    pub first_index: u32,
}

/// One triangle as the GPU reads it: three `vec4`s, the vertices in `xyz`, in the first one's
/// `w` the bits of its index into the scene's triangles (for shading data) and in the second
/// one's whether its material has an alpha mask.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BvhTriangle {
    pub v0: [f32; 3],
    pub scene_triangle: u32,
    pub v1: [f32; 3],
    /// 1 when the material has an alpha cutoff: only these hits need the (costly) alpha test.
    pub alpha_tested: u32,
    pub v2: [f32; 4],
}

/// Mirrors `BvhInstance` in `shaders/bvh.wgsl`: a bottom level placed in the world. A ray
/// enters it through `to_rest` (the rows of the affine map from the world to the level's
/// rest pose): an affine map keeps a ray's parameter, so its hits' `t` are the world's.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BvhInstance {
    pub to_rest: [[f32; 4]; 3],
    /// The level's root in [`SceneBvh::nodes`].
    pub root: u32,
    pub pad: [u32; 3],
}

impl BvhInstance {
    fn point(&self, p: Vec3) -> Vec3 {
        let r = &self.to_rest;
        Vec3::new(
            Vec3::from_slice(&r[0][..3]).dot(p) + r[0][3],
            Vec3::from_slice(&r[1][..3]).dot(p) + r[1][3],
            Vec3::from_slice(&r[2][..3]).dot(p) + r[2][3],
        )
    }

    fn direction(&self, d: Vec3) -> Vec3 {
        let r = &self.to_rest;
        Vec3::new(
            Vec3::from_slice(&r[0][..3]).dot(d),
            Vec3::from_slice(&r[1][..3]).dot(d),
            Vec3::from_slice(&r[2][..3]).dot(d),
        )
    }
}

/// One bottom level.
#[derive(Clone, Debug, PartialEq)]
pub struct Level {
    /// Its root in [`SceneBvh::nodes`].
    pub root: u32,
    /// The position in `Scene::nodes` of the node whose moves move it (`None`: static).
    pub node: Option<usize>,
    /// Its bounds at rest.
    pub min: Vec3,
    pub max: Vec3,
}

/// The top level for one set of poses.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TopLevel {
    pub nodes: Vec<BvhNode>,
    /// In the top level's leaf order.
    pub instances: Vec<BvhInstance>,
}

/// The nearest intersection of a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    /// Index into the scene's triangles (`Scene::indices` / 3).
    pub triangle: u32,
    /// Barycentric coordinates of the hit for `v1` and `v2`.
    pub u: f32,
    pub v: f32,
}

/// Deepest traversal stack the WGSL traversal keeps in a bottom level; [`SceneBvh::build`]
/// refuses deeper trees.
pub const MAX_STACK: usize = 48;
/// The same for the top level (`TLAS_STACK` in `shaders/bvh.wgsl`): its median splits keep it
/// ⌈log₂ n⌉ + 1 deep, 32 for up to 2³¹ movable nodes.
pub const MAX_TOP_STACK: usize = 32;

#[derive(Debug, thiserror::Error)]
pub enum BvhError {
    #[error("the scene's BVH is {depth} levels deep; the traversal supports {MAX_STACK}")]
    TooDeep { depth: usize },
}

/// Reference ns per triangle of [`SceneBvh::build`] (binned SAH): about 2 s for the
/// 1.2 M-triangle street. Every precomputation that builds one counts it with this.
pub const BUILD_NS_PER_TRIANGLE: f64 = 1700.0;

/// The bottom levels of a scene (nodes and leaf-ordered triangles of all of them) and the
/// top level at rest.
#[derive(Clone, Debug, Default)]
pub struct SceneBvh {
    pub nodes: Vec<BvhNode>,
    pub triangles: Vec<BvhTriangle>,
    pub levels: Vec<Level>,
    /// The top level [`Self::intersect`] and [`Self::occluded`] trace: at rest after
    /// [`Self::build`], posed by [`Self::set_top`].
    pub top: TopLevel,
}

/// obvhs's triangle is three 16-byte glam `Vec3A`s; built from plain floats so this crate
/// does not need obvhs's glam version by name.
fn obvhs_triangle(scene: &Scene, t: &[u32]) -> obvhs::triangle::Triangle {
    let mut f = [0f32; 12];
    for (k, &i) in t.iter().enumerate() {
        f[4 * k..4 * k + 3].copy_from_slice(&scene.vertices[i as usize].position);
    }
    bytemuck::cast(f)
}

impl SceneBvh {
    pub fn build(scene: &Scene) -> Result<Self, BvhError> {
        let mut built = Self::default();
        for (node, triangles) in groups(scene) {
            built.add_level(scene, node, &triangles)?;
        }
        built.top = built.top_level(&scene.nodes, &[]);
        Ok(built)
    }

    /// Builds the bottom level of scene triangles `group` (indices into `Scene::indices` / 3).
    fn add_level(
        &mut self,
        scene: &Scene,
        node: Option<usize>,
        group: &[u32],
    ) -> Result<(), BvhError> {
        let input: Vec<obvhs::triangle::Triangle> = group
            .iter()
            .map(|&t| obvhs_triangle(scene, &scene.indices[3 * t as usize..3 * t as usize + 3]))
            .collect();
        if input.is_empty() {
            return Ok(());
        }
        let mut build_time = std::time::Duration::ZERO;
        let bvh = obvhs::bvh2::builder::build_bvh2_from_tris(
            &input,
            obvhs::BvhBuildParams::medium_build(),
            &mut build_time,
        );
        let (node_base, triangle_base) = (self.nodes.len() as u32, self.triangles.len() as u32);
        self.triangles
            .extend(bvh.primitive_indices.iter().map(|&i| {
                let f: [f32; 12] = bytemuck::cast(input[i as usize]);
                let scene_triangle = group[i as usize];
                let first = scene.indices[3 * scene_triangle as usize];
                let material = scene.vertices[first as usize].material;
                BvhTriangle {
                    v0: [f[0], f[1], f[2]],
                    scene_triangle,
                    v1: [f[4], f[5], f[6]],
                    alpha_tested: u32::from(
                        scene.materials[material as usize].alpha_cutoff.is_some(),
                    ),
                    v2: [f[8], f[9], f[10], 0.0],
                }
            }));
        self.nodes.extend(bvh.nodes.iter().map(|n| BvhNode {
            min: n.aabb.min.to_array(),
            prim_count: n.prim_count,
            max: n.aabb.max.to_array(),
            first_index: n.first_index
                + if n.prim_count > 0 {
                    triangle_base
                } else {
                    node_base
                },
        }));
        let depth = depth(&self.nodes, node_base as usize);
        if depth > MAX_STACK {
            return Err(BvhError::TooDeep { depth });
        }
        let root = &self.nodes[node_base as usize];
        self.levels.push(Level {
            root: node_base,
            node,
            min: root.min.into(),
            max: root.max.into(),
        });
        Ok(())
    }

    /// [`top_level`] of this BVH's levels.
    pub fn top_level(&self, nodes: &[Node], worlds: &[Mat4]) -> TopLevel {
        top_level(&self.levels, nodes, worlds)
    }

    /// Traces [`Self::intersect`] and [`Self::occluded`] through `top` from now on.
    pub fn set_top(&mut self, top: TopLevel) {
        self.top = top;
    }

    /// The nearest hit with `t` in (0, `t_max`), walking the trees as the WGSL traversal
    /// does: in each, the nearer child first, a stack for the other.
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<Hit> {
        self.traverse(origin, dir, t_max, false)
    }

    /// The nearest hit before `t_max`, or with `any` the first one found.
    fn traverse(&self, origin: Vec3, dir: Vec3, t_max: f32, any: bool) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        walk(&self.top.nodes, 0, origin, dir, t_best, |first, count| {
            for instance in &self.top.instances[first as usize..(first + count) as usize] {
                let (o, d) = (instance.point(origin), instance.direction(dir));
                walk(&self.nodes, instance.root, o, d, t_best, |first, count| {
                    for tri in &self.triangles[first as usize..(first + count) as usize] {
                        if let Some(hit) = intersect_triangle(tri, o, d) {
                            if hit.t < t_best {
                                t_best = hit.t;
                                best = Some(hit);
                                if any {
                                    return None;
                                }
                            }
                        }
                    }
                    Some(t_best)
                })?;
            }
            Some(t_best)
        });
        best
    }

    /// Whether anything lies on the ray before `t_max`: a shadow ray, which stops at the
    /// first hit instead of looking for the nearest (visibility between two points, as a
    /// precomputation's rays trace it).
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_max: f32) -> bool {
        self.traverse(origin, dir, t_max, true).is_some()
    }

    /// The nearest hit by testing every triangle where the top level places it (the check
    /// for [`Self::intersect`]).
    pub fn intersect_brute_force(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for instance in &self.top.instances {
            let (o, d) = (instance.point(origin), instance.direction(dir));
            let level = self
                .levels
                .iter()
                .position(|l| l.root == instance.root)
                .expect("every instance places a level");
            let first = leaf_range(&self.nodes, self.levels[level].root);
            for tri in &self.triangles[first] {
                if let Some(hit) = intersect_triangle(tri, o, d) {
                    if hit.t < t_max && best.is_none_or(|b| hit.t < b.t) {
                        best = Some(hit);
                    }
                }
            }
        }
        best
    }
}

/// The top level with `levels` placed by `worlds` (every scene node's world transform,
/// `scene::nodes::posed_worlds`; empty: at rest).
pub fn top_level(levels: &[Level], nodes: &[Node], worlds: &[Mat4]) -> TopLevel {
    let placed: Vec<(BvhInstance, (Vec3, Vec3))> = levels
        .iter()
        .map(|level| {
            let delta = match (level.node, worlds.is_empty()) {
                (Some(n), false) => worlds[n] * nodes[n].rest_world.inverse(),
                _ => Mat4::IDENTITY,
            };
            let rows = delta.inverse().transpose().to_cols_array_2d();
            let instance = BvhInstance {
                to_rest: [rows[0], rows[1], rows[2]],
                root: level.root,
                pad: [0; 3],
            };
            let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
            for k in 0..8 {
                let corner = Vec3::select(
                    glam::BVec3::new(k & 1 != 0, k & 2 != 0, k & 4 != 0),
                    level.max,
                    level.min,
                );
                let p = delta.transform_point3(corner);
                lo = lo.min(p);
                hi = hi.max(p);
            }
            (instance, (lo, hi))
        })
        .collect();
    let bounds: Vec<(Vec3, Vec3)> = placed.iter().map(|(_, b)| *b).collect();
    let (nodes, order) = median_split(&bounds);
    TopLevel {
        nodes,
        instances: order.iter().map(|&i| placed[i as usize].0).collect(),
    }
}

/// A tree over `boxes` by median splits of their centres along the longest axis, one box per
/// leaf, and the boxes in leaf order. The top level holds a few boxes and is rebuilt whenever
/// poses change; unlike obvhs's builder (whose SAH collapse weighs areas against constants)
/// it builds the same tree at any power-of-two scale, so scaled scenes trace the same rays
/// in the same order. Its depth is ⌈log₂ n⌉ + 1.
fn median_split(boxes: &[(Vec3, Vec3)]) -> (Vec<BvhNode>, Vec<u32>) {
    let mut order: Vec<u32> = (0..boxes.len() as u32).collect();
    let mut nodes = vec![BvhNode::default()];
    // (node, range of `order` it holds)
    let mut work = vec![(0usize, 0..order.len())];
    while let Some((node, range)) = work.pop() {
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        let (mut c_lo, mut c_hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for &i in &order[range.clone()] {
            let (a, b) = boxes[i as usize];
            lo = lo.min(a);
            hi = hi.max(b);
            c_lo = c_lo.min((a + b) * 0.5);
            c_hi = c_hi.max((a + b) * 0.5);
        }
        nodes[node].min = lo.to_array();
        nodes[node].max = hi.to_array();
        if range.len() <= 1 {
            nodes[node].prim_count = range.len() as u32;
            nodes[node].first_index = range.start as u32;
            continue;
        }
        let extent = c_hi - c_lo;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let centre = |i: u32| {
            let (a, b) = boxes[i as usize];
            (a[axis] + b[axis]) * 0.5
        };
        order[range.clone()].sort_by(|&x, &y| centre(x).total_cmp(&centre(y)).then(x.cmp(&y)));
        let mid = range.start + range.len() / 2;
        let left = nodes.len();
        nodes.extend([BvhNode::default(), BvhNode::default()]);
        nodes[node].first_index = left as u32;
        work.push((left, range.start..mid));
        work.push((left + 1, mid..range.end));
    }
    (nodes, order)
}

/// The triangles of the level rooted at `root`: leaves hold contiguous ranges, a level's
/// leaves one range.
fn leaf_range(nodes: &[BvhNode], root: u32) -> std::ops::Range<usize> {
    let (mut lo, mut hi) = (usize::MAX, 0);
    let mut stack = vec![root];
    while let Some(n) = stack.pop() {
        let node = &nodes[n as usize];
        if node.prim_count > 0 {
            lo = lo.min(node.first_index as usize);
            hi = hi.max((node.first_index + node.prim_count) as usize);
        } else {
            stack.extend([node.first_index, node.first_index + 1]);
        }
    }
    lo.min(hi)..hi
}

/// The scene's triangles by bottom level: those whose innermost node can move (it or an
/// ancestor is movable), per node, and the rest (`None`), static first.
fn groups(scene: &Scene) -> Vec<(Option<usize>, Vec<u32>)> {
    let moves = can_move(&scene.nodes);
    let owner = owners(&scene.nodes, scene.vertices.len() as u32);
    let mut by_node: Vec<Vec<u32>> = vec![Vec::new(); scene.nodes.len()];
    let mut still = Vec::new();
    for (t, tri) in scene.indices.chunks_exact(3).enumerate() {
        match owner.get(tri[0] as usize).map(|&o| o as usize) {
            Some(o) if o < moves.len() && moves[o] => by_node[o].push(t as u32),
            _ => still.push(t as u32),
        }
    }
    std::iter::once((None, still))
        .chain(
            by_node
                .into_iter()
                .enumerate()
                .filter(|(_, g)| !g.is_empty())
                .map(|(n, g)| (Some(n), g)),
        )
        .collect()
}

fn depth(nodes: &[BvhNode], node: usize) -> usize {
    let n = &nodes[node];
    if n.prim_count > 0 {
        1
    } else {
        let first = n.first_index as usize;
        1 + depth(nodes, first).max(depth(nodes, first + 1))
    }
}

/// Walks the tree of `nodes` from `root` for a ray: nearer child first, the other on a
/// stack; `leaf(first, count)` answers the nearest `t` so far, or `None` to stop.
fn walk(
    nodes: &[BvhNode],
    root: u32,
    origin: Vec3,
    dir: Vec3,
    t_max: f32,
    mut leaf: impl FnMut(u32, u32) -> Option<f32>,
) -> Option<()> {
    if nodes.is_empty() {
        return Some(());
    }
    let inv_dir = dir.recip();
    let mut t_best = t_max;
    let mut stack = [0u32; MAX_STACK];
    let mut depth = 0;
    let mut node = root;
    loop {
        let n = &nodes[node as usize];
        if n.prim_count > 0 {
            t_best = leaf(n.first_index, n.prim_count)?;
        } else {
            let (a, b) = (n.first_index, n.first_index + 1);
            let ta = slab(&nodes[a as usize], origin, inv_dir, t_best);
            let tb = slab(&nodes[b as usize], origin, inv_dir, t_best);
            let (near, far, t_near, t_far) = if ta <= tb {
                (a, b, ta, tb)
            } else {
                (b, a, tb, ta)
            };
            if t_near < f32::INFINITY {
                if t_far < f32::INFINITY {
                    stack[depth] = far;
                    depth += 1;
                }
                node = near;
                continue;
            }
        }
        if depth == 0 {
            return Some(());
        }
        depth -= 1;
        node = stack[depth];
    }
}

/// Entry distance of the ray into the node's box, or infinity when it misses it or enters
/// beyond `t_max`.
fn slab(node: &BvhNode, origin: Vec3, inv_dir: Vec3, t_max: f32) -> f32 {
    let t0 = (Vec3::from(node.min) - origin) * inv_dir;
    let t1 = (Vec3::from(node.max) - origin) * inv_dir;
    let t_enter = t0.min(t1).max_element().max(0.0);
    let t_exit = t0.max(t1).min_element().min(t_max);
    if t_enter <= t_exit {
        t_enter
    } else {
        f32::INFINITY
    }
}

/// Möller–Trumbore, two-sided; hits at t ≤ 0 are ignored.
fn intersect_triangle(tri: &BvhTriangle, origin: Vec3, dir: Vec3) -> Option<Hit> {
    let v0 = Vec3::from(tri.v0);
    let e1 = Vec3::from(tri.v1) - v0;
    let e2 = Vec3::from_slice(&tri.v2[..3]) - v0;
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv_det = 1.0 / det;
    let s = origin - v0;
    let u = s.dot(p) * inv_det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = dir.dot(q) * inv_det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv_det;
    (t > 0.0).then_some(Hit {
        t,
        triangle: tri.scene_triangle,
        u,
        v,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::procedural;

    /// A deterministic stream of floats in [0, 1) (SplitMix64).
    pub(crate) struct Stream(u64);

    impl Stream {
        pub(crate) fn new(seed: u64) -> Self {
            Self(seed)
        }

        pub(crate) fn next(&mut self) -> f32 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
        }

        pub(crate) fn direction(&mut self) -> Vec3 {
            let z = 2.0 * self.next() - 1.0;
            let phi = std::f32::consts::TAU * self.next();
            let r = (1.0 - z * z).max(0.0).sqrt();
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        }
    }

    /// Random rays from inside and around the scene's bounds.
    pub(crate) fn rays(scene: &Scene, count: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
        let mut s = Stream::new(seed);
        let (lo, hi) = (scene.bounds.min, scene.bounds.max);
        let pad = (hi - lo) * 0.25;
        (0..count)
            .map(|_| {
                let f = Vec3::new(s.next(), s.next(), s.next());
                (lo - pad + (hi - lo + 2.0 * pad) * f, s.direction())
            })
            .collect()
    }

    fn check_against_brute_force(scene: &Scene) {
        let bvh = SceneBvh::build(scene).expect("bvh");
        assert_eq!(bvh.triangles.len(), scene.indices.len() / 3);
        let mut hits = 0;
        for (origin, dir) in rays(scene, 2000, 7) {
            let fast = bvh.intersect(origin, dir, f32::INFINITY);
            let slow = bvh.intersect_brute_force(origin, dir, f32::INFINITY);
            // The shadow query agrees with the nearest hit at the hit's distance and at half
            // and twice of it (a limit short of every hit and one past the first).
            let t = slow.map_or(1.0, |h| h.t);
            for limit in [0.5 * t, 2.0 * t, f32::INFINITY] {
                let want = bvh.intersect_brute_force(origin, dir, limit).is_some();
                assert_eq!(
                    bvh.occluded(origin, dir, limit),
                    want,
                    "ray {origin} {dir} to {limit}"
                );
            }
            match (fast, slow) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    hits += 1;
                    // Equal distances; the triangle may differ only where two share the hit
                    // (an edge).
                    assert!((a.t - b.t).abs() <= 1e-5 * b.t.max(1.0), "{a:?} vs {b:?}");
                }
                (a, b) => panic!("ray {origin} {dir}: BVH {a:?}, brute force {b:?}"),
            }
        }
        assert!(
            hits > 300,
            "only {hits} of 2000 rays hit: the test would prove little"
        );
    }

    #[test]
    fn traversal_finds_the_brute_force_hit_in_the_cornell_box() {
        check_against_brute_force(&procedural::cornell_box());
    }

    #[test]
    fn traversal_finds_the_brute_force_hit_in_a_street() {
        let street = procedural::street(&procedural::StreetParams {
            blocks: 2,
            ..Default::default()
        })
        .expect("street");
        check_against_brute_force(&street);
    }

    /// The Cornell box with its short box moved and turned: the bottom levels stay, the top
    /// level places the box's; its hits are those of the scene moved on the CPU.
    #[test]
    fn a_posed_top_level_finds_what_the_moved_scene_holds() {
        use crate::scene::nodes::{deltas, owners, posed_vertices, posed_worlds, resolve_poses};
        let scene = procedural::cornell_box();
        let base = scene
            .node(1)
            .and_then(|n| n.local)
            .expect("short box")
            .translation;
        let requested = [lightcast_protocol::NodePose {
            node: 1,
            translation: Some((base + Vec3::new(-0.5, 0.2, -0.3)).to_array()),
            rotation: Some(glam::Quat::from_rotation_y(0.8).to_array()),
            scale: Some([1.2, 0.8, 1.0]),
        }];
        let poses = resolve_poses(
            &scene.nodes,
            &scene.node_bounds(),
            &scene.bounds,
            &requested,
        )
        .expect("inside the room");
        let worlds = posed_worlds(&scene.nodes, &poses);
        let mut bvh = SceneBvh::build(&scene).expect("bvh");
        assert_eq!(bvh.levels.len(), 3, "the room and each box");
        let rest = bvh.clone();
        bvh.set_top(bvh.top_level(&scene.nodes, &worlds));
        let mut moved = scene.clone();
        let owner = owners(&scene.nodes, scene.vertices.len() as u32);
        let all = 0..scene.vertices.len() as u32;
        moved.vertices =
            posed_vertices(&scene.vertices, &owner, &deltas(&scene.nodes, &worlds), all);
        let truth = SceneBvh::build(&moved).expect("bvh");
        let (mut hits, mut changed) = (0, 0);
        for (origin, dir) in rays(&scene, 3000, 5) {
            let got = bvh.intersect(origin, dir, f32::INFINITY);
            let want = truth.intersect_brute_force(origin, dir, f32::INFINITY);
            match (got, want) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    hits += 1;
                    assert!((a.t - b.t).abs() <= 1e-4 * b.t.max(1.0), "{a:?} vs {b:?}");
                }
                (a, b) => panic!("ray {origin} {dir}: posed {a:?}, moved scene {b:?}"),
            }
            let t = want.map_or(1.0, |h| h.t);
            for limit in [0.5 * t, 2.0 * t] {
                assert_eq!(
                    bvh.occluded(origin, dir, limit),
                    truth.intersect_brute_force(origin, dir, limit).is_some()
                );
            }
            let at_rest = rest.intersect(origin, dir, f32::INFINITY).map(|h| h.t);
            changed += usize::from(at_rest != want.map(|h| h.t));
        }
        assert!(
            hits > 300 && changed > 30,
            "{hits} hits, {changed} changed by the move"
        );
    }

    #[test]
    fn triangles_of_masked_materials_are_flagged_for_the_alpha_test() {
        let mut scene = procedural::cornell_box();
        scene.materials[0].alpha_cutoff = Some(0.5);
        let bvh = SceneBvh::build(&scene).expect("bvh");
        let mut flagged = 0;
        for t in &bvh.triangles {
            let first = scene.indices[3 * t.scene_triangle as usize];
            let masked = scene.vertices[first as usize].material == 0;
            assert_eq!(t.alpha_tested, u32::from(masked), "{t:?}");
            flagged += usize::from(masked);
        }
        assert!(flagged > 0 && flagged < bvh.triangles.len());
    }

    #[test]
    fn a_limited_ray_stops_before_its_end() {
        let scene = procedural::cornell_box();
        let bvh = SceneBvh::build(&scene).expect("bvh");
        for (origin, dir) in rays(&scene, 500, 11) {
            if let Some(hit) = bvh.intersect_brute_force(origin, dir, f32::INFINITY) {
                assert_eq!(bvh.intersect(origin, dir, hit.t * 0.999), None);
            }
        }
    }
}
