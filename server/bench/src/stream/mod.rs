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
use crate::passes::frame_uniforms::MAX_LIGHTS;
use crate::passes::yuv420::{Yuv420, Yuv420Layout};
use crate::quality::{flip_mean, psnr};
use crate::renderer::{Frame, RenderSettings, Renderer};
use crate::scene::{
    default_light::{default_camera, default_lights},
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

mod codecs;
pub mod motion;
pub mod report;

use codecs::*;
pub use motion::*;
pub use report::*;

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
            poses: Vec::new(),
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
        lights: default_lights(&scene, MAX_LIGHTS),
        environment: None,
        exposure: args.exposure.0,
        shadow_map_size: args.shadow_map_size,
        capture_hdr: false,
        debug_view: lightcast_protocol::View::FINAL,
        gi,
        history: None,
        still: false,
        yuv420: false,
        poses: Vec::new(),
        pick: None,
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

#[cfg(test)]
mod tests;
