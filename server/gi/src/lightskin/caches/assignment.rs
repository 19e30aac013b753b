//! After the steps: every sample handed to its nearest compatible cache (each cache's Voronoi
//! area and area-weighted material) and every scene vertex's nearest caches.

use super::*;

/// Hands every sample to its nearest cache within d_eps whose normal is within theta_eps (else
/// to the cache that averaged it), so a cache's area is its Voronoi cell on the surface, and
/// averages the samples' materials per cache. Caches left without samples are dropped.
pub(super) fn assign(
    scene: &Scene,
    samples: &[Sample],
    joined: &[Joined],
    owner: &[u32],
    setup: &Setup,
    progress: &mut dyn FnMut(Progress),
) -> Vec<LightCache> {
    let positions: Vec<Vec3> = joined.iter().map(|c| c.position).collect();
    let tree = KdTree::new(&positions);
    let d2 = setup.d_eps * setup.d_eps;
    let assigned = par_map_chunked(samples.len(), "assigning", progress, |i| {
        let s = &samples[i];
        let mut best = Nearest::new(1);
        tree.nearest(s.position, d2, &mut best, &|c| {
            let c = &joined[c as usize];
            c.model == s.model && c.normal.dot(s.normal) > setup.cos_theta
        });
        let nearest = best.ids().next();
        nearest.unwrap_or(owner[i])
    });

    let splits = material_lobes(scene);
    #[derive(Clone, Copy, Default)]
    struct Sum {
        area: f64,
        diffuse: DVec3,
        glossy: DVec3,
        exponent: f64,
    }
    let mut sums = vec![Sum::default(); joined.len()];
    for (s, &c) in samples.iter().zip(&assigned) {
        let m = &splits[s.material as usize];
        let a = f64::from(s.area);
        let sum = &mut sums[c as usize];
        sum.area += a;
        sum.diffuse += m.diffuse.as_dvec3() * a;
        sum.glossy += m.glossy.as_dvec3() * a;
        sum.exponent += f64::from(m.exponent) * a;
    }
    joined
        .iter()
        .zip(&sums)
        .filter(|(_, s)| s.area > 0.0)
        .map(|(c, s)| {
            let area = s.area as f32;
            LightCache {
                position: c.position.to_array(),
                area,
                normal: c.normal.to_array(),
                disk_area: area,
                diffuse: (s.diffuse / s.area).as_vec3().to_array(),
                exponent: (s.exponent / s.area) as f32,
                glossy: (s.glossy / s.area).as_vec3().to_array(),
                model: c.model,
            }
        })
        .collect()
}

/// The [`NEIGHBOURS`] nearest caches of every vertex among those facing the same hemisphere
/// (normal within 90°, so a wall's caches do not light the back of the wall), nearest first;
/// if the whole scene has fewer such caches, the nearest others follow, then u32::MAX.
pub(super) fn vertex_neighbours(
    scene: &Scene,
    caches: &[LightCache],
    progress: &mut dyn FnMut(Progress),
) -> Vec<[u32; NEIGHBOURS]> {
    let positions: Vec<Vec3> = caches.iter().map(|c| Vec3::from(c.position)).collect();
    let normals: Vec<Vec3> = caches.iter().map(|c| Vec3::from(c.normal)).collect();
    let models = vertex_models(scene);
    let tree = KdTree::new(&positions);
    par_map_chunked(scene.vertices.len(), "neighbours", progress, |v| {
        let vertex = &scene.vertices[v];
        // Only its own model's caches: they move together.
        let model = models[v];
        let p = Vec3::from(vertex.position);
        // A broken (non-finite) vertex normal faces every cache (dot 0) rather than none.
        let n = Some(Vec3::from(vertex.normal))
            .filter(|n| n.is_finite())
            .unwrap_or(Vec3::ZERO);
        let mut out = [u32::MAX; NEIGHBOURS];
        let mut facing = Nearest::new(NEIGHBOURS);
        tree.nearest(p, f32::INFINITY, &mut facing, &|c| {
            caches[c as usize].model == model && normals[c as usize].dot(n) >= 0.0
        });
        let mut len = 0;
        for id in facing.ids() {
            out[len] = id;
            len += 1;
        }
        if len < NEIGHBOURS {
            let mut others = Nearest::new(NEIGHBOURS - len);
            tree.nearest(p, f32::INFINITY, &mut others, &|c| {
                caches[c as usize].model == model && normals[c as usize].dot(n) < 0.0
            });
            for id in others.ids() {
                out[len] = id;
                len += 1;
            }
        }
        out
    })
}
