//! `lightcast-server serve` options: where to listen, limits and auth.

use super::budget::fair_share;
use crate::gpu::BackendChoice;
use crate::renderer::MAX_SHADOW_MAP_SIZE;
use crate::scene::gltf_loader::MAX_TEXTURE_SIZE;
use lightcast_protocol::Limits;
use std::net::SocketAddr;
use std::path::PathBuf;

/// Options of `lightcast-server serve` (every flag also reads an environment variable).
#[derive(Clone, Debug, clap::Args)]
pub struct ServeArgs {
    /// Address and port to listen on.
    #[arg(long, env = "LIGHTCAST_LISTEN", default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,
    /// Bearer tokens that may use the API, comma-separated. Without any, auth is off.
    #[arg(long = "token", env = "LIGHTCAST_TOKENS", value_delimiter = ',')]
    pub tokens: Vec<String>,
    /// A file with one bearer token per line (blank lines and `#` comments skipped).
    #[arg(long, env = "LIGHTCAST_TOKENS_FILE")]
    pub tokens_file: Option<PathBuf>,
    /// This replica's name where several serve behind one proxy: a DNS label such as the
    /// StatefulSet pod name. Session ids then start with it and carry a signature under the
    /// routing key, so the proxy routes each session's requests to its replica and any
    /// replica answers 421 naming the owner of a session it does not hold (deploy/README.md).
    /// Needs --routing-key-file.
    #[arg(long, env = "LIGHTCAST_REPLICA")]
    pub replica: Option<String>,
    /// A file holding the key every replica signs session ids with (at least 32 bytes; a
    /// trailing newline is ignored). Needs --replica.
    #[arg(long, env = "LIGHTCAST_ROUTING_KEY_FILE")]
    pub routing_key_file: Option<PathBuf>,
    /// A directory shared by every replica (a ReadWriteMany volume) where scenes added through
    /// `POST /v1/scenes` are kept, so that each replica can load any of them on first use and a
    /// deletion reaches all (deploy/README.md). Without it a scene lives on the replica it was
    /// uploaded to.
    #[arg(long, env = "LIGHTCAST_SCENE_STORE")]
    pub scene_store: Option<PathBuf>,
    /// Count a CPU (software) adapter such as lavapipe as ready in /readyz.
    #[arg(long, env = "LIGHTCAST_ALLOW_CPU_ADAPTER")]
    pub allow_cpu_adapter: bool,
    /// Defaults of the render fields requests leave out: `software` (smaller GI settings,
    /// indirect light at half resolution) suits CPU adapters, `gpu` is the protocol's;
    /// `auto` picks by the adapter. Fields a request sets are always used.
    #[arg(long, value_enum, env = "LIGHTCAST_DEFAULTS", default_value = "auto")]
    pub defaults: super::defaults::DefaultsChoice,
    /// wgpu backend.
    #[arg(long, value_enum, env = "LIGHTCAST_BACKEND", default_value = "auto")]
    pub backend: BackendChoice,
    /// Where precomputed light caches and surfel sets are kept (default: the user's cache
    /// directory).
    #[arg(long, env = "LIGHTCAST_CACHE_DIR")]
    pub cache_dir: Option<PathBuf>,
    /// Most bytes of stored precomputations (light caches, surfel sets) kept there; the least
    /// recently used beyond it are deleted (every uploaded scene adds files).
    #[arg(long, env = "LIGHTCAST_CACHE_MAX_BYTES", default_value_t = 4 << 30)]
    pub cache_max_bytes: u64,
    /// Scene loaded at start under the id `default`.
    #[arg(long, env = "LIGHTCAST_DEFAULT_SCENE", default_value = crate::offline::DEFAULT_SCENE)]
    pub default_scene: String,
    /// Threads encoding frames (JPEG/PNG, H.264) off the render loop. Default: half the CPUs.
    #[arg(long, env = "LIGHTCAST_ENCODE_THREADS")]
    pub encode_threads: Option<usize>,
    /// The H.264 encoder of `h264` streams: `auto` (the best this machine has) or `openh264`
    /// (software, always built in). `/v1/server` says which is used.
    #[arg(long, value_enum, env = "LIGHTCAST_ENCODER", default_value = "auto")]
    pub encoder: super::video::EncoderChoice,
    /// Render every pass of every frame: by default a shadow map or RSM an earlier frame drew
    /// from the same lights and poses is reused (the images are the same bit for bit), and
    /// sessions of one scene share LightSkin's and BRSM's light-side stages per tick (pooling
    /// their views where they differ). For measuring what that saves.
    #[arg(long, env = "LIGHTCAST_NO_PASS_REUSE")]
    pub no_pass_reuse: bool,
    /// Frames handed to the readback thread and not yet read back at once (a one-shot render's
    /// comparison frames travel with it; 1 to 3, the frames of one size a renderer keeps
    /// read-back buffers for): with 3 the render loop encodes and submits the
    /// next frame while one is read back and another renders, so the GPU finds work queued
    /// (`lightcast_gpu_idle_seconds` measures what it still waits). Default: 3 on a GPU, 2
    /// on a CPU adapter (whose "GPU" shares the CPUs with the loop). After a frame slower than
    /// 100 ms the next waits until none is in flight whatever this says.
    #[arg(
        long,
        env = "LIGHTCAST_FRAMES_IN_FLIGHT",
        value_parser = clap::value_parser!(u8).range(1..=crate::renderer::READBACK_RING as i64)
    )]
    pub frames_in_flight: Option<u8>,
    /// Rasterise the G-buffer and the RSM as visibility buffers (triangle id and base colour)
    /// and resolve them by compute (`on`; needs triangle ids, the server refuses to start on
    /// an adapter without), or rasterise every target (`off`); `auto`: on except on a CPU
    /// adapter, where it measured slower. The images agree within 2^-11 either way.
    #[arg(
        long,
        value_enum,
        env = "LIGHTCAST_VISIBILITY_BUFFER",
        default_value = "auto"
    )]
    pub visibility_buffer: crate::renderer::VisibilityBuffer,
    /// Log lines for people (`text`) or one JSON object per line for log collectors (`json`).
    #[arg(long, value_enum, env = "LIGHTCAST_LOG_FORMAT", default_value = "text")]
    pub log_format: LogFormat,
    #[command(flatten)]
    pub limits: LimitArgs,
}

/// How the service writes its log.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    Text,
    Json,
}

/// Configurable maxima; requests beyond them get a 400 naming the field.
#[derive(Clone, Debug, clap::Args)]
pub struct LimitArgs {
    /// Largest frame width.
    #[arg(long, env = "LIGHTCAST_MAX_WIDTH", default_value_t = 3840)]
    pub max_width: u32,
    /// Largest frame height.
    #[arg(long, env = "LIGHTCAST_MAX_HEIGHT", default_value_t = 2160)]
    pub max_height: u32,
    /// The limits the GI methods declare (`--max-val-count`, `--max-total-caches`, …; see
    /// `gi::limits`).
    #[command(flatten)]
    pub gi_limits: crate::gi::limits::GiLimitArgs,
    /// Largest shadow map side.
    #[arg(long, env = "LIGHTCAST_MAX_SHADOW_MAP_SIZE", default_value_t = 4096)]
    pub max_shadow_map_size: u32,
    /// Most punctual lights a frame may have (`render.lights`); a scene's default is its
    /// file's first this many. At most 16 (the GPU's light list).
    #[arg(long, env = "LIGHTCAST_MAX_LIGHTS", default_value_t = 16)]
    pub max_lights: u32,
    /// Highest fps cap a session may ask for.
    #[arg(long, env = "LIGHTCAST_MAX_FPS", default_value_t = 240.0)]
    pub max_fps: f32,
    /// Most sessions open at once.
    #[arg(long, env = "LIGHTCAST_MAX_SESSIONS", default_value_t = 64)]
    pub max_sessions: u32,
    /// Most scenes held at once (the default scene included).
    #[arg(long, env = "LIGHTCAST_MAX_SCENES", default_value_t = 16)]
    pub max_scenes: u32,
    /// Largest scene upload in bytes.
    #[arg(long, env = "LIGHTCAST_MAX_UPLOAD_BYTES", default_value_t = 256 << 20)]
    pub max_upload_bytes: u64,
    /// Most triangles of an uploaded or procedural scene.
    #[arg(long, env = "LIGHTCAST_MAX_TRIANGLES", default_value_t = 10_000_000)]
    pub max_triangles: u64,
    /// Largest JSON body or WebSocket message in bytes.
    #[arg(long, env = "LIGHTCAST_MAX_MESSAGE_BYTES", default_value_t = 64 << 10)]
    pub max_message_bytes: u64,
    /// WebSocket control messages accepted per second per session (a burst of twice as many;
    /// acks of frames sent and not yet acknowledged do not count).
    #[arg(long, env = "LIGHTCAST_MAX_MESSAGES_PER_SECOND", default_value_t = 120)]
    pub max_messages_per_second: u32,
    /// Time limit of an HTTP request in milliseconds (WebSockets are not limited).
    #[arg(long, env = "LIGHTCAST_REQUEST_TIMEOUT_MS", default_value_t = 60_000)]
    pub request_timeout_ms: u64,
    /// Seconds a session may go without a stream attached before it ends, so sessions of
    /// clients that vanished do not pile up (0: never).
    #[arg(long, env = "LIGHTCAST_SESSION_IDLE_SECS", default_value_t = 300)]
    pub session_idle_secs: u64,
    /// Seconds a stream's client may send nothing, not even the pong to the server's pings
    /// (sent every third of this), before the stream is closed: clients that vanish without
    /// closing their connection would otherwise hold their session forever.
    #[arg(long, env = "LIGHTCAST_STREAM_SILENCE_SECS", default_value_t = 45)]
    pub stream_silence_secs: u64,
    /// Most connections open at once; beyond, new ones get 503 and are closed. Keep it below
    /// the process's file-descriptor limit (`ulimit -n`).
    #[arg(long, env = "LIGHTCAST_MAX_CONNECTIONS", default_value_t = 1024)]
    pub max_connections: u32,
    /// Most connections one client address (IPv6: one /64) holds at once; beyond, 429. Behind
    /// a proxy every client has the proxy's address: raise it to `--max-connections` there.
    #[arg(
        long,
        env = "LIGHTCAST_MAX_CONNECTIONS_PER_ADDRESS",
        default_value_t = 256
    )]
    pub max_connections_per_address: u32,
    /// Milliseconds a connection may take to send a whole request head, counted from when it
    /// opened or its previous response ended; then it is closed, idle or not.
    #[arg(long, env = "LIGHTCAST_HEADER_TIMEOUT_MS", default_value_t = 15_000)]
    pub header_timeout_ms: u64,
    /// Largest request head (request line and headers) in bytes; beyond, 431.
    #[arg(long, env = "LIGHTCAST_MAX_HEADER_BYTES", default_value_t = 16 << 10)]
    pub max_header_bytes: u64,
    /// Largest texture side kept: the renderer samples base colour at frame resolution, so
    /// larger images of an upload are downscaled to this (at most 8192).
    #[arg(long, env = "LIGHTCAST_MAX_TEXTURE_SIZE", default_value_t = 2048)]
    pub max_texture_size: u32,
    /// Decoded texture bytes (RGBA8, after downscaling) one scene may hold, counted from the
    /// images' declared dimensions before they are decoded.
    #[arg(long, env = "LIGHTCAST_MAX_SCENE_TEXTURE_BYTES", default_value_t = 256 << 20)]
    pub max_scene_texture_bytes: u64,
    /// Decoded texture bytes over every scene held.
    #[arg(long, env = "LIGHTCAST_MAX_TOTAL_TEXTURE_BYTES", default_value_t = 1 << 30)]
    pub max_total_texture_bytes: u64,
    /// Triangles over every scene held (degenerate ones are dropped and not counted).
    #[arg(
        long,
        env = "LIGHTCAST_MAX_TOTAL_TRIANGLES",
        default_value_t = 20_000_000
    )]
    pub max_total_triangles: u64,
    /// Scene uploads received or loading at once (each body may take --max-upload-bytes).
    #[arg(long, env = "LIGHTCAST_MAX_UPLOADS", default_value_t = 4)]
    pub max_uploads: u32,
    /// One-shot renders queued or running at once.
    #[arg(long, env = "LIGHTCAST_MAX_QUEUED_RENDERS", default_value_t = 16)]
    pub max_queued_renders: u32,
    /// Estimated seconds of adapter work one one-shot render may buy (with its comparison
    /// render; path tracing runs in chunks). Costlier requests are refused with the parameter
    /// to lower and the value that fits.
    #[arg(long, env = "LIGHTCAST_MAX_REQUEST_COST", default_value_t = 10.0)]
    pub max_request_cost: f64,
    /// Estimated seconds of adapter work one submission may take while every other session
    /// waits: a session's frame, or a one-shot's frame but for its path tracing. `auto`: 2 s
    /// on a CPU adapter, 0.1 s on a GPU.
    #[arg(long, env = "LIGHTCAST_MAX_FRAME_COST", default_value = "auto")]
    pub max_frame_cost: crate::service::cost::FrameCost,
    /// How many times faster than the reference adapter (lavapipe on 2 CPU cores) this one
    /// runs the GI methods' cost formulas: `auto` is 1 on a CPU adapter and 256 on a GPU (an
    /// H200 ran the compute-bound stages about 450 times faster, the raster ones less).
    #[arg(long, env = "LIGHTCAST_ADAPTER_SPEED", default_value = "auto")]
    pub adapter_speed: crate::service::cost::AdapterSpeed,
    /// Estimated seconds of work (on 2 CPU cores) a new per-scene precomputation (light
    /// caches, a BVH, surfel links) may take; costlier ones are refused before they start.
    #[arg(long, env = "LIGHTCAST_MAX_PRECOMPUTE_COST", default_value_t = 600.0)]
    pub max_precompute_cost: f64,
    /// Seconds a precomputation goes on after the last session or request that needed it is
    /// gone (a client retrying a 503 or a reloaded viewer picks it up again meanwhile); then it
    /// is cancelled at its next check.
    #[arg(long, env = "LIGHTCAST_UNWANTED_PRECOMPUTE_SECS", default_value_t = 60)]
    pub unwanted_precompute_secs: u64,
    /// With auth on: sessions one token may hold (default: its fair share of
    /// --max-sessions, the limit divided by the number of tokens, rounded up).
    #[arg(long, env = "LIGHTCAST_TOKEN_MAX_SESSIONS")]
    pub token_max_sessions: Option<u32>,
    /// With auth on: scenes one token may have uploaded (default: its fair share of the
    /// --max-scenes slots besides the default scene).
    #[arg(long, env = "LIGHTCAST_TOKEN_MAX_SCENES")]
    pub token_max_scenes: Option<u32>,
    /// With auth on: scene uploads of one token in flight (default: fair share of
    /// --max-uploads).
    #[arg(long, env = "LIGHTCAST_TOKEN_MAX_UPLOADS")]
    pub token_max_uploads: Option<u32>,
    /// With auth on: one-shot renders of one token queued or running (default: fair share of
    /// --max-queued-renders).
    #[arg(long, env = "LIGHTCAST_TOKEN_MAX_RENDERS")]
    pub token_max_renders: Option<u32>,
}

/// Why the options cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("--{flag}: {reason}")]
    Invalid { flag: &'static str, reason: String },
    #[error("reading tokens file {path}: {error}")]
    TokensFile {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("reading routing key file {path}: {error}")]
    RoutingKeyFile {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("--replica: {0}")]
    Routing(#[from] crate::service::routing::RoutingError),
}

impl LimitArgs {
    /// The limits for a server with `tokens` bearer tokens (0: auth off), refusing values
    /// beyond what the renderer itself supports.
    pub fn limits(&self, tokens: usize) -> Result<Limits, ConfigError> {
        let within = |flag: &'static str, v: u64, lo: u64, hi: u64| {
            if (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(ConfigError::Invalid {
                    flag,
                    reason: format!("{v} is outside {lo}..={hi}"),
                })
            }
        };
        within("max-width", self.max_width.into(), 16, 16384)?;
        within("max-height", self.max_height.into(), 16, 16384)?;
        crate::gi::limits::check(&self.gi_limits.0).map_err(|(flag, reason)| {
            ConfigError::Invalid {
                flag: &flag[2..],
                reason,
            }
        })?;
        within(
            "max-shadow-map-size",
            self.max_shadow_map_size.into(),
            16,
            MAX_SHADOW_MAP_SIZE.into(),
        )?;
        within(
            "max-lights",
            self.max_lights.into(),
            1,
            crate::passes::frame_uniforms::MAX_LIGHTS as u64,
        )?;
        if !(self.max_fps.is_finite() && (1.0..=1000.0).contains(&self.max_fps)) {
            return Err(ConfigError::Invalid {
                flag: "max-fps",
                reason: format!("{} is outside 1..=1000", self.max_fps),
            });
        }
        within("max-sessions", self.max_sessions.into(), 1, 4096)?;
        within("max-scenes", self.max_scenes.into(), 1, 1024)?;
        within("max-message-bytes", self.max_message_bytes, 1024, 16 << 20)?;
        within(
            "max-messages-per-second",
            self.max_messages_per_second.into(),
            1,
            100_000,
        )?;
        within(
            "request-timeout-ms",
            self.request_timeout_ms,
            100,
            3_600_000,
        )?;
        within("session-idle-secs", self.session_idle_secs, 0, 7 * 86_400)?;
        within("stream-silence-secs", self.stream_silence_secs, 1, 3_600)?;
        within("max-connections", self.max_connections.into(), 1, 1 << 20)?;
        within(
            "max-connections-per-address",
            self.max_connections_per_address.into(),
            1,
            self.max_connections.into(),
        )?;
        within("header-timeout-ms", self.header_timeout_ms, 100, 600_000)?;
        within("max-header-bytes", self.max_header_bytes, 1024, 1 << 20)?;
        within(
            "max-texture-size",
            self.max_texture_size.into(),
            16,
            MAX_TEXTURE_SIZE.into(),
        )?;
        within(
            "max-scene-texture-bytes",
            self.max_scene_texture_bytes,
            0,
            self.max_total_texture_bytes,
        )?;
        within("max-total-triangles", self.max_total_triangles, 1, u64::MAX)?;
        within("max-uploads", self.max_uploads.into(), 1, 1024)?;
        within(
            "max-queued-renders",
            self.max_queued_renders.into(),
            1,
            4096,
        )?;
        for (flag, seconds) in [
            ("max-request-cost", self.max_request_cost),
            ("max-precompute-cost", self.max_precompute_cost),
        ] {
            if !(seconds.is_finite() && seconds > 0.0) {
                return Err(ConfigError::Invalid {
                    flag,
                    reason: format!("{seconds} is not a positive number of seconds"),
                });
            }
        }
        // Quotas only mean something when callers are told apart by their token.
        let quota = |flag: &'static str, given: Option<u32>, global: u32| {
            if tokens == 0 {
                return Ok(None);
            }
            let quota = given.unwrap_or_else(|| fair_share(global, tokens));
            within(flag, quota.into(), 1, global.into())?;
            Ok::<_, ConfigError>(Some(quota))
        };
        // The default scene takes one of --max-scenes and belongs to no token.
        let uploadable_scenes = self.max_scenes.saturating_sub(1).max(1);
        Ok(Limits {
            token_max_sessions: quota(
                "token-max-sessions",
                self.token_max_sessions,
                self.max_sessions,
            )?,
            token_max_scenes: quota("token-max-scenes", self.token_max_scenes, uploadable_scenes)?,
            token_max_uploads: quota(
                "token-max-uploads",
                self.token_max_uploads,
                self.max_uploads,
            )?,
            token_max_renders: quota(
                "token-max-renders",
                self.token_max_renders,
                self.max_queued_renders,
            )?,
            max_texture_size: self.max_texture_size,
            max_scene_texture_bytes: self.max_scene_texture_bytes,
            max_total_texture_bytes: self.max_total_texture_bytes,
            max_total_triangles: self.max_total_triangles,
            max_uploads: self.max_uploads,
            max_queued_renders: self.max_queued_renders,
            max_request_seconds: self.max_request_cost,
            // Known once the adapter is: see [`FrameCost::resolve`].
            max_frame_seconds: 0.0,
            // Known once the adapter is: see [`AdapterSpeed::resolve`].
            adapter_speed: 1.0,
            max_precompute_seconds: self.max_precompute_cost,
            unwanted_precompute_secs: self.unwanted_precompute_secs,
            max_width: self.max_width,
            max_height: self.max_height,
            max_shadow_map_size: self.max_shadow_map_size,
            max_lights: self.max_lights,
            max_fps: self.max_fps,
            max_sessions: self.max_sessions,
            max_scenes: self.max_scenes,
            max_upload_bytes: self.max_upload_bytes,
            max_triangles: self.max_triangles,
            max_message_bytes: self.max_message_bytes,
            max_messages_per_second: self.max_messages_per_second,
            request_timeout_ms: self.request_timeout_ms,
            session_idle_secs: self.session_idle_secs,
            stream_silence_secs: self.stream_silence_secs,
            max_connections_per_address: self.max_connections_per_address,
            header_timeout_ms: self.header_timeout_ms,
            max_header_bytes: self.max_header_bytes,
            max_name_bytes: crate::service::http::MAX_NAME_BYTES,
            gi: self
                .gi_limits
                .0
                .iter()
                .map(|(name, &v)| (name.clone(), v.into()))
                .collect(),
        })
    }

    /// What the accept loop enforces.
    pub fn connections(&self) -> crate::service::listen::ConnectionLimits {
        crate::service::listen::ConnectionLimits {
            max_connections: self.max_connections as usize,
            max_per_address: self.max_connections_per_address as usize,
            header_timeout: std::time::Duration::from_millis(self.header_timeout_ms),
            max_header_bytes: self.max_header_bytes as usize,
        }
    }
}

impl ServeArgs {
    /// Session routing across replicas from `--replica` and `--routing-key-file` (both or
    /// neither).
    pub fn routing(&self) -> Result<Option<crate::service::routing::Routing>, ConfigError> {
        let (replica, path) = match (&self.replica, &self.routing_key_file) {
            (None, None) => return Ok(None),
            (Some(r), Some(p)) => (r, p),
            (Some(_), None) => {
                return Err(ConfigError::Invalid {
                    flag: "replica",
                    reason: "needs --routing-key-file, the key every replica shares".into(),
                })
            }
            (None, Some(_)) => {
                return Err(ConfigError::Invalid {
                    flag: "routing-key-file",
                    reason: "needs --replica, this replica's name".into(),
                })
            }
        };
        let mut key = std::fs::read(path).map_err(|error| ConfigError::RoutingKeyFile {
            path: path.clone(),
            error,
        })?;
        while key.last().is_some_and(|b| *b == b'\n' || *b == b'\r') {
            key.pop();
        }
        Ok(Some(crate::service::routing::Routing::new(replica, &key)?))
    }

    /// Tokens from `--token` and `--tokens-file`; empty means auth is off.
    pub fn tokens(&self) -> Result<Vec<String>, ConfigError> {
        let mut tokens: Vec<String> = self
            .tokens
            .iter()
            .map(|t| t.trim().to_string())
            .filter(|t| !t.is_empty())
            .collect();
        if let Some(path) = &self.tokens_file {
            let text = std::fs::read_to_string(path).map_err(|error| ConfigError::TokensFile {
                path: path.clone(),
                error,
            })?;
            tokens.extend(
                text.lines()
                    .map(str::trim)
                    .filter(|l| !l.is_empty() && !l.starts_with('#'))
                    .map(str::to_string),
            );
        }
        if let Some(short) = tokens.iter().find(|t| t.len() < 16) {
            return Err(ConfigError::Invalid {
                flag: "token",
                reason: format!(
                    "a token of {} characters is too easy to guess; use at least 16",
                    short.len()
                ),
            });
        }
        Ok(tokens)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use clap::Parser;

    #[derive(clap::Parser)]
    struct Args {
        #[command(flatten)]
        limits: super::LimitArgs,
    }

    /// The limits of a server started without options (auth off).
    pub(crate) fn default_limits() -> lightcast_protocol::Limits {
        Args::parse_from(["test"])
            .limits
            .limits(0)
            .expect("default limits are valid")
    }

    #[derive(clap::Parser)]
    struct Serve {
        #[command(flatten)]
        serve: super::ServeArgs,
    }

    /// `--replica` and `--routing-key-file` come together; the key file's trailing newline is
    /// not part of the key, and a short key is refused.
    #[test]
    fn routing_needs_a_name_and_a_long_enough_key_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let key = dir.path().join("key");
        let routing = |extra: &[&str]| {
            let mut argv = vec!["test"];
            argv.extend_from_slice(extra);
            Serve::parse_from(argv).serve.routing()
        };
        let path = key.to_string_lossy().into_owned();
        assert!(routing(&[]).expect("off").is_none());
        assert!(routing(&["--replica", "a"]).is_err());
        assert!(routing(&["--routing-key-file", &path]).is_err());
        assert!(matches!(
            routing(&["--replica", "a", "--routing-key-file", &path]),
            Err(super::ConfigError::RoutingKeyFile { .. })
        ));
        std::fs::write(&key, format!("{}\n", "k".repeat(31))).expect("write");
        assert!(matches!(
            routing(&["--replica", "a", "--routing-key-file", &path]),
            Err(super::ConfigError::Routing(_))
        ));
        std::fs::write(&key, format!("{}\n", "k".repeat(32))).expect("write");
        assert!(matches!(
            routing(&["--replica", "a", "--routing-key-file", &path]),
            Err(super::ConfigError::Routing(
                crate::service::routing::RoutingError::WeakKey(0)
            ))
        ));
        std::fs::write(&key, "0123456789abcdef0123456789abcdef\n").expect("write");
        let on = routing(&["--replica", "lightcast-0", "--routing-key-file", &path])
            .expect("valid")
            .expect("on");
        assert_eq!(on.replica(), "lightcast-0");
        assert!(matches!(
            routing(&["--replica", "Not_A_Label", "--routing-key-file", &path]),
            Err(super::ConfigError::Routing(_))
        ));
    }

    #[test]
    fn token_quotas_default_to_a_fair_share_only_with_auth() {
        let args = Args::parse_from(["test", "--max-sessions", "10", "--max-scenes", "7"]).limits;
        let off = args.limits(0).expect("valid");
        assert_eq!(off.token_max_sessions, None);
        let one = args.limits(1).expect("valid");
        assert_eq!(one.token_max_sessions, Some(10));
        let three = args.limits(3).expect("valid");
        assert_eq!(three.token_max_sessions, Some(4));
        assert_eq!(three.token_max_scenes, Some(2), "6 uploadable slots / 3");
        assert_eq!(
            three.token_max_uploads,
            Some(2),
            "4 uploads / 3, rounded up"
        );
        let given = Args::parse_from(["test", "--token-max-renders", "3"]).limits;
        assert_eq!(given.limits(5).expect("valid").token_max_renders, Some(3));
        let too_many = Args::parse_from(["test", "--token-max-sessions", "65"]).limits;
        let e = too_many.limits(2).expect_err("beyond the global limit");
        assert!(e.to_string().contains("--token-max-sessions"), "{e}");
    }

    /// Every protocol method has exactly one implementation and one description, whose
    /// maxima are the server's.
    #[test]
    fn every_gi_method_is_registered_once_and_described() {
        use lightcast_protocol::GiMethod;
        let limits = Args::parse_from(["test", "--max-spp", "64"])
            .limits
            .limits(0)
            .expect("default limits are valid");
        let all: Vec<GiMethod> = crate::gi::methods().collect();
        for &m in &all {
            let serving = crate::gi::REGISTRY.iter().filter(|e| e.serves(m)).count();
            assert_eq!(serving, 1, "{m:?}");
        }
        let described = crate::gi::describe_all(&limits);
        let names: Vec<GiMethod> = described.iter().map(|d| d.method).collect();
        assert_eq!(names, all);
        let spp = described
            .iter()
            .flat_map(|d| &d.parameters)
            .find(|p| p.name == "spp")
            .expect("the reference describes spp");
        assert_eq!(spp.max, Some(64.0));
    }
}
