//! Links from every SH cache to the hierarchy nodes that send it most light (seed 001, "Light
//! Transport Solution" eq. 1–4 and "Link Generation"), and the cache lighting they give.
//!
//! A cache at p sees surfel k (area a, normal n_k, at distance d_k in direction ω_k) in the
//! solid angle Ω_k = 2π(1 − (1 + a·cos_k/(π d_k²))^−½), cos_k = ⟨n_k, −ω_k⟩₊: eq. 3's a·cos/d²
//! far away, but bounded by 2π where eq. 3 diverges next to a surfel (the on-axis solid angle
//! of a disc of area a). Eq. 3's Monte Carlo estimate with one sample per surfel gives every
//! surfel the weight w_k = Ω_k·V_k/π (V_k: the ray from p reaches it), so c₀ of a node is
//! y₀·Σ w_k over its surfels. The extraction's ⟨n_s, ω_j⟩ must be ⟨n_s, −ω_j⟩ (ω_j points from
//! the cache to the sender), or every sender facing the cache would count zero.
//!
//! The links of a cache are the cut of the hierarchy found top-down by replacing the node of
//! largest c₀ with its children until n_L nodes are chosen (only nodes that send anything).
//! Each link stores its SH "form factor" in flux form: g_{s,i} = (1/m_s)·Σ_{k∈s} w_k·y_i(ω_k)
//! for a node of m_s surfels, so that with the node's flux in surfel units (the sum of its
//! surfels' radiosities B_k) eq. 4 reads L_SH,i = Σ_s Φ̃_s·g_{s,i}. This is the paper's division
//! of the form factor by the sender's area, with areas counted in surfels: g is a mean solid
//! angle, the same in any scene unit, and fits half floats.

use super::hierarchy::Tree;
use super::link_rays::LinkRays;
pub use super::senders::Senders;
use super::sh;
use crate::gpu::GpuContext;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::BinaryHeap;

/// Unused link slots of a cache.
pub const NO_NODE: u32 = u32::MAX;
/// Caches per parallel chunk, with a progress report and a cancellation check after each.
const CHUNK: usize = 64;

/// The links of every cache: `per_cache` slots each, sorted by node, unused ones
/// [`NO_NODE`] with zero coefficients.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfelLinks {
    pub per_cache: u32,
    pub bands: u32,
    /// Node ids of the hierarchy, `per_cache` per cache.
    pub nodes: Vec<u32>,
    /// g_{s,i}, `bands²` per slot.
    pub coeffs: Vec<f32>,
    /// Σ c₀ of every cache's links: how much of the scene it sees.
    pub visible: Vec<f32>,
    /// Whether a cache sees mostly back faces: it lies inside geometry or outside a closed
    /// scene, where the little it sees through seams would darken its neighbours (the
    /// paper's Fig. 7a), so the shading leaves it out.
    pub inside: Vec<bool>,
}

/// Why no links were made.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LinkError {
    #[error("SH bands must be in 1..={max}, got {0}", max = sh::MAX_BANDS)]
    Bands(u32),
    #[error("links per cache must be at least 1")]
    NoLinks,
    #[error("cancelled: the scene was deleted, or nobody waits for the set any more")]
    Cancelled,
    #[error("tracing the link rays on the GPU failed: {0}")]
    Gpu(String),
}

/// Where the link rays are traced.
#[derive(Clone, Copy)]
pub enum RayDevice<'a> {
    /// On the CPU cores, through [`crate::gi::common::bvh::SceneBvh::occluded`].
    Cpu,
    /// On the adapter ([`super::link_rays`]), falling back to the CPU where the scene does not
    /// fit its buffers.
    Gpu(&'a GpuContext),
}

impl<'a> RayDevice<'a> {
    /// The adapter when it is a GPU, else the CPU: a CPU adapter runs the same traversal
    /// slower than the Rust one (lavapipe took 4.0 s where the CPU took 0.6 s for the Cornell
    /// box's 2,048 surfels and 1,000 caches on two cores).
    pub fn for_adapter(gpu: Option<&'a GpuContext>) -> Self {
        match gpu {
            Some(ctx) if ctx.info.device_type != wgpu::DeviceType::Cpu => Self::Gpu(ctx),
            _ => Self::Cpu,
        }
    }
}

/// The links of caches at `positions`, `per_cache` each with `bands` SH bands, their rays
/// traced on `rays`, reporting `(caches done, total)` after each chunk.
pub fn build(
    senders: &Senders,
    positions: &[Vec3],
    per_cache: u32,
    bands: u32,
    rays: RayDevice,
    progress: &mut dyn FnMut(u64, u64),
    cancelled: &dyn Fn() -> bool,
) -> Result<SurfelLinks, LinkError> {
    if !(1..=sh::MAX_BANDS).contains(&bands) {
        return Err(LinkError::Bands(bands));
    }
    if per_cache == 0 {
        return Err(LinkError::NoLinks);
    }
    let mut links = SurfelLinks {
        per_cache,
        bands,
        nodes: Vec::with_capacity(positions.len() * per_cache as usize),
        coeffs: Vec::new(),
        visible: Vec::with_capacity(positions.len()),
        inside: Vec::with_capacity(positions.len()),
    };
    let mut add = |made: Vec<CacheLinks>| {
        for c in made {
            links.nodes.extend(c.nodes);
            links.coeffs.extend(c.coeffs);
            links.visible.push(c.visible);
            links.inside.push(c.inside);
        }
    };
    let gpu = match rays {
        RayDevice::Cpu => None,
        RayDevice::Gpu(ctx) => match LinkRays::new(ctx, senders) {
            Ok(traced) => Some(traced),
            Err(e) => {
                tracing::warn!("surfel link rays on the CPU: {e}");
                None
            }
        },
    };
    let total = positions.len() as u64;
    let Some(gpu) = gpu else {
        for (k, chunk) in positions.chunks(CHUNK).enumerate() {
            if cancelled() {
                return Err(LinkError::Cancelled);
            }
            add(chunk
                .par_iter()
                .map(|&p| {
                    cache_links(senders, p, per_cache, bands, &|_, dir, t| {
                        senders.bvh.occluded(p, dir, t)
                    })
                })
                .collect());
            progress((k * CHUNK + chunk.len()) as u64, total);
        }
        return Ok(links);
    };
    // Two batches in flight: the GPU traces batch k + 1 while the CPU makes batch k's links.
    let batches: Vec<&[Vec3]> = positions.chunks(gpu.batch()).collect();
    let mut pending = batches.first().map(|b| gpu.submit(0, b));
    let mut done = 0;
    for (k, batch) in batches.iter().enumerate() {
        let Some(traced) = pending.take() else {
            break;
        };
        let seen = gpu
            .wait(traced)
            .map_err(|e| LinkError::Gpu(e.to_string()))?;
        if cancelled() {
            return Err(LinkError::Cancelled);
        }
        pending = batches.get(k + 1).map(|b| gpu.submit((k + 1) % 2, b));
        add(batch
            .par_iter()
            .enumerate()
            .map(|(c, &p)| cache_links(senders, p, per_cache, bands, &|s, _, _| !seen.sees(c, s)))
            .collect());
        done += batch.len() as u64;
        progress(done, total);
    }
    Ok(links)
}

struct CacheLinks {
    nodes: Vec<u32>,
    coeffs: Vec<f32>,
    visible: f32,
    inside: bool,
}

/// Directions probed for back faces around every cache.
const PROBES: u32 = 64;

/// Whether more than half of the surfaces seen from `p` in [`PROBES`] directions spread
/// evenly over the sphere (a Fibonacci lattice) show it their back.
fn sees_mostly_back_faces(senders: &Senders, p: Vec3) -> bool {
    let (mut hits, mut back) = (0, 0);
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    for k in 0..PROBES {
        let z = 1.0 - (2 * k + 1) as f32 / PROBES as f32;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = golden * k as f32;
        let dir = Vec3::new(r * phi.cos(), r * phi.sin(), z);
        let Some(hit) = senders.bvh.intersect(p, dir, f32::INFINITY) else {
            continue;
        };
        hits += 1;
        let facing =
            crate::gi::common::triangles::triangle_normal(senders.scene, hit.triangle as usize);
        if facing.is_some_and(|(n, _)| n.dot(dir) > 0.0) {
            back += 1;
        }
    }
    2 * back > hits
}

/// Whether the ray to surfel `k` from a cache, in direction `dir`, is blocked before `t_max`.
type Occluded<'a> = dyn Fn(usize, Vec3, f32) -> bool + Sync + 'a;

/// Eq. 3 for every surfel seen from `p`, the cut of n_L nodes, and their coefficients.
fn cache_links(
    senders: &Senders,
    p: Vec3,
    per_cache: u32,
    bands: u32,
    occluded: &Occluded,
) -> CacheLinks {
    let n = senders.surfels.len();
    let a = senders.area as f32;
    let epsilon = senders.ray_offset();
    let samples: Vec<(f32, Vec3)> = senders
        .surfels
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let to = s.position - p;
            let d = to.length();
            if d <= epsilon {
                return (0.0, Vec3::Z);
            }
            let dir = to / d;
            let cos = -s.normal.dot(dir);
            if cos <= 0.0 {
                return (0.0, dir);
            }
            // The surfel's own triangle ends the ray at d: stop just short of it.
            if occluded(k, dir, d - epsilon) {
                return (0.0, dir);
            }
            let solid_angle = 2.0
                * std::f32::consts::PI
                * (1.0 - (1.0 + a * cos / (std::f32::consts::PI * d * d)).powf(-0.5));
            (solid_angle / std::f32::consts::PI, dir)
        })
        .collect();
    let tree = senders.tree;
    // Σ w per node: leaves first, internal nodes in merge order (children before parents).
    let mut weight: Vec<f32> = samples.iter().map(|(w, _)| *w).collect();
    weight.extend(tree.children.iter().map(|_| 0.0));
    for (k, [l, r]) in tree.children.iter().enumerate() {
        weight[n + k] = weight[*l as usize] + weight[*r as usize];
    }
    let cut = cut(tree, &weight, n, per_cache as usize);
    let count = sh::coefficient_count(bands);
    let mut nodes = vec![NO_NODE; per_cache as usize];
    let mut coeffs = vec![0.0; per_cache as usize * count];
    let mut y = vec![0.0; count];
    for (slot, &node) in cut.iter().enumerate() {
        nodes[slot] = node;
        let (first, m) = (
            tree.first_leaf[node as usize],
            tree.leaf_count[node as usize],
        );
        let g = &mut coeffs[slot * count..(slot + 1) * count];
        for &(w, dir) in &samples[first as usize..(first + m) as usize] {
            if w > 0.0 {
                sh::eval(bands, dir, &mut y);
                for (gi, yi) in g.iter_mut().zip(&y) {
                    *gi += w * yi;
                }
            }
        }
        for gi in g.iter_mut() {
            *gi /= m as f32;
        }
    }
    let y0 = 0.5 / std::f32::consts::PI.sqrt();
    CacheLinks {
        nodes,
        coeffs,
        visible: y0 * weight.last().copied().unwrap_or(0.0),
        inside: sees_mostly_back_faces(senders, p),
    }
}

/// The n_L nodes of the cut ("Link Generation"): from the root, the node of largest weight is
/// replaced by its children that send anything until `limit` nodes are chosen or only leaves
/// are left. Sorted by node id.
fn cut(tree: &Tree, weight: &[f32], leaves: usize, limit: usize) -> Vec<u32> {
    /// Largest weight first, then the smaller id (a total order: equal weights never tie).
    struct Entry(f32, u32);
    impl PartialEq for Entry {
        fn eq(&self, other: &Self) -> bool {
            self.cmp(other).is_eq()
        }
    }
    impl Eq for Entry {}
    impl PartialOrd for Entry {
        fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
            Some(self.cmp(other))
        }
    }
    impl Ord for Entry {
        fn cmp(&self, other: &Self) -> std::cmp::Ordering {
            self.0.total_cmp(&other.0).then(other.1.cmp(&self.1))
        }
    }
    let root = weight.len() - 1;
    let mut open = BinaryHeap::new();
    if weight[root] > 0.0 {
        open.push(Entry(weight[root], root as u32));
    }
    let mut chosen = Vec::new();
    while chosen.len() + open.len() < limit {
        let Some(Entry(_, node)) = open.pop() else {
            break;
        };
        if (node as usize) < leaves {
            chosen.push(node);
            continue;
        }
        for child in tree.children[node as usize - leaves] {
            if weight[child as usize] > 0.0 {
                open.push(Entry(weight[child as usize], child));
            }
        }
    }
    chosen.extend(open.into_iter().map(|Entry(_, node)| node));
    chosen.sort_unstable();
    chosen
}

/// Eq. 4 in flux form: every cache's incident radiance in SH, L_SH,i = Σ_s Φ̃_s·g_{s,i}, from
/// the flux of every hierarchy node in surfel units (see [`super::pull_flux`]). `bands²` RGB
/// coefficients per cache.
pub fn cache_lighting(links: &SurfelLinks, node_flux: &[Vec3]) -> Vec<Vec3> {
    let count = sh::coefficient_count(links.bands);
    let per_cache = links.per_cache as usize;
    links
        .nodes
        .chunks(per_cache)
        .zip(links.coeffs.chunks(per_cache * count))
        .flat_map(|(nodes, coeffs)| {
            let mut l = vec![Vec3::ZERO; count];
            for (&node, g) in nodes.iter().zip(coeffs.chunks(count)) {
                if node == NO_NODE {
                    continue;
                }
                for (li, gi) in l.iter_mut().zip(g) {
                    *li += node_flux[node as usize] * *gi;
                }
            }
            l
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::common::bvh::SceneBvh;
    use crate::gi::surfels::sampling::Surfel;
    use crate::gi::surfels::test_scenes::{closed_box, quads};
    use crate::gi::surfels::{hierarchy, pull_flux, sampling};
    use crate::scene::Scene;

    /// A square of half-side `h` at height `z`, facing down (towards the origin).
    fn facing_down(h: f32, z: f32) -> [Vec3; 4] {
        [
            Vec3::new(-h, -h, z),
            Vec3::new(-h, h, z),
            Vec3::new(h, h, z),
            Vec3::new(h, -h, z),
        ]
    }

    struct Built {
        scene: Scene,
        surfels: Vec<Surfel>,
        area: f64,
        tree: Tree,
        bvh: SceneBvh,
        extent: f32,
    }

    impl Built {
        fn senders(&self) -> Senders<'_> {
            Senders {
                surfels: &self.surfels,
                area: self.area,
                tree: &self.tree,
                bvh: &self.bvh,
                scene: &self.scene,
                extent: self.extent,
            }
        }
    }

    fn build_scene(scene: &Scene, count: u32) -> Built {
        let s = sampling::sample(scene, count, sampling::RELAX_STEPS, &mut |_| {}, &|| false)
            .expect("surfels");
        let leaves: Vec<hierarchy::Leaf> = s
            .surfels
            .iter()
            .map(|x| hierarchy::Leaf {
                position: x.position,
                normal: x.normal,
                area: s.area as f32,
            })
            .collect();
        let extent = (scene.bounds.max - scene.bounds.min).length();
        let tree = hierarchy::build(
            &leaves,
            f64::from(extent),
            hierarchy::ClusterWeights::default(),
            &mut |_, _| {},
            &|| false,
        )
        .expect("tree");
        let surfels = tree
            .leaf_order
            .iter()
            .map(|&i| s.surfels[i as usize])
            .collect();
        Built {
            scene: scene.clone(),
            surfels,
            area: s.area,
            tree,
            bvh: SceneBvh::build(scene).expect("bvh"),
            extent,
        }
    }

    fn links_at(b: &Built, p: Vec3, per_cache: u32, bands: u32) -> SurfelLinks {
        let senders = b.senders();
        build(
            &senders,
            &[p],
            per_cache,
            bands,
            RayDevice::Cpu,
            &mut |_, _| {},
            &|| false,
        )
        .expect("links")
    }

    /// c₀ of a 2×2 square one unit above the cache on its axis: y₀·Ω/π with the square's
    /// solid angle Ω = 4·asin(ab/√((a²+h²)(b²+h²))) = 2π/3, i.e. 1/(3√π).
    #[test]
    fn a_square_sends_its_analytic_solid_angle() {
        let b = build_scene(&quads(&[facing_down(1.0, 1.0)]), 4096);
        let links = links_at(&b, Vec3::ZERO, 64, 3);
        let expected = 1.0 / (3.0 * std::f32::consts::PI.sqrt());
        let got = links.visible[0];
        assert!(
            ((got - expected) / expected).abs() < 0.005,
            "{got} vs {expected}"
        );
        // The links hold it all: Σ m_s·g_s,0 over the cut is c₀ of the root.
        let count = sh::coefficient_count(3);
        let summed: f32 = links
            .nodes
            .iter()
            .zip(links.coeffs.chunks(count))
            .filter(|(n, _)| **n != NO_NODE)
            .map(|(&n, g)| b.tree.leaf_count[n as usize] as f32 * g[0])
            .sum();
        assert!(((summed - got) / got).abs() < 1e-4, "{summed} vs {got}");
    }

    /// An occluder of half-side 0.25 halfway up hides 4·asin(0.2) = 0.8054 sr of the square:
    /// its surfels send the rest, 2π/3 − 0.8054 sr, i.e. c₀ 0.11574.
    #[test]
    fn an_occluder_hides_what_it_covers() {
        let scene = quads(&[facing_down(1.0, 1.0), facing_down(0.25, 0.5)]);
        let b = build_scene(&scene, 16384);
        let senders = b.senders();
        let back: f32 = b
            .surfels
            .iter()
            .filter(|s| s.triangle < 2)
            .map(|s| {
                let one = Senders {
                    surfels: std::slice::from_ref(s),
                    tree: &Tree {
                        children: Vec::new(),
                        parent: vec![u32::MAX],
                        first_leaf: vec![0],
                        leaf_count: vec![1],
                        centre: vec![s.position],
                        normal: vec![s.normal],
                        area: vec![b.area as f32],
                        merge_distance: Vec::new(),
                        leaf_order: vec![0],
                        level_offsets: vec![0],
                        by_level: Vec::new(),
                    },
                    ..senders
                };
                cache_links(&one, Vec3::ZERO, 1, 1, &|_, dir, t| {
                    b.bvh.occluded(Vec3::ZERO, dir, t)
                })
                .visible
            })
            .sum();
        let y0 = 0.5 / std::f32::consts::PI.sqrt();
        let expected =
            y0 * (2.0 * std::f32::consts::PI / 3.0 - 4.0 * 0.2f32.asin()) / std::f32::consts::PI;
        assert!(
            ((back - expected) / expected).abs() < 0.015,
            "{back} vs {expected}"
        );
    }

    /// A closed box of inward-facing walls, every surfel of radiosity π (radiance 1): the cache
    /// at its centre sees the whole sphere, Σ c₀ = 4·y₀ = 2/√π, and its incident radiance in SH
    /// is 1 in every direction, L_SH,0 = 2√π and every other coefficient 0. The cut is exact
    /// here (every surfel sends the same radiosity), so the links reproduce it.
    #[test]
    fn a_furnace_box_is_seen_whole_with_unit_radiance() {
        let scene = closed_box();
        let b = build_scene(&scene, 16384);
        let links = links_at(&b, Vec3::new(0.1, -0.05, 0.02), 48, 3);
        let expected = 1.0 / std::f32::consts::PI.sqrt();
        assert!(
            ((links.visible[0] - 2.0 * expected) / (2.0 * expected)).abs() < 0.005,
            "Σ c₀ {} vs 2/√π",
            links.visible[0]
        );
        let radiosity = vec![Vec3::splat(std::f32::consts::PI); b.surfels.len()];
        let l_sh = cache_lighting(&links, &pull_flux(&b.tree, &radiosity));
        let l00 = 2.0 * std::f32::consts::PI.sqrt();
        assert!(
            ((l_sh[0].x - l00) / l00).abs() < 0.005,
            "{} vs {l00}",
            l_sh[0]
        );
        for (i, c) in l_sh.iter().enumerate().skip(1) {
            assert!(c.abs().max_element() < 0.01 * l00, "coefficient {i}: {c}");
        }
        let used = links.nodes.iter().filter(|&&n| n != NO_NODE).count();
        assert_eq!(used, 48, "a whole box fills every link");
    }

    #[test]
    fn the_cut_partitions_what_is_seen_and_is_sorted_and_padded() {
        let b = build_scene(&quads(&[facing_down(1.0, 1.0)]), 512);
        for per_cache in [1, 7, 64, 2000] {
            let links = links_at(&b, Vec3::new(0.3, 0.2, 0.0), per_cache, 2);
            let used: Vec<u32> = links
                .nodes
                .iter()
                .copied()
                .filter(|&n| n != NO_NODE)
                .collect();
            assert!(used.len() <= per_cache as usize);
            assert!(used.windows(2).all(|w| w[0] < w[1]), "sorted");
            assert!(links.nodes[used.len()..].iter().all(|&n| n == NO_NODE));
            // Every surfel facing the cache lies in exactly one chosen node.
            let mut covered = vec![0; b.surfels.len()];
            for &n in &used {
                let (first, m) = (b.tree.first_leaf[n as usize], b.tree.leaf_count[n as usize]);
                for c in &mut covered[first as usize..(first + m) as usize] {
                    *c += 1;
                }
            }
            assert!(covered.iter().all(|&c| c == 1), "n_L {per_cache}");
            if per_cache >= 512 {
                assert_eq!(used.len(), 512, "every surfel its own link");
            }
        }
        let senders = b.senders();
        let refused = |per, bands| {
            build(
                &senders,
                &[Vec3::ZERO],
                per,
                bands,
                RayDevice::Cpu,
                &mut |_, _| {},
                &|| false,
            )
            .err()
        };
        assert_eq!(refused(0, 3), Some(LinkError::NoLinks));
        assert_eq!(refused(8, 0), Some(LinkError::Bands(0)));
        assert_eq!(
            build(
                &senders,
                &[Vec3::ZERO],
                8,
                3,
                RayDevice::Cpu,
                &mut |_, _| {},
                &|| true
            )
            .err(),
            Some(LinkError::Cancelled)
        );
    }
}
