//! The light caches' distribution, areas, materials and neighbours on small scenes, and their
//! bit-identical output whatever the thread count.

use super::*;

/// Deterministic pseudo-random numbers for test inputs.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    fn point(&mut self) -> Vec3 {
        Vec3::new(self.next_f32(), self.next_f32(), self.next_f32()) * 10.0 - 5.0
    }
}

#[test]
fn bisection_covers_the_triangle_with_small_pieces() {
    // A sliver: 10 long, 0.01 high. Pieces must be short without squaring the count.
    let corners = [
        Vec3::ZERO,
        Vec3::new(10.0, 0.0, 0.0),
        Vec3::new(4.0, 0.01, 0.0),
    ];
    let mut stack = Vec::new();
    let mut total = 0.0;
    let mut centroids = Vec::new();
    let count = bisect(corners, 0.05, 0.25, u64::MAX, &mut stack, &mut |p, a| {
        total += a;
        centroids.push(p);
    });
    assert_eq!(count as usize, centroids.len());
    assert!((total - 0.05).abs() < 1e-12, "areas sum to {total}");
    assert!(count < 400, "{count} pieces for a 40-spacing-long sliver");
    // Every point along the long edge is near a sample.
    for i in 0..=100 {
        let p = Vec3::new(i as f32 * 0.1, 0.0, 0.0);
        let d = centroids
            .iter()
            .map(|c| c.distance(p))
            .fold(f32::MAX, f32::min);
        assert!(d <= 0.25, "point {p} is {d} from its nearest sample");
    }
    // The budget stops the count early.
    assert_eq!(
        bisect(corners, 0.05, 0.001, 10, &mut stack, &mut |_, _| {}),
        11
    );
}

#[test]
fn normal_bins_stay_within_theta_of_their_centre() {
    let mut rng = SplitMix64(9);
    for theta_deg in [90.0f32, 30.0, 10.0, 2.0] {
        let theta = theta_deg.to_radians();
        let res = normal_resolution(theta);
        for _ in 0..5000 {
            let Some(n) = rng.point().try_normalize() else {
                continue;
            };
            let bin = normal_bin(n, res);
            assert!(bin < 6 * res * res);
            let angle = n.dot(normal_bin_centre(bin, res)).clamp(-1.0, 1.0).acos();
            assert!(angle < theta, "{n} is {angle} rad from its bin centre");
        }
    }
}

#[test]
fn mean_linear_colour_decodes_srgb() {
    let white_black = [255, 255, 255, 255, 0, 0, 0, 255];
    assert_eq!(mean_linear_colour(&white_black), Vec3::splat(0.5));
    let mid = mean_linear_colour(&[128, 128, 128, 0]);
    assert!((mid.x - 0.2158).abs() < 1e-3, "{mid}");
    assert_eq!(mean_linear_colour(&[]), Vec3::ONE);
}

#[test]
fn rounding_keeps_three_significant_digits() {
    assert!((round_significant(0.0141421, 3) - 0.0141).abs() < 1e-12);
    assert!((round_significant(45.678, 3) - 45.7).abs() < 1e-9);
    assert!((round_up_significant(45.612, 3) - 45.7).abs() < 1e-9);
}

/// Seed 004 §3 distributes caches per model: in the Cornell box each movable box gets its own
/// caches, on its own surface, and its vertices interpolate only those (so they move with
/// it); the room's vertices never see a box's caches.
#[test]
fn caches_are_distributed_per_model() {
    let scene = crate::scene::procedural::cornell_box();
    let params = CacheParams::for_scene(&scene);
    let set = precompute(&scene, &params, &mut |_| {}).expect("caches");
    let bounds = scene.node_bounds();
    let models = vertex_models(&scene);
    for (n, node) in scene.nodes.iter().enumerate() {
        let mine: Vec<&LightCache> = set.caches.iter().filter(|c| c.model == n as u32).collect();
        if !node.movable {
            assert!(mine.is_empty(), "the room is static");
            continue;
        }
        assert!(mine.len() > 10, "{}: {} caches", node.name, mine.len());
        let b = bounds[n].expect("geometry");
        for c in mine {
            let p = Vec3::from(c.position);
            assert!(
                p.cmpge(b.min - 1e-4).all() && p.cmple(b.max + 1e-4).all(),
                "{}: a cache at {p} off the box {b:?}",
                node.name
            );
        }
    }
    let mut box_vertices = 0;
    for (v, entry) in set.vertex_caches.iter().enumerate() {
        for &c in entry.iter().filter(|&&c| c != u32::MAX) {
            assert_eq!(set.caches[c as usize].model, models[v], "vertex {v}");
        }
        box_vertices += usize::from(models[v] != STATIC);
    }
    assert!(box_vertices > 0);
}
