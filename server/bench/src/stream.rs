//! `lightcast-server bench-stream`: JPEG against H.264 on one camera path (issue 13).
//!
//! Every frame of the path is rendered twice at each size, once per way the service reads a
//! frame back: as RGBA8 (4 B/px: what JPEG encodes, and the lossless frame every codec is
//! measured against) and as the Y'CbCr 4:2:0 planes the GPU converts it to (1.5 B/px: what
//! H.264 encodes). Each JPEG quality encodes every frame on its own; each H.264 bitrate feeds
//! one stateful encoder the frames in order, as a session does, and an independent decoder
//! (OpenH264's) decodes its access units. Every decoded frame is compared with the lossless
//! one: PSNR over RGB, and the mean FLIP error (what a viewer notices). Only the encode call is
//! timed. Input→frame latency needs the whole service: `bench/stream-codecs.sh` measures it
//! with `lightcast stream` on the camera path `--write-path` writes.

use crate::bench::{stats, StageStats};
use crate::debug_views::Image;
use crate::gi::GiMethod;
use crate::gpu::timing::Stage;
use crate::gpu::{context::AdapterSummary, timing::TimingSource, BackendChoice, GpuContext};
use crate::offline::{ExposureArg, GiArgs, DEFAULT_SCENE};
use crate::passes::exposure::Exposure;
use crate::passes::yuv420::{Yuv420, Yuv420Layout};
use crate::quality::{flip_mean, psnr};
use crate::renderer::{Frame, RenderSettings, Renderer};
use crate::scene::{
    default_light::{default_camera, default_light},
    Scene,
};
use crate::service::encode::{self, EncodeError};
use crate::service::video::{EncoderKind, VideoConfig, VideoEncoder, VideoError};
use lightcast_protocol::{Camera, Codec, Encoding};
use openh264::decoder::Decoder;
use openh264::formats::YUVSource;
use rayon::prelude::*;
use std::io::Write;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Instant;

/// Issue 13's targets, at [`TARGET_SIZE`] while moving: H.264 sends at most this fraction of
/// JPEG's bytes at equal or better PSNR...
pub const TARGET_BYTES_RATIO: f64 = 0.2;
/// ...and encodes a frame within this many milliseconds at the 95th percentile.
pub const TARGET_ENCODE_P95_MS: f64 = 12.0;
pub const TARGET_SIZE: FrameSize = FrameSize {
    width: 1920,
    height: 1080,
};

/// Options of `lightcast-server bench-stream`.
#[derive(Clone, Debug, clap::Args)]
pub struct StreamBenchArgs {
    /// Scene: a .gltf/.glb file or a procedural scene (see `render --help`). Default: the
    /// built-in Cornell box, the service's default scene.
    #[arg(long)]
    pub scene: Option<String>,
    /// Frame sizes, WIDTHxHEIGHT, comma-separated (even sides: H.264 carries 4:2:0).
    #[arg(long, value_delimiter = ',', default_values = ["1280x720", "1920x1080"])]
    pub sizes: Vec<FrameSize>,
    /// Frames of the camera path at each size.
    #[arg(long, default_value_t = 60)]
    pub frames: u32,
    /// Nominal frame rate: frame i shows the path at i/fps seconds, H.264's rate control
    /// spreads its bitrate over this many frames a second, and bytes per second are the mean
    /// bytes per frame times this.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f32,
    /// How the camera moves from the scene's default camera: `orbit` (around its target,
    /// as `lightcast loadtest` moves it) or `dolly` (towards its target, the target moving on
    /// ahead: a walk or drive through the scene).
    #[arg(long, value_enum, default_value = "orbit")]
    pub motion: Motion,
    /// `orbit`: degrees per second.
    #[arg(long, default_value_t = 30.0)]
    pub orbit_degrees_per_second: f32,
    /// `dolly`: the share of the default camera's distance to its target covered per second.
    #[arg(long, default_value_t = 0.1)]
    pub dolly_per_second: f32,
    /// Indirect light (default `none`: direct light only, which a software adapter renders
    /// at 1080p in seconds; the codecs see the frames whatever lit them).
    #[arg(long, default_value = "none", value_parser = crate::gi::parse_method)]
    pub gi: GiMethod,
    /// Side of the shadow map per light face.
    #[arg(long, default_value_t = 2048)]
    pub shadow_map_size: u32,
    /// `auto` (the service's default) or a linear scale before tone mapping.
    #[arg(long, default_value = "auto", allow_negative_numbers = true)]
    pub exposure: ExposureArg,
    /// JPEG qualities, comma-separated (the service streams 70 while moving, 90 at rest).
    #[arg(long, value_delimiter = ',', default_values_t = [70, 90],
          value_parser = clap::value_parser!(u8).range(1..=100))]
    pub jpeg_qualities: Vec<u8>,
    /// H.264 bitrates, comma-separated: kbit/s in the range a session's
    /// `encoding.bitrate_kbps` accepts, or `auto`, the service's default (chosen from each
    /// frame size at `--fps`).
    #[arg(long, value_delimiter = ',', default_values_t = [H264Rate::Auto, H264Rate::Kbps(8000)])]
    pub h264_kbps: Vec<H264Rate>,
    /// Measure FLIP on every Nth frame only (FLIP is the slowest measurement here; PSNR is
    /// measured on every frame).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub flip_every: u32,
    /// Also write the camera path here, as `lightcast stream --camera-path` reads it, so the
    /// service can be driven along the same path.
    #[arg(long)]
    pub write_path: Option<PathBuf>,
    /// Seconds of the path `--write-path` writes (a client streaming longer sees the camera
    /// stop at its end).
    #[arg(long, default_value_t = 12.0)]
    pub path_seconds: f32,
    /// Also write each size's frames, as H.264 encodes them, to `PREFIX-WIDTHxHEIGHT.yuv`:
    /// raw planar Y'CbCr 4:2:0 (I420, BT.709 limited range), frame after frame, so another
    /// encoder can be measured on the same frames (`ffmpeg -f rawvideo -pix_fmt yuv420p -s
    /// WIDTHxHEIGHT -i FILE …`). 3 MB per 1080p frame.
    #[arg(long, value_name = "PREFIX")]
    pub write_yuv: Option<PathBuf>,
    /// Write the results as JSON here (with every frame's bytes, encode time and errors).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the results as markdown here.
    #[arg(long)]
    pub markdown: Option<PathBuf>,
    #[command(flatten)]
    pub caches: GiArgs,
    #[arg(long, value_enum, env = "LIGHTCAST_BACKEND", default_value = "auto")]
    pub backend: BackendChoice,
}

/// A frame size, `WIDTHxHEIGHT` on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct FrameSize {
    pub width: u32,
    pub height: u32,
}

impl FromStr for FrameSize {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || format!("expected WIDTHxHEIGHT (e.g. 1920x1080), got '{s}'");
        let (w, h) = s.split_once(['x', '×']).ok_or_else(bad)?;
        match (w.trim().parse::<u32>(), h.trim().parse::<u32>()) {
            (Ok(width), Ok(height)) if width > 0 && height > 0 => Ok(Self { width, height }),
            _ => Err(bad()),
        }
    }
}

impl std::fmt::Display for FrameSize {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}×{}", self.width, self.height)
    }
}

/// An H.264 bitrate of `--h264-kbps`: kbit/s, or the service's automatic one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum H264Rate {
    /// `encoding.bitrate_kbps: null`: [`lightcast_protocol::AUTO_BITS_PER_PIXEL`] of each
    /// size's pixel rate.
    Auto,
    Kbps(u32),
}

impl H264Rate {
    /// The kbit/s a session streaming `width`×`height` at `fps` would get.
    fn kbps(self, width: u32, height: u32, fps: f32) -> u32 {
        let bitrate_kbps = match self {
            Self::Auto => None,
            Self::Kbps(kbps) => Some(kbps),
        };
        Encoding {
            bitrate_kbps,
            ..Encoding::default()
        }
        .bitrate_kbps_for(width, height, fps)
    }
}

impl std::str::FromStr for H264Rate {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(Self::Auto);
        }
        let range = lightcast_protocol::MIN_BITRATE_KBPS..=lightcast_protocol::MAX_BITRATE_KBPS;
        match s.parse::<u32>() {
            Ok(kbps) if range.contains(&kbps) => Ok(Self::Kbps(kbps)),
            _ => Err(format!(
                "`{s}` is neither `auto` nor kbit/s in {}..={}",
                range.start(),
                range.end()
            )),
        }
    }
}

impl std::fmt::Display for H264Rate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Auto => f.write_str("auto"),
            Self::Kbps(kbps) => write!(f, "{kbps}"),
        }
    }
}

/// One codec setting under test.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "codec", rename_all = "snake_case")]
pub enum CodecSetting {
    Jpeg {
        quality: u8,
    },
    /// `auto`: the service's automatic bitrate at this size, `bitrate_kbps` what it came to.
    H264 {
        bitrate_kbps: u32,
        auto: bool,
    },
}

impl std::fmt::Display for CodecSetting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Jpeg { quality } => write!(f, "JPEG q{quality}"),
            Self::H264 {
                bitrate_kbps,
                auto: false,
            } => write!(f, "H.264 {bitrate_kbps} kbit/s"),
            Self::H264 {
                bitrate_kbps,
                auto: true,
            } => write!(f, "H.264 auto ({bitrate_kbps} kbit/s)"),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum StreamBenchError {
    #[error("scene '{scene}': {error}")]
    Scene {
        scene: String,
        error: crate::scene::OpenError,
    },
    #[error(transparent)]
    Precompute(#[from] crate::offline::PrecomputeError),
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
    #[error(transparent)]
    Render(#[from] crate::renderer::RenderError),
    #[error(transparent)]
    Video(#[from] VideoError),
    #[error(transparent)]
    Encode(#[from] EncodeError),
    #[error("decoding {setting} frame {frame}: {message}")]
    Decode {
        setting: CodecSetting,
        frame: usize,
        message: String,
    },
    #[error("{what} list is empty")]
    EmptyList { what: &'static str },
    #[error("--frames must be at least 1")]
    NoFrames,
    #[error("--fps must be a positive number, got {0}")]
    Fps(f32),
    #[error("{flag} must be a number ≥ 0, got {value}")]
    Speed { flag: &'static str, value: f32 },
    #[error("--path-seconds must be a positive number, got {0}")]
    PathSeconds(f32),
    #[error("writing the camera path to {path}: {error}")]
    WritePath {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("writing the frames to {path}: {error}")]
    WriteYuv {
        path: PathBuf,
        error: std::io::Error,
    },
}

/// One frame as one codec delivered it.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct FrameSample {
    pub bytes: usize,
    pub encode_ms: f64,
    /// CPU time of the whole process over the encode call: every encoder thread's.
    pub encode_cpu_ms: f64,
    /// PSNR of the decoded frame against the lossless one, over RGB.
    pub psnr_db: f64,
    /// Mean FLIP error of the same, on the frames FLIP was measured on.
    pub flip: Option<f64>,
    pub keyframe: bool,
}

/// What one codec setting did with one size's frames.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CodecRow {
    pub setting: CodecSetting,
    pub bytes_per_frame: f64,
    /// The first frame (H.264's keyframe).
    pub first_frame_bytes: usize,
    pub max_frame_bytes: usize,
    /// Mean bytes per frame times the nominal fps.
    pub bytes_per_second: f64,
    /// The encode call alone.
    pub encode: StageStats,
    /// Mean CPU time per encode call, all encoder threads together: what a frame costs a
    /// machine of this CPU class whatever its core count (each frame's is in `frames`).
    pub encode_cpu_mean_ms: f64,
    pub psnr_mean_db: f64,
    pub psnr_min_db: f64,
    /// Mean FLIP error over the frames it was measured on.
    pub flip_mean: f64,
    pub keyframes: usize,
    pub frames: Vec<FrameSample>,
}

/// How one of the two read-backs of a frame cost.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Readback {
    pub bytes_per_frame: usize,
    /// GPU time of the copy into the staging buffer (the `readback_copy` stage).
    pub copy_gpu: StageStats,
    /// GPU time of the whole frame, every stage.
    pub frame_gpu: StageStats,
    /// CPU time from submitting the frame until its read-back was mapped (the frame's GPU
    /// work included: the bench waits for each frame before the next).
    pub wait: StageStats,
}

/// Which JPEG an H.264 setting is compared with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Basis {
    /// The quality the service streams while the view moves (`encoding.moving_quality`).
    MovingQuality,
    /// The JPEG with the highest mean PSNR that is still at or below H.264's: JPEG at equal
    /// PSNR would need at least its bytes, so the ratio is an upper bound on the ratio at
    /// equal PSNR.
    ClosestPsnrAtOrBelow,
}

impl Basis {
    fn describe(self) -> &'static str {
        match self {
            Self::MovingQuality => "the service's moving quality",
            Self::ClosestPsnrAtOrBelow => "closest PSNR at or below H.264's",
        }
    }
}

/// One H.264 setting against one JPEG quality at one size.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Comparison {
    pub h264_kbps: u32,
    /// The service's automatic bitrate.
    pub h264_auto: bool,
    pub jpeg_quality: u8,
    /// Why this JPEG (one or both).
    pub bases: Vec<Basis>,
    /// H.264's mean bytes per frame over JPEG's.
    pub bytes_ratio: f64,
    /// H.264's mean PSNR minus JPEG's.
    pub psnr_delta_db: f64,
    /// At most [`TARGET_BYTES_RATIO`] of JPEG's bytes at equal or better PSNR.
    pub meets_bytes_target: bool,
}

/// Everything measured at one frame size.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SizeReport {
    pub width: u32,
    pub height: u32,
    /// The RGBA8 read-back JPEG encodes.
    pub rgba8: Readback,
    /// The 4:2:0 read-back H.264 encodes.
    pub yuv420: Readback,
    /// GPU time of the conversion to 4:2:0 (the `yuv420` stage).
    pub conversion_gpu: StageStats,
    /// Mean PSNR of the GPU's 4:2:0 planes converted back to RGB, no codec in between: the
    /// best any 4:2:0 codec can reach on these frames.
    pub yuv420_psnr_db: f64,
    /// Threads (and slices) each H.264 stream of this size used, as the service's would here.
    pub h264_threads: u16,
    pub rows: Vec<CodecRow>,
    pub comparisons: Vec<Comparison>,
}

/// Issue 13's targets for one H.264 bitrate at [`TARGET_SIZE`], against JPEG at the moving
/// quality.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TargetCheck {
    pub h264_kbps: u32,
    /// The service's default bitrate.
    pub default_bitrate: bool,
    pub bytes_ratio: f64,
    pub psnr_delta_db: f64,
    pub bytes_met: bool,
    pub encode_p95_ms: f64,
    pub encode_met: bool,
    /// Mean CPU time per frame, all encoder threads.
    pub encode_cpu_mean_ms: f64,
    /// Cores of this CPU class one stream at the nominal fps keeps busy encoding.
    pub cores_per_stream: f64,
}

/// Issue 13's targets at [`TARGET_SIZE`]: every H.264 bitrate of the run against JPEG at
/// `jpeg_quality`, the moving quality.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Targets {
    pub jpeg_quality: u8,
    pub checks: Vec<TargetCheck>,
}

/// The whole run.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StreamBenchReport {
    pub adapter: String,
    pub timing_source: TimingSource,
    pub scene: String,
    pub triangles: usize,
    pub gi: GiMethod,
    pub shadow_map_size: u32,
    /// `auto` or the linear scale.
    pub exposure: String,
    pub frames: u32,
    pub fps: f32,
    pub motion: CameraMotion,
    pub flip_every: u32,
    /// The H.264 settings besides the bitrate (the service's defaults).
    pub max_qp: u8,
    pub keyframe_interval: u32,
    /// CPU threads of this machine (the encoders use one each).
    pub cpu_threads: usize,
    pub sizes: Vec<SizeReport>,
    /// `None` when the run left out [`TARGET_SIZE`], the default bitrate or the moving quality.
    pub targets: Option<Targets>,
}

/// How the camera moves along the path (`--motion`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Motion {
    Orbit,
    Dolly,
}

/// The camera path: `base` (the scene's default camera) moved by `motion`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CameraMotion {
    pub motion: Motion,
    /// Degrees per second (`orbit`) or the share of the distance to the target per second
    /// (`dolly`).
    pub speed: f32,
    pub base: Camera,
}

impl CameraMotion {
    /// The camera `seconds` into the path.
    pub fn at(&self, seconds: f64) -> Camera {
        let amount = seconds * f64::from(self.speed);
        let base = &self.base;
        match self.motion {
            // As `lightcast`'s orbit: about the vertical axis through the target.
            Motion::Orbit => {
                let (s, c) = (amount.to_radians() as f32).sin_cos();
                let [px, py, pz] = base.position;
                let [tx, _, tz] = base.target;
                let (dx, dz) = (px - tx, pz - tz);
                Camera {
                    position: [tx + dx * c - dz * s, py, tz + dx * s + dz * c],
                    ..base.clone()
                }
            }
            Motion::Dolly => {
                let step = |p: [f32; 3]| {
                    [0, 1, 2].map(|k| p[k] + (base.target[k] - base.position[k]) * amount as f32)
                };
                Camera {
                    position: step(base.position),
                    target: step(base.target),
                    ..base.clone()
                }
            }
        }
    }

    /// The first `seconds` of the path as `lightcast stream --camera-path` reads it, a keyframe
    /// every 1/`fps` second (the client interpolates linearly between them).
    pub fn to_json(&self, seconds: f32, fps: f32) -> serde_json::Value {
        let count = (f64::from(seconds) * f64::from(fps)).ceil() as u32;
        let keyframes: Vec<serde_json::Value> = (0..=count)
            .map(|i| {
                let t = f64::from(i) / f64::from(fps);
                serde_json::json!({ "t": t, "camera": self.at(t) })
            })
            .collect();
        serde_json::json!({ "keyframes": keyframes })
    }
}

impl std::fmt::Display for CameraMotion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.motion {
            Motion::Orbit => write!(f, "orbits its target at {}°/s", self.speed),
            Motion::Dolly => write!(
                f,
                "dollies towards its target at {} % of the distance per second",
                self.speed * 100.0
            ),
        }
    }
}

/// A codec's encoder (and decoder) for the frames of one size.
enum CodecState {
    Jpeg {
        quality: u8,
    },
    H264 {
        encoder: Box<dyn VideoEncoder>,
        decoder: Decoder,
    },
}

/// What one codec made of one frame, before it is measured.
struct Delivered {
    bytes: usize,
    encode_ms: f64,
    encode_cpu_ms: f64,
    keyframe: bool,
    /// The frame as the viewer's decoder shows it.
    rgb: Vec<[u8; 3]>,
}

/// Runs `encode`, timing it by the wall clock and by the process's CPU clock (every thread the
/// encoder runs on; the bench runs nothing else meanwhile), both in ms.
fn timed<T>(encode: impl FnOnce() -> T) -> (T, f64, f64) {
    let cpu = || {
        let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
        t.tv_sec as f64 * 1e3 + t.tv_nsec as f64 * 1e-6
    };
    let (wall, cpu_start) = (Instant::now(), cpu());
    let out = encode();
    let cpu_ms = cpu() - cpu_start;
    (out, wall.elapsed().as_secs_f64() * 1e3, cpu_ms)
}

fn rgb_of(rgba8: &[u8]) -> Vec<[u8; 3]> {
    rgba8.chunks_exact(4).map(|p| [p[0], p[1], p[2]]).collect()
}

/// The decoder's planes in our layout, so [`Yuv420::to_rgba8`] (BT.709, limited range, as the
/// stream's VUI says) converts them as it converts the encoder's input.
fn planes_of(picture: &impl YUVSource, layout: Yuv420Layout) -> Result<Yuv420, String> {
    let (w, h) = picture.dimensions();
    if (w, h) != (layout.width as usize, layout.height as usize) {
        return Err(format!(
            "the decoder made a {w}×{h} picture of a {}×{} stream",
            layout.width, layout.height
        ));
    }
    let (luma_stride, u_stride, v_stride) = picture.strides();
    let mut data = vec![0u8; layout.bytes()];
    let (cols, rows) = (w.div_ceil(2), layout.chroma_rows() as usize);
    let (luma, chroma) = (layout.luma_stride as usize, layout.chroma_stride as usize);
    copy_rows(&mut data, picture.y(), (luma_stride, luma), (w, h));
    let (cb, cr) = data[layout.cb_offset()..].split_at_mut(layout.cr_offset() - layout.cb_offset());
    copy_rows(cb, picture.u(), (u_stride, chroma), (cols, rows));
    copy_rows(cr, picture.v(), (v_stride, chroma), (cols, rows));
    Ok(Yuv420 { layout, data })
}

/// Copies `cols`×`rows` bytes from `from` (rows `strides.0` apart) to `to` (rows `strides.1`
/// apart).
fn copy_rows(to: &mut [u8], from: &[u8], strides: (usize, usize), (cols, rows): (usize, usize)) {
    for row in 0..rows {
        to[row * strides.1..][..cols].copy_from_slice(&from[row * strides.0..][..cols]);
    }
}

/// The codecs under test at one frame size, fed that size's frames in order.
pub(crate) struct Codecs {
    /// Frame width (FLIP needs it).
    width: u32,
    states: Vec<(CodecSetting, CodecState)>,
    samples: Vec<Vec<FrameSample>>,
}

impl Codecs {
    /// Encoders for `settings` at `width`×`height`; H.264's rate control assumes `fps`.
    pub fn new(
        settings: &[CodecSetting],
        width: u32,
        height: u32,
        fps: f32,
    ) -> Result<Self, StreamBenchError> {
        let states = settings
            .iter()
            .map(|&setting| {
                let state = match setting {
                    CodecSetting::Jpeg { quality } => CodecState::Jpeg { quality },
                    CodecSetting::H264 { bitrate_kbps, .. } => {
                        let encoding = Encoding {
                            codec: Codec::H264,
                            bitrate_kbps: Some(bitrate_kbps),
                            ..Encoding::default()
                        };
                        let config = VideoConfig::new(width, height, &encoding, fps);
                        // Made here, not in the first timed encode call.
                        let encoder = EncoderKind::OpenH264.create(&config)?;
                        let decoder = Decoder::new().map_err(|e| StreamBenchError::Decode {
                            setting,
                            frame: 0,
                            message: e.to_string(),
                        })?;
                        CodecState::H264 { encoder, decoder }
                    }
                };
                Ok((setting, state))
            })
            .collect::<Result<Vec<_>, StreamBenchError>>()?;
        Ok(Self {
            width,
            samples: vec![Vec::new(); states.len()],
            states,
        })
    }

    /// Encodes the next frame with every codec (`image` for JPEG, `planes` for H.264),
    /// decodes it and measures it against `image`; FLIP too when `flip`.
    pub fn add_frame(
        &mut self,
        image: &Image,
        planes: &Yuv420,
        flip: bool,
    ) -> Result<(), StreamBenchError> {
        let frame = self.samples.first().map_or(0, Vec::len);
        let layout = planes.layout;
        // Encodes one after another, so each encode call has the CPU to itself while timed.
        let mut delivered = Vec::with_capacity(self.states.len());
        for (setting, state) in &mut self.states {
            let decode_error = |message: String| StreamBenchError::Decode {
                setting: *setting,
                frame,
                message,
            };
            delivered.push(match state {
                CodecState::Jpeg { quality } => {
                    let (bytes, encode_ms, encode_cpu_ms) =
                        timed(|| encode::encode(image, Codec::Jpeg, *quality));
                    let bytes = bytes?;
                    let decoded =
                        ::image::load_from_memory_with_format(&bytes, ::image::ImageFormat::Jpeg)
                            .map_err(|e| decode_error(e.to_string()))?;
                    Delivered {
                        bytes: bytes.len(),
                        encode_ms,
                        encode_cpu_ms,
                        keyframe: true,
                        rgb: decoded.to_rgb8().pixels().map(|p| p.0).collect(),
                    }
                }
                CodecState::H264 { encoder, decoder } => {
                    let (unit, encode_ms, encode_cpu_ms) = timed(|| encoder.encode(planes, false));
                    let unit = unit?;
                    let picture = decoder
                        .decode(&unit.data)
                        .map_err(|e| decode_error(e.to_string()))?
                        .ok_or_else(|| decode_error("no picture for an access unit".into()))?;
                    let decoded = planes_of(&picture, layout).map_err(decode_error)?;
                    Delivered {
                        bytes: unit.data.len(),
                        encode_ms,
                        encode_cpu_ms,
                        keyframe: unit.keyframe,
                        rgb: rgb_of(&decoded.to_rgba8()),
                    }
                }
            });
        }
        let reference = rgb_of(&image.rgba8);
        let width = self.width;
        // The measurements are independent of each other: FLIP dominates, so spread them.
        let errors: Vec<(f64, Option<f64>)> = delivered
            .par_iter()
            .map(|d| {
                (
                    psnr(&reference, &d.rgb),
                    flip.then(|| flip_mean(&reference, &d.rgb, width)),
                )
            })
            .collect();
        for ((samples, d), (psnr_db, flip)) in self.samples.iter_mut().zip(&delivered).zip(errors) {
            samples.push(FrameSample {
                bytes: d.bytes,
                encode_ms: d.encode_ms,
                encode_cpu_ms: d.encode_cpu_ms,
                psnr_db,
                flip,
                keyframe: d.keyframe,
            });
        }
        Ok(())
    }

    /// One row per codec setting; bytes per second at `fps` frames a second.
    pub fn rows(self, fps: f32) -> Vec<CodecRow> {
        self.states
            .into_iter()
            .zip(self.samples)
            .map(|((setting, _), frames)| {
                let n = frames.len().max(1) as f64;
                let bytes_per_frame = frames.iter().map(|f| f.bytes as f64).sum::<f64>() / n;
                let flips: Vec<f64> = frames.iter().filter_map(|f| f.flip).collect();
                CodecRow {
                    setting,
                    bytes_per_frame,
                    first_frame_bytes: frames.first().map_or(0, |f| f.bytes),
                    max_frame_bytes: frames.iter().map(|f| f.bytes).max().unwrap_or(0),
                    bytes_per_second: bytes_per_frame * f64::from(fps),
                    encode: stats(frames.iter().map(|f| f.encode_ms).collect()),
                    encode_cpu_mean_ms: frames.iter().map(|f| f.encode_cpu_ms).sum::<f64>() / n,
                    psnr_mean_db: frames.iter().map(|f| f.psnr_db).sum::<f64>() / n,
                    psnr_min_db: frames
                        .iter()
                        .map(|f| f.psnr_db)
                        .fold(f64::INFINITY, f64::min),
                    flip_mean: flips.iter().sum::<f64>() / flips.len().max(1) as f64,
                    keyframes: frames.iter().filter(|f| f.keyframe).count(),
                    frames,
                }
            })
            .collect()
    }
}

/// Every H.264 row against JPEG at `moving_quality` (when it ran) and against the JPEG whose
/// mean PSNR is the highest at or below its own (when there is one).
pub fn compare(rows: &[CodecRow], moving_quality: u8) -> Vec<Comparison> {
    let jpegs: Vec<(u8, &CodecRow)> = rows
        .iter()
        .filter_map(|r| match r.setting {
            CodecSetting::Jpeg { quality } => Some((quality, r)),
            CodecSetting::H264 { .. } => None,
        })
        .collect();
    let mut out: Vec<Comparison> = Vec::new();
    for h in rows {
        let CodecSetting::H264 { bitrate_kbps, auto } = h.setting else {
            continue;
        };
        let moving = jpegs.iter().find(|(q, _)| *q == moving_quality);
        let closest = jpegs
            .iter()
            .filter(|(_, j)| j.psnr_mean_db <= h.psnr_mean_db)
            .max_by(|a, b| a.1.psnr_mean_db.total_cmp(&b.1.psnr_mean_db));
        let picks = [
            (moving, Basis::MovingQuality),
            (closest, Basis::ClosestPsnrAtOrBelow),
        ];
        let first = out.len();
        for (pick, basis) in picks {
            let Some(&(quality, jpeg)) = pick else {
                continue;
            };
            // One row per JPEG, naming every reason it was picked.
            if let Some(c) = out[first..].iter_mut().find(|c| c.jpeg_quality == quality) {
                c.bases.push(basis);
                continue;
            }
            let psnr_delta_db = h.psnr_mean_db - jpeg.psnr_mean_db;
            let bytes_ratio = h.bytes_per_frame / jpeg.bytes_per_frame.max(1.0);
            out.push(Comparison {
                h264_kbps: bitrate_kbps,
                h264_auto: auto,
                jpeg_quality: quality,
                bases: vec![basis],
                bytes_ratio,
                psnr_delta_db,
                meets_bytes_target: bytes_ratio <= TARGET_BYTES_RATIO && psnr_delta_db >= 0.0,
            });
        }
    }
    out
}

fn stage_ms(frame: &Frame, stage: Stage) -> f64 {
    frame
        .timings
        .iter()
        .filter(|t| t.stage == stage)
        .map(|t| t.ms)
        .sum()
}

/// Per-frame times of one read-back path.
#[derive(Default)]
struct ReadbackTimes {
    bytes: usize,
    copy: Vec<f64>,
    frame: Vec<f64>,
    wait: Vec<f64>,
}

impl ReadbackTimes {
    fn add(&mut self, frame: &Frame, bytes: usize) {
        self.bytes = bytes;
        self.copy
            .push(stage_ms(frame, crate::passes::stages::READBACK_COPY));
        self.frame.push(frame.total_ms());
        self.wait.push(frame.readback_ms);
    }

    fn finish(self) -> Readback {
        Readback {
            bytes_per_frame: self.bytes,
            copy_gpu: stats(self.copy),
            frame_gpu: stats(self.frame),
            wait: stats(self.wait),
        }
    }
}

/// Renders the path at `size` and runs every codec over it.
#[allow(clippy::too_many_arguments)]
fn measure_size(
    renderer: &mut Renderer,
    base: &RenderSettings,
    motion: &CameraMotion,
    size: FrameSize,
    settings: &[CodecSetting],
    args: &StreamBenchArgs,
    moving_quality: u8,
    done: &mut u64,
    total: u64,
    progress: &mut dyn FnMut(u64, u64, &str),
) -> Result<SizeReport, StreamBenchError> {
    let mut codecs = Codecs::new(settings, size.width, size.height, args.fps)?;
    let (mut rgba8, mut yuv420) = (ReadbackTimes::default(), ReadbackTimes::default());
    let (mut conversion, mut yuv420_psnr) = (Vec::new(), Vec::new());
    let label = format!("{size}: frames");
    let mut yuv_file = args
        .write_yuv
        .as_ref()
        .map(|prefix| {
            let mut name = prefix.as_os_str().to_owned();
            name.push(format!("-{}x{}.yuv", size.width, size.height));
            let path = PathBuf::from(name);
            std::fs::File::create(&path)
                .map(|file| (std::io::BufWriter::new(file), path.clone()))
                .map_err(|error| StreamBenchError::WriteYuv { path, error })
        })
        .transpose()?;
    for i in 0..args.frames {
        let seconds = f64::from(i) / f64::from(args.fps);
        let lossless = RenderSettings {
            width: size.width,
            height: size.height,
            camera: motion.at(seconds),
            ..base.clone()
        };
        let frame = renderer.render(&lossless)?;
        let video = renderer.render(&RenderSettings {
            yuv420: true,
            ..lossless
        })?;
        rgba8.add(&frame, frame.rgba8.len());
        let planes = video
            .yuv420
            .as_ref()
            .expect("a frame rendered with yuv420 carries its planes");
        yuv420.add(&video, planes.data.len());
        if let Some((file, path)) = &mut yuv_file {
            write_i420(file, planes).map_err(|error| StreamBenchError::WriteYuv {
                path: path.clone(),
                error,
            })?;
        }
        conversion.push(stage_ms(&video, crate::passes::stages::YUV420));
        let image = Image {
            width: frame.width,
            height: frame.height,
            rgba8: frame.rgba8,
        };
        yuv420_psnr.push(psnr(&rgb_of(&image.rgba8), &rgb_of(&planes.to_rgba8())));
        codecs.add_frame(&image, planes, i % args.flip_every == 0)?;
        *done += 1;
        progress(*done, total, &label);
    }
    if let Some((mut file, path)) = yuv_file {
        file.flush()
            .map_err(|error| StreamBenchError::WriteYuv { path, error })?;
    }
    let rows = codecs.rows(args.fps);
    Ok(SizeReport {
        width: size.width,
        height: size.height,
        rgba8: rgba8.finish(),
        yuv420: yuv420.finish(),
        conversion_gpu: stats(conversion),
        yuv420_psnr_db: yuv420_psnr.iter().sum::<f64>() / yuv420_psnr.len().max(1) as f64,
        h264_threads: crate::service::video::encoder_threads(size.width, size.height),
        comparisons: compare(&rows, moving_quality),
        rows,
    })
}

/// Writes `frame` as I420: each plane's visible samples row by row, without the layout's
/// padding (what `-pix_fmt yuv420p` reads).
fn write_i420(to: &mut impl std::io::Write, frame: &Yuv420) -> std::io::Result<()> {
    let l = frame.layout;
    let (chroma_width, chroma_rows) = (l.width.div_ceil(2) as usize, l.chroma_rows() as usize);
    for (plane, stride, width, rows) in [
        (
            frame.y(),
            l.luma_stride,
            l.width as usize,
            l.height as usize,
        ),
        (frame.cb(), l.chroma_stride, chroma_width, chroma_rows),
        (frame.cr(), l.chroma_stride, chroma_width, chroma_rows),
    ] {
        for row in plane.chunks(stride as usize).take(rows) {
            to.write_all(&row[..width])?;
        }
    }
    Ok(())
}

/// Issue 13's targets from `sizes`, when the run has [`TARGET_SIZE`] and JPEG at the moving
/// quality; streams run at `fps`.
fn targets(sizes: &[SizeReport], defaults: &Encoding, fps: f32) -> Option<Targets> {
    let size = sizes
        .iter()
        .find(|s| (s.width, s.height) == (TARGET_SIZE.width, TARGET_SIZE.height))?;
    let checks: Vec<TargetCheck> = size
        .comparisons
        .iter()
        .filter(|c| c.bases.contains(&Basis::MovingQuality))
        .filter_map(|c| {
            let setting = CodecSetting::H264 {
                bitrate_kbps: c.h264_kbps,
                auto: c.h264_auto,
            };
            let row = size.rows.iter().find(|r| r.setting == setting)?;
            Some(TargetCheck {
                h264_kbps: c.h264_kbps,
                default_bitrate: match defaults.bitrate_kbps {
                    None => c.h264_auto,
                    Some(kbps) => !c.h264_auto && c.h264_kbps == kbps,
                },
                bytes_ratio: c.bytes_ratio,
                psnr_delta_db: c.psnr_delta_db,
                bytes_met: c.meets_bytes_target,
                encode_p95_ms: row.encode.p95_ms,
                encode_met: row.encode.p95_ms <= TARGET_ENCODE_P95_MS,
                encode_cpu_mean_ms: row.encode_cpu_mean_ms,
                cores_per_stream: row.encode_cpu_mean_ms * f64::from(fps) / 1e3,
            })
        })
        .collect();
    (!checks.is_empty()).then_some(Targets {
        jpeg_quality: defaults.moving_quality,
        checks,
    })
}

/// Runs the benchmark, reporting progress through `progress(done, total, label)`.
pub fn run(
    args: &StreamBenchArgs,
    log: &mut dyn FnMut(&str),
    progress: &mut dyn FnMut(u64, u64, &str),
) -> Result<StreamBenchReport, StreamBenchError> {
    if args.frames == 0 {
        return Err(StreamBenchError::NoFrames);
    }
    if !(args.fps.is_finite() && args.fps > 0.0) {
        return Err(StreamBenchError::Fps(args.fps));
    }
    let (flag, speed) = match args.motion {
        Motion::Orbit => ("--orbit-degrees-per-second", args.orbit_degrees_per_second),
        Motion::Dolly => ("--dolly-per-second", args.dolly_per_second),
    };
    if !(speed.is_finite() && speed >= 0.0) {
        return Err(StreamBenchError::Speed { flag, value: speed });
    }
    if !(args.path_seconds.is_finite() && args.path_seconds > 0.0) {
        return Err(StreamBenchError::PathSeconds(args.path_seconds));
    }
    for (what, empty) in [
        ("--sizes", args.sizes.is_empty()),
        ("--jpeg-qualities", args.jpeg_qualities.is_empty()),
        ("--h264-kbps", args.h264_kbps.is_empty()),
    ] {
        if empty {
            return Err(StreamBenchError::EmptyList { what });
        }
    }
    // Refused before minutes of rendering rather than at the first H.264 frame.
    for size in &args.sizes {
        VideoConfig::check_size(size.width, size.height)?;
    }
    let spec = args.scene.as_deref().unwrap_or(DEFAULT_SCENE);
    let scene = Scene::open(spec).map_err(|error| StreamBenchError::Scene {
        scene: spec.to_string(),
        error,
    })?;
    log(&format!(
        "scene {}: {} triangles",
        scene.name,
        scene.triangle_count()
    ));
    let ctx = GpuContext::new(args.backend)?;
    let adapter = AdapterSummary(&ctx.info).to_string();
    log(&format!("adapter: {adapter}"));
    let gi = args.caches.gi(args.gi);
    let data = args
        .caches
        .precompute(&gi, &scene, Some(&ctx), log)?
        .map(|b| b.data);
    let base = RenderSettings {
        width: TARGET_SIZE.width,
        height: TARGET_SIZE.height,
        camera: default_camera(&scene),
        light: default_light(&scene),
        exposure: args.exposure.0,
        shadow_map_size: args.shadow_map_size,
        capture_hdr: false,
        debug_view: lightcast_protocol::View::FINAL,
        gi,
        history: None,
        still: false,
        yuv420: false,
    };
    let motion = CameraMotion {
        motion: args.motion,
        speed,
        base: base.camera.clone(),
    };
    if let Some(path) = &args.write_path {
        let json = motion.to_json(args.path_seconds, args.fps);
        std::fs::write(path, json.to_string()).map_err(|error| StreamBenchError::WritePath {
            path: path.clone(),
            error,
        })?;
        log(&format!("camera path: {}", path.display()));
    }
    let (name, triangles) = (scene.name.clone(), scene.triangle_count());
    let mut renderer = Renderer::new(ctx, scene);
    if let Some(data) = &data {
        renderer.set_scene_data(args.gi, data)?;
    }
    let timing_source = renderer.timing_source();
    // An automatic bitrate comes to a different number at each size.
    let settings = |size: FrameSize| -> Vec<CodecSetting> {
        let jpegs = args
            .jpeg_qualities
            .iter()
            .map(|&quality| CodecSetting::Jpeg { quality });
        let h264 = args.h264_kbps.iter().map(|&rate| CodecSetting::H264 {
            bitrate_kbps: rate.kbps(size.width, size.height, args.fps),
            auto: rate == H264Rate::Auto,
        });
        jpegs.chain(h264).collect()
    };
    let defaults = Encoding::default();
    let total = args.sizes.len() as u64 * u64::from(args.frames);
    let mut done = 0;
    let mut sizes = Vec::new();
    for &size in &args.sizes {
        sizes.push(measure_size(
            &mut renderer,
            &base,
            &motion,
            size,
            &settings(size),
            args,
            defaults.moving_quality,
            &mut done,
            total,
            progress,
        )?);
    }
    Ok(StreamBenchReport {
        adapter,
        timing_source,
        scene: name,
        triangles,
        gi: args.gi,
        shadow_map_size: args.shadow_map_size,
        exposure: match args.exposure.0 {
            Exposure::Auto => "auto".to_string(),
            Exposure::Manual(scale) => scale.to_string(),
        },
        frames: args.frames,
        fps: args.fps,
        motion,
        flip_every: args.flip_every,
        max_qp: defaults.max_qp,
        keyframe_interval: defaults.keyframe_interval,
        cpu_threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        targets: targets(&sizes, &defaults, args.fps),
        sizes,
    })
}

fn met(ok: bool) -> &'static str {
    if ok {
        "met"
    } else {
        "**not met**"
    }
}

impl StreamBenchReport {
    /// Markdown: per size, one row per codec setting, the read-backs and the comparisons; then
    /// the targets.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "Scene `{}` ({} triangles), GI {}, shadow map {}², exposure {}; the camera {}, {} frames at {} fps nominal ({:.1} s of the path). Adapter {}, {:?}; {} CPU threads. Every decoded frame is compared with the lossless RGBA8 frame: PSNR over RGB (mean and minimum over the frames), mean FLIP error ({}). JPEG: `jpeg-encoder` (4:2:0 below quality 90, 4:4:4 from 90), one frame at a time. H.264: OpenH264, constrained baseline, low complexity without pre-analysis, threads × slices per frame ({}), max QP {}, keyframe interval {}, one stateful stream per setting fed the frames in order (its first frame is the keyframe), decoded by OpenH264's decoder and converted back with nearest chroma. Bytes per second: mean bytes per frame × {} fps. Encode ms: the encode call alone, by the wall clock; encode CPU ms: the process's CPU time over the same call (every encoder thread), what a frame costs whatever the core count.\n",
            self.scene,
            self.triangles,
            self.gi,
            self.shadow_map_size,
            self.exposure,
            self.motion,
            self.frames,
            self.fps,
            f64::from(self.frames) / f64::from(self.fps),
            self.adapter,
            self.timing_source,
            self.cpu_threads,
            if self.flip_every == 1 {
                "every frame".to_string()
            } else {
                format!("one frame in {}", self.flip_every)
            },
            self.sizes
                .iter()
                .map(|s| format!(
                    "{}×{}: {} × {}",
                    s.width,
                    s.height,
                    s.h264_threads,
                    crate::service::video::slices_for(s.h264_threads)
                ))
                .collect::<Vec<_>>()
                .join(", "),
            self.max_qp,
            self.keyframe_interval,
            self.fps,
        );
        for size in &self.sizes {
            s += &size.markdown();
        }
        s += &format!("\n## Targets (issue 13: at {TARGET_SIZE} while moving)\n\n");
        let Some(t) = &self.targets else {
            s += "Not evaluated: the run needs this size and JPEG at the moving quality.\n";
            return s;
        };
        s += &format!(
            "Every H.264 bitrate against JPEG q{} (the moving quality): at most {TARGET_BYTES_RATIO} of its bytes at equal or better PSNR, and encode p95 at most {TARGET_ENCODE_P95_MS} ms. The last two columns size a deployment of this CPU class: CPU per frame over all encoder threads, and the cores one stream at {} fps keeps busy encoding.\n\n| H.264 | bytes ratio | PSNR Δ dB | bytes target | encode p95 ms | encode target | encode CPU ms/frame | cores per stream |\n|---|---|---|---|---|---|---|---|\n",
            t.jpeg_quality, self.fps
        );
        for c in &t.checks {
            s += &format!(
                "| {} kbit/s{} | {:.3} (1/{:.1}) | {:+.2} | {} | {:.2} | {} | {:.1} | {:.2} |\n",
                c.h264_kbps,
                if c.default_bitrate { " (default)" } else { "" },
                c.bytes_ratio,
                1.0 / c.bytes_ratio.max(1e-9),
                c.psnr_delta_db,
                met(c.bytes_met),
                c.encode_p95_ms,
                met(c.encode_met),
                c.encode_cpu_mean_ms,
                c.cores_per_stream
            );
        }
        let named = |pick: fn(&TargetCheck) -> bool| {
            let kbps: Vec<String> = t
                .checks
                .iter()
                .filter(|c| pick(c))
                .map(|c| format!("{} kbit/s", c.h264_kbps))
                .collect();
            if kbps.is_empty() {
                "no bitrate tried".to_string()
            } else {
                kbps.join(", ")
            }
        };
        s += &format!(
            "\nBytes target met at: {}. Encode target met at: {}.\n",
            named(|c| c.bytes_met),
            named(|c| c.encode_met)
        );
        s
    }
}

impl SizeReport {
    fn markdown(&self) -> String {
        let mut s = format!("\n## {}×{}\n\n", self.width, self.height);
        s += "| codec | bytes/frame (mean) | first frame | largest frame | kB/s | kbit/s | encode ms p50 / p95 | encode CPU ms mean | PSNR dB mean / min | FLIP mean | keyframes |\n";
        s += "|---|---|---|---|---|---|---|---|---|---|---|\n";
        for r in &self.rows {
            s += &format!(
                "| {} | {:.0} | {} | {} | {:.0} | {:.0} | {:.2} / {:.2} | {:.2} | {:.2} / {:.2} | {:.4} | {} |\n",
                r.setting,
                r.bytes_per_frame,
                r.first_frame_bytes,
                r.max_frame_bytes,
                r.bytes_per_second / 1e3,
                r.bytes_per_second * 8.0 / 1e3,
                r.encode.median_ms,
                r.encode.p95_ms,
                r.encode_cpu_mean_ms,
                r.psnr_mean_db,
                r.psnr_min_db,
                r.flip_mean,
                r.keyframes
            );
        }
        s += "\n| read back as | bytes/frame | for | readback copy GPU ms p50 / p95 | conversion GPU ms p50 / p95 | frame GPU ms p50 | submit → mapped ms p50 |\n|---|---|---|---|---|---|---|\n";
        for (name, codec, r, conversion) in [
            ("RGBA8", "JPEG", &self.rgba8, None),
            (
                "Y'CbCr 4:2:0",
                "H.264",
                &self.yuv420,
                Some(self.conversion_gpu),
            ),
        ] {
            s += &format!(
                "| {name} | {} | {codec} | {:.3} / {:.3} | {} | {:.1} | {:.1} |\n",
                r.bytes_per_frame,
                r.copy_gpu.median_ms,
                r.copy_gpu.p95_ms,
                conversion.map_or("-".to_string(), |c| format!(
                    "{:.3} / {:.3}",
                    c.median_ms, c.p95_ms
                )),
                r.frame_gpu.median_ms,
                r.wait.median_ms
            );
        }
        s += &format!(
            "\nThe 4:2:0 conversion alone (GPU planes back to RGB, no codec): PSNR {:.2} dB, the ceiling for H.264 here.\n",
            self.yuv420_psnr_db
        );
        s += "\n| H.264 | against | basis | PSNR Δ dB | bytes ratio | ≤ 1/5 at ≥ PSNR |\n|---|---|---|---|---|---|\n";
        for c in &self.comparisons {
            s += &format!(
                "| {} kbit/s | JPEG q{} | {} | {:+.2} | {:.3} (1/{:.1}) | {} |\n",
                c.h264_kbps,
                c.jpeg_quality,
                c.bases
                    .iter()
                    .map(|b| b.describe())
                    .collect::<Vec<_>>()
                    .join("; "),
                c.psnr_delta_db,
                c.bytes_ratio,
                1.0 / c.bytes_ratio.max(1e-9),
                if c.meets_bytes_target { "yes" } else { "no" }
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_sizes_parse_and_reject() {
        let size = |s: &str| s.parse::<FrameSize>();
        assert_eq!(
            size("1920x1080"),
            Ok(FrameSize {
                width: 1920,
                height: 1080
            })
        );
        assert_eq!(size("64×48").map(|s| s.to_string()), Ok("64×48".into()));
        for bad in ["1920", "0x10", "10x", "axb", "-2x4"] {
            assert!(size(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_camera_orbits_or_dollies_and_the_path_file_follows_it() {
        let base = Camera {
            position: [1.0, 2.0, 5.0],
            target: [1.0, 1.0, 1.0],
            fov_y_degrees: 45.0,
        };
        let distance = |c: &Camera| {
            let d = [0, 1, 2].map(|k| c.position[k] - c.target[k]);
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        };
        let orbit = CameraMotion {
            motion: Motion::Orbit,
            speed: 30.0,
            base: base.clone(),
        };
        let quarter = orbit.at(3.0);
        assert!((distance(&quarter) - distance(&base)).abs() < 1e-5);
        assert_eq!(quarter.position[1], base.position[1], "height kept");
        assert!(
            (quarter.position[0] - (1.0 - 4.0)).abs() < 1e-5,
            "{quarter:?}"
        );
        assert_eq!(quarter.target, base.target);
        let dolly = CameraMotion {
            motion: Motion::Dolly,
            speed: 0.1,
            base: base.clone(),
        };
        let ahead = dolly.at(5.0);
        assert_eq!(
            ahead.position,
            [1.0, 1.5, 3.0],
            "half way to the old target"
        );
        assert!(
            (distance(&ahead) - distance(&base)).abs() < 1e-5,
            "the target moves on"
        );
        let path = orbit.to_json(12.0, 30.0);
        let keyframes = path["keyframes"].as_array().expect("keyframes");
        assert_eq!(keyframes.len(), 361);
        assert_eq!(keyframes[360]["t"], 12.0);
        let last: Camera =
            serde_json::from_value(keyframes[90]["camera"].clone()).expect("a camera");
        assert_eq!(last, quarter);
    }

    fn row(setting: CodecSetting, bytes: f64, psnr_db: f64) -> CodecRow {
        CodecRow {
            setting,
            bytes_per_frame: bytes,
            first_frame_bytes: bytes as usize,
            max_frame_bytes: bytes as usize,
            bytes_per_second: bytes * 30.0,
            encode: stats(vec![1.0]),
            encode_cpu_mean_ms: 1.0,
            psnr_mean_db: psnr_db,
            psnr_min_db: psnr_db,
            flip_mean: 0.0,
            keyframes: 1,
            frames: Vec::new(),
        }
    }

    #[test]
    fn h264_rates_are_auto_or_kbit_per_second_in_the_sessions_range() {
        assert_eq!("auto".parse(), Ok(H264Rate::Auto));
        assert_eq!("3000".parse(), Ok(H264Rate::Kbps(3000)));
        for bad in ["99", "200001", "fast", "", "-5"] {
            let e = bad.parse::<H264Rate>().expect_err(bad);
            assert!(e.contains("100..=200000"), "{bad}: {e}");
        }
        // `auto` is what a session with `bitrate_kbps: null` gets at each size.
        assert_eq!(H264Rate::Auto.kbps(1920, 1080, 30.0), 3110);
        assert_eq!(H264Rate::Auto.kbps(1280, 720, 30.0), 1382);
        assert_eq!(H264Rate::Kbps(8000).kbps(1280, 720, 30.0), 8000);
    }

    #[test]
    fn h264_is_compared_with_the_moving_quality_and_the_closest_psnr_below() {
        let jpeg = |quality| CodecSetting::Jpeg { quality };
        let h264 = |bitrate_kbps| CodecSetting::H264 {
            bitrate_kbps,
            auto: false,
        };
        let rows = [
            row(jpeg(50), 60_000.0, 36.0),
            row(jpeg(70), 80_000.0, 38.0),
            row(jpeg(80), 100_000.0, 39.5),
            row(jpeg(90), 150_000.0, 42.0),
            row(h264(8000), 15_000.0, 40.0),
            row(h264(3000), 9_000.0, 38.5),
            row(h264(300), 1_000.0, 30.0),
        ];
        let c = compare(&rows, 70);
        assert_eq!(c.len(), 4, "{c:?}");
        // 8000: q70 (moving), and q80 as the closest below 40 dB.
        assert_eq!((c[0].h264_kbps, c[0].jpeg_quality), (8000, 70));
        assert_eq!(c[0].bases, [Basis::MovingQuality]);
        assert!((c[0].bytes_ratio - 15.0 / 80.0).abs() < 1e-12);
        assert!((c[0].psnr_delta_db - 2.0).abs() < 1e-12);
        assert!(c[0].meets_bytes_target);
        assert_eq!(
            (c[1].jpeg_quality, &c[1].bases[..]),
            (80, &[Basis::ClosestPsnrAtOrBelow][..])
        );
        assert!(c[1].meets_bytes_target, "0.15 of the bytes at +0.5 dB");
        // 3000: q70 is both, in one row.
        assert_eq!((c[2].h264_kbps, c[2].jpeg_quality), (3000, 70));
        assert_eq!(
            c[2].bases,
            [Basis::MovingQuality, Basis::ClosestPsnrAtOrBelow]
        );
        // 300 kbit/s: an eightieth of the bytes, but below every JPEG's PSNR: no closest
        // JPEG, and the moving comparison fails on PSNR.
        assert_eq!(
            (c[3].h264_kbps, &c[3].bases[..]),
            (300, &[Basis::MovingQuality][..])
        );
        assert!(c[3].bytes_ratio < TARGET_BYTES_RATIO && !c[3].meets_bytes_target);
    }

    #[test]
    fn targets_check_every_bitrate_at_1080p_against_the_moving_quality() {
        let readback = || Readback {
            bytes_per_frame: 1,
            copy_gpu: stats(vec![1.0]),
            frame_gpu: stats(vec![1.0]),
            wait: stats(vec![1.0]),
        };
        let size = |width, height| {
            let h264 = |bitrate_kbps, auto| CodecSetting::H264 { bitrate_kbps, auto };
            let mut fast = row(h264(3000, false), 9_000.0, 38.5);
            fast.encode = stats(vec![5.0, 6.0]);
            fast.encode_cpu_mean_ms = 11.0;
            let rows = vec![
                row(CodecSetting::Jpeg { quality: 70 }, 80_000.0, 38.0),
                // The automatic bitrate (the service's default) came to 8000 here.
                row(h264(8000, true), 20_000.0, 41.0),
                fast,
            ];
            SizeReport {
                width,
                height,
                rgba8: readback(),
                yuv420: readback(),
                conversion_gpu: stats(vec![1.0]),
                yuv420_psnr_db: 45.0,
                h264_threads: 2,
                comparisons: compare(&rows, 70),
                rows,
            }
        };
        let defaults = Encoding::default();
        assert!(
            targets(&[size(1280, 720)], &defaults, 30.0).is_none(),
            "1080p only"
        );
        let t = targets(&[size(1280, 720), size(1920, 1080)], &defaults, 30.0).expect("1080p ran");
        assert_eq!(t.jpeg_quality, 70);
        let checks: Vec<_> = t
            .checks
            .iter()
            .map(|c| (c.h264_kbps, c.default_bitrate, c.bytes_met, c.encode_met))
            .collect();
        // 8000: a quarter of the bytes; 3000: under a fifth at +0.5 dB, encoded in 6 ms.
        assert_eq!(
            checks,
            [(8000, true, false, true), (3000, false, true, true)]
        );
        // 11 ms of CPU per frame, 30 frames a second: a third of a core.
        assert!((t.checks[1].cores_per_stream - 0.33).abs() < 1e-9);
        let markdown = StreamBenchReport {
            adapter: "test".into(),
            timing_source: TimingSource::CpuWallClock,
            scene: "test".into(),
            triangles: 0,
            gi: crate::gi::none::NONE,
            shadow_map_size: 256,
            exposure: "auto".into(),
            frames: 1,
            fps: 30.0,
            motion: CameraMotion {
                motion: Motion::Orbit,
                speed: 30.0,
                base: Camera {
                    position: [0.0, 0.0, 1.0],
                    target: [0.0; 3],
                    fov_y_degrees: 45.0,
                },
            },
            flip_every: 1,
            max_qp: defaults.max_qp,
            keyframe_interval: defaults.keyframe_interval,
            cpu_threads: 1,
            sizes: Vec::new(),
            targets: Some(t),
        }
        .markdown();
        assert!(
            markdown.contains(
                "Bytes target met at: 3000 kbit/s. Encode target met at: 8000 kbit/s, 3000 kbit/s."
            ),
            "{markdown}"
        );
    }

    /// A moving gradient with a bright square: frame `t` of a tiny synthetic path.
    fn frame(width: u32, height: u32, t: u32) -> Image {
        let rgba8 = (0..width * height)
            .flat_map(|i| {
                let (x, y) = (i % width, i / width);
                if (x + 3 * t) % width < width / 4 && y > height / 3 && y < height / 2 {
                    [230, 200, 40, 255]
                } else {
                    [
                        ((x + 2 * t) * 255 / width) as u8,
                        (y * 255 / height) as u8,
                        (((x + y) / 2) % 256) as u8,
                        255,
                    ]
                }
            })
            .collect();
        Image {
            width,
            height,
            rgba8,
        }
    }

    #[test]
    fn codecs_measure_a_stream_of_frames() {
        let (w, h, n) = (64, 48, 6);
        let settings = [
            CodecSetting::Jpeg { quality: 50 },
            CodecSetting::Jpeg { quality: 95 },
            CodecSetting::H264 {
                bitrate_kbps: 8000,
                auto: false,
            },
        ];
        let mut codecs = Codecs::new(&settings, w, h, 30.0).expect("encoders");
        let mut ceiling = 0.0;
        for t in 0..n {
            let image = frame(w, h, t);
            let planes = Yuv420::from_rgba8(&image.rgba8, w, h);
            ceiling += psnr(&rgb_of(&image.rgba8), &rgb_of(&planes.to_rgba8())) / f64::from(n);
            codecs
                .add_frame(&image, &planes, t % 2 == 0)
                .expect("frame");
        }
        let rows = codecs.rows(30.0);
        assert_eq!(rows.len(), 3);
        for r in &rows {
            assert_eq!(r.frames.len(), n as usize, "{}", r.setting);
            assert!(r.frames.iter().all(|f| f.bytes > 0), "{}", r.setting);
            assert_eq!(r.frames.iter().filter(|f| f.flip.is_some()).count(), 3);
            assert!((r.bytes_per_second - 30.0 * r.bytes_per_frame).abs() < 1e-9);
            assert!(r.psnr_min_db <= r.psnr_mean_db);
            assert!(r.flip_mean > 0.0 && r.flip_mean < 0.5, "{}", r.setting);
            assert!(r.encode_cpu_mean_ms > 0.0, "{}: {r:?}", r.setting);
        }
        let (q50, q95, video) = (&rows[0], &rows[1], &rows[2]);
        assert!(q95.bytes_per_frame > q50.bytes_per_frame);
        assert!(q95.psnr_mean_db > q50.psnr_mean_db + 3.0, "{q95:?}");
        assert!(q95.flip_mean < q50.flip_mean);
        // One keyframe, then P-frames smaller than it; at 8 Mbit/s a 64×48 frame loses next
        // to nothing beyond what 4:2:0 loses (the square's sharp chroma edges: under 30 dB).
        assert_eq!(video.keyframes, 1);
        assert!(video.frames[0].keyframe);
        assert!(video.frames[1..]
            .iter()
            .all(|f| f.bytes < video.first_frame_bytes));
        assert!(
            video.psnr_mean_db > ceiling - 1.0 && video.psnr_mean_db <= ceiling + 0.1,
            "{video:?}, 4:2:0 alone {ceiling:.2} dB"
        );
        assert_eq!(video.max_frame_bytes, video.first_frame_bytes);
    }

    #[test]
    fn frames_are_written_as_i420_without_the_layout_padding() {
        // 6 wide: chroma rows of 3 samples padded to 4, luma rows of 6 padded to 8.
        let (w, h) = (6, 4);
        let rgba8: Vec<u8> = (0..w * h * 4).map(|i| (i * 7 % 251) as u8).collect();
        let frame = Yuv420::from_rgba8(&rgba8, w, h);
        assert_eq!(
            (frame.layout.luma_stride, frame.layout.chroma_stride),
            (8, 4)
        );
        let mut written = Vec::new();
        write_i420(&mut written, &frame).expect("written");
        assert_eq!(written.len(), (w * h + 2 * (w / 2) * (h / 2)) as usize);
        let (y, c) = ((w * h) as usize, ((w / 2) * (h / 2)) as usize);
        assert_eq!(&written[6..12], &frame.y()[8..14], "luma row 1");
        assert_eq!(&written[y + 3..y + 6], &frame.cb()[4..7], "Cb row 1");
        assert_eq!(&written[y + c..y + c + 3], &frame.cr()[..3], "Cr row 0");
    }

    #[test]
    fn decoded_planes_are_copied_row_by_row() {
        let (w, h) = (10, 6);
        let source = Yuv420::from_rgba8(&frame(w, h, 0).rgba8, w, h);
        // A decoder's rows are padded otherwise than ours: the copy drops its padding.
        let decoded = Padded::of(&source, 7);
        assert_eq!(planes_of(&decoded, source.layout), Ok(source.clone()));
        assert!(planes_of(&decoded, Yuv420Layout::new(12, 6)).is_err());
    }

    /// The planes of a [`Yuv420`] with `pad` more bytes per row, as a decoder may hand out
    /// its picture; the padding is 0xEE.
    struct Padded {
        width: usize,
        height: usize,
        planes: [(Vec<u8>, usize); 3],
    }

    impl Padded {
        fn of(source: &Yuv420, pad: usize) -> Self {
            let l = source.layout;
            let (w, h) = (l.width as usize, l.height as usize);
            let repad = |plane: &[u8], stride: usize, cols: usize, rows: usize| {
                let mut out = vec![0xEE; rows * (cols + pad)];
                copy_rows(&mut out, plane, (stride, cols + pad), (cols, rows));
                (out, cols + pad)
            };
            let (cols, rows, chroma) = (w.div_ceil(2), h.div_ceil(2), l.chroma_stride as usize);
            Self {
                width: w,
                height: h,
                planes: [
                    repad(source.y(), l.luma_stride as usize, w, h),
                    repad(source.cb(), chroma, cols, rows),
                    repad(source.cr(), chroma, cols, rows),
                ],
            }
        }
    }

    impl YUVSource for Padded {
        fn dimensions(&self) -> (usize, usize) {
            (self.width, self.height)
        }
        fn strides(&self) -> (usize, usize, usize) {
            let [y, u, v] = &self.planes;
            (y.1, u.1, v.1)
        }
        fn y(&self) -> &[u8] {
            &self.planes[0].0
        }
        fn u(&self) -> &[u8] {
            &self.planes[1].0
        }
        fn v(&self) -> &[u8] {
            &self.planes[2].0
        }
    }
}
