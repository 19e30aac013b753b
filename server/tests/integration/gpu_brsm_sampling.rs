//! The BRSM sampling stages on the GPU (lavapipe in CI) against CPU ports of their equations:
//! RSM flux and disk areas (eq. 1), view samples, importance (eq. 10–11), cumulative sums and
//! VAL selection with its probabilities (eq. 13–15).

use crate::support::*;
use glam::Vec3;
use lightcast_protocol::{Light, LightKind};
use lightcast_server::gi::common::halton::halton;
use lightcast_server::gi::lightskin::caches::{precompute, CacheParams};
use lightcast_server::gi::lightskin::sampling::SamplingReadback;
use lightcast_server::gi::lightskin::LightSkin;
use lightcast_server::gi::GiParams;
use lightcast_server::passes::frame_uniforms::{light_faces, Coverage};
use lightcast_server::passes::rsm::GlossySender;
use lightcast_server::renderer::{RenderSettings, Renderer};
use lightcast_server::scene::default_light::{default_camera, default_light};
use lightcast_server::scene::{procedural, Scene};

const W: u32 = 64;
const H: u32 = 48;

fn sampling(rsm_size: u32, view_samples: u32, val_count: u32) -> GiParams {
    GiParams::new(lightcast_server::gi::lightskin::BRSM)
        .with("rsm_size", rsm_size)
        .with("view_samples", view_samples)
        .with("val_count", val_count)
        .with("jitter", 0.5)
        .with("defensive", 0.0)
        .with("uniform_importance", false)
        .with("occlusion", false)
        // The light's RSM alone: the Cornell box's lamp would add an emitter face.
        .with("emitters", false)
}

fn renderer_with_caches(scene: &Scene) -> Renderer {
    let caches = precompute(scene, &CacheParams::for_scene(scene), &mut |_| {}).expect("caches");
    let mut renderer = Renderer::new(gpu(), scene.clone());
    renderer
        .gi::<LightSkin>()
        .expect("LightSkin is registered")
        .set_caches(&caches)
        .expect("caches fit the scene");
    renderer
}

fn run(scene: &Scene, light: Light, sampling: GiParams) -> (RenderSettings, SamplingReadback) {
    let mut s = settings(W, H, default_camera(scene), light);
    s.gi = sampling;
    let mut renderer = renderer_with_caches(scene);
    renderer.render(&s).expect("render");
    let readback = renderer
        .gi_if_created::<LightSkin>()
        .expect("a GI frame ran")
        .read_sampling()
        .expect("readback")
        .expect("sampling ran");
    (s, readback)
}

/// Every covered texel's disk area (eq. 1) and flux, the flux derived independently of the
/// shader as the power through the texel: ρ_d · intensity · solid angle (s²·cos³θ for a
/// perspective texel of side s at unit depth, θ off the face's axis), or ρ_d · E · texel area
/// for an orthographic one. The material is found by casting a ray from the light to the
/// texel's position.
fn check_rsm_flux(scene: &Scene, light: &Light, rb: &SamplingReadback, size: u32) {
    let faces = light_faces(light, &scene.bounds, Coverage::Scene);
    let light_pos = Vec3::from(light.position);
    let (mut checked, mut worst, mut worst_glossy) = (0, 0.0f32, 0.0f32);
    for (i, (p, fa)) in rb.rsm_position.iter().zip(&rb.rsm_flux_area).enumerate() {
        if p[3] == 0.0 {
            continue;
        }
        let x = i as u32 % rb.rsm_width;
        let face = &faces[(x / size) as usize];
        let p = Vec3::new(p[0], p[1], p[2]);
        let texel_area = (face.extent / size as f32).powi(2);
        let area = if face.perspective {
            let z = (p - light_pos).dot(face.axis);
            texel_area * z * z
        } else {
            texel_area
        };
        assert!(
            (fa[3] - area).abs() <= 1e-4 * area.max(1e-6),
            "texel {i}: area {} vs {area}",
            fa[3]
        );
        // The surface the light sees through this texel.
        let origin = if light.kind == LightKind::Directional {
            p - Vec3::from(light.direction).normalize() * 100.0
        } else {
            light_pos
        };
        let to_p = p - origin;
        let Some((t, tri)) = trace(scene, origin, to_p.normalize(), to_p.length() + 0.01) else {
            continue;
        };
        if (t - to_p.length()).abs() > 1e-3 {
            continue; // the texel's centre straddles an edge
        }
        let n = Vec3::from_slice(&rb.rsm_normal[i][..3]).normalize();
        // Skip texels on a seam between two surfaces (the ray may pick the other one).
        let corners = [0, 1, 2]
            .map(|k| Vec3::from(scene.vertices[scene.indices[tri * 3 + k] as usize].position));
        let geometric = (corners[1] - corners[0])
            .cross(corners[2] - corners[0])
            .normalize();
        if geometric.dot(n).abs() < 0.99 {
            continue;
        }
        let m = &scene.materials[triangle_material(scene, tri) as usize];
        let (l, e) = incident(light, p);
        let facing = if n.dot(l) > 0.0 { 1.0 } else { 0.0 };
        let received = if face.perspective {
            let r = (p - light_pos).length();
            let cos_theta = (p - light_pos).dot(face.axis) / r;
            let intensity = e * r * r;
            intensity * texel_area * cos_theta.powi(3)
        } else {
            e * texel_area
        };
        let lobes = m.brdf().lobes(n.dot(l));
        let expected = lobes.diffuse * received * facing;
        let got = Vec3::new(fa[0], fa[1], fa[2]);
        let err = (got - expected).abs().max_element() / expected.max_element().max(1e-12);
        if expected.max_element() > 0.0 {
            worst = worst.max(err);
        }
        // The glossy lobe it sends on (`senders: full`, the default): the Phong lobe's colour
        // times what it receives, about the light's mirror direction, its exponent within the
        // texel's quantization (log2 k in 10 bits over [0, 12]: 0.41 %; the direction in 11-bit
        // octahedral coordinates: under a milliradian).
        let g = GlossySender::decode(rb.rsm_glossy[i]);
        let expected = lobes.glossy * received * facing;
        let err = (Vec3::from(g.weight) - expected).abs().max_element()
            / expected.max_element().max(1e-12);
        if expected.max_element() > 0.0 {
            worst_glossy = worst_glossy.max(err);
            let mirror = 2.0 * n.dot(l) * n - l;
            assert!(
                Vec3::from(g.mirror).angle_between(mirror) < 2e-3,
                "texel {i}: mirror {:?} vs {mirror}",
                g.mirror
            );
            assert!(
                (g.exponent / lobes.exponent - 1.0).abs() < 5e-3,
                "texel {i}: exponent {} vs {}",
                g.exponent,
                lobes.exponent
            );
        }
        checked += 1;
    }
    assert!(checked > 50, "only {checked} texels could be checked");
    assert!(worst < 2e-3, "worst relative flux error {worst}");
    assert!(
        worst_glossy < 2e-3,
        "worst relative glossy weight error {worst_glossy}"
    );
}

/// `alpha`: the defensive mixture weight the selection ran with.
fn check_importance_sums_and_selection(rb: &SamplingReadback, val_count: u32, alpha: f64) {
    // Importance against eq. 10–11.
    let want: Vec<f32> = (0..rb.importance.len())
        .map(|i| cpu_importance(rb, i))
        .collect();
    let scale = want.iter().copied().fold(0.0f32, f32::max);
    assert!(scale > 0.0, "no VAL is important");
    for (i, (&g, &c)) in rb.importance.iter().zip(&want).enumerate() {
        assert!(
            (g - c).abs() <= 1e-4 * scale + 1e-3 * c,
            "texel {i}: importance {g} vs CPU {c}"
        );
    }
    // Cumulative sums: down each column, then across the column totals.
    let (w, h) = (rb.rsm_width as usize, rb.rsm_height as usize);
    let mut row_total = 0.0f64;
    for x in 0..w {
        let mut acc = 0.0f64;
        for y in 0..h {
            acc += f64::from(rb.importance[y * w + x]);
            let got = f64::from(rb.column_sums[y * w + x]);
            assert!(
                (got - acc).abs() <= 1e-5 * acc.max(f64::from(scale)),
                "column sum ({x},{y}) {got} vs {acc}"
            );
        }
        row_total += acc;
        let got = f64::from(rb.row_sums[x]);
        assert!(
            (got - row_total).abs() <= 1e-5 * row_total.max(1e-30),
            "row sum {x}: {got} vs {row_total}"
        );
    }
    // Selection: stratified draws hit every texel N·P times, rounded up or down, with
    // P = (1 − α)·I/ΣI + α/M.
    let total: f64 = rb.importance.iter().map(|&v| f64::from(v)).sum();
    let texels = rb.importance.len() as f64;
    let pdf = |i: usize| (1.0 - alpha) * f64::from(rb.importance[i]) / total + alpha / texels;
    let mut counts = vec![0u32; rb.importance.len()];
    for v in &rb.vals {
        counts[v.texel as usize] += 1;
        let expected_weight = 1.0 / (f64::from(val_count) * pdf(v.texel as usize));
        assert!(
            (f64::from(v.weight) - expected_weight).abs() <= 1e-3 * expected_weight,
            "weight {} vs {expected_weight}",
            v.weight
        );
        let texel = v.texel as usize;
        assert_eq!(
            v.position,
            [
                rb.rsm_position[texel][0],
                rb.rsm_position[texel][1],
                rb.rsm_position[texel][2]
            ]
        );
        assert_eq!(v.area, rb.rsm_flux_area[texel][3]);
    }
    let mut worst = 0.0f64;
    for (i, &c) in counts.iter().enumerate() {
        let expected = f64::from(val_count) * pdf(i);
        worst = worst.max((f64::from(c) - expected).abs());
    }
    assert!(
        worst < 1.05,
        "selection frequency deviates from N·P by {worst}"
    );
}

#[test]
fn spot_light_rsm_importance_sums_and_selection_match_the_cpu() {
    let scene = procedural::cornell_box();
    let light = default_light(&scene);
    assert_eq!(light.kind, LightKind::Spot);
    let (settings, rb) = run(&scene, light.clone(), sampling(32, 128, 4096));
    check_rsm_flux(&scene, &light, &rb, 32);
    check_importance_sums_and_selection(&rb, 4096, 0.0);

    // View samples sit at Halton pixel positions of the G-buffer (checked by ray casting).
    assert_eq!(rb.view_samples.len(), 128);
    let mut hits = 0;
    for (i, vs) in rb.view_samples.iter().enumerate() {
        let px = ((halton(i as u32 + 1, 2) * W as f32) as u32).min(W - 1);
        let py = ((halton(i as u32 + 1, 3) * H as f32) as u32).min(H - 1);
        let (o, d) = pixel_ray(&settings.camera, &scene, W, H, px, py);
        match trace(&scene, o, d, 100.0) {
            Some((t, _)) if vs.valid > 0.0 => {
                let dist = (o + d * t).distance(Vec3::from(vs.position));
                assert!(
                    dist < 0.02,
                    "view sample {i} at {:?}, ray hit {}",
                    vs.position,
                    o + d * t
                );
                hits += 1;
            }
            Some(_) => panic!("view sample {i} missed geometry the CPU ray hits"),
            None => assert_eq!(vs.valid, 0.0, "view sample {i} on background"),
        }
    }
    assert!(hits > 64);
}

#[test]
fn point_light_atlas_has_six_faces_with_correct_areas_and_flux() {
    let scene = procedural::cornell_box();
    let light = Light {
        kind: LightKind::Point,
        position: [0.1, 1.2, 0.2],
        direction: [0.0, -1.0, 0.0],
        color: [1.0, 0.9, 0.8],
        intensity: 20.0,
        inner_cone: 0.0,
        outer_cone: 0.0,
    };
    let (_, rb) = run(&scene, light.clone(), sampling(16, 64, 2048));
    assert_eq!((rb.rsm_width, rb.rsm_height), (96, 16));
    // Every face but +Z (the room's open side) sees some surface.
    for face in [0, 1, 2, 3, 5] {
        let covered = (0..16 * 16)
            .filter(|k| {
                let (x, y) = (face * 16 + k % 16, k / 16);
                rb.rsm_position[y * 96 + x][3] > 0.0
            })
            .count();
        assert!(covered > 0, "face {face} is empty");
    }
    check_rsm_flux(&scene, &light, &rb, 16);
    check_importance_sums_and_selection(&rb, 2048, 0.0);
}

#[test]
fn directional_light_uses_constant_disk_areas() {
    let scene = procedural::build("street?blocks=2").expect("street");
    let light = default_light(&scene);
    assert_eq!(light.kind, LightKind::Directional);
    let (_, rb) = run(&scene, light.clone(), sampling(32, 64, 1024));
    check_rsm_flux(&scene, &light, &rb, 32);
    check_importance_sums_and_selection(&rb, 1024, 0.0);
}

#[test]
fn defensive_mixture_draws_by_the_mixed_pdf_and_reaches_unimportant_vals() {
    let scene = procedural::cornell_box();
    let light = default_light(&scene);
    let mut s = sampling(32, 64, 4096);
    s.set("defensive", 0.25);
    let (_, rb) = run(&scene, light, s);
    check_importance_sums_and_selection(&rb, 4096, 0.25);
    // Every texel has P ≥ α/M = 0.25/1024, so 4,096 stratified draws reach each one.
    let mut drawn = vec![false; rb.importance.len()];
    for v in &rb.vals {
        drawn[v.texel as usize] = true;
    }
    assert!(drawn.iter().all(|&d| d), "some texel was never drawn");
}

#[test]
fn uniform_importance_with_one_draw_per_texel_selects_every_val_exactly_once() {
    let scene = procedural::cornell_box();
    let mut s = sampling(16, 32, 16 * 16);
    s.set("uniform_importance", true);
    let (_, rb) = run(&scene, default_light(&scene), s);
    // Every texel is drawn exactly once with weight 1: the estimator then sums each VAL once,
    // like LightSkin's full accumulation (uncovered texels carry no flux).
    let mut weight = vec![0.0f32; rb.importance.len()];
    for v in &rb.vals {
        weight[v.texel as usize] += v.weight;
    }
    for (i, w) in weight.iter().enumerate() {
        assert!(
            (w - 1.0).abs() < 1e-4,
            "texel {i}: total weight {w}, want 1"
        );
    }
}

#[test]
fn sampling_settings_are_validated() {
    let scene = procedural::cornell_box();
    let mut renderer = renderer_with_caches(&scene);
    for (field, s) in [
        ("rsm_size", sampling(8, 64, 64)),
        ("rsm_size", sampling(8192, 64, 64)),
        ("view_samples", sampling(32, 0, 64)),
        ("val_count", sampling(32, 64, 0)),
        ("val_count", sampling(32, 64, u32::MAX)),
    ] {
        let mut settings = settings(16, 16, default_camera(&scene), default_light(&scene));
        settings.gi = s;
        match renderer.render(&settings) {
            Err(lightcast_server::renderer::RenderError::InvalidSetting { field: f, .. }) => {
                assert_eq!(f, field)
            }
            other => panic!(
                "{field}: expected InvalidSetting, got {:?}",
                other.map(|f| f.width)
            ),
        }
    }
}
