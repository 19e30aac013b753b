//! Surfel hierarchy (seed 001, "Surfel Clustering and Tree Metric"): a binary tree over the
//! surfels built by exact greedy hierarchical agglomerative clustering (HAC) with the paper's
//! tree metric
//!
//!   d(a,b) = ‖x_a−x_b‖²/Ē² + C_n(1−⟨n_a,n_b⟩) + C_b·|A_a−A_b|/max(A_a,A_b),
//!
//! x the area-weighted mean position, n the normalised area-weighted normal sum, A the area.
//!
//! The paper runs Müllner's generic algorithm on the O(n²) distance matrix (4 GB at 32k
//! surfels). d is not reducible (the spatial term is centroid linkage, which has inversions, and
//! the normal and balance terms can drop after a merge), so the nearest-neighbour chain would be
//! wrong. We run the heap form of Walter et al. 2008 instead: a lazy min-heap of each cluster's
//! nearest neighbour, found exactly in a dynamic R*-tree with the spatial term as a lower bound.
//! Memory is O(n) and the merge sequence equals the O(n³) greedy's (see `cluster` below).
//!
//! The output is the same whatever the thread count: the parallel first pass is concatenated in
//! order and the heap pops in a total order, (d, smaller id, larger id).

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use rstar::{primitives::GeomWithData, RTree};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// C_n and C_b of the tree metric. The default is the paper's "C_n = 0.1 and C_b = 0.02 worked
/// well for all our scenes".
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterWeights {
    /// C_n: keeps opposite faces (the two sides of a wall) apart until late.
    pub normal: f64,
    /// C_b: penalises unbalanced merges, which keeps the tree, and so the runtime pull with one
    /// pass per level, shallow.
    pub balance: f64,
}

impl Default for ClusterWeights {
    fn default() -> Self {
        Self {
            normal: 0.1,
            balance: 0.02,
        }
    }
}

/// One surfel as input: position, geometric normal and area.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Leaf {
    pub position: Vec3,
    pub normal: Vec3,
    pub area: f32,
}

/// The cluster tree. Node ids: leaves 0..n in DFS (left-to-right) order, so every node's leaves
/// are contiguous; internal nodes n..2n-1 in merge order (children < parent); the root is last.
#[derive(Clone, Debug, PartialEq)]
pub struct Tree {
    /// Per internal node (index id - n).
    pub children: Vec<[u32; 2]>,
    /// Per node; `u32::MAX` for the root.
    pub parent: Vec<u32>,
    /// Per node: its leaves are `first_leaf..first_leaf + leaf_count`.
    pub first_leaf: Vec<u32>,
    pub leaf_count: Vec<u32>,
    /// Per node: x, n (zero where the normals cancel) and A of the metric.
    pub centre: Vec<Vec3>,
    pub normal: Vec<Vec3>,
    pub area: Vec<f32>,
    /// Per internal node: d at its merge. Not monotone: centroid linkage has inversions.
    pub merge_distance: Vec<f32>,
    /// `leaf_order[k]` = index into the caller's input of the k-th leaf.
    pub leaf_order: Vec<u32>,
    /// Internal nodes by height: level l (height l + 1) is
    /// `by_level[level_offsets[l]..level_offsets[l + 1]]`. All children of a level lie in lower
    /// levels, so pulling flux up is one GPU pass per level.
    pub level_offsets: Vec<u32>,
    pub by_level: Vec<u32>,
}

/// Why no tree was built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum HierarchyError {
    #[error("there are no surfels to cluster")]
    Empty,
    #[error("cancelled: the scene was deleted, or nobody waits for the set any more")]
    Cancelled,
    #[error("surfel {index} has a non-finite position or normal, or an area that is not > 0")]
    InvalidLeaf { index: usize },
    #[error("the scene extent {0} is not > 0 with a finite, normal square")]
    InvalidExtent(f64),
    #[error("the weights {0:?} are not finite and >= 0")]
    InvalidWeights(ClusterWeights),
    #[error("{0} surfels are too many for u32 node ids")]
    TooMany(usize),
}

/// Merges between progress reports and cancellation checks.
const MERGES_PER_CHECK: usize = 1024;
/// Clusters per parallel chunk of the first nearest-neighbour pass (a cancellation check each).
const CHUNK: usize = 4096;

type Point = GeomWithData<[f64; 3], u32>;

/// One merge: (smaller id, larger id, d); the merged cluster's id is n + the merge's index.
type Merge = (u32, u32, f64);

/// A heap entry: `owner`'s nearest neighbour when it was computed, and their d. The derived order
/// is (d, smaller id, larger id, owner): d ≥ +0 (every term is), and the bits of such floats order
/// like `total_cmp`. For a fixed owner it orders neighbours by (d, id), so a nearest neighbour
/// under (d, id) is the owner's smallest pair; `owner` last only makes the order total.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Candidate {
    d_bits: u64,
    low: u32,
    high: u32,
    owner: u32,
}

impl Candidate {
    fn new(d: f64, owner: u32, other: u32) -> Self {
        let (low, high) = (owner.min(other), owner.max(other));
        Self {
            d_bits: d.to_bits(),
            low,
            high,
            owner,
        }
    }

    fn other(self) -> u32 {
        if self.owner == self.low {
            self.high
        } else {
            self.low
        }
    }
}

/// A cluster of the metric, in f64.
#[derive(Clone, Copy)]
struct Cluster {
    position: DVec3,
    normal_sum: DVec3,
    normal: DVec3,
    area: f64,
    alive: bool,
}

impl Cluster {
    fn new(position: DVec3, normal_sum: DVec3, area: f64) -> Self {
        // A cancelling sum (the paper leaves it open) gets n = 0, so the normal term is C_n.
        // Division rather than `normalize` keeps parallel sums exactly unit: ties stay exact.
        let len = normal_sum.length();
        let normal = if len < 1e-6 * area {
            DVec3::ZERO
        } else {
            normal_sum / len
        };
        Self {
            position,
            normal_sum,
            normal,
            area,
            alive: true,
        }
    }

    fn merged(a: &Self, b: &Self) -> Self {
        let area = a.area + b.area;
        let position = (a.position * a.area + b.position * b.area) / area;
        Self::new(position, a.normal_sum + b.normal_sum, area)
    }

    fn point(&self, id: u32) -> Point {
        Point::new(self.position.to_array(), id)
    }
}

/// The tree metric: Ē² and the weights.
struct Metric {
    extent2: f64,
    weights: ClusterWeights,
}

impl Metric {
    /// d(a, b) given ‖x_a−x_b‖². The cosine term is clamped against rounding, so every term is
    /// ≥ 0 and the spatial term alone is a lower bound.
    fn distance(&self, dist2: f64, a: &Cluster, b: &Cluster) -> f64 {
        let w = self.weights;
        dist2 / self.extent2
            + w.normal * (1.0 - a.normal.dot(b.normal)).max(0.0)
            + w.balance * (a.area - b.area).abs() / a.area.max(b.area)
    }

    /// Exact nearest neighbour of `owner` under (d, id), if any other cluster is alive: branch
    /// and bound over the centres in increasing distance, until the bound exceeds the best d
    /// strictly (an equal bound can still win on the id).
    fn nearest(&self, clusters: &[Cluster], tree: &RTree<Point>, owner: u32) -> Option<Candidate> {
        let a = &clusters[owner as usize];
        let mut best: Option<(f64, Candidate)> = None;
        for (point, dist2) in tree.nearest_neighbor_iter_with_distance_2(a.position.to_array()) {
            if best.is_some_and(|(d, _)| dist2 / self.extent2 > d) {
                break;
            }
            if point.data != owner {
                let d = self.distance(dist2, a, &clusters[point.data as usize]);
                let found = Candidate::new(d, owner, point.data);
                if best.is_none_or(|(_, b)| found < b) {
                    best = Some((d, found));
                }
            }
        }
        best.map(|(_, c)| c)
    }
}

/// Builds the hierarchy over `leaves`. `extent` is Ē, the diagonal of the scene's bounds (the
/// paper's "maximum scene extent"). `progress(merges done, n - 1)` is called every 1024 merges,
/// when `cancelled` is also checked.
pub fn build(
    leaves: &[Leaf],
    extent: f64,
    weights: ClusterWeights,
    progress: &mut dyn FnMut(u64, u64),
    cancelled: &dyn Fn() -> bool,
) -> Result<Tree, HierarchyError> {
    let (clusters, merges) = cluster(leaves, extent, weights, progress, cancelled)?;
    Ok(assemble(&clusters, &merges))
}

/// Greedy HAC: all clusters and the merges in order. Exact for any symmetric d: let (p, q) be
/// the smallest live pair in the heap order, q the newer. q's entry was last computed while p
/// was alive, so it is ≤ (p, q); if smaller, it names a dead cluster and is recomputed when
/// popped. So (p, q) merges before any other pair, as in the O(n³) greedy.
fn cluster(
    leaves: &[Leaf],
    extent: f64,
    weights: ClusterWeights,
    progress: &mut dyn FnMut(u64, u64),
    cancelled: &dyn Fn() -> bool,
) -> Result<(Vec<Cluster>, Vec<Merge>), HierarchyError> {
    let n = leaves.len();
    if n == 0 {
        return Err(HierarchyError::Empty);
    }
    if n > (u32::MAX / 2) as usize {
        return Err(HierarchyError::TooMany(n));
    }
    // Ē² must be a normal float too, or the spatial term turns into ∞ or NaN.
    if !(extent > 0.0 && (extent * extent).is_normal()) {
        return Err(HierarchyError::InvalidExtent(extent));
    }
    if ![weights.normal, weights.balance]
        .iter()
        .all(|w| *w >= 0.0 && w.is_finite())
    {
        return Err(HierarchyError::InvalidWeights(weights));
    }
    let metric = Metric {
        extent2: extent * extent,
        weights,
    };
    let mut clusters = Vec::with_capacity(2 * n - 1);
    for (index, leaf) in leaves.iter().enumerate() {
        let area = f64::from(leaf.area);
        let finite = leaf.position.is_finite() && leaf.normal.is_finite() && area.is_finite();
        if !(finite && area > 0.0) {
            return Err(HierarchyError::InvalidLeaf { index });
        }
        let (position, normal) = (leaf.position.as_dvec3(), leaf.normal.as_dvec3());
        clusters.push(Cluster::new(position, normal * area, area));
    }
    let total = n as u64 - 1;
    progress(0, total);

    let mut tree = RTree::bulk_load(
        clusters
            .iter()
            .zip(0..)
            .map(|(c, id)| c.point(id))
            .collect(),
    );
    let mut heap = BinaryHeap::with_capacity(2 * n);
    for start in (0..n).step_by(CHUNK) {
        if cancelled() {
            return Err(HierarchyError::Cancelled);
        }
        let ids = start as u32..(start + CHUNK).min(n) as u32;
        let nearest = |a| metric.nearest(&clusters, &tree, a);
        let found: Vec<_> = ids.into_par_iter().filter_map(nearest).collect();
        heap.extend(found.into_iter().map(Reverse));
    }

    let mut merges: Vec<Merge> = Vec::with_capacity(n - 1);
    while let Some(Reverse(top)) = heap.pop() {
        let (a, b) = (top.owner as usize, top.other() as usize);
        if !clusters[a].alive {
            continue;
        }
        if !clusters[b].alive {
            // Stale: the neighbour has merged since. Look again.
            heap.extend(metric.nearest(&clusters, &tree, top.owner).map(Reverse));
            continue;
        }
        for id in [a, b] {
            let removed = tree.remove(&clusters[id].point(id as u32));
            debug_assert!(removed.is_some(), "cluster {id} is not in the R*-tree");
            clusters[id].alive = false;
        }
        let id = clusters.len() as u32;
        clusters.push(Cluster::merged(&clusters[a], &clusters[b]));
        tree.insert(clusters[id as usize].point(id));
        merges.push((top.low, top.high, f64::from_bits(top.d_bits)));
        heap.extend(metric.nearest(&clusters, &tree, id).map(Reverse));
        if merges.len().is_multiple_of(MERGES_PER_CHECK) {
            progress(merges.len() as u64, total);
            if cancelled() {
                return Err(HierarchyError::Cancelled);
            }
        }
    }
    debug_assert_eq!(merges.len(), n - 1, "a live cluster lost its heap entry");
    progress(total, total);
    Ok((clusters, merges))
}

/// Renumbers the leaves in DFS order and fills the per-node arrays and the levels.
fn assemble(clusters: &[Cluster], merges: &[Merge]) -> Tree {
    let (n, nodes) = (merges.len() + 1, clusters.len());
    // Iterative DFS (a chain-like tree is n deep), left child first.
    let mut new_id: Vec<u32> = (0..nodes as u32).collect();
    let mut leaf_order = Vec::with_capacity(n);
    let mut stack = vec![nodes - 1];
    while let Some(v) = stack.pop() {
        if v < n {
            new_id[v] = leaf_order.len() as u32;
            leaf_order.push(v as u32);
        } else {
            let (left, right, _) = merges[v - n];
            stack.extend([right as usize, left as usize]);
        }
    }
    let children: Vec<[u32; 2]> = merges
        .iter()
        .map(|&(l, r, _)| [new_id[l as usize], new_id[r as usize]])
        .collect();

    let mut parent = vec![u32::MAX; nodes];
    let mut first_leaf: Vec<u32> = (0..nodes as u32).collect();
    let mut leaf_count = vec![1u32; nodes];
    let mut height = vec![0u32; nodes];
    for (v, &[l, r]) in (n..).zip(&children) {
        let (l, r) = (l as usize, r as usize);
        (parent[l], parent[r]) = (v as u32, v as u32);
        first_leaf[v] = first_leaf[l];
        leaf_count[v] = leaf_count[l] + leaf_count[r];
        height[v] = 1 + height[l].max(height[r]);
    }
    let mut by_level: Vec<u32> = (n as u32..nodes as u32).collect();
    by_level.sort_by_key(|&v| (height[v as usize], v));
    // Count the nodes of each height h at index h, then prefix-sum into the level starts.
    let mut level_offsets = vec![0u32; height[nodes - 1] as usize + 1];
    for &v in &by_level {
        level_offsets[height[v as usize] as usize] += 1;
    }
    for l in 1..level_offsets.len() {
        level_offsets[l] += level_offsets[l - 1];
    }

    let node = |k: usize| &clusters[if k < n { leaf_order[k] as usize } else { k }];
    Tree {
        children,
        parent,
        first_leaf,
        leaf_count,
        centre: (0..nodes).map(|k| node(k).position.as_vec3()).collect(),
        normal: (0..nodes).map(|k| node(k).normal.as_vec3()).collect(),
        area: (0..nodes).map(|k| node(k).area as f32).collect(),
        merge_distance: merges.iter().map(|m| m.2 as f32).collect(),
        leaf_order,
        level_offsets,
        by_level,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::cell::Cell;

    fn leaf(p: [f32; 3], n: [f32; 3], a: f32) -> Leaf {
        Leaf {
            position: p.into(),
            normal: n.into(),
            area: a,
        }
    }

    const UP: [f32; 3] = [0.0, 0.0, 1.0];

    /// A unit-area surfel facing +z.
    fn at(x: f32, y: f32) -> Leaf {
        leaf([x, y, 0.0], UP, 1.0)
    }

    fn merges_of(leaves: &[Leaf], extent: f64, w: ClusterWeights) -> Vec<Merge> {
        let merges = cluster(leaves, extent, w, &mut |_, _| {}, &|| false);
        merges.expect("valid input").1
    }

    fn tree_of(leaves: &[Leaf], extent: f64) -> Result<Tree, HierarchyError> {
        let w = ClusterWeights::default();
        build(leaves, extent, w, &mut |_, _| {}, &|| false)
    }

    /// Same id pairs (ids are given in merge order, so equal id sequences are equal sequences of
    /// pairs of input-index sets) and heights within `rel`.
    fn assert_merges(got: &[Merge], want: &[Merge], rel: f64) {
        assert_eq!(got.len(), want.len());
        for (step, (g, w)) in got.iter().zip(want).enumerate() {
            assert_eq!((g.0, g.1), (w.0, w.1), "step {step}: {got:?} vs {want:?}");
            let close = (g.2 - w.2).abs() <= rel * w.2.abs();
            assert!(close, "step {step}: {g:?} vs {w:?}");
        }
    }

    /// O(n³) greedy from the definition: merge the smallest live pair by (d, min id, max id).
    fn brute_force(leaves: &[Leaf], extent: f64, w: ClusterWeights) -> Vec<Merge> {
        let unit = |s: DVec3, a: f64| (s.length() >= 1e-6 * a).then(|| s / s.length());
        let unit = |s, a| unit(s, a).unwrap_or_default();
        let sum = |l: &Leaf| l.normal.as_dvec3() * f64::from(l.area);
        let mut c: Vec<(DVec3, DVec3, f64)> = (leaves.iter())
            .map(|l| (l.position.as_dvec3(), sum(l), f64::from(l.area)))
            .collect();
        let (mut live, mut out): (Vec<usize>, _) = ((0..c.len()).collect(), Vec::new());
        while live.len() > 1 {
            let mut best = (f64::INFINITY, 0, 0);
            for (i, &a) in live.iter().enumerate() {
                for &b in &live[i + 1..] {
                    let ((xa, sa, aa), (xb, sb, ab)) = (c[a], c[b]);
                    let cos = unit(sa, aa).dot(unit(sb, ab));
                    let d = (xa - xb).length_squared() / (extent * extent)
                        + w.normal * (1.0 - cos).max(0.0)
                        + w.balance * (aa - ab).abs() / aa.max(ab);
                    // d ≥ 0 is never NaN, so the tuple order is (d, a, b) with a < b.
                    if (d, a, b) < best {
                        best = (d, a, b);
                    }
                }
            }
            let (d, a, b) = best;
            let ((xa, sa, aa), (xb, sb, ab)) = (c[a], c[b]);
            c.push(((xa * aa + xb * ab) / (aa + ab), sa + sb, aa + ab));
            live.retain(|&k| k != a && k != b);
            live.push(c.len() - 1);
            out.push((a as u32, b as u32, d));
        }
        out
    }

    fn check_invariants(leaves: &[Leaf], t: &Tree) {
        let (n, nodes) = (leaves.len(), 2 * leaves.len() - 1);
        assert_eq!(
            [t.parent.len(), t.first_leaf.len(), t.leaf_count.len()],
            [nodes; 3]
        );
        assert_eq!([t.centre.len(), t.normal.len(), t.area.len()], [nodes; 3]);
        assert_eq!((t.children.len(), t.merge_distance.len()), (n - 1, n - 1));
        let mut seen = vec![false; n];
        for (k, &i) in t.leaf_order.iter().enumerate() {
            assert!(!std::mem::replace(&mut seen[i as usize], true));
            let want = (k as u32, 1, leaves[i as usize].position);
            assert_eq!((t.first_leaf[k], t.leaf_count[k], t.centre[k]), want);
        }
        assert!(seen.iter().all(|&s| s), "every leaf once");
        for (v, &[l, r]) in (n..).zip(&t.children) {
            let (l, r) = (l as usize, r as usize);
            assert!(l < v && r < v && t.parent[l] == v as u32 && t.parent[r] == v as u32);
            assert_eq!(t.first_leaf[v], t.first_leaf[l]);
            assert_eq!(t.first_leaf[r], t.first_leaf[l] + t.leaf_count[l]);
            assert_eq!(t.leaf_count[v], t.leaf_count[l] + t.leaf_count[r]);
        }
        let root = t.parent.iter().position(|&p| p == u32::MAX);
        assert_eq!(root, Some(nodes - 1));
        let root = (t.first_leaf[nodes - 1], t.leaf_count[nodes - 1]);
        assert_eq!(root, (0, n as u32));
        let sum: f64 = leaves.iter().map(|l| f64::from(l.area)).sum();
        let error = (f64::from(t.area[nodes - 1]) - sum).abs();
        assert!(error <= 1e-6 * sum, "root area off by {error}");
        // Levels: non-empty, each internal node once, at 1 + its highest child's level.
        let mut level = vec![0usize; nodes];
        let offsets = &t.level_offsets;
        assert_eq!((offsets[0], offsets.last()), (0, Some(&(n as u32 - 1))));
        for (l, range) in offsets.windows(2).enumerate() {
            assert!(range[0] < range[1], "empty level {l}");
            for &v in &t.by_level[range[0] as usize..range[1] as usize] {
                assert_eq!(std::mem::replace(&mut level[v as usize], l + 1), 0);
            }
        }
        for (v, &[l, r]) in (n..).zip(&t.children) {
            assert_eq!(level[v], 1 + level[l as usize].max(level[r as usize]));
        }
    }

    /// SplitMix64 in [0, 1): deterministic test data without a `rand` dependency.
    struct SplitMix(u64);

    impl SplitMix {
        fn unit(&mut self) -> f32 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let z = (self.0 ^ (self.0 >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            let z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// `n` unit-area surfels on four noisy planes of a 10-unit room (floor, two walls and a
    /// tilted slab), and the diagonal of their bounds.
    fn noisy_planes(n: usize, seed: u64) -> (Vec<Leaf>, f64) {
        let mut rng = SplitMix(seed);
        let (slab, tilt) = (Vec3::new(2.0, 2.0, 3.0), Vec3::new(6.0, 0.0, 2.0));
        let planes = [
            (Vec3::ZERO, Vec3::X * 10.0, Vec3::Y * 10.0),
            (Vec3::ZERO, Vec3::Y * 10.0, Vec3::Z * 10.0),
            (Vec3::Y * 10.0, Vec3::Z * 10.0, Vec3::X * 10.0),
            (slab, tilt, Vec3::Y * 6.0),
        ];
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        let mut leaves = Vec::with_capacity(n);
        for i in 0..n {
            let (origin, u, v) = planes[i % planes.len()];
            let normal = u.cross(v).normalize();
            let noise = normal * (0.01 * (rng.unit() - 0.5));
            let p = origin + u * rng.unit() + v * rng.unit() + noise;
            (lo, hi) = (lo.min(p), hi.max(p));
            leaves.push(leaf(p.into(), normal.into(), 1.0));
        }
        (leaves, f64::from((hi - lo).length()))
    }

    // The spec's hand-worked cases; 1e-6 relative because the inputs are f32 (1.1f32 ≠ 1.1).
    #[test]
    fn case_a_the_balance_term_reorders_a_line() {
        let line = [at(0.0, 0.0), at(0.5, 0.0), at(1.1, 0.0), at(2.2, 0.0)];
        // d({a,b}, c) = 0.85²/100 + 0.02·½ = 0.017225 > d(c, e) = 1.1²/100.
        let want = [(0, 1, 0.0025), (2, 3, 0.0121), (4, 5, 0.0196)];
        let w = ClusterWeights::default();
        assert_merges(&merges_of(&line, 10.0, w), &want, 1e-6);
        // Without C_b, {a,b} + c is second, and e meets the centroid 1.6/3 at (5/3)²/100 = 1/36.
        let want = [(0, 1, 0.0025), (2, 4, 0.007225), (3, 5, 1.0 / 36.0)];
        let w = ClusterWeights { balance: 0.0, ..w };
        assert_merges(&merges_of(&line, 10.0, w), &want, 1e-6);
    }

    #[test]
    fn case_b_the_normal_term_keeps_opposite_faces_apart() {
        let (up, down) = ([0.0, 1.0, 0.0], [0.0, -1.0, 0.0]);
        let leaves = [
            leaf([0.0; 3], up, 1.0),
            leaf([0.1, 0.0, 0.0], down, 1.0),
            leaf([0.5, 0.0, 0.0], up, 1.0),
        ];
        // a + c (0.0025) beats a + b (0.2001); b joins at 0.15²/100 + 0.1·2 + 0.02·½.
        let want = [(0, 2, 0.0025), (1, 3, 0.210225)];
        let w = ClusterWeights::default();
        assert_merges(&merges_of(&leaves, 10.0, w), &want, 1e-6);
    }

    #[test]
    fn case_c_an_inversion_and_the_dfs_order() {
        let leaves = [at(-1.0, 0.0), at(1.0, 0.0), at(0.0, 1.8)];
        let want = [(0, 1, 4.0), (2, 3, 3.25)];
        let w = ClusterWeights::default();
        assert_merges(&merges_of(&leaves, 1.0, w), &want, 1e-6);
        let t = tree_of(&leaves, 1.0).expect("valid input");
        check_invariants(&leaves, &t);
        // The root's children are k and {i, j}, so DFS renumbers k, i, j as 0, 1, 2.
        assert_eq!(
            (t.leaf_order, t.children),
            (vec![2, 0, 1], vec![[1, 2], [0, 3]])
        );
        assert_eq!((t.level_offsets, t.by_level), (vec![0, 1, 2], vec![3, 4]));
    }

    #[test]
    fn cancelling_normals_give_a_zero_normal() {
        let mut down = at(0.0, 0.0);
        down.normal = -down.normal;
        let t = tree_of(&[at(0.0, 0.0), down], 1.0).expect("valid input");
        assert_eq!((t.normal[2], t.merge_distance[0]), (Vec3::ZERO, 0.2));
    }

    /// Integer coordinates, one normal, areas 1 or 2: many exact ties, to check the tie order.
    fn tied_case() -> impl Strategy<Value = (Vec<Leaf>, f64)> {
        let cell =
            |(x, y, z, a): (i8, i8, i8, u8)| leaf([x.into(), y.into(), z.into()], UP, a.into());
        let cells = prop::collection::vec((-2i8..=2, -2i8..=2, 0i8..=1, 1u8..=2), 2..=60);
        cells.prop_map(move |v| (v.into_iter().map(cell).collect(), 4.0))
    }

    fn random_case() -> impl Strategy<Value = (Vec<Leaf>, f64)> {
        let v3 = || [-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0];
        let leaves = prop::collection::vec((v3(), v3(), 0.25f32..4.0), 2..=60);
        let leaves = leaves.prop_map(|v| v.into_iter().map(|(p, n, a)| leaf(p, n, a)).collect());
        (leaves, 0.5f64..8.0)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn merges_equal_the_brute_force_greedy(
            (leaves, extent) in prop_oneof![tied_case(), random_case()]
        ) {
            let w = ClusterWeights::default();
            assert_merges(&merges_of(&leaves, extent, w), &brute_force(&leaves, extent, w), 1e-9);
            check_invariants(&leaves, &tree_of(&leaves, extent).expect("valid input"));
        }
    }

    #[test]
    fn centroid_linkage_equals_kodama() {
        let mut rng = SplitMix(7);
        let mut point = || [rng.unit(), rng.unit(), rng.unit()];
        let leaves: Vec<Leaf> = (0..300).map(|_| leaf(point(), UP, 1.0)).collect();
        let mut condensed = Vec::new();
        for (i, a) in leaves.iter().enumerate() {
            let a = a.position.as_dvec3();
            let to = |b: &Leaf| a.distance(b.position.as_dvec3());
            condensed.extend(leaves[i + 1..].iter().map(to));
        }
        // With C_n = C_b = 0 and equal areas d is centroid linkage on squared distances. kodama
        // squares the Euclidean input for Centroid (where Lance–Williams is exact) and returns the
        // roots of the heights.
        let dendrogram = kodama::linkage(&mut condensed, leaves.len(), kodama::Method::Centroid);
        let want: Vec<Merge> = (dendrogram.steps().iter())
            .map(|s| {
                (
                    s.cluster1 as u32,
                    s.cluster2 as u32,
                    s.dissimilarity.powi(2),
                )
            })
            .collect();
        let mut w = ClusterWeights::default();
        (w.normal, w.balance) = (0.0, 0.0);
        assert_merges(&merges_of(&leaves, 1.0, w), &want, 1e-9);
    }

    #[test]
    fn the_tree_is_the_same_for_any_thread_count() {
        let (leaves, extent) = noisy_planes(5000, 2);
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads);
            let pool = pool.build().expect("thread pool");
            pool.install(|| tree_of(&leaves, extent))
        };
        let one = run(1).expect("valid input");
        check_invariants(&leaves, &one);
        assert_eq!(Ok(one), run(3));
    }

    #[test]
    fn cancellation_is_checked_every_1024_merges() {
        let (leaves, extent) = noisy_planes(3000, 3);
        let (calls, mut last) = (Cell::new(0), (0, 0));
        let cancelled = || {
            calls.set(calls.get() + 1);
            calls.get() > 1
        };
        let mut progress = |done, total| last = (done, total);
        let w = ClusterWeights::default();
        let result = build(&leaves, extent, w, &mut progress, &cancelled);
        assert_eq!(result, Err(HierarchyError::Cancelled));
        assert_eq!(last, (1024, 2999));
    }

    #[test]
    fn bad_input_is_rejected_and_one_leaf_is_a_tree() {
        use HierarchyError::*;
        let good = at(0.0, 0.0);
        assert_eq!(tree_of(&[], 1.0), Err(Empty));
        let mut bad = [good; 4];
        bad[2].position.y = f32::NAN;
        assert_eq!(tree_of(&bad, 1.0), Err(InvalidLeaf { index: 2 }));
        (bad[2], bad[3].area) = (good, 0.0);
        assert_eq!(tree_of(&bad, 1.0), Err(InvalidLeaf { index: 3 }));
        assert_eq!(tree_of(&[good; 2], 0.0), Err(InvalidExtent(0.0)));
        check_invariants(&[good], &tree_of(&[good], 1.0).expect("one leaf is a tree"));
    }

    #[test]
    #[ignore = "timing: cargo test --release -- --ignored --nocapture"]
    fn timing_32k_surfels_on_noisy_planes() {
        let (leaves, extent) = noisy_planes(32_768, 1);
        let start = std::time::Instant::now();
        let t = tree_of(&leaves, extent).expect("valid input");
        let (seconds, levels) = (start.elapsed().as_secs_f64(), t.level_offsets.len() - 1);
        println!("32768 surfels: {seconds:.2} s, {levels} levels");
        check_invariants(&leaves, &t);
    }
}
