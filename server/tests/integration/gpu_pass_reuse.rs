//! Issue 36, first part: sessions of one scene take turns on one renderer, and the passes that
//! do not depend on the camera (the shadow map, the RSM) are reused from the frame before
//! while the lights and poses are the same (`passes::reuse`). Every method's frames must be
//! what they are with reuse off, bit for bit, whatever order the sessions come in.

use crate::support::*;
use glam::Vec3;
use lightcast_server::gi::{self, precompute::SceneFacts};
use lightcast_server::passes::stages::{RSM, SHADOW_MAP};
use lightcast_server::renderer::{Frame, RenderSettings, Renderer};
use lightcast_server::scene::default_light::{default_camera, default_light};
use lightcast_server::scene::nodes::resolve_poses;
use lightcast_server::scene::procedural;

const W: u32 = 48;
const H: u32 = 36;

fn reused(frame: &Frame) -> Vec<&'static str> {
    let mut names: Vec<&'static str> = frame
        .timings
        .iter()
        .filter(|t| t.reused)
        .map(|t| t.stage.name())
        .collect();
    names.sort_unstable();
    names
}

/// Two cameras (two sessions' views), a light moved, and the short box moved: the frames of
/// a renderer that reuses equal those of one that does not, and the shadow map and RSM are
/// reused exactly where the frame before had the same lights and poses.
#[test]
fn reused_passes_leave_every_frame_as_it_was() {
    let scene = procedural::cornell_box();
    let facts = SceneFacts::of(&scene);
    let base = settings(W, H, default_camera(&scene), default_light(&scene));
    let mut other_view = base.clone();
    other_view.camera.position =
        (Vec3::from(base.camera.position) + Vec3::new(0.4, -0.2, -0.5)).to_array();
    let mut other_light = base.clone();
    other_light.lights[0].position[0] += 0.1;
    let node = scene.node(1).and_then(|n| n.local).expect("the short box");
    let posed = RenderSettings {
        poses: resolve_poses(
            &scene.nodes,
            &scene.node_bounds(),
            &scene.bounds,
            &[lightcast_protocol::NodePose {
                node: 1,
                translation: Some((node.translation - Vec3::X * 0.2).to_array()),
                rotation: None,
                scale: None,
            }],
        )
        .expect("a pose inside the room"),
        ..base.clone()
    };
    // Which frames may reuse: after the same lights and poses, whatever the camera.
    let sequence = [
        (&base, false),
        (&other_view, true),
        (&base, true),
        (&other_light, false),
        (&other_light, true),
        (&posed, false),
        (&base, false),
    ];
    for method in gi::methods() {
        let gi = (gi::table(method).testing.small)(&facts);
        let mut on = Renderer::new(gpu(), scene.clone());
        let mut off = Renderer::new(gpu(), scene.clone());
        off.set_reuse(false);
        precompute(&mut on, &gi);
        precompute(&mut off, &gi);
        for (i, &(frame_settings, may_reuse)) in sequence.iter().enumerate() {
            let s = RenderSettings {
                gi: gi.clone(),
                ..frame_settings.clone()
            };
            let (a, b) = (
                on.render(&s).expect("render"),
                off.render(&s).expect("render"),
            );
            assert!(
                a.hdr == b.hdr,
                "{method}, frame {i}: reuse changed the image"
            );
            assert_eq!(reused(&b), Vec::<&str>::new(), "{method}: reuse off");
            let has_rsm = a.timings.iter().any(|t| t.stage == RSM) || reused(&a).contains(&"rsm");
            let want: Vec<&str> = match (may_reuse, has_rsm) {
                (false, _) => vec![],
                (true, false) => vec![SHADOW_MAP.name()],
                (true, true) => vec![RSM.name(), SHADOW_MAP.name()],
            };
            assert_eq!(reused(&a), want, "{method}, frame {i}");
        }
    }
}

/// A frame whose encoding fails part-way (LightSkin without its light caches) recorded its
/// shadow map as drawn for its lights but never submitted it: the next frame with those lights
/// draws it again (reuse equals no reuse), and frames of another size or under a uniform sky are
/// what they are without reuse too.
#[test]
fn nothing_is_reused_from_a_frame_that_failed_or_of_other_inputs() {
    let scene = procedural::cornell_box();
    let facts = SceneFacts::of(&scene);
    let gi = (gi::table(gi::lightskin::LIGHTSKIN).testing.small)(&facts);
    let lit = settings(W, H, default_camera(&scene), default_light(&scene));
    let mut moved_light = lit.clone();
    moved_light.lights[0].position[2] -= 0.3;
    let none = RenderSettings {
        gi: gi::GiParams::new(gi::none::NONE),
        ..lit.clone()
    };
    let lightskin = RenderSettings {
        gi: gi.clone(),
        ..moved_light.clone()
    };
    let mut on = Renderer::new(gpu(), scene.clone());
    on.render(&none).expect("render");
    assert!(
        on.render(&lightskin).is_err(),
        "LightSkin without its caches"
    );
    precompute(&mut on, &gi);
    let mut off = Renderer::new(gpu(), scene.clone());
    off.set_reuse(false);
    precompute(&mut off, &gi);
    let smaller = RenderSettings {
        width: 32,
        height: 24,
        ..lightskin.clone()
    };
    let sky = RenderSettings {
        environment: Some(lightcast_protocol::Environment {
            kind: lightcast_protocol::EnvironmentKind::Uniform,
            ..Default::default()
        }),
        ..lightskin.clone()
    };
    for (i, s) in [&lightskin, &smaller, &sky, &sky, &lightskin]
        .into_iter()
        .enumerate()
    {
        let (a, b) = (
            on.render(s).expect("render"),
            off.render(s).expect("render"),
        );
        assert!(a.hdr == b.hdr, "frame {i}: reuse changed the image");
        if i == 0 {
            assert_eq!(reused(&a), Vec::<&str>::new(), "after the failed frame");
        }
        if i == 3 {
            assert!(
                reused(&a).contains(&SHADOW_MAP.name()),
                "the same sky again"
            );
        }
    }
}
