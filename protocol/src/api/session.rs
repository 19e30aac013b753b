//! Sessions: what a frame renders (`render`), how it is encoded and streamed, and what
//! `/v1/sessions` answers.

use super::*;

/// What to render: scene, size, camera, lights and GI. Shared by sessions and one-shot renders.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(default)]
pub struct RenderParams {
    /// Scene id (see `/v1/scenes`).
    pub scene: String,
    pub width: u32,
    pub height: u32,
    /// `null`: the scene's camera, else one framing its bounds.
    pub camera: Option<Camera>,
    /// One punctual light: shorthand for `lights: [light]` (give one of the two; a patch that
    /// sets either clears the other). `null` with `lights` `null`: the scene's lights (its
    /// `default_lights`).
    pub light: Option<Light>,
    /// The punctual lights, 0 to the server's `max_lights` (none: a frame lit by emissive
    /// surfaces, `render.gi.emitters`, or `environment` alone); `null`: see `light`.
    pub lights: Option<Vec<Light>>,
    /// Light from every direction (a sky); `null`: none.
    pub environment: Option<Environment>,
    /// Linear scale before tone mapping; `null` for automatic exposure.
    pub exposure: Option<f32>,
    /// Shadow map side in texels (per cube face for point lights).
    pub shadow_map_size: u32,
    pub gi: GiParams,
    pub view: View,
    /// Movable nodes posed away from where the scene has them (`GET /v1/scenes/{id}`'s
    /// `nodes`, those with `movable`), at most one entry per node; a node not listed keeps
    /// its own pose. Per session: one viewer moving a box does not move it for another.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub nodes: Vec<NodePose>,
    /// One of the scene's glTF animations (`GET /v1/scenes/{id}`'s `animations`) posing the
    /// nodes it moves; `render.nodes` entries override it for their nodes. `null`: none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub animation: Option<AnimationParams>,
}

/// `RenderParams::animation`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AnimationParams {
    pub name: String,
    /// Seconds into the animation: a one-shot render shows it at this time (clamped to its
    /// duration); a session starts playing from it.
    #[serde(default)]
    pub time: f32,
    /// A session plays it (looping) from `time` at `speed`; a one-shot render ignores this.
    /// A patch that stops it without giving `time` keeps the time it had reached.
    #[serde(default)]
    pub playing: bool,
    /// Seconds of animation per second, −100 … 100 (negative plays backwards).
    #[serde(default = "one")]
    pub speed: f32,
}

fn one() -> f32 {
    1.0
}

/// A movable node's pose relative to its parent (glTF's translation, rotation, scale); a
/// field left out keeps the node's own, so `{"node": 1}` puts node 1 back where it was.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NodePose {
    /// The node's `id`.
    pub node: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translation: Option<[f32; 3]>,
    /// A quaternion `[x, y, z, w]` (normalised by the server; not zero).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[f32; 4]>,
    /// Per axis, each within [10⁻³, 10³].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<[f32; 3]>,
}

impl Default for RenderParams {
    fn default() -> Self {
        Self {
            scene: DEFAULT_SCENE_ID.to_string(),
            width: 960,
            height: 540,
            camera: None,
            light: None,
            lights: None,
            environment: None,
            exposure: None,
            shadow_map_size: 2048,
            gi: GiParams::default(),
            view: View::FINAL,
            nodes: Vec::new(),
            animation: None,
        }
    }
}

/// Codecs of a session's frames and stills. `h264` is a video codec: a stream's frames only
/// (each frame message one access unit), never a still.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Codec {
    #[default]
    Jpeg,
    Png,
    /// H.264 constrained baseline, Annex B byte stream (start codes; SPS and PPS in front of
    /// every keyframe), as WebCodecs' `VideoDecoder` takes it without a `description`.
    H264,
}

impl Codec {
    /// The codec's byte in a frame header.
    pub fn wire(self) -> u8 {
        match self {
            Self::Jpeg => 0,
            Self::Png => 1,
            Self::H264 => 2,
        }
    }

    /// The codec of a frame header's byte.
    pub fn from_wire(byte: u8) -> Option<Self> {
        [Self::Jpeg, Self::Png, Self::H264]
            .into_iter()
            .find(|c| c.wire() == byte)
    }

    /// Whether frames of this codec depend on earlier ones (so none may be dropped).
    pub fn is_video(self) -> bool {
        self == Self::H264
    }
}

/// How a session encodes its frames. While input keeps arriving frames use
/// `moving_quality` (JPEG); once input has rested for `still_after_ms` one still follows in
/// `still_codec` at `quality` (as remote-visualisation tools do). With `codec: h264` the
/// frames are video: rate-controlled to `bitrate_kbps`, never worse than `max_qp`, with a
/// keyframe every `keyframe_interval` frames and whenever the stream (re)connects, the size or
/// a parameter changes, or the client sends `keyframe`. With `interactive_scale` below 1,
/// frames while moving are rendered and encoded smaller (see [`Encoding::interactive_size`])
/// for the client to upscale; frames at rest and stills keep the full size.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(default)]
pub struct Encoding {
    pub codec: Codec,
    /// JPEG quality 1–100 at rest.
    pub quality: u8,
    /// JPEG quality 1–100 while the camera, light or parameters change.
    pub moving_quality: u8,
    /// Rest time before the high-quality still; 0 turns stills off.
    pub still_after_ms: u32,
    /// `png` (lossless) or `jpeg` at `quality`; not `h264`.
    pub still_codec: Codec,
    /// H.264: target bitrate in kbit/s (100–200,000). `null`, the default, chooses it from
    /// the frame: [`AUTO_BITS_PER_PIXEL`] bits for every pixel of every frame at `fps_cap`
    /// (about 3.1 Mbit/s at 1920×1080 and 30 fps; see [`Encoding::bitrate_kbps_for`]).
    pub bitrate_kbps: Option<u32>,
    /// H.264: the coarsest quantiser the rate control may use (10–51; lower keeps more detail
    /// when the bitrate is tight, at the cost of exceeding it).
    pub max_qp: u8,
    /// H.264: frames between periodic keyframes (0: only the keyframes the stream needs).
    pub keyframe_interval: u32,
    /// While moving (input within the last `still_after_ms`), render and encode at this
    /// fraction of `render.width` × `render.height` (0.25–1; 1, the default, turns it off).
    /// Fewer pixels to shade, encode and send while the view changes; the client stretches
    /// the frame to the full size. With `still_after_ms` 0 nothing counts as moving.
    pub interactive_scale: f32,
}

/// The smallest side [`Encoding::interactive_size`] scales down to.
pub const MIN_INTERACTIVE_SIDE: u32 = 16;

/// The range of `encoding.bitrate_kbps`, also what an automatic bitrate is held to.
pub const MIN_BITRATE_KBPS: u32 = 100;
pub const MAX_BITRATE_KBPS: u32 = 200_000;

/// Bits per pixel per frame of an automatic H.264 bitrate (`bitrate_kbps: null`). Chosen from
/// `bench-stream` on the street at 1920×1080 while moving (bench/results/
/// lavapipe-stream-codecs.md): about 3 Mbit/s at 30 fps sent under 1/5 of JPEG q70's bytes at
/// 2 dB better PSNR, where the old fixed 8 Mbit/s sent a third of them. A fixed rate was also
/// far too much for a small window and too little for 4K at 60 fps.
pub const AUTO_BITS_PER_PIXEL: f64 = 0.05;

impl Encoding {
    /// The size of a frame rendered while moving, for a session of `width` × `height`: each
    /// side times `interactive_scale`, rounded down to an even number (H.264's 4:2:0 needs
    /// one), never below [`MIN_INTERACTIVE_SIDE`] nor above the full side.
    pub fn interactive_size(&self, width: u32, height: u32) -> (u32, u32) {
        let scale = |side: u32| {
            let scaled = (side as f32 * self.interactive_scale) as u32 & !1;
            scaled.max(MIN_INTERACTIVE_SIDE).min(side)
        };
        (scale(width), scale(height))
    }

    /// The H.264 target bitrate for frames of `width` × `height` at `fps`: `bitrate_kbps`
    /// when set, else [`AUTO_BITS_PER_PIXEL`] of the pixel rate, within
    /// [`MIN_BITRATE_KBPS`]..=[`MAX_BITRATE_KBPS`].
    pub fn bitrate_kbps_for(&self, width: u32, height: u32, fps: f32) -> u32 {
        self.bitrate_kbps.unwrap_or_else(|| {
            let bits = AUTO_BITS_PER_PIXEL * f64::from(width) * f64::from(height) * f64::from(fps);
            ((bits / 1000.0).round() as u32).clamp(MIN_BITRATE_KBPS, MAX_BITRATE_KBPS)
        })
    }
}

impl Default for Encoding {
    fn default() -> Self {
        Self {
            codec: Codec::Jpeg,
            quality: 90,
            moving_quality: 70,
            still_after_ms: 300,
            still_codec: Codec::Png,
            bitrate_kbps: None,
            max_qp: 40,
            keyframe_interval: 300,
            interactive_scale: 1.0,
        }
    }
}

/// When a session renders.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum StreamMode {
    /// A frame every tick at the fps cap, changed or not (live timings, load tests).
    #[default]
    Continuous,
    /// Frames only while something changes, then one still.
    OnChange,
}

/// Everything a session's owner can set. `POST /v1/sessions` takes it (every field
/// optional); `PATCH /v1/sessions/{id}` and the WebSocket `update` message take a JSON merge
/// patch of it (RFC 7396: fields present replace, `null` restores the default).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(default)]
pub struct SessionParams {
    pub render: RenderParams,
    pub encoding: Encoding,
    /// Most frames per second sent to this session.
    pub fps_cap: f32,
    pub mode: StreamMode,
    pub paused: bool,
}

impl Default for SessionParams {
    fn default() -> Self {
        Self {
            render: RenderParams::default(),
            encoding: Encoding::default(),
            fps_cap: 30.0,
            mode: StreamMode::Continuous,
            paused: false,
        }
    }
}

/// Counters of one session since it was created.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SessionStats {
    /// Frames the GPU rendered for this session.
    pub frames_rendered: u64,
    /// Frames written to the WebSocket.
    pub frames_sent: u64,
    /// Encoded frames replaced in the latest-frame slot before the client took them.
    pub frames_dropped: u64,
    /// Ticks skipped because the client still had frames in flight (it reads too slowly).
    pub frames_throttled: u64,
    /// Frames acknowledged by the client.
    pub frames_acked: u64,
    pub bytes_sent: u64,
    /// Render errors (e.g. a parameter the GPU cannot honour); the last one is in `last_error`.
    pub errors: u64,
    pub last_error: Option<ErrorBody>,
    /// Per-stage GPU milliseconds of the last frame.
    pub last_stages: Vec<StageMs>,
}

/// One pipeline stage's time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct StageMs {
    pub stage: String,
    pub ms: f64,
    /// Its output was reused from an earlier frame made from the same inputs (lights, poses):
    /// no GPU work this frame, `ms` 0.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub reused: bool,
    /// Its output serves this many sessions' frames, made once for them all (sessions of one
    /// scene sharing LightSkin's and BRSM's light-side stages): the frame that made it reports
    /// its whole `ms`, the others reuse it; each frame's share is `ms` over this. 0 (left
    /// out): this frame alone.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub shared_by: u32,
}

fn is_zero(n: &u32) -> bool {
    *n == 0
}

/// A session as `GET /v1/sessions/{id}` shows it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SessionInfo {
    pub id: String,
    pub params: SessionParams,
    /// Path of the session's WebSocket.
    pub stream: String,
    /// Whether a WebSocket is attached.
    pub connected: bool,
    pub created_unix_ms: u64,
    pub stats: SessionStats,
}

/// A short-lived ticket that opens the session's WebSocket where headers cannot be set
/// (browsers): `GET /v1/sessions/{id}/stream?ticket=…`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct StreamTicket {
    pub ticket: String,
    pub expires_in_ms: u64,
}

/// Answer to `POST /v1/sessions`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SessionCreated {
    pub session: SessionInfo,
    /// Opens the WebSocket without a bearer header.
    pub ticket: StreamTicket,
}
