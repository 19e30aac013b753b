//! The scene's triangles in a bounding volume hierarchy, for the reference path tracer.
//!
//! Built on the CPU with `obvhs` (PLOC with reinsertion: a well-kept builder made for GPU
//! traversal, and faster than a hand-written binned SAH), then flattened into 32-byte nodes the
//! WGSL traversal (`shaders/bvh.wgsl`) reads. Triangles are stored in leaf order so a
//! leaf's triangles are contiguous. [`SceneBvh::intersect`] is the CPU port of that traversal
//! and [`SceneBvh::intersect_brute_force`] the independent check it is tested against. Both
//! are geometry only: the WGSL traversal also skips hits on alpha-masked texels, which needs
//! the materials and textures (`shaders/reference/surfaces.wgsl`).

use crate::scene::Scene;
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// Mirrors `BvhNode` in `shaders/bvh.wgsl`. An inner node (`prim_count` 0) has its
/// children at `first_index` and `first_index + 1`; a leaf's triangles are
/// `first_index .. first_index + prim_count` of [`SceneBvh::triangles`].
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

/// Deepest traversal stack the WGSL traversal keeps; [`SceneBvh::build`] refuses deeper trees.
pub const MAX_STACK: usize = 48;

#[derive(Debug, thiserror::Error)]
pub enum BvhError {
    #[error("the scene's BVH is {depth} levels deep; the traversal supports {MAX_STACK}")]
    TooDeep { depth: usize },
}

/// Reference ns per triangle of [`SceneBvh::build`] (binned SAH): about 2 s for the
/// 1.2 M-triangle street. Every precomputation that builds one counts it with this.
pub const BUILD_NS_PER_TRIANGLE: f64 = 1700.0;

/// Nodes and leaf-ordered triangles of a scene.
#[derive(Clone, Debug, Default)]
pub struct SceneBvh {
    pub nodes: Vec<BvhNode>,
    pub triangles: Vec<BvhTriangle>,
}

impl SceneBvh {
    pub fn build(scene: &Scene) -> Result<Self, BvhError> {
        // obvhs's triangle is three 16-byte glam `Vec3A`s; built from plain floats so this crate
        // does not need obvhs's glam version by name.
        let alpha_tested: Vec<u32> = scene
            .indices
            .chunks_exact(3)
            .map(|t| {
                let material = scene.vertices[t[0] as usize].material;
                u32::from(scene.materials[material as usize].alpha_cutoff.is_some())
            })
            .collect();
        let input: Vec<obvhs::triangle::Triangle> = scene
            .indices
            .chunks_exact(3)
            .map(|t| {
                let mut f = [0f32; 12];
                for (k, &i) in t.iter().enumerate() {
                    f[4 * k..4 * k + 3].copy_from_slice(&scene.vertices[i as usize].position);
                }
                bytemuck::cast(f)
            })
            .collect();
        if input.is_empty() {
            return Ok(Self::default());
        }
        let mut build_time = std::time::Duration::ZERO;
        let bvh = obvhs::bvh2::builder::build_bvh2_from_tris(
            &input,
            obvhs::BvhBuildParams::medium_build(),
            &mut build_time,
        );
        let triangles: Vec<BvhTriangle> = bvh
            .primitive_indices
            .iter()
            .map(|&i| {
                let f: [f32; 12] = bytemuck::cast(input[i as usize]);
                BvhTriangle {
                    v0: [f[0], f[1], f[2]],
                    scene_triangle: i,
                    v1: [f[4], f[5], f[6]],
                    alpha_tested: alpha_tested[i as usize],
                    v2: [f[8], f[9], f[10], 0.0],
                }
            })
            .collect();
        let nodes: Vec<BvhNode> = bvh
            .nodes
            .iter()
            .map(|n| BvhNode {
                min: n.aabb.min.to_array(),
                prim_count: n.prim_count,
                max: n.aabb.max.to_array(),
                first_index: n.first_index,
            })
            .collect();
        let built = Self { nodes, triangles };
        let depth = built.depth(0);
        if depth > MAX_STACK {
            return Err(BvhError::TooDeep { depth });
        }
        Ok(built)
    }

    fn depth(&self, node: usize) -> usize {
        let n = &self.nodes[node];
        if n.prim_count > 0 {
            1
        } else {
            let first = n.first_index as usize;
            1 + self.depth(first).max(self.depth(first + 1))
        }
    }

    /// The nearest hit with `t` in (0, `t_max`), walking the tree as the WGSL traversal does:
    /// the nearer child first, a stack for the other.
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<Hit> {
        self.traverse(origin, dir, t_max, false)
    }

    /// The nearest hit before `t_max`, or with `any` the first one found.
    fn traverse(&self, origin: Vec3, dir: Vec3, t_max: f32, any: bool) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        let inv_dir = dir.recip();
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        let mut stack = [0u32; MAX_STACK];
        let mut depth = 0;
        let mut node = 0u32;
        loop {
            let n = &self.nodes[node as usize];
            if n.prim_count > 0 {
                for i in n.first_index..n.first_index + n.prim_count {
                    if let Some(hit) = intersect_triangle(&self.triangles[i as usize], origin, dir)
                    {
                        if hit.t < t_best {
                            if any {
                                return Some(hit);
                            }
                            t_best = hit.t;
                            best = Some(hit);
                        }
                    }
                }
            } else {
                let (a, b) = (n.first_index, n.first_index + 1);
                let ta = slab(&self.nodes[a as usize], origin, inv_dir, t_best);
                let tb = slab(&self.nodes[b as usize], origin, inv_dir, t_best);
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
                return best;
            }
            depth -= 1;
            node = stack[depth];
        }
    }

    /// Whether anything lies on the ray before `t_max`: a shadow ray, which stops at the
    /// first hit instead of looking for the nearest (visibility between two points, as a
    /// precomputation's rays trace it).
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_max: f32) -> bool {
        self.traverse(origin, dir, t_max, true).is_some()
    }

    /// The nearest hit by testing every triangle (the check for [`Self::intersect`]).
    pub fn intersect_brute_force(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<Hit> {
        self.triangles
            .iter()
            .filter_map(|t| intersect_triangle(t, origin, dir))
            .filter(|h| h.t < t_max)
            .min_by(|a, b| a.t.total_cmp(&b.t))
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
