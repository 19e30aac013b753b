//! CPU reference of `clustered` (seed paper 003), used by tests to check the GPU passes. It
//! evaluates in plain `f32` the same reading of the paper as `shaders/clustered/`:
//!
//! * §6 "VPL Generation": N VPLs fetched from the RSM at Halton positions ([`generate_vpls`]);
//! * §5.1–5.2: k-means with d = w_x·Δx + w_α·Δα from the same seeds every frame ([`seed`],
//!   [`assign`], [`update`]), then the mapping C and the VALs with their areas ([`finalize`]);
//! * §4, §6 "Indirect Lighting": the light of a set of VPLs at a surface point ([`shade`]),
//!   interleaved sampling ([`interleave_class`]) and the geometry-aware blur ([`blur`]).
//!
//! Nothing here depends on the GPU.

use crate::gi::common::halton::halton;
use crate::gi::common::vpl::{vpl_light, VplLight};
use crate::passes::rsm::GlossySender;
use crate::scene::brdf::Brdf;
use glam::{Vec2, Vec3};

/// An RSM atlas as read back: per texel RGBA position (w = 1 where a surface is), normal and
/// flux with disk area.
pub struct RsmTexels<'a> {
    pub width: u32,
    pub height: u32,
    pub position: &'a [[f32; 4]],
    pub normal: &'a [[f32; 4]],
    pub flux_area: &'a [[f32; 4]],
    /// [`GlossySender::decode`] reads these.
    pub glossy: &'a [[u32; 4]],
}

/// A virtual point light.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RefVpl {
    pub position: Vec3,
    /// Unit normal.
    pub normal: Vec3,
    /// Φ_i (rgb).
    pub flux: Vec3,
    /// Disk area of the texels it stands for.
    pub area: f32,
    /// The glossy lobe of the texels it stands for.
    pub glossy: GlossySender,
    /// Whether it reflects light (a surface with flux under its texel).
    pub lit: bool,
    /// Row-major RSM texel.
    pub texel: u32,
}

impl RefVpl {
    /// A GPU VPL and its glossy lobe as read back.
    pub fn read_back(v: &super::passes::Vpl, glossy: &GlossySender) -> Self {
        Self {
            position: Vec3::from(v.position),
            normal: Vec3::from(v.normal),
            flux: Vec3::from(v.flux),
            area: v.area,
            glossy: *glossy,
            lit: v.lit != 0,
            texel: v.texel,
        }
    }

    /// Every VPL of a clustered frame's readback.
    pub fn all_read_back(rb: &super::ClusteredReadback) -> Vec<Self> {
        rb.vpls
            .iter()
            .zip(&rb.vpl_glossy)
            .map(|(v, g)| Self::read_back(v, g))
            .collect()
    }
}

/// The texel VPL `i` of `n` is fetched from in a `width`×`height` atlas (Halton index i + 1:
/// index 0 is the origin).
pub fn vpl_texel(i: u32, width: u32, height: u32) -> u32 {
    let x = ((halton(i + 1, 2) * width as f32) as u32).min(width - 1);
    let y = ((halton(i + 1, 3) * height as f32) as u32).min(height - 1);
    y * width + x
}

/// §6 "VPL Generation": each of the `n` VPLs carries the flux and disk area of W·H/n texels,
/// so that their sum estimates the whole RSM's.
pub fn generate_vpls(rsm: &RsmTexels, n: u32) -> Vec<RefVpl> {
    let share = (rsm.width * rsm.height) as f32 / n as f32;
    (0..n)
        .map(|i| {
            let texel = vpl_texel(i, rsm.width, rsm.height);
            let t = texel as usize;
            let [px, py, pz, pw] = rsm.position[t];
            let [fr, fg, fb, area] = rsm.flux_area[t];
            let flux = Vec3::new(fr, fg, fb);
            let glossy = GlossySender::decode(rsm.glossy[t]);
            // A metal texel reflects nothing diffusely, but its glossy lobe makes it a VPL.
            let sends = flux.max_element() > 0.0 || Vec3::from(glossy.weight).max_element() > 0.0;
            if pw > 0.0 && sends {
                let [nx, ny, nz, _] = rsm.normal[t];
                RefVpl {
                    position: Vec3::new(px, py, pz),
                    normal: Vec3::new(nx, ny, nz).normalize(),
                    flux: flux * share,
                    area: area * share,
                    glossy: glossy.scaled(share),
                    lit: true,
                    texel,
                }
            } else {
                RefVpl {
                    texel,
                    ..RefVpl::default()
                }
            }
        })
        .collect()
}

/// A cluster: its centre during k-means, the VAL after [`finalize`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RefCluster {
    pub position: Vec3,
    pub normal: Vec3,
    /// VPLs mapped to it.
    pub count: u32,
    /// Seeded (§5.2); without a centre it takes no VPL.
    pub centred: bool,
    /// Bounding rectangle of its VPLs in the plane of its normal (after [`finalize`]).
    pub area: f32,
}

/// The weights of the clustering distance: w_x per unit of the scene's extent, w_α per radian.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Weights {
    pub position: f32,
    pub normal: f32,
}

/// d = w_x·Δx + w_α·Δα (§5.1).
pub fn distance(w: Weights, vpl: &RefVpl, c: &RefCluster) -> f32 {
    let angle = vpl.normal.dot(c.normal).clamp(-1.0, 1.0).acos();
    w.position * vpl.position.distance(c.position) + w.normal * angle
}

/// §5.2: cluster k starts at VPL k (or the next lit one of k + j·M), every frame; see
/// `seed_clusters` in `shaders/clustered/kmeans.wgsl` for why not the paper's VPL k·N/M.
pub fn seed(vpls: &[RefVpl], m: u32) -> Vec<RefCluster> {
    (0..m as usize)
        .map(|k| {
            vpls.iter()
                .skip(k)
                .step_by(m as usize)
                .find(|v| v.lit)
                .map_or_else(RefCluster::default, |v| RefCluster {
                    position: v.position,
                    normal: v.normal,
                    centred: true,
                    ..RefCluster::default()
                })
        })
        .collect()
}

/// Each lit VPL's nearest centre (ties to the lower index), with its distance.
pub fn assign_with_distances(
    vpls: &[RefVpl],
    clusters: &[RefCluster],
    w: Weights,
) -> Vec<Option<(u32, f32)>> {
    vpls.iter()
        .map(|v| {
            if !v.lit {
                return None;
            }
            let mut best: Option<(u32, f32)> = None;
            for (k, c) in clusters.iter().enumerate().filter(|(_, c)| c.centred) {
                let d = distance(w, v, c);
                if best.is_none_or(|(_, b)| d < b) {
                    best = Some((k as u32, d));
                }
            }
            best
        })
        .collect()
}

/// The mapping C: each lit VPL's nearest centre.
pub fn assign(vpls: &[RefVpl], clusters: &[RefCluster], w: Weights) -> Vec<Option<u32>> {
    assign_with_distances(vpls, clusters, w)
        .into_iter()
        .map(|a| a.map(|(k, _)| k))
        .collect()
}

/// The k-means update: every non-empty centre moves to the mean of its VPLs.
pub fn update(
    vpls: &[RefVpl],
    mapping: &[Option<u32>],
    clusters: &[RefCluster],
) -> Vec<RefCluster> {
    clusters
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let members: Vec<&RefVpl> = members(vpls, mapping, k as u32).collect();
            let mut next = RefCluster {
                count: members.len() as u32,
                ..*c
            };
            if !members.is_empty() {
                next.position =
                    members.iter().map(|v| v.position).sum::<Vec3>() / members.len() as f32;
                let n: Vec3 = members.iter().map(|v| v.normal).sum();
                if n.length_squared() > 1e-12 {
                    next.normal = n.normalize();
                }
            }
            next
        })
        .collect()
}

fn members<'a>(
    vpls: &'a [RefVpl],
    mapping: &'a [Option<u32>],
    k: u32,
) -> impl Iterator<Item = &'a RefVpl> {
    vpls.iter()
        .zip(mapping)
        .filter(move |(_, c)| **c == Some(k))
        .map(|(v, _)| v)
}

/// An orthonormal tangent basis of unit `n` (Duff et al. 2017, listing 3), as the shader
/// builds it.
pub fn tangent_basis(n: Vec3) -> (Vec3, Vec3) {
    let s = if n.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + s * n.x * n.x * a, s * b, -s * n.x),
        Vec3::new(b, s + n.y * n.y * a, -n.y),
    )
}

/// The VALs for the mapping C (§5, §6): the mean normal of their VPLs, the area of the 2D
/// bounding rectangle of the VPLs projected onto the plane of that normal, and as position
/// the VPL nearest to their mean position (the lowest index among equals). The paper keeps
/// the mean; but a cluster of VPLs on a floor and on a box top has its mean inside the box,
/// whose paraboloid map then shadows every receiver (on the Cornell box with 30 VALs the
/// indirect light lost 67 % instead of 28 %): the VAL's map must look out from a surface.
pub fn finalize(
    vpls: &[RefVpl],
    mapping: &[Option<u32>],
    clusters: &[RefCluster],
) -> Vec<RefCluster> {
    update(vpls, mapping, clusters)
        .into_iter()
        .enumerate()
        .map(|(k, c)| {
            let (t, b) = tangent_basis(c.normal);
            let (lo, hi) = members(vpls, mapping, k as u32).fold(
                (Vec2::splat(f32::MAX), Vec2::splat(f32::MIN)),
                |(lo, hi), v| {
                    let d = v.position - c.position;
                    let st = Vec2::new(d.dot(t), d.dot(b));
                    (lo.min(st), hi.max(st))
                },
            );
            let area = if c.count > 0 {
                (hi - lo).x * (hi - lo).y
            } else {
                0.0
            };
            let position = members(vpls, mapping, k as u32)
                .map(|v| v.position)
                .min_by(|a, b| a.distance(c.position).total_cmp(&b.distance(c.position)))
                .unwrap_or(c.position);
            RefCluster {
                area,
                position,
                ..c
            }
        })
        .collect()
}

/// The whole clustering of a frame: seeds, `iterations` k-means steps, the mapping C and
/// the VALs.
pub fn cluster(
    vpls: &[RefVpl],
    m: u32,
    iterations: u32,
    w: Weights,
) -> (Vec<Option<u32>>, Vec<RefCluster>) {
    cluster_from(vpls, seed(vpls, m), iterations, w)
}

/// [`cluster`] from the centres `start` instead of the seeds: with the last frame's VALs it
/// is the strategy §5.2 rejects, kept to show why.
pub fn cluster_from(
    vpls: &[RefVpl],
    start: Vec<RefCluster>,
    iterations: u32,
    w: Weights,
) -> (Vec<Option<u32>>, Vec<RefCluster>) {
    let mut clusters = start;
    for _ in 0..iterations {
        let mapping = assign(vpls, &clusters, w);
        clusters = update(vpls, &mapping, &clusters);
    }
    let mapping = assign(vpls, &clusters, w);
    let vals = finalize(vpls, &mapping, &clusters);
    (mapping, vals)
}

/// A surface point seen from `viewer`.
#[derive(Clone, Copy, Debug)]
pub struct RefSurface {
    pub position: Vec3,
    /// Unit normal.
    pub normal: Vec3,
    pub brdf: Brdf,
}

/// §4's sum Σ L_i(x, ω_o) over `vpls` without visibility: f_r·Φ_i·cosθ_i·cosθ_x over
/// A_i + π d² (the irradiance of the VPL's disk on its axis, finite at d = 0).
pub fn shade<'a>(s: &RefSurface, viewer: Vec3, vpls: impl IntoIterator<Item = &'a RefVpl>) -> Vec3 {
    shade_visible(s, viewer, vpls.into_iter().enumerate(), |_| 1.0)
}

/// §4's Σ L_i(x, ω_o)·V_C(i)(x) over indexed VPLs, `visibility(i)` giving VPL i's V.
pub fn shade_visible<'a>(
    s: &RefSurface,
    viewer: Vec3,
    vpls: impl IntoIterator<Item = (usize, &'a RefVpl)>,
    visibility: impl Fn(usize) -> f32,
) -> Vec3 {
    let v = (viewer - s.position).normalize();
    vpls.into_iter()
        .filter(|(_, vpl)| vpl.lit)
        .map(|(i, vpl)| {
            let light = vpl_light(
                &VplLight {
                    position: vpl.position,
                    normal: vpl.normal,
                    flux: vpl.flux,
                    glossy: vpl.glossy,
                    area: vpl.area,
                    footprint: vpl.area,
                },
                s.position,
                s.normal,
                v,
                &s.brdf,
            );
            if light.max_element() > 0.0 {
                light * visibility(i)
            } else {
                light
            }
        })
        .sum()
}

/// The interleave class of pixel (x, y) with `b`×`b` blocks: it is lit by the VPLs of
/// [`class_vpls`].
pub fn interleave_class(x: u32, y: u32, b: u32) -> u32 {
    (y % b) * b + x % b
}

/// The VPLs (indices into the Halton-ordered list of `vpl_count`) that light interleave class
/// `class` of `b`×`b` blocks: the run `class·N/b² .. (class+1)·N/b²`. Consecutive Halton
/// points cover the whole RSM; the indices of one residue class modulo b² share their low
/// bits and so one strip of it (see `shaders/clustered/indirect.wgsl`).
pub fn class_vpls(class: u32, b: u32, vpl_count: u32) -> std::ops::Range<usize> {
    let classes = b * b;
    let first = class * vpl_count / classes;
    let end = (class + 1) * vpl_count / classes;
    first as usize..end as usize
}

/// The interleaved shading of a pixel: its class's VPLs, times N over their number.
pub fn shade_interleaved(
    s: &RefSurface,
    viewer: Vec3,
    vpls: &[RefVpl],
    class: u32,
    b: u32,
) -> Vec3 {
    shade_interleaved_visible(s, viewer, vpls, class, b, |_| 1.0)
}

/// [`shade_interleaved`] with VPL i weighted by `visibility(i)`.
pub fn shade_interleaved_visible(
    s: &RefSurface,
    viewer: Vec3,
    vpls: &[RefVpl],
    class: u32,
    b: u32,
    visibility: impl Fn(usize) -> f32,
) -> Vec3 {
    let run = class_vpls(class, b, vpls.len() as u32);
    let weight = vpls.len() as f32 / run.len().max(1) as f32;
    let own = vpls.iter().enumerate().skip(run.start).take(run.len());
    shade_visible(s, viewer, own, visibility) * weight
}

/// A G-buffer texel as the blur reads it: position (w = 1 where covered) and normal.
#[derive(Clone, Copy, Debug)]
pub struct BlurTexel {
    pub position: [f32; 4],
    pub normal: Vec3,
}

/// The geometry-aware blur of pixel (x, y): the mean of the b×b block around it over the
/// neighbours within `max_distance` and `min_cos`, the pixel itself always included.
#[allow(clippy::too_many_arguments)]
pub fn blur(
    gbuffer: &[BlurTexel],
    interleaved: &[[f32; 4]],
    width: u32,
    height: u32,
    x: u32,
    y: u32,
    b: u32,
    max_distance: f32,
    min_cos: f32,
) -> Vec3 {
    let at = |x: i64, y: i64| (y * i64::from(width) + x) as usize;
    let (x, y) = (i64::from(x), i64::from(y));
    let own = gbuffer[at(x, y)];
    if own.position[3] == 0.0 {
        return Vec3::ZERO;
    }
    let centre = Vec3::from_slice(&own.position[..3]);
    let half = i64::from(b / 2);
    let (mut sum, mut count) = (Vec3::ZERO, 0.0);
    for qy in y - half..y - half + i64::from(b) {
        for qx in x - half..x - half + i64::from(b) {
            if qx < 0 || qy < 0 || qx >= i64::from(width) || qy >= i64::from(height) {
                continue;
            }
            let q = gbuffer[at(qx, qy)];
            let apart = q.position[3] == 0.0
                || Vec3::from_slice(&q.position[..3]).distance(centre) > max_distance
                || q.normal.dot(own.normal) < min_cos;
            if apart && (qx, qy) != (x, y) {
                continue;
            }
            sum += Vec3::from_slice(&interleaved[at(qx, qy)][..3]);
            count += 1.0;
        }
    }
    sum / count
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::PI;

    fn vpl(position: Vec3, normal: Vec3) -> RefVpl {
        RefVpl {
            position,
            normal,
            flux: Vec3::ONE,
            area: 0.01,
            glossy: GlossySender::default(),
            lit: true,
            texel: 0,
        }
    }

    #[test]
    fn seeds_are_vpl_k_or_the_next_lit_one_of_its_residue() {
        let mut vpls: Vec<RefVpl> = (0..8)
            .map(|i| vpl(Vec3::new(i as f32, 0.0, 0.0), Vec3::Y))
            .collect();
        vpls[1].lit = false;
        vpls[3].lit = false;
        vpls[7].lit = false;
        let seeds = seed(&vpls, 4);
        assert_eq!(seeds[0].position.x, 0.0);
        assert_eq!(seeds[1].position.x, 5.0, "VPL 1 is unlit: the next of 1, 5");
        assert_eq!(seeds[2].position.x, 2.0);
        assert!(!seeds[3].centred, "no lit VPL among 3, 7");
        assert!(seeds[..3].iter().all(|s| s.centred));
    }

    /// A long row of VPLs on the floor and a short one up the wall from its end: by position
    /// alone the floor's corner VPL is nearer the wall's centre and joins it; with the angle
    /// term the clusters follow the surfaces (Figure 6's point).
    #[test]
    fn the_angle_term_separates_surfaces_of_different_orientation() {
        let floor: Vec<RefVpl> = (0..4)
            .map(|i| vpl(Vec3::new(0.3 * i as f32, 0.0, 0.0), Vec3::Y))
            .collect();
        let wall: Vec<RefVpl> = (1..5)
            .map(|i| vpl(Vec3::new(0.0, 0.02 * i as f32, 0.0), Vec3::X))
            .collect();
        let vpls: Vec<RefVpl> = floor.iter().chain(&wall).copied().collect();
        let w = Weights {
            position: 0.7,
            normal: 0.3,
        };
        let (mapping, vals) = cluster(&vpls, 2, 4, w);
        assert!(mapping[..4].iter().all(|&c| c == mapping[0]));
        assert!(mapping[4..].iter().all(|&c| c == mapping[4]));
        assert_ne!(mapping[0], mapping[4]);
        let positions_only = Weights {
            position: 1.0,
            normal: 0.0,
        };
        let (plain, _) = cluster(&vpls, 2, 4, positions_only);
        assert_ne!(plain, mapping, "without normals the corner VPLs mix");
        for v in &vals {
            assert_eq!(v.count, 4);
            assert!((v.normal.length() - 1.0).abs() < 1e-6);
        }
    }

    /// The area is the bounding rectangle of the VPLs in the plane of the mean normal: a
    /// 0.3 × 0.2 grid on the floor, whatever the tangent basis' orientation in that plane; the
    /// position is the VPL nearest the mean.
    #[test]
    fn val_area_is_the_bounding_rectangle_in_the_plane_of_the_normal() {
        let vpls: Vec<RefVpl> = (0..4)
            .flat_map(|i| (0..3).map(move |j| (i, j)))
            .map(|(i, j)| vpl(Vec3::new(0.1 * i as f32, 2.0, 0.1 * j as f32), Vec3::Y))
            .collect();
        let mapping = vec![Some(0); vpls.len()];
        let vals = finalize(&vpls, &mapping, &seed(&vpls, 1));
        assert!((vals[0].area - 0.3 * 0.2).abs() < 1e-6, "{}", vals[0].area);
        // The position is the VPL nearest the mean (0.15, 2, 0.1): one of the two at 0.05.
        let mean = Vec3::new(0.15, 2.0, 0.1);
        assert!(vpls.iter().any(|v| v.position == vals[0].position));
        assert!((vals[0].position.distance(mean) - 0.05).abs() < 1e-6);
        let (t, b) = tangent_basis(Vec3::new(0.3, -0.5, 0.8).normalize());
        assert!(t.dot(b).abs() < 1e-6 && (t.length() - 1.0).abs() < 1e-6);
        let lone = finalize(&vpls[..1], &[Some(0)], &seed(&vpls[..1], 1));
        assert_eq!(lone[0].area, 0.0, "one VPL spans no rectangle");
    }

    /// A VPL straight above a floor point lights it with Φ·f_r/(A + π d²) (both cosines 1).
    #[test]
    fn one_vpl_overhead_gives_the_disk_irradiance_times_the_brdf() {
        let s = RefSurface {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            brdf: Brdf::lambertian(Vec3::splat(0.5)),
        };
        let light = vpl(Vec3::new(0.0, 2.0, 0.0), -Vec3::Y);
        let got = shade(&s, Vec3::new(1.0, 1.0, 0.0), [&light]);
        let want = 0.5 / PI / (0.01 + PI * 4.0);
        assert!(
            (got - Vec3::splat(want)).abs().max_element() < 1e-7,
            "{got}"
        );
    }

    /// The b² interleave classes' runs partition the VPLs, and where every VPL lights a pixel
    /// alike the average of the classes' shading over a block is the full sum: the blur's
    /// average over a block estimates all N VPLs (unbiased when the runs' means agree, which
    /// runs of Halton points make likely).
    #[test]
    fn interleave_classes_partition_the_vpls() {
        for (b, n) in [(3, 37), (8, 1024), (16, 256), (16, 1000)] {
            let mut covered: Vec<usize> = (0..b * b).flat_map(|c| class_vpls(c, b, n)).collect();
            assert!(
                (0..b * b).all(|c| !class_vpls(c, b, n).is_empty()),
                "{b}, {n}"
            );
            covered.sort_unstable();
            assert_eq!(covered, (0..n as usize).collect::<Vec<_>>(), "{b}, {n}");
        }
        let vpls: Vec<RefVpl> = (0..37)
            .map(|_| vpl(Vec3::new(0.3, 1.0, 0.0), -Vec3::Y))
            .collect();
        let s = RefSurface {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            brdf: Brdf::new(Vec3::splat(0.8), 0.0, 0.4, 1.0),
        };
        let viewer = Vec3::new(0.5, 3.0, 1.0);
        let b = 3;
        let classes: Vec<u32> = (0..b)
            .flat_map(|y| (0..b).map(move |x| interleave_class(x, y, b)))
            .collect();
        let mut sorted = classes.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..b * b).collect::<Vec<_>>());
        let mean: Vec3 = classes
            .iter()
            .map(|&c| shade_interleaved(&s, viewer, &vpls, c, b))
            .sum::<Vec3>()
            / (b * b) as f32;
        let full = shade(&s, viewer, &vpls);
        assert!(
            (mean - full).abs().max_element() < 1e-5 * full.max_element(),
            "{mean} vs {full}"
        );
    }
}
