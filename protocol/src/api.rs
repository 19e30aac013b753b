//! Bodies of the HTTP API (`/v1/scenes`, `/v1/sessions`, `/v1/render`) and its error format.
//!
//! Every field has a default, so `{}` is a valid request. The types accept fields they do not
//! know, so a client keeps reading the answers of a newer server; the server itself refuses
//! unknown fields in requests, so a misspelt parameter is an error that names it rather than a
//! silently ignored value.

use crate::{Camera, GiMethod, Light, View};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use utoipa::ToSchema;

/// The id of the scene the server loads at start (the built-in Cornell box).
pub const DEFAULT_SCENE_ID: &str = "default";

/// Every error the API returns, with a 4xx or 5xx status.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ErrorBody {
    /// Stable machine-readable kind, e.g. `invalid_field`, `not_found`, `unauthorized`.
    pub error: String,
    /// The request field at fault, as a path (`render.gi.rsm_size`), when one is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// What went wrong, for people.
    pub message: String,
}

/// The type of a GI parameter, for clients that build their controls from `/v1/server`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum GiParamKind {
    Integer,
    Number,
    Boolean,
    /// A number or `null` (the default named in the description).
    OptionalNumber,
    /// One of the strings in `choices`.
    Choice,
}

/// One parameter of a GI method: a field of `render.gi`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct GiParamInfo {
    /// The field name in `render.gi`.
    pub name: String,
    pub kind: GiParamKind,
    /// Default value: a number, boolean or string (a `choice`), or `null` for an optional
    /// number left unset.
    pub default: serde_json::Value,
    /// Smallest accepted value (numbers).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// Largest accepted value on this server (numbers).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    /// `min` itself is refused (the range is open there).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub min_exclusive: bool,
    /// `max` itself is refused (the range is open there).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub max_exclusive: bool,
    /// The accepted values of a `choice`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub choices: Vec<String>,
    /// The unit of a number (`texels`, `scene units`), when it has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    pub description: String,
}

/// A GI method as `/v1/server` describes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct GiMethodInfo {
    pub method: GiMethod,
    /// One line for people, naming the paper and equations.
    pub summary: String,
    /// Whether frames refine while nothing changes (the frame header carries the samples).
    pub progressive: bool,
    /// The fields of `render.gi` this method reads; the others are accepted and ignored.
    pub parameters: Vec<GiParamInfo>,
    /// The debug views the method draws, besides `final` (which every method shows).
    #[serde(default)]
    pub views: Vec<ViewInfo>,
}

/// A debug view as `/v1/server` describes it (`render.view`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ViewInfo {
    pub view: View,
    /// What the image shows, for people.
    pub summary: String,
}

/// Parameters of the GI methods, tagged by `method`: every other field is a parameter one or
/// more methods read, named and bounded by their tables (`/v1/server`'s `gi_methods` lists
/// each method's, with its default, range and unit), so switching methods keeps every other
/// method's settings. The protocol names no method's parameters: the server's methods own
/// them, checks every field against them and fills the ones a request leaves out.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GiParams {
    #[serde(default)]
    pub method: GiMethod,
    /// The parameters by name (`rsm_size`), as JSON values.
    #[serde(flatten)]
    pub values: BTreeMap<String, serde_json::Value>,
}

impl GiParams {
    /// `method` with every parameter at its default.
    pub fn new(method: GiMethod) -> Self {
        Self {
            method,
            values: BTreeMap::new(),
        }
    }

    /// With parameter `name` set to `value`.
    pub fn with(mut self, name: &str, value: impl Into<serde_json::Value>) -> Self {
        self.set(name, value);
        self
    }

    /// Sets parameter `name` to `value`.
    pub fn set(&mut self, name: &str, value: impl Into<serde_json::Value>) {
        self.values.insert(name.to_string(), value.into());
    }

    /// The value of parameter `name` if the parameters name it.
    pub fn get(&self, name: &str) -> Option<&serde_json::Value> {
        self.values.get(name)
    }
}

impl utoipa::PartialSchema for GiParams {
    /// `method` and any parameters; the server's `openapi` command adds every registered
    /// parameter with its bounds to this schema.
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        use utoipa::openapi::schema::{AdditionalProperties, ObjectBuilder};
        ObjectBuilder::new()
            .property(
                "method",
                utoipa::openapi::Ref::from_schema_name(<GiMethod as ToSchema>::name()),
            )
            .additional_properties(Some(AdditionalProperties::FreeForm(true)))
            .description(Some(
                "Parameters of the GI methods, tagged by `method`; every other field is a \
                 parameter of one or more methods (see `/v1/server`'s `gi_methods`).",
            ))
            .into()
    }
}

impl ToSchema for GiParams {
    fn name() -> std::borrow::Cow<'static, str> {
        "GiParams".into()
    }
}

/// What to render: scene, size, camera, light and GI. Shared by sessions and one-shot renders.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(default)]
pub struct RenderParams {
    /// Scene id (see `/v1/scenes`).
    pub scene: String,
    pub width: u32,
    pub height: u32,
    /// `null`: the scene's camera, else one framing its bounds.
    pub camera: Option<Camera>,
    /// `null`: the scene's light (see the scene's `default_light`).
    pub light: Option<Light>,
    /// Linear scale before tone mapping; `null` for automatic exposure.
    pub exposure: Option<f32>,
    /// Shadow map side in texels (per cube face for point lights).
    pub shadow_map_size: u32,
    pub gi: GiParams,
    pub view: View,
}

impl Default for RenderParams {
    fn default() -> Self {
        Self {
            scene: DEFAULT_SCENE_ID.to_string(),
            width: 960,
            height: 540,
            camera: None,
            light: None,
            exposure: None,
            shadow_map_size: 2048,
            gi: GiParams::default(),
            view: View::FINAL,
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

/// State of one of a scene's precomputations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum PrecomputeState {
    Queued,
    Running,
    Ready,
    Failed,
}

/// One per-scene precomputation of a GI method, one per distinct parameters in use: the
/// light caches of `lightskin`/`brsm` (kind `light_caches`), the BVH of `reference` (kind
/// `bvh`). Frames of a method whose precomputation is not ready show direct light.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Precomputed {
    /// `light_caches` or `bvh`.
    pub kind: String,
    /// What people call it (`light caches`, `BVH`).
    pub label: String,
    /// Its parameters by their names in the render's `gi` object (e.g. `cache_distance`),
    /// the scene's defaults filled in.
    pub params: std::collections::BTreeMap<String, f32>,
    pub state: PrecomputeState,
    /// Its size in the units the server budgets it in, once ready; absent for kinds whose
    /// size follows from the scene's triangles.
    pub units: Option<u64>,
    /// What `units` counts (`light caches`).
    pub unit: Option<String>,
    /// Current step while running (e.g. `clustering`), with progress in [0, 1].
    pub step: Option<String>,
    pub progress: Option<f32>,
    /// Time the precomputation (or loading it from the store) took.
    pub seconds: Option<f64>,
    pub from_store: Option<bool>,
    pub error: Option<String>,
}

/// Kind of [`Precomputed`] for the light caches.
pub const LIGHT_CACHES: &str = "light_caches";

impl CacheVariant {
    /// The light-cache view of a [`Precomputed`] of kind [`LIGHT_CACHES`].
    pub fn from_precomputed(p: &Precomputed) -> Option<Self> {
        if p.kind != LIGHT_CACHES {
            return None;
        }
        let param = |name: &str| p.params.get(name).copied().unwrap_or(f32::NAN);
        Some(Self {
            state: p.state,
            cache_distance: param("cache_distance"),
            cache_angle: param("cache_angle"),
            caches: p.units,
            step: p.step.clone(),
            progress: p.progress,
            seconds: p.seconds,
            from_store: p.from_store,
            error: p.error.clone(),
        })
    }
}

/// One set of light caches of a scene (one per distinct cache parameters in use): the
/// `light_caches` entries of [`SceneInfo::precomputed`], as older clients read them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct CacheVariant {
    pub state: PrecomputeState,
    pub cache_distance: f32,
    pub cache_angle: f32,
    /// Number of caches, once ready.
    pub caches: Option<u64>,
    /// Current step while running (e.g. `clustering`), with progress.
    pub step: Option<String>,
    pub progress: Option<f32>,
    /// Time the precomputation (or loading from the cache store) took.
    pub seconds: Option<f64>,
    pub from_store: Option<bool>,
    pub error: Option<String>,
}

/// JSON body of `POST /v1/scenes` that builds a procedural scene instead of uploading one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ProceduralScene {
    /// `cornell`, or `street?blocks=N&detail=D&seed=S`.
    pub procedural: String,
    /// Display name; default: the spec.
    #[serde(default)]
    pub name: Option<String>,
}

/// Axis-aligned bounds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Bounds {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

/// A scene as `GET /v1/scenes/{id}` shows it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SceneInfo {
    pub id: String,
    pub name: String,
    /// Where it came from: `procedural:…` or `upload`.
    pub source: String,
    pub triangles: u64,
    pub vertices: u64,
    pub materials: u64,
    pub textures: u64,
    pub bounds: Bounds,
    /// The file's `KHR_lights_punctual` lights.
    pub lights: Vec<Light>,
    /// The file's cameras.
    pub cameras: Vec<Camera>,
    /// What a render uses when it names no camera or light.
    pub default_camera: Camera,
    pub default_light: Light,
    /// Where the viewer keeps the camera while orbiting, panning and flying: a room's inside
    /// (and, for a room open on one side, the space in front of that side), whose walls
    /// are black from outside. Absent: anywhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_region: Option<Bounds>,
    /// Light caches: the default set first (the `light_caches` entries of `precomputed`).
    pub caches: Vec<CacheVariant>,
    /// Every precomputation of the scene (light caches, BVH) with its state, oldest first.
    #[serde(default)]
    pub precomputed: Vec<Precomputed>,
    /// Sessions using the scene (it cannot be deleted while any do).
    pub sessions: u64,
    pub load_ms: f64,
}

/// Output of a one-shot render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ImageFormat {
    #[default]
    Png,
    Jpeg,
    /// Linear float32 RGBA of the final HDR radiance (before exposure), little-endian, rows top
    /// to bottom.
    RawFinal,
    /// Linear float32 RGBA of the indirect light alone.
    RawIndirect,
}

impl ImageFormat {
    pub fn content_type(self) -> &'static str {
        match self {
            Self::Png => "image/png",
            Self::Jpeg => "image/jpeg",
            Self::RawFinal | Self::RawIndirect => "application/octet-stream",
        }
    }
}

/// Body of `POST /v1/render`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(default)]
pub struct RenderRequest {
    pub render: RenderParams,
    pub format: ImageFormat,
    /// JPEG quality 1–100 (default 90).
    pub quality: Option<u8>,
    /// Also render the same view with this method (`reference`: the path-traced truth) and
    /// report the errors of this render against it in the report's `comparison`. The
    /// comparison render is cached by its parameters, so repeating it costs one render.
    pub compare_to: Option<GiMethod>,
    /// Samples per pixel of a `reference` comparison render (default 256; at most the
    /// server's `max_spp`). Its bounces are `render.gi.bounces`; emissive surfaces light it
    /// only when the compared method lights from them (its parameters include `emitters`)
    /// with `render.gi.emitters` on, so both see the same light sources.
    pub compare_spp: Option<u32>,
}

/// A render's errors against another method's render of the same view (see
/// `RenderRequest::compare_to`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Comparison {
    pub against: GiMethod,
    /// Samples per pixel of the reference (0 when `against` is not progressive).
    pub reference_samples: u32,
    /// The reference's own convergence: RMS standard error of pixel luminance over the mean.
    pub reference_relative_error: f32,
    /// Mean absolute error of the indirect buffer (linear radiance, per channel).
    pub indirect_mae: f64,
    /// Root-mean-square error of the indirect buffer.
    pub indirect_rmse: f64,
    /// `indirect_mae` over the reference's mean indirect radiance.
    pub indirect_mae_relative: f64,
    /// MAE of 8×8-pixel block means over the reference's mean (the reference's noise
    /// averages out; errors in where the light lands remain).
    pub indirect_block_mae_relative: f64,
    /// Signed difference of the means over the reference's mean (> 0: too bright).
    pub indirect_bias_relative: f64,
    /// PSNR in dB of the final images, both tone-mapped with the reference's exposure;
    /// `null` when they are identical.
    pub final_psnr_db: Option<f64>,
    /// Mean LDR-FLIP error of the same two final images (0: indistinguishable, 1: the
    /// largest perceived difference), at 67 pixels per degree.
    pub final_flip: f64,
}

/// The timing report of a one-shot render; sent in the `x-lightcast-report` header of the
/// image response.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct RenderReport {
    /// The server build (`lightcast-server` version and git revision).
    pub build: String,
    pub adapter: String,
    /// SHA-256 of the canonical JSON of the request after defaults were applied: equal hashes
    /// on the same build and adapter give identical pixels.
    pub request_hash: String,
    pub width: u32,
    pub height: u32,
    pub format: ImageFormat,
    pub stages: Vec<StageMs>,
    pub gpu_ms: f64,
    /// `gpu_timestamps` or `cpu_wall`.
    pub timing_source: String,
    pub encode_ms: f64,
    /// Time waiting for the render loop (queueing behind sessions).
    pub queue_ms: f64,
    pub exposure_scale: f32,
    /// The camera and light actually used (after scene defaults).
    pub camera: Camera,
    pub light: Light,
    /// Samples per pixel of a progressive method (`reference`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples: Option<u32>,
    /// How noisy a progressive method's image still is: the root-mean-square standard error
    /// of the pixels' luminance over their mean luminance (0.05: ±5 %), as the viewer's
    /// "N spp, ±x %" shows it. It falls as 1/√samples.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_error: Option<f64>,
    /// Errors against `compare_to`'s render, when the request asked for one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub comparison: Option<Comparison>,
    /// What the request was estimated to cost before it ran (the comparison render included),
    /// in seconds of this server's adapter: the number checked against `max_request_seconds`
    /// (absent from offline renders, which have no such limit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimated_seconds: Option<f64>,
    /// How far `stages` can be trusted, when not fully: a CPU adapter's (lavapipe's) timestamp
    /// queries put the work of some stages into others, so single stages may read hundredths
    /// of a millisecond for seconds of work. The request's wall time is then the measure.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timing_note: Option<String>,
}

/// [`RenderReport::timing_note`] on a CPU adapter that times stages with its timestamps.
pub const CPU_TIMESTAMPS_NOTE: &str = "this CPU adapter's timestamps put the work of some \
    stages into others: single stage times under-report (the request's wall time does not; \
    `lightcast-server bench --stage-clock wall` times each stage by the clock)";

/// The server's limits; requests beyond them are refused with `invalid_field`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Limits {
    pub max_width: u32,
    pub max_height: u32,
    pub max_shadow_map_size: u32,
    pub max_fps: f32,
    pub max_sessions: u32,
    pub max_scenes: u32,
    pub max_upload_bytes: u64,
    /// Most triangles of an uploaded or procedural scene.
    pub max_triangles: u64,
    pub max_message_bytes: u64,
    /// WebSocket control messages per second per session.
    pub max_messages_per_second: u32,
    pub request_timeout_ms: u64,
    /// A session with no stream attached for this long ends (0: never).
    #[serde(default)]
    pub session_idle_secs: u64,
    /// A stream whose client sends nothing for this long, not even the pong to the server's
    /// pings (sent every third of it), is closed.
    #[serde(default)]
    pub stream_silence_secs: u64,
    /// Connections one client address (IPv6: one /64) may hold open; beyond, 429.
    #[serde(default)]
    pub max_connections_per_address: u32,
    /// A connection must send a whole request head within this of opening or of its previous
    /// response, or it is closed (idle connections included).
    #[serde(default)]
    pub header_timeout_ms: u64,
    /// Largest request head (request line and headers); beyond, 431 (414 for a URI longer
    /// than 8 KiB).
    #[serde(default)]
    pub max_header_bytes: u64,
    /// Longest name or procedural spec a scene may have, in bytes; beyond, 400.
    #[serde(default)]
    pub max_name_bytes: u32,
    /// Largest texture side kept; larger images of an upload are downscaled to it.
    #[serde(default)]
    pub max_texture_size: u32,
    /// Decoded texture bytes (RGBA8, after downscaling) of one scene (413 beyond).
    #[serde(default)]
    pub max_scene_texture_bytes: u64,
    /// Decoded texture bytes over every scene held (413 beyond).
    #[serde(default)]
    pub max_total_texture_bytes: u64,
    /// Triangles over every scene held, degenerate ones not counted (413 beyond).
    #[serde(default)]
    pub max_total_triangles: u64,
    /// Scene uploads (`.glb`/multipart bodies of `/v1/scenes` and `/v1/render`) received or
    /// loading at once (429 beyond).
    #[serde(default)]
    pub max_uploads: u32,
    /// One-shot renders queued or running at once (429 beyond).
    #[serde(default)]
    pub max_queued_renders: u32,
    /// Estimated seconds of adapter work one one-shot render may buy, its path tracing (a
    /// `reference` frame, a comparison) accumulated in chunks (400 naming the parameter to
    /// lower, and the value that fits, beyond). Estimates are the GI methods' cost formulas.
    #[serde(default)]
    pub max_request_seconds: f64,
    /// Estimated seconds of adapter work one submission may take while every other session
    /// waits: a session's frame, a one-shot's frame but for its path tracing (400 beyond).
    #[serde(default)]
    pub max_frame_seconds: f64,
    /// How many times faster than the reference adapter (lavapipe on 2 CPU cores, where the
    /// cost formulas were measured) this server's adapter is taken to be.
    #[serde(default)]
    pub adapter_speed: f64,
    /// Estimated seconds (on 2 CPU cores) a new per-scene precomputation may take (400
    /// naming the parameter to lower beyond).
    #[serde(default)]
    pub max_precompute_seconds: f64,
    /// A precomputation no session or waiting request has needed for this many seconds is
    /// cancelled at its next check (the surfel links check between chunks of caches).
    #[serde(default)]
    pub unwanted_precompute_secs: u64,
    /// Per-token quotas (auth on only; `null` without auth): sessions one token holds (429
    /// `session_quota` beyond).
    #[serde(default)]
    pub token_max_sessions: Option<u32>,
    /// Scenes one token has uploaded and not deleted (429 `scene_quota`).
    #[serde(default)]
    pub token_max_scenes: Option<u32>,
    /// Scene uploads of one token in flight (429 `upload_quota`).
    #[serde(default)]
    pub token_max_uploads: Option<u32>,
    /// One-shot renders of one token queued or running (429 `render_quota`).
    #[serde(default)]
    pub token_max_renders: Option<u32>,
    /// The limits the server's GI methods declare (largest values of their parameters, such
    /// as `max_val_count`, and the budgets of their precomputations, such as
    /// `max_total_caches`), flattened among these fields; the OpenAPI schema lists this
    /// server's.
    #[serde(flatten)]
    pub gi: BTreeMap<String, serde_json::Value>,
}

/// `GET /v1/server`: who is serving and under which limits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ServerInfo {
    pub build: String,
    pub adapter: String,
    pub timing_source: String,
    pub auth: bool,
    pub limits: Limits,
    /// Names of the pipeline stages; a frame header's per-stage timings index this list.
    #[serde(default)]
    pub stages: Vec<String>,
    /// The GI methods this server runs, with their parameters and limits.
    #[serde(default)]
    pub gi_methods: Vec<GiMethodInfo>,
    /// This replica's name where several serve behind one proxy (`--replica`): session ids
    /// start with it, and every response carries it as `Lightcast-Replica`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replica: Option<String>,
    /// What a request gets for the render fields it leaves out.
    #[serde(default)]
    pub defaults: RenderDefaults,
    /// Session stream codecs and the video encoder behind `h264`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video: Option<VideoInfo>,
}

/// What a server can encode a session's frames in.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct VideoInfo {
    /// Codecs `encoding.codec` may name.
    pub codecs: Vec<Codec>,
    /// The H.264 encoder in use (`--encoder`): `openh264`.
    pub encoder: String,
    /// Whether that encoder runs on dedicated hardware rather than the CPU.
    pub hardware: bool,
    /// Bits per pixel per frame of an automatic bitrate (`encoding.bitrate_kbps: null`).
    pub auto_bits_per_pixel: f64,
    /// Threads one stream's encoder uses for frames of 1920×1080 on this machine: one per
    /// about half a megapixel, at most the CPUs and OpenH264's four; with several, each frame
    /// is four slices per thread.
    pub threads_1080p: u16,
}

/// Which set of defaults a server gives requests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum DefaultsProfile {
    /// The protocol's defaults ([`RenderParams::default`]): the paper's evaluation settings.
    #[default]
    Gpu,
    /// Smaller GI settings and indirect light at reduced resolution, so a CPU (software)
    /// adapter answers interactively.
    Software,
}

/// The defaults of the render fields a request leaves out (`POST /v1/render`,
/// `POST /v1/sessions`, and a merge patch's `null`). Fields a request sets are always used.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct RenderDefaults {
    pub profile: DefaultsProfile,
    /// Why the server chose the profile.
    pub reason: String,
    /// The complete defaults (`camera` and `light` `null`: the scene's own).
    pub render: RenderParams,
    /// The share of the viewer's canvas (in device pixels) a new viewer streams at.
    pub viewer_scale: f32,
}
