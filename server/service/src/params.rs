//! Turns request parameters into renderer settings, enforcing the server's limits and naming
//! the request field at fault.

use super::error::ApiError;
use super::scenes::{Demand, SceneEntry};
use crate::debug_views;
use crate::gi::common::params::EMITTERS;
use crate::gi::precompute::PrecomputeKey;
use crate::passes::exposure::Exposure;
use crate::renderer::{RenderError, RenderSettings};
use crate::scene::default_light::emitters_for;
use crate::scene::nodes::{merge_poses, Poses};
use crate::service::video::{VideoConfig, VideoError};
use lightcast_protocol::{Encoding, GiParams, Light, Limits, RenderParams, SessionParams, View};
use std::sync::Arc;

/// Settings of one frame, ready for the render loop.
#[derive(Clone, Debug)]
pub struct Resolved {
    pub settings: RenderSettings,
    pub view: View,
    /// The per-scene precomputation the frame's GI method needs (`None`: none).
    pub precompute: Option<PrecomputeKey>,
    /// The claim on it that keeps it building while the session or request holds these
    /// settings.
    pub demand: Option<Arc<Demand>>,
    /// The animation a session plays: its poses are worked out per frame.
    pub playing: Option<Playing>,
}

/// A playing animation (`render.animation` with `playing`), which a session poses its frames
/// with at the time each is planned.
#[derive(Clone, Debug)]
pub struct Playing {
    /// Index in the scene's animations.
    pub animation: usize,
    /// Seconds into it when it was set, and seconds of animation per second.
    pub time: f32,
    pub speed: f32,
    /// `render.nodes`, which override it.
    pub explicit: Poses,
    /// The frame's lights are the scene's: those carried by moving nodes move with them.
    pub scene_lights: bool,
}

impl Playing {
    /// Seconds into the animation `elapsed` seconds after it was set: it loops (in f64, so
    /// a session playing for days keeps its precision).
    pub fn time_at(&self, scene: &crate::scene::Scene, elapsed: f64) -> f32 {
        let duration = f64::from(scene.animations[self.animation].duration());
        if duration > 0.0 {
            (f64::from(self.time) + f64::from(self.speed) * elapsed).rem_euclid(duration) as f32
        } else {
            0.0
        }
    }

    /// Poses `settings` `elapsed` seconds after the animation was set (and moves the scene's
    /// lights with their nodes where the frame has the scene's lights).
    pub fn pose(&self, settings: &mut RenderSettings, entry: &SceneEntry, elapsed: f64) {
        settings.poses = self.poses(&entry.scene, elapsed);
        if self.scene_lights {
            settings.lights = scene_lights(entry, &settings.poses);
        }
    }

    /// The frame's poses `elapsed` seconds after it was set.
    pub fn poses(&self, scene: &crate::scene::Scene, elapsed: f64) -> Poses {
        let t = self.time_at(scene, elapsed);
        let animation = &scene.animations[self.animation];
        merge_poses(
            &scene.nodes,
            animation.locals_at(&scene.nodes, t),
            &self.explicit,
        )
    }
}

/// The scene's lights (its default ones) with those carried by nodes moved by `poses`.
fn scene_lights(entry: &SceneEntry, poses: &Poses) -> Vec<Light> {
    let scene = &entry.scene;
    crate::scene::nodes::posed_lights(
        &scene.nodes,
        &entry.default_lights,
        &scene.light_nodes,
        poses,
    )
}

/// `nodes` (a `render.nodes` list, or a WebSocket `nodes` message's) checked against the
/// scene and resolved; errors name `nodes[i].field`.
pub fn poses(
    nodes: &[lightcast_protocol::NodePose],
    entry: &SceneEntry,
) -> Result<Poses, ApiError> {
    crate::scene::nodes::resolve_poses(
        &entry.scene.nodes,
        &entry.node_bounds,
        &entry.scene.bounds,
        nodes,
    )
    .map_err(|e| {
        let field = match e.index {
            None => "nodes".to_owned(),
            Some(i) => format!("nodes[{i}].{}", e.field),
        };
        ApiError::field(field, e.reason)
    })
}

/// Most seconds of animation per second a session plays.
const MAX_ANIMATION_SPEED: f32 = 100.0;

/// `render.animation` checked against the scene: its index there, and its time clamped to
/// its duration.
fn animation(
    a: &lightcast_protocol::AnimationParams,
    scene: &crate::scene::Scene,
) -> Result<(usize, f32), ApiError> {
    let Some(index) = scene.animations.iter().position(|x| x.name == a.name) else {
        let names: Vec<&str> = scene.animations.iter().map(|x| x.name.as_str()).collect();
        return Err(ApiError::field(
            "animation.name",
            if names.is_empty() {
                format!("'{:.64}': the scene has no animations", a.name)
            } else {
                format!(
                    "'{:.64}' is not one of the scene's: {}",
                    a.name,
                    names.join(", ")
                )
            },
        ));
    };
    if !(a.time.is_finite() && a.time >= 0.0) {
        return Err(ApiError::field(
            "animation.time",
            format!("{} must be a finite number of seconds ≥ 0", a.time),
        ));
    }
    if !(a.speed.is_finite() && a.speed.abs() <= MAX_ANIMATION_SPEED) {
        return Err(ApiError::field(
            "animation.speed",
            format!("{} is outside ±{MAX_ANIMATION_SPEED}", a.speed),
        ));
    }
    Ok((index, a.time.min(scene.animations[index].duration())))
}

/// The renderer's own field names, as paths of the request's `render` object: a GI
/// parameter's under `gi`.
fn request_field(renderer_field: &str) -> String {
    if let Some((light, field)) = renderer_field
        .strip_prefix("lights[")
        .and_then(|rest| rest.split_once("]."))
    {
        let field = if field == "cone" { "outer_cone" } else { field };
        return format!("lights[{light}].{field}");
    }
    match renderer_field {
        "method" => "gi.method".to_string(),
        name if crate::gi::params::find(name).is_some() => format!("gi.{name}"),
        other => other.to_string(),
    }
}

/// What a frame of `settings` on the scene of `entry` costs besides its GI parameters.
/// Multi-bounce methods are counted with every bounce: a still frame of a session adds them
/// all, as a one-shot render does.
pub fn frame_shape(settings: &RenderSettings, entry: &SceneEntry) -> crate::gi::cost::FrameShape {
    crate::gi::cost::FrameShape {
        width: settings.width,
        height: settings.height,
        shadow_map_size: settings.shadow_map_size,
        lights: settings.lights.len() as u32,
        // The emitter face is one more RSM face (counted as a light's, shadow map included).
        light_faces: crate::passes::frame_uniforms::face_count(
            &settings.lights,
            settings.coverage(),
        ) + u32::from(
            entry.facts.emitters
                && crate::gi::common::params::emitters(&settings.gi)
                && crate::gi::lights_from_emitters(settings.gi.method),
        ),
        environment: settings.environment.as_ref().map(|e| e.directions),
        directional_faces: settings
            .coverage()
            .faces(lightcast_protocol::LightKind::Directional),
        triangles: entry.scene.triangle_count() as u64,
        set_units: 0,
        all_bounces: true,
    }
}

/// `value` within `min..=max`, the error naming this server's range.
fn within(field: &str, value: u32, min: u32, max: u32) -> Result<(), ApiError> {
    if !(min..=max).contains(&value) {
        return Err(ApiError::field(
            field,
            format!("{value} is outside this server's range {min}..={max}"),
        ));
    }
    Ok(())
}

/// Checks `params` against `limits` and the adapter's largest texture (`max_texture`) and
/// builds the frame settings. Field paths are relative to the `render` object.
pub fn resolve(
    params: &RenderParams,
    entry: &SceneEntry,
    limits: &Limits,
    max_texture: u32,
) -> Result<Resolved, ApiError> {
    within("width", params.width, 1, limits.max_width)?;
    within("height", params.height, 1, limits.max_height)?;
    within(
        "shadow_map_size",
        params.shadow_map_size,
        16,
        limits.max_shadow_map_size,
    )?;
    let g = &params.gi;
    check_gi(g, limits)?;
    let exposure = match params.exposure {
        None => Exposure::Auto,
        Some(s) if s.is_finite() && s > 0.0 => Exposure::Manual(s),
        Some(s) => return Err(ApiError::field("exposure", format!("{s} must be > 0"))),
    };
    debug_views::check(params.view, g.method)
        .map_err(|e| ApiError::field("view", e.to_string()))?;
    let precompute = entry.precompute_key(g)?;
    let lights = lights(params, entry, limits)?;
    let mut gi = g.clone();
    let asked = g.get(EMITTERS.name).and_then(serde_json::Value::as_bool);
    gi.set(
        EMITTERS.name,
        emitters_for(asked, entry.emitter_stand_in.as_ref(), &lights),
    );
    let explicit = poses(&params.nodes, entry)?;
    // Without lights of its own the frame has the scene's, which move with their nodes.
    let from_scene = params.light.is_none() && params.lights.is_none();
    let (poses, playing) = match &params.animation {
        None => (merge_poses(&entry.scene.nodes, Vec::new(), &explicit), None),
        Some(a) => {
            let (index, time) = animation(a, &entry.scene)?;
            let scene = &entry.scene;
            let at = scene.animations[index].locals_at(&scene.nodes, time);
            let playing = a.playing.then(|| Playing {
                animation: index,
                time,
                speed: a.speed,
                explicit: explicit.clone(),
                scene_lights: from_scene,
            });
            (merge_poses(&scene.nodes, at, &explicit), playing)
        }
    };
    let lights = if from_scene {
        scene_lights(entry, &poses)
    } else {
        lights
    };
    let moves = !poses.is_empty() || playing.is_some();
    if moves {
        (crate::gi::entry(g.method).1.follows_moved_nodes)(g).map_err(|e| {
            let with = if merge_poses(&entry.scene.nodes, Vec::new(), &explicit).is_empty() {
                "animation"
            } else {
                "nodes"
            };
            ApiError::field(
                format!("gi.{}", e.field),
                format!("{} (render.{with} moves nodes)", e.reason),
            )
        })?;
    }
    let settings = RenderSettings {
        width: params.width,
        height: params.height,
        camera: params
            .camera
            .clone()
            .unwrap_or_else(|| entry.default_camera.clone()),
        lights,
        environment: params.environment.clone(),
        exposure,
        shadow_map_size: params.shadow_map_size,
        capture_hdr: debug_views::reads_indirect(params.view),
        debug_view: params.view,
        gi,
        history: None,
        still: false,
        yuv420: false,
        poses,
        pick: None,
    };
    settings.validate_for(max_texture).map_err(|e| {
        // A request that gave the one-light shorthand hears about `light`, not `lights[0]`.
        let e = if params.light.is_some() {
            e.for_one_light()
        } else {
            e
        };
        render_error(&e)
    })?;
    if let Some(e) = &settings.environment {
        crate::scene::environment::check_image(e, entry.scene.environment_image.as_deref())
            .map_err(|e| ApiError::field(format!("environment.{}", e.field), e.reason))?;
    }
    if let Some(key) = &precompute {
        entry.check_precompute_cost(g, key, limits)?;
    }
    Ok(Resolved {
        settings,
        view: params.view,
        demand: precompute.as_ref().map(|key| Arc::new(entry.demand(key))),
        precompute,
        playing,
    })
}

/// The frame's lights: `render.lights`, or `render.light` alone, or the scene's default
/// lights (the first `max_lights`); both given or too many is refused naming the field. An
/// empty `lights` is a frame lit by emissive surfaces or an environment alone.
pub fn lights(
    params: &RenderParams,
    entry: &SceneEntry,
    limits: &Limits,
) -> Result<Vec<Light>, ApiError> {
    let max = limits.max_lights as usize;
    match (&params.light, &params.lights) {
        (Some(_), Some(_)) => Err(ApiError::field(
            "lights",
            "give `light` (one light) or `lights`, not both",
        )),
        (Some(light), None) => Ok(vec![light.clone()]),
        (None, Some(lights)) if lights.len() > max => Err(ApiError::field(
            "lights",
            format!(
                "{} lights; this server allows at most {max} (max_lights)",
                lights.len()
            ),
        )),
        (None, Some(lights)) => Ok(lights.clone()),
        (None, None) => Ok(entry.default_lights.iter().take(max).cloned().collect()),
    }
}

/// Checks a request's GI parameters against the methods' tables and this server's limits
/// (see [`crate::gi::params::check_request`]).
pub fn check_gi(g: &GiParams, limits: &Limits) -> Result<(), ApiError> {
    crate::gi::params::check_request(g, limits)
        .map_err(|r| ApiError::field(format!("gi.{}", r.field), r.reason))
}

/// A renderer error as the API reports it.
pub fn render_error(e: &RenderError) -> ApiError {
    match e {
        RenderError::InvalidSetting { field, reason } => {
            ApiError::field(request_field(field), reason.clone())
        }
        RenderError::Gpu(crate::gpu::GpuError::OutOfMemory { .. }) => ApiError::new(
            axum::http::StatusCode::INSUFFICIENT_STORAGE,
            "out_of_gpu_memory",
            e.to_string(),
        ),
        other => ApiError::internal(other.to_string()),
    }
}

fn quality(field: &str, q: u8) -> Result<(), ApiError> {
    if (1..=100).contains(&q) {
        Ok(())
    } else {
        Err(ApiError::field(field, format!("{q} is outside 1..=100")))
    }
}

/// Checks the session-only parameters (encoding, fps cap) and resolves the render part.
pub fn resolve_session(
    params: &SessionParams,
    entry: &SceneEntry,
    limits: &Limits,
    max_texture: u32,
) -> Result<Resolved, ApiError> {
    let Encoding {
        codec,
        quality: q,
        moving_quality,
        still_after_ms,
        still_codec,
        bitrate_kbps,
        max_qp,
        keyframe_interval,
        interactive_scale,
    } = params.encoding;
    quality("encoding.quality", q)?;
    quality("encoding.moving_quality", moving_quality)?;
    within("encoding.still_after_ms", still_after_ms, 0, 60_000)?;
    if still_codec.is_video() {
        return Err(ApiError::field(
            "encoding.still_codec",
            "h264 is a stream codec; a still is png or jpeg",
        ));
    }
    if let Some(kbps) = bitrate_kbps {
        within(
            "encoding.bitrate_kbps",
            kbps,
            lightcast_protocol::MIN_BITRATE_KBPS,
            lightcast_protocol::MAX_BITRATE_KBPS,
        )?;
    }
    within("encoding.max_qp", u32::from(max_qp), 10, 51)?;
    within("encoding.keyframe_interval", keyframe_interval, 0, 100_000)?;
    if !(0.25..=1.0).contains(&interactive_scale) {
        return Err(ApiError::field(
            "encoding.interactive_scale",
            format!("{interactive_scale} is outside 0.25..=1"),
        ));
    }
    if codec.is_video() {
        let (w, h) = (params.render.width, params.render.height);
        if let Err(e @ VideoError::Size { side, .. }) = VideoConfig::check_size(w, h) {
            return Err(ApiError::field(
                format!("render.{side}"),
                format!("encoding.codec h264: {e}"),
            ));
        }
    }
    if !(params.fps_cap.is_finite() && params.fps_cap >= 0.1 && params.fps_cap <= limits.max_fps) {
        return Err(ApiError::field(
            "fps_cap",
            format!("{} is outside 0.1..={}", params.fps_cap, limits.max_fps),
        ));
    }
    let resolved =
        resolve(&params.render, entry, limits, max_texture).map_err(|e| e.within("render"))?;
    super::cost::check_frame(
        &params.render.gi,
        frame_shape(&resolved.settings, entry),
        &|g| entry.estimated_set_units(g),
        super::cost::Submission::SessionFrame,
        limits,
    )
    .map_err(|e| e.within("render"))?;
    Ok(resolved)
}

/// Checks a one-shot render's JPEG quality.
pub fn check_quality(q: Option<u8>) -> Result<u8, ApiError> {
    let q = q.unwrap_or(90);
    quality("quality", q)?;
    Ok(q)
}
