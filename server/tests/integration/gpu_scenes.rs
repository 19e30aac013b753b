//! Whole-scene renders on the GPU (lavapipe in CI) at small sizes, checked with image metrics
//! and a CPU ray caster rather than byte comparisons.

use crate::support::*;
use glam::Vec3;
use lightcast_protocol::{Camera, LightKind};
use lightcast_server::passes::exposure::Exposure;
use lightcast_server::renderer::{RenderError, Renderer};
use lightcast_server::scene::default_light::{default_camera, default_light};
use lightcast_server::scene::{load_gltf, procedural, Scene, Texture};

fn default_settings(scene: &Scene, w: u32, h: u32) -> lightcast_server::renderer::RenderSettings {
    let mut s = settings(w, h, default_camera(scene), default_light(scene));
    s.exposure = Exposure::Auto;
    s.shadow_map_size = 512;
    s
}

/// Mean 8-bit colour of the pixels whose camera ray first hits a red-dominant and a
/// green-dominant material (found with the CPU ray caster), and the mean image column of each.
fn wall_colours(
    scene: &Scene,
    settings: &lightcast_server::renderer::RenderSettings,
    frame: &lightcast_server::renderer::Frame,
) -> [(Vec3, f32); 2] {
    let (w, h) = (frame.width, frame.height);
    let mut sums = [(Vec3::ZERO, 0.0f32, 0usize); 2];
    for y in (0..h).step_by(2) {
        for x in (0..w).step_by(2) {
            let (o, d) = pixel_ray(&settings.camera, scene, w, h, x, y);
            let Some((_, tri)) = trace(scene, o, d, 100.0) else {
                continue;
            };
            let [r, g, b, _] = scene.materials[triangle_material(scene, tri) as usize].base_color;
            let slot = if r > 2.0 * g && r > 2.0 * b {
                0
            } else if g > 2.0 * r && g > 2.0 * b {
                1
            } else {
                continue;
            };
            let px = rgba_at(frame, x, y);
            sums[slot].0 += Vec3::new(px[0] as f32, px[1] as f32, px[2] as f32);
            sums[slot].1 += x as f32;
            sums[slot].2 += 1;
        }
    }
    sums.map(|(c, x, n)| {
        assert!(n > 20, "too few wall pixels: {n}");
        (c / n as f32, x / n as f32)
    })
}

fn assert_red_left_green_right(scene: &Scene, w: u32, h: u32) {
    let settings = default_settings(scene, w, h);
    let frame = render(scene.clone(), &settings);
    let [(red, red_x), (green, green_x)] = wall_colours(scene, &settings, &frame);
    assert!(
        red.x > 2.0 * red.y && red.x > 2.0 * red.z && red.x > 40.0,
        "red wall {red}"
    );
    assert!(
        green.y > 1.4 * green.x && green.y > 1.4 * green.z && green.y > 40.0,
        "green wall {green}"
    );
    assert!(
        red_x < w as f32 * 0.4 && green_x > w as f32 * 0.6,
        "red at x={red_x}, green at x={green_x}"
    );
}

#[test]
fn builtin_cornell_box_has_red_left_and_green_right_walls() {
    assert_red_left_green_right(&procedural::cornell_box(), 128, 96);
}

#[test]
fn floor_in_the_boxes_shadow_is_darker_than_lit_floor_as_a_cpu_ray_caster_predicts() {
    let scene = procedural::cornell_box();
    let (w, h) = (128, 96);
    let mut settings = default_settings(&scene, w, h);
    // The ray caster's 4 cm margin must exceed the lookup's normal offset (2 texels, more at
    // grazing angles) plus the PCF radius: 2048² texels of the spot's 150° cone are ~0.8 cm
    // at the floor.
    settings.shadow_map_size = 2048;
    assert_eq!(settings.lights[0].kind, LightKind::Spot);
    let frame = render(scene.clone(), &settings);
    let light_pos = Vec3::from(settings.lights[0].position);
    let (mut lit, mut shadowed) = (Vec::new(), Vec::new());
    for y in 0..h {
        for x in 0..w {
            let (o, d) = pixel_ray(&settings.camera, &scene, w, h, x, y);
            let Some((t, _)) = trace(&scene, o, d, 100.0) else {
                continue;
            };
            let p = o + d * t;
            if p.y.abs() > 1e-3 {
                continue; // not the floor
            }
            let to_light = light_pos - p;
            // Keep well-defined cases: skip the penumbra (PCF footprint and normal offset are a
            // few centimetres at this shadow-map size) by also tracing from nearby points.
            let blocked = |q: Vec3| {
                trace(
                    &scene,
                    q,
                    (light_pos - q).normalize(),
                    (light_pos - q).length() - 0.05,
                )
                .is_some()
            };
            let offsets = [
                Vec3::ZERO,
                Vec3::X * 0.04,
                -Vec3::X * 0.04,
                Vec3::Z * 0.04,
                -Vec3::Z * 0.04,
            ];
            let votes = offsets
                .iter()
                .filter(|&&o| blocked(p + o + Vec3::Y * 1e-3))
                .count();
            let l = luminance(hdr_at(&frame, x, y));
            if votes == 0 && to_light.normalize().y > 0.5 {
                lit.push(l);
            } else if votes == offsets.len() {
                shadowed.push(l);
            }
        }
    }
    assert!(
        lit.len() > 100 && shadowed.len() > 20,
        "lit {} shadowed {}",
        lit.len(),
        shadowed.len()
    );
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
    let (lit_mean, shadow_mean) = (mean(&lit), mean(&shadowed));
    assert!(
        shadow_mean < 0.05 * lit_mean,
        "shadowed floor {shadow_mean} vs lit floor {lit_mean}"
    );
    // Every confidently lit pixel is lit on the GPU too, every shadowed one dark.
    let min_lit = lit.iter().copied().fold(f32::INFINITY, f32::min);
    assert!(
        min_lit > 0.2 * lit_mean,
        "a floor pixel the ray caster sees lit is dark: {min_lit}"
    );
    let worst = shadowed.iter().copied().fold(0.0, f32::max);
    assert!(
        worst < 0.2 * lit_mean,
        "a floor pixel the ray caster sees shadowed is lit: {worst}"
    );
}

#[test]
fn shared_cornell_box_glb_renders_recognisably() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/cornell-box/cornell-box.glb"
    );
    let scene = load_gltf(std::path::Path::new(path)).expect("cornell-box.glb loads");
    assert_red_left_green_right(&scene, 128, 128);
}

#[test]
fn procedural_street_renders_with_coverage_and_colour() {
    let scene = procedural::build("street?blocks=3").expect("street scene");
    let frame = render(scene.clone(), &default_settings(&scene, 128, 72));
    let hdr = frame.hdr.as_ref().expect("hdr");
    let covered = hdr.iter().filter(|c| c[3] > 0.0).count();
    assert!(
        covered > hdr.len() / 2,
        "covered {covered} of {}",
        hdr.len()
    );
    let lit = hdr
        .iter()
        .filter(|c| c[3] > 0.0 && c[0] + c[1] + c[2] > 0.0)
        .count();
    assert!(lit > covered / 4, "lit {lit} of {covered}");
}

#[test]
fn auto_exposure_maps_log_average_luminance_to_middle_grey_and_tonemap_matches_cpu() {
    let scene = procedural::cornell_box();
    let frame = render(scene.clone(), &default_settings(&scene, 96, 64));
    let hdr = frame.hdr.as_ref().expect("hdr");
    let (mut sum, mut n) = (0.0f64, 0usize);
    for c in hdr {
        let l = luminance(Vec3::new(c[0], c[1], c[2]));
        if c[3] > 0.0 && l > 1e-6 {
            sum += f64::from(l.log2());
            n += 1;
        }
    }
    let expected = 0.18 / (sum / n as f64).exp2();
    let rel = (f64::from(frame.exposure_scale) - expected).abs() / expected;
    assert!(
        rel < 1e-3,
        "GPU exposure {} vs CPU {expected}",
        frame.exposure_scale
    );

    // CPU port of tonemap.wgsl: exposure, ACES fit, sRGB; 8-bit output within one level.
    let aces = |x: f32| ((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0);
    let srgb = |c: f32| {
        if c <= 0.0031308 {
            c * 12.92
        } else {
            1.055 * c.powf(1.0 / 2.4) - 0.055
        }
    };
    let mut worst = 0.0f32;
    for (i, c) in hdr.iter().enumerate() {
        if c[3] == 0.0 {
            continue;
        }
        for (&radiance, &got) in c[..3].iter().zip(&frame.rgba8[i * 4..i * 4 + 3]) {
            let want = srgb(aces(radiance * frame.exposure_scale)) * 255.0;
            worst = worst.max((want - got as f32).abs());
        }
    }
    assert!(worst <= 1.5, "largest 8-bit difference {worst}");
}

#[test]
fn odd_sizes_read_back_without_row_shear() {
    // Left half red, right half green, seen from straight above at 37×23 (rows are padded).
    let (mut v, mut i) = (Vec::new(), Vec::new());
    quad(
        &mut v,
        &mut i,
        [
            Vec3::new(-2.0, 0.0, 2.0),
            Vec3::new(0.0, 0.0, 2.0),
            Vec3::new(0.0, 0.0, -2.0),
            Vec3::new(-2.0, 0.0, -2.0),
        ],
        0,
    );
    quad(
        &mut v,
        &mut i,
        [
            Vec3::new(0.0, 0.0, 2.0),
            Vec3::new(2.0, 0.0, 2.0),
            Vec3::new(2.0, 0.0, -2.0),
            Vec3::new(0.0, 0.0, -2.0),
        ],
        1,
    );
    let scene = scene(
        v,
        i,
        vec![
            plain_material([0.8, 0.05, 0.05], 0.0, 1.0),
            plain_material([0.05, 0.8, 0.05], 0.0, 1.0),
        ],
    );
    let camera = Camera {
        position: [0.0, 3.0, 0.001],
        target: [0.0; 3],
        fov_y_degrees: 40.0,
    };
    let frame = render(
        scene,
        &settings(37, 23, camera, directional(Vec3::NEG_Y, 3.0)),
    );
    assert_eq!(frame.rgba8.len(), 37 * 23 * 4);
    let boundaries: Vec<u32> = (0..23)
        .map(|y| {
            (0..37)
                .find(|&x| {
                    let [r, g, _, _] = rgba_at(&frame, x, y);
                    g > r
                })
                .expect("green half")
        })
        .collect();
    assert!(
        boundaries
            .iter()
            .all(|&b| b.abs_diff(boundaries[0]) <= 1 && (17..=20).contains(&b)),
        "{boundaries:?}"
    );
}

#[test]
fn base_colour_texture_is_sampled_as_srgb() {
    // A 4×4 texture of 2×2-texel quadrants: red, green / blue, mid-grey (sRGB 128 = linear
    // 0.2158). Quadrant centres are then far from any other colour under bilinear filtering.
    let quadrant = |x: usize, y: usize| match (x / 2, y / 2) {
        (0, 0) => [255, 0, 0, 255],
        (1, 0) => [0, 255, 0, 255],
        (0, 1) => [0, 0, 255, 255],
        _ => [128, 128, 128, 255],
    };
    let texels: Vec<u8> = (0..16).flat_map(|i| quadrant(i % 4, i / 4)).collect();
    let (mut v, mut i) = (Vec::new(), Vec::new());
    quad(&mut v, &mut i, floor_corners(0.0, 0.0, 0.0, 1.0), 0);
    let mut m = plain_material([1.0; 3], 0.0, 1.0);
    m.base_color_texture = Some(0);
    let tex = Texture {
        name: "quadrants".into(),
        width: 4,
        height: 4,
        rgba8: texels,
    };
    let scene = Scene::new("tex", v, i, vec![m], vec![tex], vec![], vec![]).expect("scene");
    let camera = Camera {
        position: [0.0, 2.0, 0.001],
        target: [0.0; 3],
        fov_y_degrees: 60.0,
    };
    let light = directional(Vec3::NEG_Y, std::f32::consts::PI);
    let frame = render(
        scene.clone(),
        &settings(64, 64, camera.clone(), light.clone()),
    );
    // The floor point and HDR radiance of the pixel nearest to world point (x, 0, z).
    let at = |x: f32, z: f32| {
        let target = Vec3::new(x, 0.0, z);
        (0..64u32)
            .flat_map(|py| (0..64u32).map(move |px| (px, py)))
            .filter_map(|(px, py)| {
                hit_plane(&camera, &scene, 64, 64, px, py, 0.0).map(|p| (p, hdr_at(&frame, px, py)))
            })
            .min_by(|a, b| a.0.distance(target).total_cmp(&b.0.distance(target)))
            .expect("floor pixels")
    };
    // UV (0,0) is corner 0 at (-1, +1) in floor_corners order: u grows with x, v towards -z.
    let quadrants = [
        ((-0.5, 0.5), [1.0, 0.0, 0.0]),
        ((0.5, 0.5), [0.0, 1.0, 0.0]),
        ((-0.5, -0.5), [0.0, 0.0, 1.0]),
        ((0.5, -0.5), [0.2158; 3]),
    ];
    for ((x, z), linear) in quadrants {
        let (p, got) = at(x, z);
        // The paper's BRDF with the texel's linear colour as base colour.
        let want = direct_radiance(
            &plain_material(linear, 0.0, 1.0),
            &light,
            &camera,
            p,
            Vec3::Y,
        );
        assert!(
            (got - want).abs().max_element() < 0.01,
            "texel {linear:?}: got {got}, want {want}"
        );
    }
}

#[test]
fn every_stage_is_timed_in_order() {
    let scene = procedural::cornell_box();
    let mut renderer = Renderer::new(gpu(), scene.clone());
    let frame = renderer
        .render(&default_settings(&scene, 32, 32))
        .expect("render");
    let names: Vec<&str> = frame.timings.iter().map(|t| t.stage.name()).collect();
    // The visibility buffer's resolve follows the raster where the renderer uses it (by
    // default on a GPU with triangle ids).
    let resolve: &[&str] = if renderer.visibility_buffer() {
        &["gbuffer_resolve"]
    } else {
        &[]
    };
    let want = [
        &["shadow_map", "gbuffer"][..],
        resolve,
        &[
            "indirect_clear",
            "direct_light",
            "exposure",
            "tonemap",
            "readback_copy",
        ],
    ]
    .concat();
    assert_eq!(names, want);
    assert!(frame
        .timings
        .iter()
        .all(|t| t.ms.is_finite() && t.ms >= 0.0));
    assert!(frame.total_ms() > 0.0);
}

type Mutation = Box<dyn Fn(&mut lightcast_server::renderer::RenderSettings)>;

#[test]
fn invalid_settings_are_rejected_naming_the_field() {
    let scene = procedural::cornell_box();
    let mut renderer = Renderer::new(gpu(), scene.clone());
    let good = default_settings(&scene, 16, 16);
    let cases: Vec<(&str, Mutation)> = vec![
        ("width", Box::new(|s| s.width = 0)),
        (
            "width",
            Box::new(|s| {
                s.width = 12_000;
                s.height = 12_000;
            }),
        ),
        (
            "shadow_map_size",
            Box::new(|s| {
                s.lights[0].kind = LightKind::Point;
                s.shadow_map_size = 8192;
            }),
        ),
        ("height", Box::new(|s| s.height = 1 << 20)),
        ("shadow_map_size", Box::new(|s| s.shadow_map_size = 8)),
        (
            "camera.target",
            Box::new(|s| s.camera.target = s.camera.position),
        ),
        (
            "camera.position",
            Box::new(|s| s.camera.position[1] = f32::NAN),
        ),
        (
            "camera.fov_y_degrees",
            Box::new(|s| s.camera.fov_y_degrees = 0.0),
        ),
        (
            "lights[0].direction",
            Box::new(|s| s.lights[0].direction = [0.0; 3]),
        ),
        (
            "lights[0].intensity",
            Box::new(|s| s.lights[0].intensity = f32::INFINITY),
        ),
        (
            "lights[0].color",
            Box::new(|s| s.lights[0].color = [-1.0, 0.0, 0.0]),
        ),
        ("lights[0].cone", Box::new(|s| s.lights[0].inner_cone = 2.0)),
        ("exposure", Box::new(|s| s.exposure = Exposure::Manual(0.0))),
    ];
    for (field, mutate) in cases {
        let mut s = good.clone();
        mutate(&mut s);
        match renderer.render(&s) {
            Err(RenderError::InvalidSetting { field: f, .. }) => assert_eq!(f, field),
            other => panic!(
                "{field}: expected InvalidSetting, got {:?}",
                other.map(|f| f.width)
            ),
        }
    }
    // The renderer still works after rejecting all of that.
    assert_eq!(renderer.render(&good).expect("valid settings").width, 16);
}
