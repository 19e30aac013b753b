//! A balanced, implicit k-d tree over points, for nearest-neighbour and radius queries in
//! the precomputations (the light caches' merging, assignment and per-vertex neighbours).
//! Hand-written (where the surfels use `rstar`'s R-tree) because its k-nearest search takes
//! the caller's filter inside the search and breaks distance ties by id, so the caches built
//! from it do not depend on the order of equal distances.

use glam::Vec3;

/// Up to `k` (≤ `N`) nearest candidates, sorted by (distance², id).
pub struct Nearest<const N: usize> {
    items: [(f32, u32); N],
    len: usize,
    k: usize,
}

impl<const N: usize> Nearest<N> {
    pub fn new(k: usize) -> Self {
        Self {
            items: [(0.0, 0); N],
            len: 0,
            k: k.min(N),
        }
    }

    /// Squared search radius: the k-th distance once full, else `limit`.
    fn bound(&self, limit: f32) -> f32 {
        if self.len == self.k {
            self.items[self.k - 1].0
        } else {
            limit
        }
    }

    fn offer(&mut self, d2: f32, id: u32) {
        let better = |a: (f32, u32)| d2.total_cmp(&a.0).then(id.cmp(&a.1)).is_lt();
        if self.k == 0 || (self.len == self.k && !better(self.items[self.k - 1])) {
            return;
        }
        let mut i = self.len.min(self.k - 1);
        while i > 0 && better(self.items[i - 1]) {
            self.items[i] = self.items[i - 1];
            i -= 1;
        }
        self.items[i] = (d2, id);
        self.len = (self.len + 1).min(self.k);
    }

    pub fn ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.items[..self.len].iter().map(|&(_, id)| id)
    }
}

/// A balanced, implicit k-d tree: the node of a range is its middle element, split along the
/// axis of largest extent. Built once per query set; queries are read-only and parallel.
pub struct KdTree {
    points: Vec<Vec3>,
    ids: Vec<u32>,
    axes: Vec<u8>,
}

impl KdTree {
    pub fn new(points: &[Vec3]) -> Self {
        let mut ids: Vec<u32> = (0..points.len() as u32).collect();
        let mut axes = vec![0u8; points.len()];
        build(points, &mut ids, &mut axes);
        Self {
            points: ids.iter().map(|&i| points[i as usize]).collect(),
            ids,
            axes,
        }
    }

    /// Offers every point within `sqrt(limit2)` that passes `accept` to `best`.
    pub fn nearest<const N: usize>(
        &self,
        q: Vec3,
        limit2: f32,
        best: &mut Nearest<N>,
        accept: &dyn Fn(u32) -> bool,
    ) {
        self.nearest_in(0, self.ids.len(), q, limit2, best, accept);
    }

    fn nearest_in<const N: usize>(
        &self,
        lo: usize,
        hi: usize,
        q: Vec3,
        limit2: f32,
        best: &mut Nearest<N>,
        accept: &dyn Fn(u32) -> bool,
    ) {
        if lo >= hi {
            return;
        }
        let mid = (lo + hi) / 2;
        let p = self.points[mid];
        let d2 = q.distance_squared(p);
        if d2 <= best.bound(limit2) && accept(self.ids[mid]) {
            best.offer(d2, self.ids[mid]);
        }
        let axis = usize::from(self.axes[mid]);
        let diff = q[axis] - p[axis];
        let (near, far) = if diff < 0.0 {
            ((lo, mid), (mid + 1, hi))
        } else {
            ((mid + 1, hi), (lo, mid))
        };
        self.nearest_in(near.0, near.1, q, limit2, best, accept);
        if diff * diff <= best.bound(limit2) {
            self.nearest_in(far.0, far.1, q, limit2, best, accept);
        }
    }

    /// Calls `visit` for every point strictly within `sqrt(r2)` of `q`.
    pub fn within(&self, q: Vec3, r2: f32, visit: &mut dyn FnMut(u32)) {
        let mut stack = vec![(0, self.ids.len())];
        while let Some((lo, hi)) = stack.pop() {
            if lo >= hi {
                continue;
            }
            let mid = (lo + hi) / 2;
            let p = self.points[mid];
            if q.distance_squared(p) < r2 {
                visit(self.ids[mid]);
            }
            let axis = usize::from(self.axes[mid]);
            let diff = q[axis] - p[axis];
            if diff < 0.0 || diff * diff < r2 {
                stack.push((lo, mid));
            }
            if diff >= 0.0 || diff * diff < r2 {
                stack.push((mid + 1, hi));
            }
        }
    }
}

/// Orders `ids` into an implicit k-d tree (see [`KdTree`]), recording each node's axis.
fn build(points: &[Vec3], ids: &mut [u32], axes: &mut [u8]) {
    if ids.len() <= 1 {
        return;
    }
    let (min, max) = ids.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &i| (lo.min(points[i as usize]), hi.max(points[i as usize])),
    );
    let extent = max - min;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let mid = ids.len() / 2;
    ids.select_nth_unstable_by(mid, |&a, &b| {
        points[a as usize][axis]
            .total_cmp(&points[b as usize][axis])
            .then(a.cmp(&b))
    });
    axes[mid] = axis as u8;
    let (left, right) = ids.split_at_mut(mid);
    let (left_axes, right_axes) = axes.split_at_mut(mid);
    let right = &mut right[1..];
    let right_axes = &mut right_axes[1..];
    if left.len() > 4096 {
        rayon::join(
            || build(points, left, left_axes),
            || build(points, right, right_axes),
        );
    } else {
        build(points, left, left_axes);
        build(points, right, right_axes);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::common::halton::halton;

    /// The `i`-th point of a 3D Halton sequence in [-5, 5)³.
    fn point(i: u32) -> Vec3 {
        Vec3::new(halton(i, 2), halton(i, 3), halton(i, 5)) * 10.0 - 5.0
    }

    #[test]
    fn kd_tree_matches_brute_force() {
        const K: usize = 16;
        let points: Vec<Vec3> = (1..=2000).map(point).collect();
        let tree = KdTree::new(&points);
        // Queries from further along the sequence, between the points.
        for q in (5000..5200).map(point) {
            let even = |i: u32| i.is_multiple_of(2);
            let mut best = Nearest::<K>::new(K);
            tree.nearest(q, f32::INFINITY, &mut best, &even);
            let mut brute: Vec<(f32, u32)> = (0..points.len() as u32)
                .filter(|&i| even(i))
                .map(|i| (q.distance_squared(points[i as usize]), i))
                .collect();
            brute.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let expected: Vec<u32> = brute[..K].iter().map(|e| e.1).collect();
            assert_eq!(best.ids().collect::<Vec<_>>(), expected);

            let mut found = Vec::new();
            tree.within(q, 1.5, &mut |i| found.push(i));
            found.sort_unstable();
            let expected: Vec<u32> = (0..points.len() as u32)
                .filter(|&i| q.distance_squared(points[i as usize]) < 1.5)
                .collect();
            assert_eq!(found, expected);
        }
    }

    #[test]
    fn nearest_respects_radius_limit() {
        let tree = KdTree::new(&[Vec3::ZERO, Vec3::X * 3.0]);
        let mut best = Nearest::<1>::new(1);
        tree.nearest(Vec3::X * 1.6, 1.0, &mut best, &|_| true);
        assert_eq!(best.ids().count(), 0);
        tree.nearest(Vec3::X * 2.5, 1.0, &mut best, &|_| true);
        assert_eq!(best.ids().collect::<Vec<_>>(), vec![1]);
    }
}
