//! Issue 36, thin raster passes: with triangle ids the G-buffer and the RSM are rasterised as
//! visibility buffers (triangle id, base colour and facing) and resolved by compute passes
//! (`passes::gbuffer`, `passes::rsm`). Their frames must be today's: the same scenes rendered
//! with the visibility buffers off (every target rasterised) agree within the stated
//! tolerances, for the direct light, every GI method's indirect light, textured and
//! alpha-masked materials, back faces, emitters and a moved node.

use crate::support::*;
use glam::Vec3;
use lightcast_protocol::Camera;
use lightcast_server::gi::{self, precompute::SceneFacts};
use lightcast_server::passes::stages::{GBUFFER, GBUFFER_RESOLVE, RSM, RSM_RESOLVE};
use lightcast_server::renderer::{Frame, RenderSettings, Renderer};
use lightcast_server::scene::default_light::{default_camera, default_light};
use lightcast_server::scene::{procedural, Material, Scene, Texture};

const W: u32 = 64;
const H: u32 = 48;

/// Relative MAE of the HDR images (and of the indirect light) within which the two G-buffers'
/// frames agree: the resolve interpolates positions and normals at the pixel centre from the
/// vertices as the rasteriser does, up to rounding (measured on lavapipe: at most 1.2e-6 over
/// these scenes and methods, 0 for the textured square), which a shadow-map or cache lookup
/// could turn into a neighbouring texel on another adapter.
const TOLERANCE: f32 = 1e-4;

/// Relative MAE of the indirect light (and so of the frame) of a method lit from an RSM. The
/// RSM's visibility buffer holds the base colour in half floats
/// (`passes::rsm::BASE_FACING_FORMAT`), each channel within 2^-11 = 4.9e-4 relative of the
/// f32 the fat raster lights with; each lobe a texel sends is a non-negative affine function
/// of it (the diffuse albedo proportional, the Fresnel term's F0 mixing it with the dielectric
/// constant), so within that relative bound too, and the indirect light is a positive sum of
/// texels' light: within it, plus [`TOLERANCE`] for the rest. Measured on lavapipe: 3e-5 to
/// 8.6e-5 on the Cornell box, 3.5e-4 on the street (its few materials' colours happen to
/// round far; with f32 base colours the street's is 2.2e-5).
const RSM_INDIRECT_TOLERANCE: f32 = 4.9e-4 + TOLERANCE;

/// Whether this adapter draws visibility buffers (triangle ids); if not, says so (and fails in
/// CI, whose lavapipe has them).
fn exercised() -> bool {
    let ids = gpu().primitive_index;
    if !ids {
        not_exercised("this adapter has no triangle ids (PRIMITIVE_INDEX)");
    }
    ids
}

/// Renders `s` with the visibility buffer on and off: (on, off).
fn both(scene: &Scene, s: &RenderSettings) -> (Frame, Frame) {
    let ctx = gpu();
    let render = |on: bool| {
        let mut r = Renderer::new(ctx.clone(), scene.clone());
        r.set_visibility_buffer(on);
        precompute(&mut r, &s.gi);
        r.render(s).expect("render")
    };
    let (on, off) = (render(true), render(false));
    let ran = |f: &Frame, stage| f.timings.iter().any(|t| t.stage == stage);
    assert!(
        ran(&on, GBUFFER_RESOLVE),
        "the visibility buffer is resolved"
    );
    assert!(!ran(&off, GBUFFER_RESOLVE), "off rasterises every target");
    assert!(ran(&on, GBUFFER));
    // An RSM-based method's RSM is resolved too.
    assert_eq!(
        ran(&on, RSM_RESOLVE),
        ran(&on, RSM),
        "the RSM's visibility buffer"
    );
    assert!(!ran(&off, RSM_RESOLVE));
    (on, off)
}

fn agree(label: &str, on: &Frame, off: &Frame) -> f32 {
    // The frame adds direct light, within TOLERANCE, to the indirect.
    let lit_from_rsm = on.timings.iter().any(|t| t.stage == RSM);
    let tolerance = if lit_from_rsm {
        RSM_INDIRECT_TOLERANCE
    } else {
        TOLERANCE
    };
    let (a, b) = (
        on.hdr.as_ref().expect("hdr"),
        off.hdr.as_ref().expect("hdr"),
    );
    let covered = |f: &[[f32; 4]]| f.iter().filter(|p| p[3] > 0.0).count();
    assert_eq!(
        covered(a),
        covered(b),
        "{label}: the same pixels are covered"
    );
    let e = relative_mae(a, b);
    let (ia, ib) = (
        on.indirect.as_ref().expect("indirect"),
        off.indirect.as_ref().expect("indirect"),
    );
    let ei = if ib.iter().any(|p| p[0] + p[1] + p[2] > 0.0) {
        relative_mae(ia, ib)
    } else {
        0.0
    };
    eprintln!("{label}: relative MAE {e:.2e}, indirect {ei:.2e}");
    assert!(e <= tolerance, "{label}: frames differ by {e}");
    assert!(ei <= tolerance, "{label}: indirect light differs by {ei}");
    e
}

/// The Cornell box (its lamp an emitter) under every GI method's small test parameters,
/// and with the short box moved.
#[test]
fn every_method_renders_the_cornell_box_as_with_the_fat_gbuffer() {
    if !exercised() {
        return;
    }
    let scene = procedural::cornell_box();
    let facts = SceneFacts::of(&scene);
    let base = settings(W, H, default_camera(&scene), default_light(&scene));
    for method in gi::methods() {
        let s = RenderSettings {
            gi: (gi::table(method).testing.small)(&facts),
            ..base.clone()
        };
        let (on, off) = both(&scene, &s);
        agree(&format!("cornell, {method}"), &on, &off);
    }
    let moved = RenderSettings {
        poses: short_box_posed(&scene, 0.2, 0.0),
        ..base
    };
    let picked = RenderSettings {
        pick: Some([W / 2, H * 3 / 4]),
        ..moved
    };
    let (on, off) = both(&scene, &picked);
    agree("cornell, short box moved", &on, &off);
    // A click reads the same triangle and, within rounding, the same position.
    let surface = |f: &Frame| f.pick.and_then(|p| p.surface).expect("a surface");
    let (a, b) = (surface(&on), surface(&off));
    assert_eq!((a.vertex, a.node), (b.vertex, b.node));
    let d = (Vec3::from(a.position) - Vec3::from(b.position)).length();
    assert!(d < 1e-5, "picked positions {d} apart");
}

/// The RSM's faces for every kind of light, one at a time and together (a point light's six
/// perspective faces, a spot's one, a directional light's cascades, which leave what the near
/// one covers to it), with glossy senders: an RSM-based method's frames are the fat RSM's.
#[test]
fn every_kind_of_light_fills_the_rsm_as_rasterised() {
    if !exercised() {
        return;
    }
    let scene = procedural::cornell_box();
    let facts = SceneFacts::of(&scene);
    let spot = default_light(&scene);
    let point = crate::support::plates::point_light(Vec3::new(0.1, 1.3, 0.2), 2.0);
    // In through the box's open front.
    let sun = directional(Vec3::new(0.3, -0.5, -1.0).normalize(), 3.0);
    let base = settings(W, H, default_camera(&scene), spot.clone());
    let gi = (gi::table(gi::rsm_gather::RSM_GATHER).testing.small)(&facts).with("senders", "full");
    for (label, lights) in [
        ("spot", vec![spot.clone()]),
        ("point", vec![point.clone()]),
        ("directional", vec![sun.clone()]),
        ("all three", vec![spot, point, sun]),
    ] {
        let s = RenderSettings {
            lights,
            gi: gi.clone(),
            ..base.clone()
        };
        let (on, off) = both(&scene, &s);
        assert!(on.timings.iter().any(|t| t.stage == RSM_RESOLVE));
        agree(&format!("cornell, rsm_gather, {label}"), &on, &off);
    }
}

/// A thin RSM made from the same lights and poses as the frame before is reused whole: neither
/// its raster nor its resolve runs again.
#[test]
fn a_resolved_rsm_is_reused_with_its_resolve() {
    if !exercised() {
        return;
    }
    let scene = procedural::cornell_box();
    let gi = (gi::table(gi::rsm_gather::RSM_GATHER).testing.small)(&SceneFacts::of(&scene));
    let s = RenderSettings {
        gi: gi.clone(),
        ..settings(W, H, default_camera(&scene), default_light(&scene))
    };
    let mut r = Renderer::new(gpu(), scene.clone());
    r.set_visibility_buffer(true);
    precompute(&mut r, &gi);
    let stage = |f: &Frame, stage| {
        f.timings
            .iter()
            .find(|t| t.stage == stage)
            .map(|t| t.reused)
    };
    let first = r.render(&s).expect("render");
    assert_eq!(
        (stage(&first, RSM), stage(&first, RSM_RESOLVE)),
        (Some(false), Some(false))
    );
    let second = r.render(&s).expect("render");
    assert_eq!(
        (stage(&second, RSM), stage(&second, RSM_RESOLVE)),
        (Some(true), Some(true))
    );
}

/// A textured square with an alpha mask over a floor, seen from above and (its back faces)
/// from below: base colours from the texture, masked texels cut away, back faces' normals
/// flipped, as the fat G-buffer and RSM have them (a wall of the same material lights the
/// floor under `rsm_gather`).
#[test]
fn textures_masks_and_back_faces_resolve_as_rasterised() {
    if !exercised() {
        return;
    }
    let texture = Texture {
        name: "stripes".into(),
        width: 4,
        height: 2,
        rgba8: (0..8)
            .flat_map(|i| match i % 4 {
                0 => [230, 40, 40, 255],
                1 => [40, 200, 60, 255],
                2 => [30, 60, 220, 255],
                _ => [0, 0, 0, 0],
            })
            .collect(),
    };
    let (mut v, mut i) = (Vec::new(), Vec::new());
    quad(&mut v, &mut i, floor_corners(0.0, 0.0, 0.0, 2.0), 0);
    quad(&mut v, &mut i, floor_corners(0.1, -0.1, 0.4, 0.6), 1);
    // A wall of the same facing the light, whose RSM texels light the floor.
    let wall = [
        [0.9, 0.0, -0.8],
        [0.9, 0.0, 0.8],
        [0.9, 1.2, 0.8],
        [0.9, 1.2, -0.8],
    ];
    quad(&mut v, &mut i, wall.map(Vec3::from), 1);
    let cover = Material {
        base_color_texture: Some(0),
        alpha_cutoff: Some(0.5),
        emissive: [0.0, 0.3, 0.6],
        ..plain_material([1.0; 3], 0.3, 0.4)
    };
    let scene = Scene::new(
        "textured",
        v,
        i,
        vec![plain_material([0.6, 0.6, 0.6], 0.0, 0.8), cover],
        vec![texture],
        vec![],
        vec![],
    )
    .expect("scene");
    let light = directional(Vec3::new(0.3, -1.0, 0.2).normalize(), 3.0);
    let facts = SceneFacts::of(&scene);
    let gather = (gi::table(gi::rsm_gather::RSM_GATHER).testing.small)(&facts);
    for (label, position) in [("above", [0.4, 1.6, 1.5]), ("below", [0.3, -1.2, 1.4])] {
        let camera = Camera {
            position,
            target: [0.0, 0.2, 0.0],
            fov_y_degrees: 55.0,
        };
        let s = settings(W, H, camera, light.clone());
        for gi in [s.gi.clone(), gather.clone()] {
            let method = gi.method;
            let (on, off) = both(&scene, &RenderSettings { gi, ..s.clone() });
            agree(&format!("textured, {label}, {method}"), &on, &off);
        }
    }
}

/// The street from its default camera, standing on the road: the road's and the facades'
/// triangles reach behind the camera, cut by the near plane (the resolve never divides by a
/// vertex's w); and its sun's RSM cascades over the facades under `rsm_gather`.
#[test]
fn triangles_cut_by_the_near_plane_resolve_as_rasterised() {
    if !exercised() {
        return;
    }
    let scene = procedural::build("street?blocks=2&cars=0").expect("the street");
    let s = settings(W, H, default_camera(&scene), default_light(&scene));
    let gather = (gi::table(gi::rsm_gather::RSM_GATHER).testing.small)(&SceneFacts::of(&scene));
    for gi in [s.gi.clone(), gather] {
        let method = gi.method;
        let (on, off) = both(&scene, &RenderSettings { gi, ..s.clone() });
        agree(&format!("street, {method}"), &on, &off);
    }
}
