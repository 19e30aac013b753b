//! Environments (`render.environment`) on lavapipe against answers known without them: the
//! reference on an open white plane under a uniform environment and under the analytic sky
//! converges to albedo × irradiance / π (the irradiance integrated on the CPU from the same
//! map), and a real-time method's directional lights light that plane the same; the sky
//! shows where no geometry is.

use super::support::{self, directional, floor_corners, plain_material, quad};
use glam::Vec3;
use lightcast_protocol::{Camera, Environment, EnvironmentKind};
use lightcast_server::gi::reference::{PathTracer, ReferenceSettings, Senders, SurfaceGpu};
use lightcast_server::gi::GiParams;
use lightcast_server::passes::environment::FrameEnvironment;
use lightcast_server::renderer::{RenderSettings, Renderer};
use lightcast_server::scene::environment::texel_solid_angle;
use lightcast_server::scene::{brdf::Brdf, Scene};
use std::sync::Arc;

const ALBEDO: f32 = 0.6;

/// A 40 m square floor at y = 0 seen from 1 m above, looking down at its centre: nothing
/// but the floor in view, and the floor sees only the sky.
fn open_plane() -> (Scene, Camera) {
    let (mut vertices, mut indices) = (Vec::new(), Vec::new());
    quad(
        &mut vertices,
        &mut indices,
        floor_corners(0.0, 0.0, 0.0, 20.0),
        0,
    );
    let scene = support::scene(
        vertices,
        indices,
        vec![plain_material([ALBEDO; 3], 0.0, 1.0)],
    );
    let camera = Camera {
        position: [0.0, 1.0, 0.3],
        target: [0.0, 0.0, 0.0],
        fov_y_degrees: 60.0,
    };
    (scene, camera)
}

/// The reference over `scene` with a Lambertian of albedo [`ALBEDO`] everywhere: without the
/// glTF material's specular lobe, so that albedo/π × irradiance is the exact answer.
fn lambertian_tracer(scene: &Scene) -> PathTracer {
    let lambertian = Brdf::lambertian(Vec3::splat(ALBEDO));
    PathTracer::with_surfaces(support::gpu(), scene, |_| {
        vec![SurfaceGpu::new(&lambertian, [0.0; 3])]
    })
    .expect("tracer")
}

/// The mean indirect light of 16×16 pixels at 256 samples each under `env` alone.
fn traced_mean(tracer: &mut PathTracer, camera: &Camera, env: &Arc<FrameEnvironment>) -> Vec3 {
    traced_mean_with(tracer, camera, env, &ReferenceSettings::default())
}

fn traced_mean_with(
    tracer: &mut PathTracer,
    camera: &Camera,
    env: &Arc<FrameEnvironment>,
    settings: &ReferenceSettings,
) -> Vec3 {
    for _ in 0..4 {
        tracer
            .accumulate(16, 16, camera, &[], Some(env), settings, 64)
            .expect("accumulate");
    }
    let image = tracer.read().expect("read").expect("samples");
    image
        .indirect
        .iter()
        .fold(Vec3::ZERO, |s, p| s + Vec3::from(*p))
        / image.indirect.len() as f32
}

/// The irradiance per channel on a surface facing +Y under `env`'s map, texel by texel.
fn horizontal_irradiance(env: &FrameEnvironment) -> Vec3 {
    let m = &env.map;
    let (w, h) = (m.width, m.height);
    let mut e = Vec3::ZERO;
    for j in 0..h {
        let theta = std::f32::consts::PI * (j as f32 + 0.5) / h as f32;
        let cos = theta.cos().max(0.0);
        for i in 0..w {
            e += Vec3::from(m.radiance[(j * w + i) as usize]) * texel_solid_angle(j, w, h) * cos;
        }
    }
    e
}

fn environments() -> Vec<(&'static str, Environment)> {
    vec![
        (
            "uniform",
            Environment {
                color: [0.5, 0.7, 1.0],
                intensity: Some(2.0),
                ..Environment::default()
            },
        ),
        (
            "sky",
            Environment {
                kind: EnvironmentKind::Sky,
                intensity: Some(0.25),
                ..Environment::default()
            },
        ),
    ]
}

#[test]
fn reference_on_an_open_lambertian_plane_converges_to_albedo_times_irradiance_over_pi() {
    let (scene, camera) = open_plane();
    let mut tracer = lambertian_tracer(&scene);
    let sun = directional(Vec3::new(0.3, -0.6, 0.4), 3.0);
    for (name, env) in environments() {
        let frame_env =
            Arc::new(FrameEnvironment::new(&env, std::slice::from_ref(&sun), None).expect("env"));
        let mean = traced_mean(&mut tracer, &camera, &frame_env);
        let expected = horizontal_irradiance(&frame_env) * ALBEDO / std::f32::consts::PI;
        let rel = ((mean - expected) / expected).abs();
        eprintln!("{name}: mean {mean}, expected {expected}, relative {rel}");
        // 256 pixels × 256 samples: the mean's noise is far below 1 %.
        assert!(rel.max_element() < 0.01, "{name}: {mean} vs {expected}");
    }
}

/// With `senders: diffuse` the environment reaches the surfaces after the first by next-event
/// estimation alone (no shared estimate with the escaping bounce ray): on Lambertian surfaces,
/// where the diffuse lobe is the whole BRDF, that must converge to the same light. A 2 m wall
/// standing on the open plane sends the sky's light onto it, over two bounces.
#[test]
fn diffuse_senders_under_the_sky_equal_full_ones_on_lambertian_surfaces() {
    let (plane, camera) = open_plane();
    let (mut vertices, mut indices) = (plane.vertices, plane.indices);
    let wall = [
        Vec3::new(-1.0, 0.0, -0.3),
        Vec3::new(1.0, 0.0, -0.3),
        Vec3::new(1.0, 2.0, -0.3),
        Vec3::new(-1.0, 2.0, -0.3),
    ];
    quad(&mut vertices, &mut indices, wall, 0);
    let scene = support::scene(vertices, indices, plane.materials);
    let mut tracer = lambertian_tracer(&scene);
    let sun = directional(Vec3::new(0.3, -0.6, 0.4), 3.0);
    for (name, env) in environments() {
        let frame_env =
            Arc::new(FrameEnvironment::new(&env, std::slice::from_ref(&sun), None).expect("env"));
        let [full, diffuse] = [Senders::Full, Senders::Diffuse].map(|senders| {
            let settings = ReferenceSettings {
                bounces: 2,
                senders,
                ..ReferenceSettings::default()
            };
            traced_mean_with(&mut tracer, &camera, &frame_env, &settings)
        });
        let rel = ((diffuse - full) / full).abs();
        eprintln!("{name}: full {full}, diffuse senders {diffuse}, relative {rel}");
        // 256 pixels × 256 samples each: the means' noise is well below 1 %.
        assert!(rel.max_element() < 0.01, "{name}: {diffuse} vs {full}");
    }
}

/// One frame of `gi` over the open plane lit by `env` and a sun, with the indirect light
/// (plus the environment's light) and the HDR image read back.
fn render(
    renderer: &mut Renderer,
    camera: &Camera,
    env: &Environment,
    gi: GiParams,
) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let settings = RenderSettings {
        environment: Some(env.clone()),
        gi,
        ..support::settings(
            24,
            16,
            camera.clone(),
            directional(Vec3::new(0.3, -0.6, 0.4), 3.0),
        )
    };
    support::precompute(renderer, &settings.gi);
    let frame = renderer.render(&settings).expect("render");
    (
        frame.indirect.expect("captured"),
        frame.hdr.expect("captured"),
    )
}

#[test]
fn directional_lights_of_the_environment_light_an_open_plane_like_the_reference() {
    let (scene, camera) = open_plane();
    let mut renderer = Renderer::new(support::gpu(), scene);
    for (name, env) in environments() {
        let mean = |image: &[[f32; 4]]| {
            image
                .iter()
                .fold(Vec3::ZERO, |s, p| s + Vec3::new(p[0], p[1], p[2]))
                / image.len() as f32
        };
        let mut reference = GiParams::new(lightcast_server::gi::reference::REFERENCE);
        reference.set("spp", 256);
        let (truth, _) = render(&mut renderer, &camera, &env, reference);
        let none = GiParams::new(lightcast_server::gi::none::NONE);
        let (approx, hdr) = render(&mut renderer, &camera, &env, none);
        let (t, a) = (mean(&truth), mean(&approx));
        let rel = ((a - t) / t).abs();
        eprintln!("{name}: reference {t}, directional lights {a}, relative {rel}");
        // An upward surface sees each light's region whole (the regions' irradiance vectors
        // give its irradiance exactly); what remains is the reference's noise and the
        // shadow maps' edge filtering.
        assert!(rel.max_element() < 0.03, "{name}: {a} vs {t}");
        // The HDR image has the environment's light in it besides the sun's.
        assert!(mean(&hdr).min_element() > a.min_element());
    }
}

#[test]
fn the_environment_shows_where_no_geometry_is() {
    let (scene, _) = open_plane();
    let mut renderer = Renderer::new(support::gpu(), scene);
    // Looking up: nothing but sky.
    let camera = Camera {
        position: [0.0, 1.0, 0.0],
        target: [0.0, 2.0, 0.1],
        fov_y_degrees: 40.0,
    };
    let env = Environment {
        color: [0.2, 0.4, 0.8],
        intensity: Some(3.0),
        ..Environment::default()
    };
    let (_, hdr) = render(
        &mut renderer,
        &camera,
        &env,
        GiParams::new(lightcast_server::gi::none::NONE),
    );
    for p in &hdr {
        assert_eq!(p[3], 1.0, "the sky counts as something to expose");
        for (k, want) in [0.6f32, 1.2, 2.4].iter().enumerate() {
            // RGBA16F: three significant decimal digits.
            assert!((p[k] - want).abs() < 2e-3 * want, "{p:?}");
        }
    }
}

/// An equirectangular image of one bright texel lights the open plane as a directional light
/// of the same irradiance does: the reference under the image (no punctual light) on a
/// Lambertian plane against albedo/π × the texel's irradiance E = L ∫cos θ dω computed on the
/// CPU, and, with the glTF material, against `none` lit by a directional light from the
/// texel's centre giving the plane E.
#[test]
fn one_bright_texel_lights_like_a_directional_light_of_its_irradiance() {
    use lightcast_server::scene::environment::{texel_centre, texel_of};
    use lightcast_server::scene::environment_image::EnvironmentImage;
    let (mut scene, camera) = open_plane();
    // 64×32 texels; the bright one 40° from the zenith.
    let (w, h) = (64u32, 32u32);
    let target = Vec3::new(0.5, 40f32.to_radians().cos(), 0.3).normalize();
    let (ti, tj) = texel_of(target, w, h);
    let radiance = 500.0f32;
    // The image's own convention starts a quarter turn before ours (environment_image.rs).
    let texels: Vec<[f32; 3]> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            if ((x + w - w / 4) % w, y) == (ti, tj) {
                [radiance; 3]
            } else {
                [0.0; 3]
            }
        })
        .collect();
    let image = Arc::new(EnvironmentImage::from_texels("sun.hdr", w, h, &texels).expect("image"));
    assert_eq!(image.radiance[(tj * w + ti) as usize], [radiance; 3]);
    scene.environment_image = Some(Arc::clone(&image));
    // E = L ∫ cos θ dω over the texel: Δφ · ½ (sin²θ₁ − sin²θ₀).
    let (t0, t1) = (
        std::f32::consts::PI * tj as f32 / h as f32,
        std::f32::consts::PI * (tj + 1) as f32 / h as f32,
    );
    let irradiance = radiance * 2.0 * std::f32::consts::PI / w as f32
        * 0.5
        * (t1.sin().powi(2) - t0.sin().powi(2));
    let expected = irradiance * ALBEDO / std::f32::consts::PI;

    let env = Environment {
        kind: EnvironmentKind::Image,
        directions: 1,
        ..Environment::default()
    };
    let mean = |image: &[[f32; 4]]| {
        image
            .iter()
            .fold(Vec3::ZERO, |s, p| s + Vec3::new(p[0], p[1], p[2]))
            / image.len() as f32
    };

    let mut tracer = lambertian_tracer(&scene);
    let frame_env = Arc::new(FrameEnvironment::new(&env, &[], Some(&image)).expect("env"));
    let exact = traced_mean(&mut tracer, &camera, &frame_env);
    eprintln!("one bright texel, Lambertian: reference {exact}, expected {expected}");
    // Next-event estimation finds the one texel every sample: the noise is small.
    assert!(
        (exact / expected - Vec3::ONE).abs().max_element() < 0.01,
        "{exact} vs {expected}"
    );

    let mut renderer = Renderer::new(support::gpu(), scene);
    support::set_bvh(&mut renderer);
    let mut reference = GiParams::new(lightcast_server::gi::reference::REFERENCE);
    reference.set("spp", 256);
    let settings = RenderSettings {
        environment: Some(env),
        lights: Vec::new(),
        gi: reference,
        ..support::settings(24, 16, camera.clone(), directional(Vec3::NEG_Y, 0.0))
    };
    let frame = renderer.render(&settings).expect("render");
    let sky = mean(&frame.indirect.expect("captured"));
    eprintln!("one bright texel, glTF material: reference {sky}");

    // A sun whose illuminance across its rays gives the plane E at the texel's centre angle.
    let centre = texel_centre(ti, tj, w, h);
    let sun = directional(-centre, irradiance / centre.y);
    let settings = RenderSettings {
        gi: GiParams::new(lightcast_server::gi::none::NONE),
        capture_hdr: true,
        ..support::settings(24, 16, camera, sun)
    };
    let frame = renderer.render(&settings).expect("render");
    let lit = mean(&frame.hdr.expect("captured"));
    eprintln!("directional light of that irradiance: {lit}");
    // The texel's centre direction stands for its whole solid angle (cos θ varies across it
    // by ±2.8° of θ; measured: 0.1 %).
    assert!(
        (lit / sky - Vec3::ONE).abs().max_element() < 0.01,
        "{lit} vs {sky}"
    );
}
