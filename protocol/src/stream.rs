//! Messages on a session's WebSocket (`/v1/sessions/{id}/stream`).
//!
//! The client sends JSON text messages ([`ClientMessage`]); the server sends binary frames
//! (a [`crate::FrameHeader`] then the encoded image) and JSON text events ([`ServerEvent`]).

use crate::{Camera, ErrorBody, Light, SessionInfo};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// A control message from the client, tagged by `type`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClientMessage {
    /// Move the camera. `input_id` (any number the client picks, > 0) comes back in the header
    /// of the first frame that shows the change, so the client can measure input→frame latency.
    Camera {
        camera: Camera,
        #[serde(default)]
        input_id: u64,
    },
    /// Replace light `index` of the session's lights (0-based, below their count); without
    /// `index`, the session gets this one light instead of all it had (`render.light`).
    Light {
        light: Light,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        index: Option<u32>,
        #[serde(default)]
        input_id: u64,
    },
    /// Replace every light of the session (`render.lights`): add or remove lights this way.
    Lights {
        lights: Vec<Light>,
        #[serde(default)]
        input_id: u64,
    },
    /// Pose movable nodes (`render.nodes`): each entry replaces the session's entry for its
    /// node, others are kept (`{"node": 1}` alone puts node 1 back).
    Nodes {
        nodes: Vec<crate::NodePose>,
        #[serde(default)]
        input_id: u64,
    },
    /// Play, pause or scrub one of the scene's animations (`render.animation`); `name` alone
    /// plays it from the start.
    Animation {
        name: String,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        time: Option<f32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        playing: Option<bool>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        speed: Option<f32>,
        #[serde(default)]
        input_id: u64,
    },
    /// A JSON merge patch (RFC 7396) of the session's [`crate::SessionParams`], as for
    /// `PATCH /v1/sessions/{id}`.
    Update {
        #[schema(value_type = Object)]
        patch: serde_json::Value,
        #[serde(default)]
        input_id: u64,
    },
    /// What the view shows at a point: answered by a `picked` event (with the same `nonce`)
    /// from the next frame's G-buffer. `x`, `y` are fractions of the frame's width and height
    /// from its top left corner, in [0, 1].
    Pick {
        x: f32,
        y: f32,
        #[serde(default)]
        nonce: u64,
    },
    /// Stop rendering until `resume`.
    Pause,
    Resume,
    /// Send one lossless (PNG) still of the current view now.
    Still,
    /// Make the next video frame a keyframe (`h264`: a decoder that lost its place restarts).
    Keyframe,
    /// The client has shown frame `seq`; frames not acknowledged do not hold anything back,
    /// but the server measures the round trip from them.
    Ack {
        seq: u64,
    },
    /// Answered by a `pong` event with the same `nonce`.
    Ping {
        #[serde(default)]
        nonce: u64,
    },
}

/// A JSON text message from the server, tagged by `type`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerEvent {
    /// First message on a new WebSocket: the session as it stands.
    Hello {
        session: Box<SessionInfo>,
        /// The codecs this server encodes a session's frames in (`jpeg`, `png`, `h264`); a
        /// client switches `encoding.codec` to one it can decode.
        #[serde(default)]
        codecs: Vec<crate::Codec>,
        /// The video encoder behind `h264` (`openh264`), absent where there is none.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        video_encoder: Option<String>,
    },
    /// Parameters changed (by this socket, another or `PATCH`); the new state.
    Updated {
        session: Box<SessionInfo>,
    },
    /// A message was refused; the session goes on unchanged.
    Error {
        error: ErrorBody,
    },
    /// A frame could not be rendered (e.g. the GPU refused the size); the session goes on.
    RenderError {
        error: ErrorBody,
    },
    /// What the session's GI method precomputes per scene (`what`: `light caches`, `BVH`)
    /// is being computed; frames show direct light until then.
    CachesPending {
        scene: String,
        /// The precomputation's `kind` in the scene's `precomputed` list.
        #[serde(default = "light_caches_kind")]
        kind: String,
        #[serde(default = "light_caches")]
        what: String,
    },
    CachesReady {
        scene: String,
        #[serde(default = "light_caches_kind")]
        kind: String,
        #[serde(default = "light_caches")]
        what: String,
    },
    Pong {
        nonce: u64,
    },
    /// What a `pick` found at its point. Without `position` no surface shows there.
    Picked {
        nonce: u64,
        x: f32,
        y: f32,
        /// World position of the surface seen (as posed in that frame).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        position: Option<[f32; 3]>,
        /// The innermost node holding the surface (`SceneInfo::nodes`).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        node: Option<u32>,
        /// The movable node a drag of this surface moves (`render.nodes`): the outermost
        /// movable node holding it (clicking a wheel drags its car). Absent: nothing there
        /// moves.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        movable: Option<u32>,
        /// The `movable` node's translation, rotation and scale (in its parent's space) as
        /// that frame posed it, an animation's pose included: where a drag starts from.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        pose: Option<crate::NodePose>,
    },
    /// The session is ending (deleted, or the server is shutting down); the socket closes next.
    Closing {
        reason: String,
    },
}

/// What older servers' `caches_pending` and `caches_ready` events were about.
fn light_caches() -> String {
    "light caches".into()
}

fn light_caches_kind() -> String {
    crate::LIGHT_CACHES.into()
}
