//! Helpers shared by the GPU tests: tiny scenes, a CPU ray caster for planes and CPU ports of
//! the shading equations in `shaders/` (the references the GPU output is compared against).

pub mod plates;

use glam::{Vec3, Vec4Swizzles};
use lightcast_protocol::{Camera, Light, LightKind};
use lightcast_server::gpu::{BackendChoice, GpuContext};
use lightcast_server::passes::exposure::Exposure;
use lightcast_server::passes::frame_uniforms::camera_view_proj;
use lightcast_server::passes::rsm::GlossySender;
use lightcast_server::renderer::{Frame, RenderSettings, Renderer};
use lightcast_server::scene::{brdf::Brdf, Material, Scene, Vertex};

pub fn gpu() -> GpuContext {
    GpuContext::new(BackendChoice::Auto).expect("a GPU adapter (lavapipe in CI)")
}

/// Builds what frames of `gi` precompute per scene (in a temporary store) and hands it to the
/// renderer, as the service's precompute worker does; nothing for a method without.
pub fn precompute(renderer: &mut Renderer, gi: &lightcast_server::gi::GiParams) {
    use lightcast_server::gi::precompute::{entry_for, BuildEnv, SceneFacts, Store};
    let Some(entry) = entry_for(gi.method) else {
        return;
    };
    let key = (entry.key)(gi, &SceneFacts::of(renderer.scene())).expect("a valid setting");
    let dir = tempfile::tempdir().expect("a temporary store");
    let store = Store::new(dir.path());
    let ctx = renderer.context().clone();
    let mut env = BuildEnv {
        store: &store,
        progress: &mut |_| {},
        cancelled: &|| false,
        gpu: Some(&ctx),
    };
    let built = (entry.build)(renderer.scene(), &key, &mut env).expect("the precomputation");
    renderer
        .set_scene_data(gi.method, &built.data)
        .expect("the set fits the scene");
}

/// The small setting of `method` for `scene` (its table's [`Testing::small`]).
///
/// [`Testing::small`]: lightcast_server::gi::params::Testing::small
pub fn small(
    method: lightcast_server::gi::GiMethod,
    scene: &Scene,
) -> lightcast_server::gi::GiParams {
    let facts = lightcast_server::gi::precompute::SceneFacts::of(scene);
    (lightcast_server::gi::table(method).testing.small)(&facts)
}

/// Hands the renderer the scene's BVH for `reference` frames, as the service's precompute
/// worker does.
pub fn set_bvh(renderer: &mut Renderer) {
    let bvh = lightcast_server::gi::common::bvh::SceneBvh::build(renderer.scene()).expect("bvh");
    let data: lightcast_server::gi::precompute::SceneData = std::sync::Arc::new(bvh);
    renderer
        .set_scene_data(lightcast_server::gi::reference::REFERENCE, &data)
        .expect("the BVH fits the scene");
}

/// Appends a quad with corners `a, b, c, d` (counter-clockwise seen from its normal side).
pub fn quad(vertices: &mut Vec<Vertex>, indices: &mut Vec<u32>, corners: [Vec3; 4], material: u32) {
    let n = (corners[1] - corners[0])
        .cross(corners[2] - corners[0])
        .normalize();
    let base = vertices.len() as u32;
    let uvs = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    for (p, uv) in corners.iter().zip(uvs) {
        vertices.push(Vertex {
            position: p.to_array(),
            normal: n.to_array(),
            uv,
            material,
        });
    }
    indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
}

/// A horizontal square at height `y`, facing up, half-size `h`, centred at (cx, cz).
pub fn floor_corners(cx: f32, cz: f32, y: f32, h: f32) -> [Vec3; 4] {
    [
        Vec3::new(cx - h, y, cz + h),
        Vec3::new(cx + h, y, cz + h),
        Vec3::new(cx + h, y, cz - h),
        Vec3::new(cx - h, y, cz - h),
    ]
}

pub fn plain_material(base: [f32; 3], metallic: f32, roughness: f32) -> Material {
    Material {
        name: "test".into(),
        base_color: [base[0], base[1], base[2], 1.0],
        metallic,
        roughness,
        ..Material::default()
    }
}

pub fn scene(vertices: Vec<Vertex>, indices: Vec<u32>, materials: Vec<Material>) -> Scene {
    Scene::new("test", vertices, indices, materials, vec![], vec![], vec![]).expect("valid scene")
}

pub fn settings(width: u32, height: u32, camera: Camera, light: Light) -> RenderSettings {
    RenderSettings {
        width,
        height,
        camera,
        lights: vec![light],
        environment: None,
        exposure: Exposure::Manual(1.0),
        shadow_map_size: 256,
        capture_hdr: true,
        debug_view: lightcast_protocol::View::FINAL,
        gi: lightcast_server::gi::GiParams::new(lightcast_server::gi::none::NONE),
        history: None,
        still: false,
        yuv420: false,
        poses: Vec::new(),
        pick: None,
    }
}

/// The indirect-light buffer of `settings` rendered with `gi` instead of its own GI.
pub fn indirect_with(
    renderer: &mut Renderer,
    settings: &RenderSettings,
    gi: lightcast_server::gi::GiParams,
) -> Vec<[f32; 4]> {
    let s = RenderSettings {
        gi,
        ..settings.clone()
    };
    renderer
        .render(&s)
        .expect("render")
        .indirect
        .expect("captured")
}

pub fn render(scene: Scene, settings: &RenderSettings) -> Frame {
    let mut renderer = Renderer::new(gpu(), scene);
    renderer.render(settings).expect("render")
}

pub fn directional(direction: Vec3, illuminance: f32) -> Light {
    Light {
        kind: LightKind::Directional,
        position: [0.0; 3],
        direction: direction.to_array(),
        color: [1.0; 3],
        intensity: illuminance,
        inner_cone: 0.0,
        outer_cone: 0.0,
    }
}

/// World-space ray through the centre of pixel (x, y).
pub fn pixel_ray(
    camera: &Camera,
    scene: &Scene,
    width: u32,
    height: u32,
    x: u32,
    y: u32,
) -> (Vec3, Vec3) {
    subpixel_ray(camera, scene, width, height, x as f32 + 0.5, y as f32 + 0.5)
}

/// The camera ray through the point (`fx`, `fy`) of the image, in pixels from its top left
/// corner.
pub fn subpixel_ray(
    camera: &Camera,
    scene: &Scene,
    width: u32,
    height: u32,
    fx: f32,
    fy: f32,
) -> (Vec3, Vec3) {
    let view_proj = camera_view_proj(camera, width as f32 / height as f32, &scene.bounds);
    let inv = view_proj.inverse();
    let ndc_x = fx / width as f32 * 2.0 - 1.0;
    let ndc_y = 1.0 - fy / height as f32 * 2.0;
    let unproject = |z: f32| {
        let p = inv * glam::Vec4::new(ndc_x, ndc_y, z, 1.0);
        p.xyz() / p.w
    };
    let near = unproject(0.0);
    let far = unproject(1.0);
    (near, (far - near).normalize())
}

/// Where a pixel's ray meets the plane y = `plane_y`, if it does.
pub fn hit_plane(
    camera: &Camera,
    scene: &Scene,
    w: u32,
    h: u32,
    x: u32,
    y: u32,
    plane_y: f32,
) -> Option<Vec3> {
    let (o, d) = pixel_ray(camera, scene, w, h, x, y);
    if d.y.abs() < 1e-6 {
        return None;
    }
    let t = (plane_y - o.y) / d.y;
    (t > 0.0).then(|| o + d * t)
}

/// `eval_brdf` of `shaders/brdf_eval.wgsl` through its CPU reference, `scene::brdf`.
pub fn brdf(m: &Material, n: Vec3, to_light: Vec3, to_viewer: Vec3) -> Vec3 {
    m.brdf().eval(n, to_light, to_viewer)
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// CPU port of `light_incident` in `shaders/lights.wgsl`: (direction to light, irradiance).
pub fn incident(light: &Light, p: Vec3) -> (Vec3, Vec3) {
    let radiance = Vec3::from(light.color) * light.intensity;
    let dir = Vec3::from(light.direction).normalize();
    match light.kind {
        LightKind::Directional => (-dir, radiance),
        LightKind::Spot | LightKind::Point => {
            let d = Vec3::from(light.position) - p;
            let l = d.normalize();
            let mut e = radiance / d.length_squared();
            if light.kind == LightKind::Spot {
                let outer = light.outer_cone.max(1e-4);
                let inner = light.inner_cone.clamp(0.0, outer * 0.999);
                e *= smoothstep(outer.cos(), inner.cos(), (-l).dot(dir));
            }
            (l, e)
        }
    }
}

/// Unshadowed direct radiance leaving `p` towards the camera (CPU reference).
pub fn direct_radiance(m: &Material, light: &Light, camera: &Camera, p: Vec3, n: Vec3) -> Vec3 {
    let (l, e) = incident(light, p);
    let v = (Vec3::from(camera.position) - p).normalize();
    brdf(m, n, l, v) * e * n.dot(l).max(0.0)
}

pub fn hdr_at(frame: &Frame, x: u32, y: u32) -> Vec3 {
    let hdr = frame.hdr.as_ref().expect("HDR captured");
    let c = hdr[(y * frame.width + x) as usize];
    Vec3::new(c[0], c[1], c[2])
}

pub fn rgba_at(frame: &Frame, x: u32, y: u32) -> [u8; 4] {
    let i = ((y * frame.width + x) * 4) as usize;
    [
        frame.rgba8[i],
        frame.rgba8[i + 1],
        frame.rgba8[i + 2],
        frame.rgba8[i + 3],
    ]
}

pub fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// Distance along the ray to triangle `tri` (Möller–Trumbore), if it is hit.
fn intersect(scene: &Scene, tri: usize, origin: Vec3, dir: Vec3) -> Option<f32> {
    let idx = &scene.indices[tri * 3..tri * 3 + 3];
    let [a, b, c] =
        [idx[0], idx[1], idx[2]].map(|i| Vec3::from(scene.vertices[i as usize].position));
    let (e1, e2) = (b - a, c - a);
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - a;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(e2.dot(q) * inv)
}

/// Distance along the ray to the nearest scene triangle and its index, if any.
pub fn trace(scene: &Scene, origin: Vec3, dir: Vec3, max_t: f32) -> Option<(f32, usize)> {
    (0..scene.indices.len() / 3)
        .filter_map(|tri| intersect(scene, tri, origin, dir).map(|t| (t, tri)))
        .filter(|&(t, _)| t > 1e-4 && t < max_t)
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

/// Whether more than one triangle is hit within `eps` of distance `t` (coplanar overlaps,
/// where the rasteriser's choice is arbitrary).
pub fn ambiguous_hit(scene: &Scene, origin: Vec3, dir: Vec3, t: f32, eps: f32) -> bool {
    (0..scene.indices.len() / 3)
        .filter_map(|tri| intersect(scene, tri, origin, dir))
        .filter(|&h| (h - t).abs() < eps)
        .count()
        > 1
}

/// The material of triangle `tri` (triangles are sorted by material in [`Scene`]).
pub fn triangle_material(scene: &Scene, tri: usize) -> u32 {
    scene.vertices[scene.indices[tri * 3] as usize].material
}

/// CPU port of `estimate_importance` in `shaders/importance.wgsl` (eq. 10–11) for RSM texel
/// `i` of a read-back sampling run.
pub fn cpu_importance(
    rb: &lightcast_server::gi::lightskin::sampling::SamplingReadback,
    i: usize,
) -> f32 {
    let p = rb.rsm_position[i];
    if p[3] == 0.0 {
        return 0.0;
    }
    let (x, nl) = (
        Vec3::from_slice(&p[..3]),
        Vec3::from_slice(&rb.rsm_normal[i][..3]),
    );
    let flux = Vec3::from_slice(&rb.rsm_flux_area[i][..3]);
    let glossy = GlossySender::decode(rb.rsm_glossy[i]);
    let sum: f32 = rb
        .view_samples
        .iter()
        .map(|vs| {
            let l = Vec3::from(vs.position) - x;
            let d2 = l.length_squared();
            let d = l / d2.max(1e-24).sqrt();
            // Eq. 11: the squared distance is clamped to at least 1.
            vs.valid * nl.dot(d).max(0.0) * Vec3::from(vs.normal).dot(-d).max(0.0) / d2.max(1.0)
        })
        .sum();
    // Eq. 10's Φ_VAL: its glossy part ρ_g·P·Φ_in as if it left diffusely, with P ≈ n·r.
    let glossy = Vec3::from(glossy.weight) * nl.dot(Vec3::from(glossy.mirror)).max(0.0);
    luminance(flux + glossy) * sum / rb.view_samples.len() as f32
}

/// The selected VALs as inputs of the CPU reference.
pub fn ref_vals(
    vals: &[lightcast_server::gi::lightskin::val_select::Val],
) -> Vec<lightcast_server::gi::lightskin::cpu::RefVal> {
    vals.iter()
        .map(|v| lightcast_server::gi::lightskin::cpu::RefVal {
            position: Vec3::from(v.position),
            normal: Vec3::from(v.normal),
            flux: Vec3::from(v.flux),
            area: v.area,
            weight: v.weight,
            glossy: v.glossy,
        })
        .collect()
}

/// The G-buffer texel the CPU expects at pixel (x, y): the nearest surface along the pixel's
/// ray, with its material as the G-buffer stores it (its factors in half floats); `None`
/// where rays a tenth of a pixel away meet another plane (near an edge the rasteriser may
/// pick either).
pub fn surface_at(
    scene: &Scene,
    s: &RenderSettings,
    x: u32,
    y: u32,
) -> Option<lightcast_server::gi::clustered::cpu::RefSurface> {
    let hit = |fx: f32, fy: f32| {
        let (o, d) = subpixel_ray(&s.camera, scene, s.width, s.height, fx, fy);
        let (t, tri) = trace(scene, o, d, 100.0)?;
        let corner =
            |k: usize| Vec3::from(scene.vertices[scene.indices[tri * 3 + k] as usize].position);
        let mut n = (corner(1) - corner(0))
            .cross(corner(2) - corner(0))
            .normalize();
        if n.dot(d) > 0.0 {
            n = -n;
        }
        Some((o + d * t, n, tri, n.dot(corner(0))))
    };
    let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
    let (position, n, tri, plane) = hit(cx, cy)?;
    for (dx, dy) in [(-0.1, 0.0), (0.1, 0.0), (0.0, -0.1), (0.0, 0.1)] {
        let (_, other_n, _, other_plane) = hit(cx + dx, cy + dy)?;
        if other_n.dot(n) < 0.9999 || (other_plane - plane).abs() > 1e-4 {
            return None;
        }
    }
    let m = scene.materials[triangle_material(scene, tri) as usize].brdf();
    Some(lightcast_server::gi::clustered::cpu::RefSurface {
        position,
        normal: n,
        brdf: gbuffer_brdf(&m),
    })
}

/// A material's BRDF as the G-buffer stores it: its factors in half floats.
pub fn gbuffer_brdf(m: &Brdf) -> Brdf {
    let f16 = |v: f32| half::f16::from_f32(v).to_f32();
    Brdf {
        base: m.base.to_array().map(f16).into(),
        metallic: f16(m.metallic),
        roughness: f16(m.roughness),
        specular: f16(m.specular),
    }
}

/// A test whose environment is missing here (a tool or driver the set-up script installs):
/// on a developer's machine it says so and passes without exercising anything; in CI
/// (`CI` set, as `.ci/run` does), where the set-up script ran first, it fails, so a check
/// never passes there by not running.
pub fn not_exercised(reason: &str) {
    assert!(
        std::env::var_os("CI").is_none(),
        "{reason}; CI must exercise this test (deploy/setup-debian.sh sets the machine up)"
    );
    eprintln!("{reason}: not exercised here");
}

/// Σ|a − b| / Σ|b| over the RGB of every pixel.
pub fn relative_mae(a: &[[f32; 4]], b: &[[f32; 4]]) -> f32 {
    assert_eq!(a.len(), b.len());
    let (mut diff, mut total) = (0.0f64, 0.0f64);
    for (p, q) in a.iter().zip(b) {
        for c in 0..3 {
            diff += f64::from((p[c] - q[c]).abs());
            total += f64::from(q[c].abs());
        }
    }
    (diff / total.max(f64::MIN_POSITIVE)) as f32
}

/// The RGB of an RGBA image (what `quality::errors` compares with its truth).
pub fn rgb(image: &[[f32; 4]]) -> Vec<[f32; 3]> {
    image.iter().map(|p| [p[0], p[1], p[2]]).collect()
}

/// The Cornell box's short box (node 1) slid `slide` to the left (−x) and turned `turn`
/// radians about its vertical axis.
pub fn short_box_posed(
    scene: &Scene,
    slide: f32,
    turn: f32,
) -> lightcast_server::scene::nodes::Poses {
    let base = scene
        .node(1)
        .and_then(|n| n.local)
        .expect("the short box")
        .translation;
    let requested = [lightcast_protocol::NodePose {
        node: 1,
        translation: Some((base - Vec3::X * slide).to_array()),
        rotation: (turn != 0.0).then(|| glam::Quat::from_rotation_y(turn).to_array()),
        scale: None,
    }];
    lightcast_server::scene::nodes::resolve_poses(
        &scene.nodes,
        &scene.node_bounds(),
        &scene.bounds,
        &requested,
    )
    .expect("a pose inside the room")
}
