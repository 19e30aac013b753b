//! What `bench-stream` reports: per codec and frame, per size, the comparisons of H.264 with
//! JPEG and issue 13's targets, and the report's markdown.

use super::*;

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

/// Issue 13's targets from `sizes`, when the run has [`TARGET_SIZE`] and JPEG at the moving
/// quality; streams run at `fps`.
pub(super) fn targets(sizes: &[SizeReport], defaults: &Encoding, fps: f32) -> Option<Targets> {
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
