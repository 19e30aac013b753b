//! Light cache precomputation (`gi::lightskin::caches`) and its on-disk store (`gi::lightskin::cache_store`) checked
//! against independent references: random surface points, brute-force nearest neighbours and
//! triangle areas summed here.

use glam::Vec3;
use lightcast_server::gi::lightskin::cache_store::CacheStore;
use lightcast_server::gi::lightskin::caches::{
    precompute, CacheError, CacheParams, CacheSet, Progress, NEIGHBOURS,
};
use lightcast_server::scene::{brdf::Brdf, procedural, Material, Scene, Texture, Vertex};
use std::path::PathBuf;

/// Deterministic pseudo-random numbers in [0, 1).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn no_progress() -> impl FnMut(Progress) {
    |_| {}
}

fn scene(name: &str, positions: Vec<Vec3>, normals: Vec<Vec3>, indices: Vec<u32>) -> Scene {
    let vertices = positions
        .iter()
        .zip(&normals)
        .map(|(p, n)| Vertex {
            position: p.to_array(),
            normal: n.to_array(),
            uv: [0.0, 0.0],
            material: 0,
        })
        .collect();
    Scene::new(
        name,
        vertices,
        indices,
        vec![Material::default()],
        vec![],
        vec![],
        vec![],
    )
    .expect("valid test scene")
}

/// An `n × n` grid of quads spanning `corner + [0,1]·u + [0,1]·v`, facing `u × v`.
fn grid(corner: Vec3, u: Vec3, v: Vec3, n: u32, out: &mut (Vec<Vec3>, Vec<Vec3>, Vec<u32>)) {
    let normal = u.cross(v).normalize();
    let base = out.0.len() as u32;
    for j in 0..=n {
        for i in 0..=n {
            out.0
                .push(corner + u * (i as f32 / n as f32) + v * (j as f32 / n as f32));
            out.1.push(normal);
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = base + j * (n + 1) + i;
            let (b, c, d) = (a + 1, a + n + 2, a + n + 1);
            out.2.extend([a, b, c, a, c, d]);
        }
    }
}

/// A 4 × 3 plane tilted 20° about X, so voxel boundaries cut it at odd places.
fn tilted_plane() -> Scene {
    let tilt = glam::Quat::from_rotation_x(20f32.to_radians());
    let mut g = Default::default();
    grid(
        tilt * Vec3::new(-2.0, 0.1, 1.5),
        tilt * Vec3::new(4.0, 0.0, 0.0),
        tilt * Vec3::new(0.0, 0.0, -3.0),
        12,
        &mut g,
    );
    scene("plane", g.0, g.1, g.2)
}

/// A UV sphere of radius 1 with smooth vertex normals.
fn sphere() -> Scene {
    let (rings, segments) = (24u32, 48u32);
    let mut positions = Vec::new();
    for r in 0..=rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..=segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            positions.push(Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                -theta.sin() * phi.sin(),
            ));
        }
    }
    let mut indices = Vec::new();
    for r in 0..rings {
        for s in 0..segments {
            let a = r * (segments + 1) + s;
            let (b, c, d) = (a + segments + 1, a + segments + 2, a + 1);
            // Pole quads collapse to one triangle; skip their zero-area halves.
            if r != 0 {
                indices.extend([a, b, d]);
            }
            if r != rings - 1 {
                indices.extend([b, c, d]);
            }
        }
    }
    let normals = positions.clone();
    scene("sphere", positions, normals, indices)
}

/// An axis-aligned cube of edge 1, offset from the origin, faces split 3 × 3.
fn cube() -> Scene {
    let mut g = Default::default();
    let o = Vec3::new(0.3, 0.2, -0.4);
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
    grid(o, z, y, 3, &mut g); // -X
    grid(o + x, y, z, 3, &mut g); // +X
    grid(o, x, z, 3, &mut g); // -Y
    grid(o + y, z, x, 3, &mut g); // +Y
    grid(o, y, x, 3, &mut g); // -Z
    grid(o + z, x, y, 3, &mut g); // +Z
    scene("cube", g.0, g.1, g.2)
}

fn corners(scene: &Scene, t: usize) -> [Vec3; 3] {
    std::array::from_fn(|k| Vec3::from(scene.vertices[scene.indices[3 * t + k] as usize].position))
}

fn total_area(scene: &Scene) -> f64 {
    (0..scene.triangle_count())
        .map(|t| {
            let [a, b, c] = corners(scene, t);
            f64::from(0.5 * (b - a).cross(c - a).length())
        })
        .sum()
}

fn params(d_eps: f32) -> CacheParams {
    CacheParams {
        d_eps,
        theta_eps_degrees: 30.0,
    }
}

fn compute(scene: &Scene, params: &CacheParams) -> CacheSet {
    precompute(scene, params, &mut no_progress()).expect("caches for a valid scene")
}

/// Every random surface point has a cache within d_eps whose normal is within theta_eps of the
/// geometric surface normal (the paper's two control parameters, checked independently of the
/// algorithm's own sampling).
fn assert_covered(scene: &Scene, set: &CacheSet, points_per_triangle: usize) {
    let mut rng = Rng(42);
    let d = set.params.d_eps;
    let cos = set.params.theta_eps_degrees.to_radians().cos();
    let mut checked = 0;
    for t in 0..scene.triangle_count() {
        let [a, b, c] = corners(scene, t);
        let Some(n) = (b - a).cross(c - a).try_normalize() else {
            continue;
        };
        for _ in 0..points_per_triangle {
            let (mut u, mut v) = (rng.next(), rng.next());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let p = a + (b - a) * u + (c - a) * v;
            let best = set
                .caches
                .iter()
                .filter(|cache| Vec3::from(cache.normal).dot(n) >= cos)
                .map(|cache| Vec3::from(cache.position).distance(p))
                .fold(f32::INFINITY, f32::min);
            assert!(
                best <= d,
                "{}: point {p} (normal {n}) has no compatible cache within d_eps = {d}; nearest \
                 compatible is {best} away",
                scene.name
            );
            checked += 1;
        }
    }
    assert!(checked > 0);
}

fn assert_area_matches(scene: &Scene, set: &CacheSet) {
    let expected = total_area(scene);
    let sum: f64 = set.caches.iter().map(|c| f64::from(c.area)).sum();
    assert!(
        (sum - expected).abs() <= 0.01 * expected,
        "{}: cache areas sum to {sum}, surface area is {expected}",
        scene.name
    );
    assert!(set
        .caches
        .iter()
        .all(|c| c.area > 0.0 && c.disk_area == c.area));
    assert!((set.stats.surface_area - expected).abs() <= 1e-3 * expected);
}

fn assert_neighbours_valid(scene: &Scene, set: &CacheSet) {
    assert_eq!(set.vertex_caches.len(), scene.vertices.len());
    for (v, entry) in scene.vertices.iter().zip(&set.vertex_caches) {
        let p = Vec3::from(v.position);
        let n = Vec3::from(v.normal);
        let facing: Vec<usize> = (0..set.caches.len())
            .filter(|&c| Vec3::from(set.caches[c].normal).dot(n) >= 0.0)
            .collect();
        let distance = |c: u32| Vec3::from(set.caches[c as usize].position).distance_squared(p);
        let valid: Vec<u32> = entry.iter().copied().filter(|&c| c != u32::MAX).collect();
        assert_eq!(valid.len(), NEIGHBOURS.min(set.caches.len()));
        assert!(valid.iter().all(|&c| (c as usize) < set.caches.len()));
        let facing_count = NEIGHBOURS.min(facing.len());
        for w in valid[..facing_count].windows(2) {
            assert!(distance(w[0]) <= distance(w[1]), "not sorted by distance");
        }
        let nearest = facing
            .iter()
            .map(|&c| distance(c as u32))
            .fold(f32::INFINITY, f32::min);
        assert_eq!(
            distance(valid[0]),
            nearest,
            "first entry is not the nearest"
        );
        // The 16th facing neighbour is no further than any facing cache left out.
        if let Some(&last) = valid[..facing_count].last() {
            for &c in &facing {
                if !valid.contains(&(c as u32)) {
                    assert!(distance(c as u32) >= distance(last));
                }
            }
        }
    }
}

#[test]
fn cornell_box_is_covered_with_exact_areas() {
    let scene = procedural::cornell_box();
    let p = CacheParams::for_scene(&scene);
    let set = compute(&scene, &p);
    assert!(
        (3000..12000).contains(&set.caches.len()),
        "{} caches",
        set.caches.len()
    );
    assert_covered(&scene, &set, 4);
    assert_area_matches(&scene, &set);
    // The red and green walls tint their caches; white surfaces stay grey.
    assert!(set
        .caches
        .iter()
        .any(|c| c.diffuse[0] > 0.6 && c.diffuse[1] < 0.1));
    assert!(set
        .caches
        .iter()
        .any(|c| c.diffuse[1] > 0.4 && c.diffuse[0] < 0.2));
}

#[test]
fn small_street_is_covered_with_exact_areas() {
    let scene = procedural::build("street?blocks=3&detail=1").expect("street scene");
    let set = compute(&scene, &CacheParams::for_scene(&scene));
    assert_covered(&scene, &set, 4);
    assert_area_matches(&scene, &set);
}

#[test]
fn textured_materials_use_the_mean_linear_texture_colour() {
    let mut g = Default::default();
    grid(Vec3::ZERO, Vec3::X, -Vec3::Z, 2, &mut g);
    let plain = scene("textured", g.0, g.1, g.2);
    // Half white, half black texels: mean linear colour 0.5.
    let texture = Texture {
        name: "checker".into(),
        width: 2,
        height: 1,
        rgba8: vec![255, 255, 255, 255, 0, 0, 0, 255],
    };
    let material = Material {
        base_color: [0.8, 0.4, 0.2, 1.0],
        base_color_texture: Some(0),
        ..Material::default()
    };
    let textured = Scene::new(
        "textured",
        plain.vertices.clone(),
        plain.indices.clone(),
        vec![material],
        vec![texture],
        vec![],
        vec![],
    )
    .expect("valid textured scene");
    let set = compute(&textured, &params(0.5));
    // The untextured material of half the base colour, as its lobes reflect it.
    let half = Brdf::new(Vec3::new(0.4, 0.2, 0.1), 0.0, 1.0, 1.0).mean_lobes();
    for c in &set.caches {
        for (got, want) in c.diffuse.iter().zip(half.diffuse.to_array()) {
            assert!((got - want).abs() < 1e-5, "diffuse {:?}", c.diffuse);
        }
    }
}

#[test]
fn synthetic_shapes_are_covered_with_exact_areas() {
    for (shape, d_eps) in [(tilted_plane(), 0.2), (sphere(), 0.15), (cube(), 0.1)] {
        let set = compute(&shape, &params(d_eps));
        assert_covered(&shape, &set, 20);
        assert_area_matches(&shape, &set);
    }
}

#[test]
fn coarse_angle_and_distance_still_cover_the_sphere() {
    let shape = sphere();
    for p in [
        CacheParams {
            d_eps: 0.6,
            theta_eps_degrees: 90.0,
        },
        CacheParams {
            d_eps: 0.3,
            theta_eps_degrees: 10.0,
        },
    ] {
        let set = compute(&shape, &p);
        assert_covered(&shape, &set, 10);
        assert_area_matches(&shape, &set);
    }
}

#[test]
fn plane_cache_count_scales_with_inverse_square_distance() {
    let plane = tilted_plane();
    let coarse = compute(&plane, &params(0.4)).caches.len() as f64;
    let fine = compute(&plane, &params(0.2)).caches.len() as f64;
    let ratio = fine / coarse;
    assert!(
        (3.0..=5.0).contains(&ratio),
        "{coarse} caches at d_eps 0.4, {fine} at 0.2 (ratio {ratio})"
    );
}

#[test]
fn vertex_neighbours_match_brute_force() {
    let cube = cube();
    let set = compute(&cube, &params(0.2));
    assert_neighbours_valid(&cube, &set);
    let sphere = sphere();
    let set = compute(&sphere, &params(0.3));
    assert_neighbours_valid(&sphere, &set);
}

#[test]
fn few_caches_pad_with_max_and_fall_back_to_any_cache() {
    // One quad with d_eps larger than the quad: a single cache. A vertex facing away still
    // gets it (fallback), then padding.
    let mut g = Default::default();
    grid(Vec3::ZERO, Vec3::X, Vec3::Z * -1.0, 1, &mut g);
    g.1[0] = -Vec3::Y;
    let quad = scene("quad", g.0, g.1, g.2);
    let set = compute(&quad, &params(4.0));
    assert_eq!(set.caches.len(), 1);
    for entry in &set.vertex_caches {
        assert_eq!(entry[0], 0);
        assert!(entry[1..].iter().all(|&c| c == u32::MAX));
    }
}

#[test]
fn output_is_deterministic_across_thread_counts() {
    let scene = procedural::cornell_box();
    let p = CacheParams::for_scene(&scene);
    let parallel = compute(&scene, &p);
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool")
        .install(|| compute(&scene, &p));
    assert_eq!(parallel.caches, single.caches);
    assert_eq!(parallel.vertex_caches, single.vertex_caches);
    let counts = |s: &CacheSet| {
        (
            s.stats.samples,
            s.stats.voxels,
            s.stats.caches_before_merge,
            s.stats.merged_away,
        )
    };
    assert_eq!(counts(&parallel), counts(&single));
}

#[test]
fn progress_reports_every_step_to_completion() {
    let mut reports: Vec<Progress> = Vec::new();
    precompute(&cube(), &params(0.2), &mut |p| reports.push(p)).expect("caches");
    for step in [
        "sampling",
        "voxelising",
        "clustering",
        "merging",
        "assigning",
        "neighbours",
    ] {
        let last = reports
            .iter()
            .rev()
            .find(|p| p.step == step)
            .unwrap_or_else(|| panic!("no progress for {step}"));
        assert_eq!(last.done, last.total, "{step} did not finish");
    }
}

#[test]
fn invalid_parameters_name_the_field() {
    let scene = cube();
    let err = |d_eps, theta| {
        precompute(
            &scene,
            &CacheParams {
                d_eps,
                theta_eps_degrees: theta,
            },
            &mut no_progress(),
        )
        .expect_err("invalid parameters")
    };
    for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        let e = err(bad, 30.0);
        assert!(matches!(e, CacheError::InvalidDistance(_)));
        assert!(e.to_string().contains("d_eps"), "{e}");
    }
    for bad in [0.0, 90.5, -5.0, f32::NAN] {
        let e = err(0.1, bad);
        assert!(e.to_string().contains("theta_eps_degrees"), "{e}");
    }
    // 6 square units at d_eps 1e-4 would be 2.4e9 caches: refused before any work.
    let e = err(1e-4, 30.0);
    let text = e.to_string();
    assert!(matches!(e, CacheError::TooManyCaches { .. }), "{e}");
    assert!(
        text.contains("d_eps = 0.0001") && text.contains("d_eps >= 0.00347"),
        "{text}"
    );
}

#[test]
fn default_parameters_follow_scene_scale() {
    let scene = cube();
    let p = CacheParams::for_scene(&scene);
    // 2·sqrt(6 / 6000) = 0.063245… → 0.0632.
    assert_eq!(p.d_eps, 0.0632);
    assert_eq!(p.theta_eps_degrees, 30.0);
    assert!(p.validate().is_ok());
}

// ---------------------------------------------------------------------------------------------
// Store
// ---------------------------------------------------------------------------------------------

/// A fresh directory under Cargo's per-test scratch space.
fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("caches-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn only_file(dir: &std::path::Path) -> PathBuf {
    let files: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("store directory exists")
        .map(|e| e.expect("directory entry").path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    files[0].clone()
}

#[test]
fn store_loads_what_it_computed() {
    let dir = scratch("roundtrip");
    let store = CacheStore::new(dir.join("nested"));
    let scene = cube();
    let p = params(0.2);
    let (first, from_disk) = store
        .load_or_compute(&scene, &p, &mut no_progress())
        .expect("computed");
    assert!(!from_disk);
    let (second, from_disk) = store
        .load_or_compute(&scene, &p, &mut no_progress())
        .expect("loaded");
    assert!(from_disk);
    assert_eq!(first, second);

    // Different parameters: different key, recomputed, second file.
    let other = params(0.25);
    assert_ne!(CacheStore::key(&scene, &p), CacheStore::key(&scene, &other));
    let (third, from_disk) = store
        .load_or_compute(&scene, &other, &mut no_progress())
        .expect("computed");
    assert!(!from_disk);
    assert_eq!(third.params, other);
    assert_eq!(
        std::fs::read_dir(dir.join("nested")).expect("dir").count(),
        2
    );

    // A different material changes the key too.
    let mut tinted = scene.clone();
    tinted.materials[0].base_color = [0.1, 0.2, 0.3, 1.0];
    assert_ne!(CacheStore::key(&scene, &p), CacheStore::key(&tinted, &p));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn store_recomputes_corrupt_files_without_panicking() {
    let dir = scratch("corrupt");
    let store = CacheStore::new(&dir);
    let scene = cube();
    let p = params(0.2);
    let (reference, _) = store
        .load_or_compute(&scene, &p, &mut no_progress())
        .expect("computed");
    let path = only_file(&dir);
    let good = std::fs::read(&path).expect("stored file");

    let mut flipped = good.clone();
    let middle = flipped.len() / 2;
    flipped[middle] ^= 0xff;
    let damaged: Vec<Vec<u8>> = vec![
        good[..good.len() / 3].to_vec(),
        good[..good.len() - 1].to_vec(),
        flipped,
        Vec::new(),
        b"not a cache file at all".to_vec(),
    ];
    for bytes in damaged {
        std::fs::write(&path, &bytes).expect("overwrite");
        let (set, from_disk) = store
            .load_or_compute(&scene, &p, &mut no_progress())
            .expect("recomputed");
        assert!(!from_disk);
        assert_eq!(set.caches, reference.caches);
        // The recomputed set replaced the damaged file.
        assert_eq!(std::fs::read(&path).expect("rewritten").len(), good.len());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn unwritable_store_still_returns_caches() {
    let dir = scratch("unwritable");
    std::fs::create_dir_all(&dir).expect("scratch dir");
    // A directory below a regular file can never be created, even as root.
    let blocker = dir.join("file");
    std::fs::write(&blocker, b"x").expect("blocker file");
    let store = CacheStore::new(blocker.join("store"));
    let scene = cube();
    let (set, from_disk) = store
        .load_or_compute(&scene, &params(0.2), &mut no_progress())
        .expect("computed despite the store");
    assert!(!from_disk);
    assert!(!set.caches.is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn store_rejects_invalid_parameters() {
    let dir = scratch("invalid");
    let store = CacheStore::new(&dir);
    let e = store
        .load_or_compute(&cube(), &params(-1.0), &mut no_progress())
        .expect_err("invalid d_eps");
    assert!(e.to_string().contains("d_eps"), "{e}");
    assert!(!dir.exists());
}
