//! `/v1/server`: the server's limits, video encoder and render defaults.

use super::*;

/// The server's limits; requests beyond them are refused with `invalid_field`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Limits {
    pub max_width: u32,
    pub max_height: u32,
    pub max_shadow_map_size: u32,
    /// Most punctual lights a frame may have (`render.lights`; a scene's default is its first
    /// this many).
    #[serde(default)]
    pub max_lights: u32,
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
