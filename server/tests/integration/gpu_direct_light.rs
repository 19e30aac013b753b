//! Direct lighting on the GPU (lavapipe in CI) against CPU ports of the shading equations,
//! at small sizes. Radiance is compared in the HDR buffer, before exposure and tone mapping.

use crate::support::*;
use glam::Vec3;
use lightcast_protocol::{Camera, Light, LightKind};

const W: u32 = 64;
const H: u32 = 48;

/// A 4 m floor at y = 0 seen from above at an angle.
fn floor_scene(material: lightcast_server::scene::Material) -> lightcast_server::scene::Scene {
    let (mut v, mut i) = (Vec::new(), Vec::new());
    quad(&mut v, &mut i, floor_corners(0.0, 0.0, 0.0, 2.0), 0);
    scene(v, i, vec![material])
}

fn oblique_camera() -> Camera {
    Camera {
        position: [0.3, 1.5, 1.6],
        target: [0.0, 0.0, 0.0],
        fov_y_degrees: 50.0,
    }
}

/// Mean relative error between GPU HDR radiance and the CPU reference over floor pixels.
fn compare_with_reference(
    material: lightcast_server::scene::Material,
    light: Light,
) -> (f32, usize) {
    let scene = floor_scene(material.clone());
    let camera = oblique_camera();
    let frame = render(
        scene.clone(),
        &settings(W, H, camera.clone(), light.clone()),
    );
    let (mut err_sum, mut ref_sum, mut count) = (0.0f32, 0.0f32, 0usize);
    for y in 0..H {
        for x in 0..W {
            let Some(p) = hit_plane(&camera, &scene, W, H, x, y, 0.0) else {
                continue;
            };
            // Skip pixels near the floor's edge, where coverage of the pixel is partial.
            if p.x.abs() > 1.9 || p.z.abs() > 1.9 {
                continue;
            }
            let expected = direct_radiance(&material, &light, &camera, p, Vec3::Y);
            let got = hdr_at(&frame, x, y);
            err_sum += (got - expected).abs().element_sum();
            ref_sum += expected.element_sum();
            count += 1;
        }
    }
    assert!(
        count > (W * H / 3) as usize,
        "floor covers too few pixels: {count}"
    );
    (err_sum / ref_sum.max(1e-12), count)
}

#[test]
fn diffuse_floor_under_a_sun_matches_lambert() {
    let light = directional(Vec3::new(0.3, -1.0, -0.2), 3.0);
    let (rel, _) = compare_with_reference(plain_material([0.6, 0.4, 0.2], 0.0, 1.0), light);
    assert!(rel < 0.01, "relative mean error {rel}");
}

#[test]
fn glossy_metal_matches_the_ggx_lobe() {
    // A sun whose mirror reflection points near the camera, so the lobe dominates.
    let light = directional(Vec3::new(0.1, -1.0, 1.0), 2.0);
    let metal = plain_material([0.9, 0.7, 0.3], 1.0, 0.45);
    assert_eq!(
        metal.brdf().lobes(1.0).diffuse,
        Vec3::ZERO,
        "a metal is all specular"
    );
    let (rel, _) = compare_with_reference(metal, light);
    assert!(rel < 0.02, "relative mean error {rel}");
}

#[test]
fn spot_light_cone_and_inverse_square_match() {
    let light = Light {
        kind: LightKind::Spot,
        position: [0.2, 1.2, 0.1],
        direction: [0.0, -1.0, 0.0],
        color: [1.0, 0.8, 0.6],
        intensity: 5.0,
        inner_cone: 20f32.to_radians(),
        outer_cone: 35f32.to_radians(),
    };
    let (rel, _) = compare_with_reference(plain_material([0.8, 0.8, 0.8], 0.0, 0.8), light);
    assert!(rel < 0.02, "relative mean error {rel}");
}

#[test]
fn point_light_falls_off_with_distance_squared() {
    let light = Light {
        kind: LightKind::Point,
        position: [-0.4, 0.6, 0.2],
        direction: [0.0, -1.0, 0.0],
        color: [1.0; 3],
        intensity: 2.0,
        inner_cone: 0.0,
        outer_cone: 0.0,
    };
    let (rel, _) = compare_with_reference(plain_material([0.5, 0.5, 0.5], 0.0, 1.0), light);
    assert!(rel < 0.01, "relative mean error {rel}");
}

/// Floor with a 0.5 m square occluder hovering above its centre, seen from straight above.
fn occluder_scene() -> lightcast_server::scene::Scene {
    let (mut v, mut i) = (Vec::new(), Vec::new());
    quad(&mut v, &mut i, floor_corners(0.0, 0.0, 0.0, 2.0), 0);
    quad(&mut v, &mut i, floor_corners(0.0, 0.0, 0.5, 0.25), 0);
    scene(v, i, vec![plain_material([0.7; 3], 0.0, 1.0)])
}

fn top_camera() -> Camera {
    Camera {
        position: [0.0, 4.0, 0.001],
        target: [0.0, 0.0, 0.0],
        fov_y_degrees: 60.0,
    }
}

/// Luminance of the floor at world point (x, 0, z), found by searching the pixel whose ray hits it.
fn floor_luminance_at(
    frame: &lightcast_server::renderer::Frame,
    scene: &lightcast_server::scene::Scene,
    camera: &Camera,
    target: Vec3,
) -> f32 {
    let mut best = (f32::INFINITY, 0.0);
    for y in 0..frame.height {
        for x in 0..frame.width {
            if let Some(p) = hit_plane(camera, scene, frame.width, frame.height, x, y, 0.0) {
                let d = p.distance(target);
                if d < best.0 {
                    best = (d, luminance(hdr_at(frame, x, y)));
                }
            }
        }
    }
    best.1
}

#[test]
fn occluder_casts_a_shadow_from_a_sun_with_a_soft_pcf_edge() {
    let scene = occluder_scene();
    let camera = top_camera();
    // The sun comes in at an angle so the shadow lands beside the occluder, visible from above.
    let light = directional(Vec3::new(1.0, -1.0, 0.0), 3.0);
    let frame = render(scene.clone(), &settings(96, 96, camera.clone(), light));
    // The occluder at height 0.5 shifts its shadow by 0.5 m along +x.
    let shadowed = floor_luminance_at(
        &frame,
        &scene,
        &camera,
        Vec3::new(0.5 + 0.0, 0.0, 0.0) + Vec3::new(0.0, 0.0, 0.1),
    );
    let lit = floor_luminance_at(&frame, &scene, &camera, Vec3::new(-1.2, 0.0, 0.0));
    assert!(lit > 0.1, "lit floor luminance {lit}");
    assert!(shadowed < 0.05 * lit, "shadow {shadowed} vs lit {lit}");
    // PCF: somewhere along the edge there are values strictly between lit and shadowed.
    let edge = (0..40)
        .map(|k| {
            floor_luminance_at(
                &frame,
                &scene,
                &camera,
                Vec3::new(0.55 + 0.25 + (k as f32 - 20.0) * 0.005, 0.0, 0.0),
            )
        })
        .any(|l| l > 0.1 * lit && l < 0.9 * lit);
    assert!(edge, "no penumbra texels found at the shadow edge");
}

#[test]
fn point_light_shadows_work_on_side_faces_of_the_cube() {
    // A wall at x = 0.6 between a point light at the origin's height 1 and the floor beyond.
    let (mut v, mut i) = (Vec::new(), Vec::new());
    quad(&mut v, &mut i, floor_corners(0.0, 0.0, 0.0, 2.0), 0);
    quad(
        &mut v,
        &mut i,
        [
            Vec3::new(0.6, 0.0, 1.0),
            Vec3::new(0.6, 0.0, -1.0),
            Vec3::new(0.6, 2.0, -1.0),
            Vec3::new(0.6, 2.0, 1.0),
        ],
        0,
    );
    let scene = scene(v, i, vec![plain_material([0.7; 3], 0.0, 1.0)]);
    let camera = top_camera();
    let light = Light {
        kind: LightKind::Point,
        position: [0.0, 1.0, 0.0],
        direction: [0.0, -1.0, 0.0],
        color: [1.0; 3],
        intensity: 3.0,
        inner_cone: 0.0,
        outer_cone: 0.0,
    };
    let frame = render(scene.clone(), &settings(96, 96, camera.clone(), light));
    let behind_wall = floor_luminance_at(&frame, &scene, &camera, Vec3::new(1.4, 0.0, 0.0));
    let mirror_side = floor_luminance_at(&frame, &scene, &camera, Vec3::new(-1.4, 0.0, 0.0));
    let below = floor_luminance_at(&frame, &scene, &camera, Vec3::new(-0.2, 0.0, 0.3));
    assert!(
        mirror_side > 0.05,
        "unoccluded floor luminance {mirror_side}"
    );
    assert!(
        below > mirror_side,
        "floor under the light should be brightest"
    );
    assert!(
        behind_wall < 0.05 * mirror_side,
        "behind the wall {behind_wall} vs open {mirror_side}"
    );
}

/// Several lights of different kinds, each with its own shadow-map layers (a spot, a point
/// light's six faces, a sun): the HDR radiance of all three together is the sum of each
/// alone, pixel by pixel (f16 rounding: 0.5 %), shadows included (the occluder's shadow
/// from each light lands in its own place).
#[test]
fn three_lights_light_the_floor_as_the_sum_of_each_alone() {
    let scene = occluder_scene();
    let camera = top_camera();
    let lights = [
        Light {
            kind: LightKind::Spot,
            position: [-0.8, 1.5, 0.4],
            direction: [0.5, -1.0, -0.2],
            color: [1.0, 0.8, 0.6],
            intensity: 4.0,
            inner_cone: 0.4,
            outer_cone: 0.7,
        },
        Light {
            kind: LightKind::Point,
            position: [0.7, 1.2, -0.5],
            direction: [0.0, -1.0, 0.0],
            color: [0.5, 0.7, 1.0],
            intensity: 2.0,
            inner_cone: 0.0,
            outer_cone: 0.0,
        },
        directional(Vec3::new(1.0, -1.0, 0.3), 1.5),
    ];
    let hdr = |lights: Vec<Light>| {
        let mut s = settings(64, 64, camera.clone(), lights[0].clone());
        s.lights = lights;
        render(scene.clone(), &s)
    };
    let all = hdr(lights.to_vec());
    let alone: Vec<_> = lights.iter().map(|l| hdr(vec![l.clone()])).collect();
    let (mut worst, mut lit) = (0.0f32, 0);
    for y in 0..64 {
        for x in 0..64 {
            let sum: Vec3 = alone.iter().map(|f| hdr_at(f, x, y)).sum();
            let got = hdr_at(&all, x, y);
            if sum.max_element() > 1e-3 {
                lit += 1;
                worst = worst.max((got - sum).abs().max_element() / sum.max_element());
            }
        }
    }
    assert!(lit > 64 * 64 / 2, "only {lit} lit pixels");
    assert!(
        worst < 5e-3,
        "all lights differ from the sum of each by {worst}"
    );
}

/// A square hovering over the floor under a sun straight above: drawn opaque it shadows the
/// floor beneath it; with a texture whose alpha mask cuts it away entirely, the shadow map
/// skips it as the G-buffer does and the floor is lit exactly as without it; masked on its
/// left half only, only the right half's shadow remains.
#[test]
fn alpha_masked_texels_cast_no_shadow() {
    use lightcast_server::scene::{Scene, Texture};
    let light = directional(Vec3::new(0.0, -1.0, 0.0), 3.0);
    let floor = plain_material([0.6, 0.6, 0.6], 0.0, 1.0);
    let camera = oblique_camera();
    let (clear, solid) = ([0, 0, 0, 0], [0, 0, 0, 255]);
    let halves = |left: [u8; 4], right: [u8; 4]| Texture {
        name: "halves".into(),
        width: 4,
        height: 2,
        rgba8: (0..8)
            .flat_map(|i| if i % 4 < 2 { left } else { right })
            .collect(),
    };
    let with_blocker = |texture: Texture, alpha_cutoff: Option<f32>| {
        let (mut v, mut i) = (Vec::new(), Vec::new());
        quad(&mut v, &mut i, floor_corners(0.0, 0.0, 0.0, 2.0), 0);
        quad(&mut v, &mut i, floor_corners(0.0, -0.2, 0.5, 0.5), 1);
        let cover = lightcast_server::scene::Material {
            base_color_texture: Some(0),
            alpha_cutoff,
            ..plain_material([1.0; 3], 0.0, 1.0)
        };
        Scene::new(
            "blocker",
            v,
            i,
            vec![floor.clone(), cover],
            vec![texture],
            vec![],
            vec![],
        )
        .expect("scene")
    };
    let s = settings(W, H, camera.clone(), light.clone());
    let open_scene = floor_scene(floor.clone());
    let open = render(open_scene.clone(), &s);
    let masked = render(with_blocker(halves(clear, clear), Some(0.5)), &s);
    let opaque_scene = with_blocker(halves(clear, clear), None);
    let opaque = render(opaque_scene.clone(), &s);
    let half = render(with_blocker(halves(clear, solid), Some(0.5)), &s);

    // Masked away entirely: the camera sees the floor through it, lit as without it.
    let mut floor_pixels = 0;
    for y in 0..H {
        for x in 0..W {
            if hit_plane(&camera, &open_scene, W, H, x, y, 0.0).is_none() {
                continue;
            }
            floor_pixels += 1;
            let (m, o) = (hdr_at(&masked, x, y), hdr_at(&open, x, y));
            assert!(
                (m - o).abs().max_element() <= 1e-6 * o.max_element().max(1e-6),
                "pixel ({x}, {y}): masked {m} vs no blocker {o}"
            );
        }
    }
    assert!(floor_pixels > (W * H / 3) as usize, "{floor_pixels}");

    // Drawn opaque, or masked on its left half: floor points beneath it that the camera sees
    // past its edge.
    let lit = direct_radiance(&floor, &light, &camera, Vec3::ZERO, Vec3::Y);
    let (mut shadowed, mut left_lit, mut right_dark) = (0, 0, 0);
    for y in 0..H {
        for x in 0..W {
            let Some(p) = hit_plane(&camera, &open_scene, W, H, x, y, 0.0) else {
                continue;
            };
            let origin = Vec3::from(camera.position);
            let sees_floor = trace(&opaque_scene, origin, (p - origin).normalize(), 100.0)
                .is_some_and(|(_, triangle)| triangle < 2);
            let margin = 0.1;
            let beneath = p.x.abs() < 0.5 - margin && (p.z + 0.2).abs() < 0.5 - margin;
            if !sees_floor || !beneath {
                continue;
            }
            let o = luminance(hdr_at(&opaque, x, y));
            assert!(
                o < 0.02 * luminance(lit),
                "({x}, {y}) at {p}: opaque shadow {o}"
            );
            shadowed += 1;
            let h = luminance(hdr_at(&half, x, y));
            if p.x < -margin {
                assert!(
                    (h - luminance(lit)).abs() < 0.01 * luminance(lit),
                    "({x}, {y}) at {p}: under the masked half {h} vs lit {}",
                    luminance(lit)
                );
                left_lit += 1;
            } else if p.x > margin {
                assert!(h < 0.02 * luminance(lit), "({x}, {y}) at {p}: {h}");
                right_dark += 1;
            }
        }
    }
    eprintln!("{shadowed} shadowed floor pixels seen: {left_lit} under the masked half, {right_dark} under the solid one");
    assert!(
        left_lit >= 10 && right_dark >= 10,
        "{left_lit} lit, {right_dark} dark"
    );
}

/// The sun's shadow map fitted to the view (`light_fit: view`, two cascades) shadows the
/// street as the whole-scene map does, with the finer texels the viewer gets: at 512² its
/// direct light is nearer that of a 2048² whole-scene map than the 512² whole-scene map is,
/// and no pixel is lit by one and dark in the other beyond the maps' shadow edges.
#[test]
fn view_fitted_sun_shadows_match_the_scene_fitted_ones_more_finely() {
    use lightcast_server::scene::default_light::{default_camera, default_light};
    let street = lightcast_server::scene::procedural::build("street?blocks=2").expect("street");
    let (w, h) = (96, 54);
    let mut renderer = lightcast_server::renderer::Renderer::new(gpu(), street.clone());
    let mut direct = |fit: &str, size: u32| {
        let mut s = settings(w, h, default_camera(&street), default_light(&street));
        s.shadow_map_size = size;
        s.gi = lightcast_server::gi::GiParams::new(lightcast_server::gi::rsm_gather::RSM_GATHER)
            .with("rsm_size", 16)
            .with("light_fit", fit);
        let frame = renderer.render(&s).expect("render");
        let (hdr, indirect) = (frame.hdr.expect("hdr"), frame.indirect.expect("indirect"));
        hdr.iter()
            .zip(&indirect)
            .map(|(a, b)| Vec3::new(a[0] - b[0], a[1] - b[1], a[2] - b[2]))
            .collect::<Vec<_>>()
    };
    let truth = direct("scene", 2048);
    let coarse = direct("scene", 512);
    let fitted = direct("view", 512);
    let mean = truth.iter().map(|c| c.element_sum()).sum::<f32>();
    let error = |image: &[Vec3]| {
        image
            .iter()
            .zip(&truth)
            .map(|(a, b)| (*a - *b).abs().element_sum())
            .sum::<f32>()
            / mean
    };
    let (e_coarse, e_fitted) = (error(&coarse), error(&fitted));
    eprintln!("direct light against a 2048² map: scene-fitted 512² {e_coarse:.4}, view-fitted 512² {e_fitted:.4}");
    assert!(e_fitted < 0.05, "{e_fitted}");
    assert!(e_fitted < e_coarse, "{e_fitted} vs {e_coarse}");
}

/// The indirect buffer's alpha, which sorts a comparison's pixels into diffuse and specular
/// receivers (`quality::receiver_errors`), is each pixel's specular share seen from the camera
/// as `Brdf::specular_share` computes it (within 2·10⁻³: half floats), and −1 where no
/// surface shows.
#[test]
fn the_indirect_alpha_is_the_receivers_specular_share() {
    let camera = oblique_camera();
    let materials = [
        plain_material([0.6, 0.4, 0.2], 0.0, 1.0),
        plain_material([0.3, 0.6, 0.9], 0.5, 0.5),
        plain_material([0.5, 0.5, 0.55], 0.9, 0.2),
    ];
    let light = directional(Vec3::new(0.3, -1.0, -0.2), 3.0);
    let mut shares = Vec::new();
    for material in materials {
        let scene = floor_scene(material.clone());
        let frame = render(
            scene.clone(),
            &settings(W, H, camera.clone(), light.clone()),
        );
        let indirect = frame.indirect.as_ref().expect("captured");
        let (mut floor, mut background, mut worst) = (0, 0, 0.0f32);
        for y in 0..H {
            for x in 0..W {
                let got = indirect[(y * W + x) as usize][3];
                match hit_plane(&camera, &scene, W, H, x, y, 0.0) {
                    Some(p) if p.x.abs() < 1.9 && p.z.abs() < 1.9 => {
                        let mu = (Vec3::from(camera.position) - p).normalize().y;
                        let want = material.brdf().specular_share(mu);
                        worst = worst.max((got - want).abs());
                        shares.push(want);
                        floor += 1;
                    }
                    Some(p) if p.x.abs() < 2.1 && p.z.abs() < 2.1 => {}
                    _ => {
                        assert_eq!(got, -1.0, "pixel ({x}, {y}) shows no surface");
                        background += 1;
                    }
                }
            }
        }
        assert!(
            floor > (W * H / 3) as usize && background > 0,
            "{floor} {background}"
        );
        assert!(worst < 2e-3, "specular share off by up to {worst}");
    }
    // The three floors span both kinds of receiver.
    let (lo, hi) = shares
        .iter()
        .fold((1.0f32, 0.0f32), |(lo, hi), &s| (lo.min(s), hi.max(s)));
    assert!(lo < 0.2 && hi > 0.8, "shares from {lo} to {hi}");
}
