//! `lightcast-server bench`: the paper's evaluation (its Figures 3 and 5) on our scenes.
//!
//! For every RSM size the LightSkin baseline is rendered first; every BRSM configuration (VAL
//! count × view samples) is then timed at the same RSM size and its indirect buffer compared
//! with the baseline's (mean absolute difference, absolute and relative to the baseline's
//! mean). All configurations run in one process on one GPU, so ratios between them are fair.
//!
//! With `--reference-spp` above 0, the reference path tracer (`gi::reference`) first renders
//! the indirect light at the same camera, light and size, and every configuration's indirect
//! buffer is also compared with it: the error against the truth, not only against LightSkin.

use crate::gi::clustered::params::{CLUSTER_COUNT, VISIBILITY};
use crate::gi::lightskin::params::{VAL_COUNT, VIEW_SAMPLES};
use crate::gi::{lightskin::LightSkin, GiMethod};
use crate::gpu::{context::AdapterSummary, BackendChoice, GpuContext};
use crate::offline::{ExposureArg, GiArgs, DEFAULT_SCENE};
use crate::passes::tonemap::luminance;
use crate::quality::{errors, final_errors, ErrorStats};
use crate::renderer::{RenderSettings, Renderer};
use crate::scene::{
    default_light::{default_camera, default_light},
    Scene,
};
use lightcast_protocol::GiParams;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Options of `lightcast-server bench`.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchArgs {
    /// Which evaluation: `brsm` (seed 004: LightSkin and BRSM over RSM sizes, VAL counts and
    /// view samples), `surfels` (seed 001: surfel count, links and SH bands, see
    /// `crate::bench_surfels`) or `clustered` (seed 003: VPL and VAL counts against per-VPL
    /// shadows and no visibility, see `crate::bench_clustered`; its RSM is the first of
    /// `--rsm-sizes`).
    #[arg(long, default_value = "brsm", value_parser = crate::gi::parse_method)]
    pub gi: GiMethod,
    /// Scene: a .gltf/.glb file or a procedural scene (see `render --help`).
    #[arg(long)]
    pub scene: Option<String>,
    #[arg(long, default_value_t = 1920)]
    pub width: u32,
    #[arg(long, default_value_t = 1080)]
    pub height: u32,
    /// RSM sides to test (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = [128, 256, 512, 1024, 2048])]
    pub rsm_sizes: Vec<u32>,
    /// VAL counts N_sVAL for BRSM (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = [2048, 4096, 8192])]
    pub vals: Vec<u32>,
    /// View-sample counts N_VS for BRSM (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = [256, 512])]
    pub view_samples: Vec<u32>,
    /// Weight α of the uniform part of BRSM's selection pdf (0 = the paper's plain BRSM).
    #[arg(long, default_value_t = crate::gi::lightskin::params::DEFAULT_DEFENSIVE as f32)]
    pub defensive: f32,
    /// Phong exponent k for every material, for LightSkin and BRSM alike (default: each
    /// material's own).
    #[arg(long)]
    pub glossy_exponent: Option<f32>,
    /// Dim proxy lights hidden behind other caches (the paper's double projection), for
    /// LightSkin and BRSM alike.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub occlusion: bool,
    /// Samples per pixel of the path-traced reference every configuration is compared with
    /// (0: no reference).
    #[arg(long, default_value_t = 256)]
    pub reference_spp: u32,
    /// Bounces of the reference's paths (1: the single-bounce light seed 004 approximates).
    #[arg(long, default_value_t = 1)]
    pub reference_bounces: u32,
    /// Emissive surfaces light the scene as area lights for `surfels` and its reference. Off
    /// by default: the built-in scenes' light stands in for their emitters (the Cornell box's
    /// lamp), and the other methods light from the punctual light alone, so every method is
    /// measured from the same sources. With it on, the other methods of
    /// `--compare-methods` are still measured against a reference without emitters.
    #[arg(long, default_value_t = false, action = clap::ArgAction::Set)]
    pub emitters: bool,
    /// Indirect light of every configuration at 1/N of the output's width and height (1, 2 or
    /// 4; the reference stays at full resolution).
    #[arg(long, default_value_t = 1)]
    pub indirect_downscale: u32,
    /// Timed frames per configuration.
    #[arg(long, default_value_t = 30)]
    pub frames: u32,
    /// Untimed frames before timing each configuration.
    #[arg(long, default_value_t = 5)]
    pub warmup: u32,
    #[command(flatten)]
    pub caches: GiArgs,
    #[command(flatten)]
    pub surfels: crate::bench_surfels::SurfelSweep,
    #[command(flatten)]
    pub clustered: crate::bench_clustered::ClusteredSweep,
    /// Write the results as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the results as a markdown table here.
    #[arg(long)]
    pub markdown: Option<PathBuf>,
    /// Write PNG plots to PREFIX-error.png (error vs RSM size) and PREFIX-fps.png (fps vs RSM
    /// size, per configuration). Needs a build with `--features plots`.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// Exposure for the frames (only the indirect buffer is compared, so this does not matter
    /// for the error; `auto` costs one extra stage).
    #[arg(long, default_value = "1", allow_negative_numbers = true)]
    pub exposure: ExposureArg,
    #[arg(long, value_enum, env = "LIGHTCAST_BACKEND", default_value = "auto")]
    pub backend: BackendChoice,
    /// How stages are timed: `gpu` (timestamp queries between stages), `wall` (each stage
    /// submitted and waited for, timed by the CPU clock) or `auto` (`wall` on a CPU adapter,
    /// whose timestamps put the work of some stages into others: on lavapipe a surfels cache
    /// lighting of 10⁷ multiply-adds read 0.03 ms; `gpu` elsewhere).
    #[arg(long, value_enum, default_value = "auto")]
    pub stage_clock: StageClock,
}

/// See [`BenchArgs::stage_clock`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum StageClock {
    Auto,
    Gpu,
    Wall,
}

/// The adapter of `args.backend`, logged, with its stages timed as `args.stage_clock` says.
pub fn open_adapter(args: &BenchArgs, log: &mut dyn FnMut(&str)) -> Result<GpuContext, BenchError> {
    let mut ctx = GpuContext::new(args.backend)?;
    let wall = match args.stage_clock {
        StageClock::Auto => ctx.info.device_type == wgpu::DeviceType::Cpu,
        StageClock::Gpu => false,
        StageClock::Wall => true,
    };
    if wall {
        ctx.timestamps = false;
    }
    log(&format!("adapter: {}", AdapterSummary(&ctx.info)));
    Ok(ctx)
}

/// Median and 95th percentile of a stage's time.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct StageStats {
    pub median_ms: f64,
    pub p95_ms: f64,
}

/// One configuration's results.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchRow {
    pub method: GiMethod,
    pub rsm_size: u32,
    pub val_count: Option<u32>,
    pub view_samples: Option<u32>,
    pub stages: BTreeMap<String, StageStats>,
    pub gi: StageStats,
    pub frame: StageStats,
    pub fps: f64,
    /// Mean absolute difference of the indirect buffer against LightSkin at this RSM size.
    pub mad: f64,
    /// `mad` divided by the mean of LightSkin's indirect buffer.
    pub mad_relative: f64,
    /// LightSkin's frame time divided by this configuration's.
    pub speedup_vs_lightskin: f64,
    /// Errors of the indirect buffer against the path-traced reference, when one was rendered.
    pub vs_reference: Option<ErrorStats>,
    /// PSNR in dB of the final image against the same frame with the reference's indirect
    /// light (see [`crate::quality::final_errors`]).
    pub final_psnr_db: Option<f64>,
    /// Mean LDR-FLIP error of the same two images.
    pub final_flip: Option<f64>,
    /// RGB8 difference image against the reference (red: too bright, blue: too dark), when
    /// plots were asked for (written by `bench_plots`, not serialized).
    #[serde(skip)]
    pub difference_image: Option<Vec<u8>>,
}

/// The reference the rows were compared with.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ReferenceSummary {
    pub spp: u32,
    pub bounces: u32,
    /// The reference's own convergence estimate (relative standard error).
    pub relative_standard_error: f32,
    /// Mean of its indirect buffer, per channel.
    pub mean: f64,
}

/// The whole run.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchReport {
    pub adapter: String,
    pub timing_source: crate::gpu::timing::TimingSource,
    pub scene: String,
    pub triangles: usize,
    pub caches: usize,
    pub width: u32,
    pub height: u32,
    pub frames: u32,
    pub warmup: u32,
    /// α of BRSM's defensive selection mixture.
    pub defensive: f32,
    /// The Phong exponent every material used, if overridden.
    pub glossy_exponent: Option<f32>,
    /// Whether proxy occlusion was on.
    pub occlusion: bool,
    pub reference: Option<ReferenceSummary>,
    /// RGB8 picture of the reference's indirect light, when plots were asked for.
    #[serde(skip)]
    pub reference_image: Option<Vec<u8>>,
    pub rows: Vec<BenchRow>,
}

#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    // Messages are complete on their own (the inner error is not a `source`, so a printed
    // chain does not repeat it).
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
    #[error("{what} list is empty")]
    EmptyList { what: &'static str },
    #[error("--frames must be at least 1")]
    NoFrames,
    #[error("reference: {0}")]
    Reference(#[from] crate::gi::reference::ReferenceError),
    #[error(
        "bench --gi {0}: only brsm (with LightSkin as its baseline), surfels and clustered have an evaluation"
    )]
    NoEvaluation(GiMethod),
    #[error("surfels: {0}")]
    Surfels(String),
    #[error("clustered: {0}")]
    Clustered(String),
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

pub(crate) fn stats(mut v: Vec<f64>) -> StageStats {
    v.sort_by(f64::total_cmp);
    StageStats {
        median_ms: percentile(&v, 0.5),
        p95_ms: percentile(&v, 0.95),
    }
}

/// Mean absolute difference (per channel) and the reference's mean.
fn mad(reference: &[[f32; 4]], other: &[[f32; 4]]) -> (f64, f64) {
    let mut diff = 0.0f64;
    let mut sum = 0.0f64;
    for (a, b) in reference.iter().zip(other) {
        for k in 0..3 {
            diff += f64::from((a[k] - b[k]).abs());
            sum += f64::from(a[k]);
        }
    }
    let n = (reference.len() * 3).max(1) as f64;
    (diff / n, sum / n)
}

/// sRGB-ish 8-bit value of a linear one (display gamma 2.2; the pictures are diagnostics).
fn to_u8(v: f64) -> u8 {
    (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8
}

/// The reference's indirect light as RGB8, tone mapped by x / (x + mean).
fn reference_picture(truth: &[[f32; 3]], mean: f64) -> Vec<u8> {
    let key = mean.max(1e-12);
    truth
        .iter()
        .flat_map(|p| p.map(|c| to_u8(f64::from(c) / (f64::from(c) + key))))
        .collect()
}

/// |other − truth| in luminance as RGB8: red where `other` is brighter, blue where darker,
/// full intensity at twice the reference's mean.
fn difference_picture(truth: &[[f32; 3]], other: &[[f32; 4]], mean: f64) -> Vec<u8> {
    let scale = 1.0 / (2.0 * mean.max(1e-12));
    truth
        .iter()
        .zip(other)
        .flat_map(|(a, b)| {
            let d = f64::from(luminance([b[0], b[1], b[2]]) - luminance(*a)) * scale;
            let v = to_u8(d.abs());
            if d > 0.0 {
                [v, 0, 0]
            } else {
                [0, 0, v]
            }
        })
        .collect()
}

/// Renders the reference's indirect light for `settings`' camera, light and size, with paths
/// of `bounces` reflections, lit by the sources `settings`' method lights from: emissive
/// surfaces only for a method that models them and has `emitters` on.
pub(crate) fn render_reference(
    ctx: &GpuContext,
    scene: &Scene,
    settings: &RenderSettings,
    args: &BenchArgs,
    bounces: u32,
    progress: &mut dyn FnMut(u64, u64, &str),
) -> Result<crate::gi::reference::ReferenceImage, BenchError> {
    use crate::gi::reference::{PathTracer, ReferenceSettings};
    let mut tracer = PathTracer::new(ctx.clone(), scene)?;
    let reference = ReferenceSettings {
        bounces,
        seed: 0,
        glossy_exponent: args.glossy_exponent,
        emitters: crate::gi::reference_emitters(&settings.gi),
    };
    // Small calls keep each submission short (lavapipe drops long ones) and show progress.
    let per_call = 4;
    let mut done = 0;
    let label = format!("reference path tracing, {bounces} bounce(s): samples per pixel");
    while done < args.reference_spp {
        let n = per_call.min(args.reference_spp - done);
        tracer.accumulate(
            settings.width,
            settings.height,
            &settings.camera,
            &settings.light,
            &reference,
            n,
        )?;
        done += n;
        progress(u64::from(done), u64::from(args.reference_spp), &label);
    }
    Ok(tracer
        .read()?
        .expect("the reference has accumulated samples"))
}

pub(crate) struct Timed {
    pub stages: BTreeMap<String, StageStats>,
    pub gi: StageStats,
    pub frame: StageStats,
    pub indirect: Vec<[f32; 4]>,
    /// The last frame's HDR image and exposure scale.
    pub hdr: Vec<[f32; 4]>,
    pub exposure: f32,
}

/// Renders `warmup + frames` frames, frame `i` with the settings `vary(i, settings)` makes of
/// `settings`; the last one also captures the indirect buffer.
pub(crate) fn time_config(
    renderer: &mut Renderer,
    settings: &RenderSettings,
    warmup: u32,
    frames: u32,
    vary: &dyn Fn(u32, &mut RenderSettings),
    tick: &mut dyn FnMut(),
) -> Result<Timed, BenchError> {
    let mut per_stage: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let (mut gi, mut total) = (Vec::new(), Vec::new());
    let (mut indirect, mut hdr, mut exposure) = (Vec::new(), Vec::new(), 1.0);
    for i in 0..warmup + frames {
        let mut s = settings.clone();
        vary(i, &mut s);
        s.capture_hdr = i + 1 == warmup + frames;
        let frame = renderer.render(&s)?;
        tick();
        if i < warmup {
            continue;
        }
        let mut gi_ms = 0.0;
        for t in &frame.timings {
            if t.stage == crate::passes::stages::READBACK_COPY {
                continue;
            }
            per_stage.entry(t.stage.to_string()).or_default().push(t.ms);
            if crate::passes::stages::is_gi(t.stage) {
                gi_ms += t.ms;
            }
        }
        gi.push(gi_ms);
        total.push(
            frame
                .timings
                .iter()
                .filter(|t| t.stage != crate::passes::stages::READBACK_COPY)
                .map(|t| t.ms)
                .sum(),
        );
        if let (Some(i), Some(h)) = (frame.indirect, frame.hdr) {
            (indirect, hdr, exposure) = (i, h, frame.exposure_scale);
        }
    }
    Ok(Timed {
        stages: per_stage.into_iter().map(|(k, v)| (k, stats(v))).collect(),
        gi: stats(gi),
        frame: stats(total),
        indirect,
        hdr,
        exposure,
    })
}

/// One method at one setting of the equal-time comparison.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MethodRow {
    pub method: GiMethod,
    /// The setting, e.g. `RSM 256², 2048 VALs`.
    pub setting: String,
    pub gi: StageStats,
    /// Error against the single-bounce reference.
    pub vs_reference: ErrorStats,
    /// The method's setting whose GI time is nearest the centre's.
    pub nearest_equal_time: bool,
}

/// The settings each method is tried at in the equal-time comparison, cheapest first
/// (`surfels` is left out: each setting is a precomputation of its own).
fn ladders(base: &GiParams) -> Vec<(GiParams, String)> {
    let as_method = |method| {
        let mut gi = base.clone();
        gi.method = method;
        gi
    };
    let lightskin = [64, 128, 256].map(|rsm_size| {
        (
            as_method(crate::gi::lightskin::LIGHTSKIN).with("rsm_size", rsm_size),
            format!("RSM {rsm_size}²"),
        )
    });
    let brsm = [512, 2048, 8192].map(|val_count| {
        (
            as_method(crate::gi::lightskin::BRSM)
                .with("rsm_size", 256)
                .with("val_count", val_count),
            format!(
                "RSM 256², {val_count} VALs, {} view samples",
                VIEW_SAMPLES.u32(base)
            ),
        )
    });
    let clustered = [256, 1024, 4096].map(|vpl_count| {
        (
            as_method(crate::gi::clustered::CLUSTERED).with("vpl_count", vpl_count),
            format!(
                "{vpl_count} VPLs, {} VALs, {}",
                CLUSTER_COUNT.u32(base),
                VISIBILITY.value(base).as_str().unwrap_or_default()
            ),
        )
    });
    lightskin.into_iter().chain(brsm).chain(clustered).collect()
}

/// The comparison of all GI methods at equal time: `centre` (a method's setting with its GI
/// time and single-bounce error) first, then the ladder of every other method, each rung's
/// error against the single-bounce reference `truth`; per method the rung nearest the
/// centre's GI time is marked.
#[allow(clippy::too_many_arguments)]
pub(crate) fn equal_time(
    renderer: &mut Renderer,
    scene: &Scene,
    base: &RenderSettings,
    args: &BenchArgs,
    centre: MethodRow,
    truth: &[[f32; 3]],
    log: &mut dyn FnMut(&str),
    progress: &mut dyn FnMut(u64, u64, &str),
) -> Result<Vec<MethodRow>, BenchError> {
    let target = centre.gi.median_ms;
    let skip = centre.method;
    let mut out = vec![centre];
    let caches = args.caches.load(scene, log)?;
    renderer
        .gi::<crate::gi::lightskin::LightSkin>()?
        .set_caches(&caches)
        .map_err(crate::renderer::RenderError::from)?;
    let ladder: Vec<_> = ladders(&base.gi.clone().with("bounces", 1))
        .into_iter()
        .filter(|(gi, _)| gi.method != skip)
        .collect();
    let total = ladder.len() as u64 * u64::from(args.warmup + args.frames);
    let mut done = 0;
    for (gi, setting) in ladder {
        let method = gi.method;
        let label = format!("{method:?} {setting}: frames");
        let settings = RenderSettings { gi, ..base.clone() };
        let timed = time_config(
            renderer,
            &settings,
            args.warmup,
            args.frames,
            &|_, _| {},
            &mut || {
                done += 1;
                progress(done, total, &label);
            },
        )?;
        out.push(MethodRow {
            method,
            setting,
            gi: timed.gi,
            vs_reference: errors(truth, &timed.indirect, args.width as usize),
            nearest_equal_time: false,
        });
    }
    for method in [
        crate::gi::lightskin::LIGHTSKIN,
        crate::gi::lightskin::BRSM,
        crate::gi::clustered::CLUSTERED,
    ] {
        if method == skip {
            continue;
        }
        let nearest = out
            .iter_mut()
            .filter(|r| r.method == method)
            .min_by(|a, b| {
                let d = |r: &MethodRow| (r.gi.median_ms - target).abs();
                d(a).total_cmp(&d(b))
            });
        if let Some(row) = nearest {
            row.nearest_equal_time = true;
        }
    }
    Ok(out)
}

/// The equal-time table of [`equal_time`]'s rows; `against` names the centre's method.
pub(crate) fn equal_time_table(rows: &[MethodRow], against: &str) -> String {
    let mut s = format!(
        "\nAll GI methods at one bounce against the same reference; ✓ marks each method's setting whose GI time is nearest {against}'s (equal time):\n\n| method | setting | GI ms (median / p95) | MAE / mean | 8×8-block MAE / mean | bias | equal time |\n|---|---|---|---|---|---|---|\n"
    );
    for m in rows {
        s += &format!(
            "| {:?} | {} | {:.3} / {:.3} | {:.2} % | {:.2} % | {:+.2} % | {} |\n",
            m.method,
            m.setting,
            m.gi.median_ms,
            m.gi.p95_ms,
            m.vs_reference.mae_relative * 100.0,
            m.vs_reference.block_mae_relative * 100.0,
            m.vs_reference.bias_relative * 100.0,
            if m.nearest_equal_time { "✓" } else { "" }
        );
    }
    s
}

/// Frames of one configuration under a moving light: each frame's light differs from the last
/// by a millionth of its intensity, so nothing that depends on the light is reused, as in a
/// session while the light moves.
pub(crate) fn time_moving_light(
    renderer: &mut Renderer,
    settings: &RenderSettings,
    args: &BenchArgs,
    what: &str,
    progress: &mut dyn FnMut(u64, u64, &str),
) -> Result<Timed, BenchError> {
    let total = u64::from(args.warmup + args.frames);
    let mut done = 0;
    let label = format!("{what}: frames");
    time_config(
        renderer,
        settings,
        args.warmup,
        args.frames,
        &|i, s| s.light.intensity *= 1.0 + 1e-6 * (i % 2) as f32,
        &mut || {
            done += 1;
            progress(done, total, &label);
        },
    )
}

/// The frame every configuration of a bench renders: the scene's camera and light at the
/// bench's size and exposure, a 2048² shadow map, indirect light by `gi`.
pub(crate) fn base_settings(args: &BenchArgs, scene: &Scene, gi: GiParams) -> RenderSettings {
    RenderSettings {
        width: args.width,
        height: args.height,
        camera: default_camera(scene),
        light: default_light(scene),
        exposure: args.exposure.0,
        shadow_map_size: 2048,
        capture_hdr: false,
        debug_view: lightcast_protocol::View::FINAL,
        gi,
        history: None,
        still: false,
        yuv420: false,
    }
}

/// Runs the benchmark, reporting progress through `progress(done, total, label)`.
pub fn run(
    args: &BenchArgs,
    log: &mut dyn FnMut(&str),
    progress: &mut dyn FnMut(u64, u64, &str),
) -> Result<BenchReport, BenchError> {
    if args.frames == 0 {
        return Err(BenchError::NoFrames);
    }
    for (what, list) in [
        ("--rsm-sizes", &args.rsm_sizes),
        ("--vals", &args.vals),
        ("--view-samples", &args.view_samples),
    ] {
        if list.is_empty() {
            return Err(BenchError::EmptyList { what });
        }
    }
    let spec = args.scene.as_deref().unwrap_or(DEFAULT_SCENE);
    let scene = Scene::open(spec).map_err(|error| BenchError::Scene {
        scene: spec.to_string(),
        error,
    })?;
    let caches = args.caches.load(&scene, log)?;
    log(&format!(
        "scene {}: {} triangles, {} light caches",
        scene.name,
        scene.triangle_count(),
        caches.caches.len()
    ));
    let ctx = open_adapter(args, log)?;
    let adapter = AdapterSummary(&ctx.info).to_string();
    let base = base_settings(args, &scene, GiParams::default());
    let (name, triangles, cache_count) = (
        scene.name.clone(),
        scene.triangle_count(),
        caches.caches.len(),
    );
    let truth = if args.reference_spp > 0 {
        let image = render_reference(&ctx, &scene, &base, args, args.reference_bounces, progress)?;
        log(&format!(
            "reference: {} spp, {} bounce(s), relative standard error {:.2} %",
            image.samples,
            args.reference_bounces,
            image.relative_standard_error * 100.0
        ));
        Some(image)
    } else {
        None
    };
    let truth_mean = truth.as_ref().map_or(0.0, |r| {
        let sum: f64 = r.indirect.iter().flatten().map(|&c| f64::from(c)).sum();
        sum / (r.indirect.len() * 3).max(1) as f64
    });
    let pictures = args.plots.is_some();
    let mut renderer = Renderer::new(ctx, scene);
    renderer
        .gi::<LightSkin>()?
        .set_caches(&caches)
        .map_err(crate::renderer::RenderError::from)?;
    let timing_source = renderer.timing_source();

    let brsm_configs: Vec<(u32, u32)> = args
        .vals
        .iter()
        .flat_map(|&v| args.view_samples.iter().map(move |&s| (v, s)))
        .collect();
    let per_config = u64::from(args.warmup + args.frames);
    let total = args.rsm_sizes.len() as u64 * (1 + brsm_configs.len() as u64) * per_config;
    let mut done = 0u64;
    let mut rows = Vec::new();
    for &rsm_size in &args.rsm_sizes {
        // LightSkin first: every BRSM configuration is compared with it.
        let mut shared = GiParams::new(crate::gi::lightskin::LIGHTSKIN)
            .with("rsm_size", rsm_size)
            .with("occlusion", args.occlusion)
            .with("indirect_downscale", args.indirect_downscale);
        if let Some(k) = args.glossy_exponent {
            shared.set("glossy_exponent", k);
        }
        let brsm = |&(val_count, view_samples): &(u32, u32)| {
            let mut gi = shared
                .clone()
                .with("val_count", val_count)
                .with("view_samples", view_samples)
                .with("defensive", args.defensive);
            gi.method = crate::gi::lightskin::BRSM;
            gi
        };
        let configs = std::iter::once(shared.clone()).chain(brsm_configs.iter().map(brsm));
        let mut baseline: Option<(Vec<[f32; 4]>, f64, f64)> = None;
        for gi in configs {
            let label = match gi.method {
                crate::gi::lightskin::BRSM => format!(
                    "brsm rsm {rsm_size}² vals {} vs {}",
                    VAL_COUNT.u32(&gi),
                    VIEW_SAMPLES.u32(&gi)
                ),
                _ => format!("lightskin rsm {rsm_size}²"),
            } + ": frames";
            let settings = RenderSettings {
                gi: gi.clone(),
                ..base.clone()
            };
            let timed = time_config(
                &mut renderer,
                &settings,
                args.warmup,
                args.frames,
                &|_, _| {},
                &mut || {
                    done += 1;
                    progress(done, total, &label);
                },
            )?;
            let (reference, reference_mean, reference_ms) = baseline.get_or_insert_with(|| {
                let (_, mean) = mad(&timed.indirect, &timed.indirect);
                (timed.indirect.clone(), mean, timed.frame.median_ms)
            });
            let (difference, _) = mad(reference, &timed.indirect);
            let brsm = gi.method == crate::gi::lightskin::BRSM;
            let finals = truth.as_ref().map(|r| {
                final_errors(
                    &timed.hdr,
                    &timed.indirect,
                    &r.indirect,
                    timed.exposure,
                    args.width,
                )
            });
            rows.push(BenchRow {
                method: gi.method,
                rsm_size,
                val_count: brsm.then(|| VAL_COUNT.u32(&gi)),
                view_samples: brsm.then(|| VIEW_SAMPLES.u32(&gi)),
                fps: 1e3 / timed.frame.median_ms,
                mad: difference,
                mad_relative: if *reference_mean > 0.0 {
                    difference / *reference_mean
                } else {
                    0.0
                },
                speedup_vs_lightskin: *reference_ms / timed.frame.median_ms,
                vs_reference: truth
                    .as_ref()
                    .map(|r| errors(&r.indirect, &timed.indirect, args.width as usize)),
                final_psnr_db: finals.and_then(|f| f.psnr_db),
                final_flip: finals.map(|f| f.flip_mean),
                difference_image: truth
                    .as_ref()
                    .filter(|_| pictures)
                    .map(|r| difference_picture(&r.indirect, &timed.indirect, truth_mean)),
                stages: timed.stages,
                gi: timed.gi,
                frame: timed.frame,
            });
        }
    }
    Ok(BenchReport {
        adapter,
        timing_source,
        scene: name,
        triangles,
        caches: cache_count,
        width: args.width,
        height: args.height,
        frames: args.frames,
        warmup: args.warmup,
        defensive: args.defensive,
        glossy_exponent: args.glossy_exponent,
        occlusion: args.occlusion,
        reference_image: truth
            .as_ref()
            .filter(|_| pictures)
            .map(|r| reference_picture(&r.indirect, truth_mean)),
        reference: truth.map(|r| ReferenceSummary {
            spp: r.samples,
            bounces: args.reference_bounces,
            relative_standard_error: r.relative_standard_error,
            mean: truth_mean,
        }),
        rows,
    })
}

impl BenchReport {
    /// A markdown table: one row per configuration.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "Scene `{}` ({} triangles, {} light caches), {}×{}, adapter {}, {:?}, {} frames after {} warm-up, BRSM defensive α = {}.\n\n",
            self.scene,
            self.triangles,
            self.caches,
            self.width,
            self.height,
            self.adapter,
            self.timing_source,
            self.frames,
            self.warmup,
            self.defensive
        );
        if let Some(k) = self.glossy_exponent {
            s.insert_str(
                s.len() - 2,
                &format!(" Every material's Phong exponent set to {k}."),
            );
        }
        if !self.occlusion {
            s.insert_str(s.len() - 2, " Proxy occlusion off.");
        }
        if let Some(r) = &self.reference {
            s.insert_str(
                s.len() - 2,
                &format!(
                    " Reference: path traced, {} spp, {} bounce(s), relative standard error {:.2} %, mean {:.4e}.",
                    r.spp,
                    r.bounces,
                    r.relative_standard_error * 100.0,
                    r.mean
                ),
            );
        }
        s += "| method | RSM | VALs | view samples | GI ms (median / p95) | frame ms (median / p95) | fps | speed-up vs LightSkin | MAD vs LightSkin | MAD / mean | MAE vs reference | RMSE vs reference | MAE / mean vs reference | 8×8-block MAE / mean vs reference | bias vs reference | final PSNR vs reference | final FLIP vs reference |\n";
        s += "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
        for r in &self.rows {
            let opt = |v: Option<u32>| v.map_or("all".to_string(), |v| v.to_string());
            s += &format!(
                "| {:?} | {}² | {} | {} | {:.3} / {:.3} | {:.3} / {:.3} | {:.1} | {:.2}× | {:.3e} | {:.2} % | {} | {} | {} |\n",
                r.method,
                r.rsm_size,
                opt(r.val_count),
                r.view_samples.map_or("-".to_string(), |v| v.to_string()),
                r.gi.median_ms,
                r.gi.p95_ms,
                r.frame.median_ms,
                r.frame.p95_ms,
                r.fps,
                r.speedup_vs_lightskin,
                r.mad,
                r.mad_relative * 100.0,
                r.vs_reference.map_or("- | - | - | - | -".to_string(), |e| format!(
                    "{:.3e} | {:.3e} | {:.2} % | {:.2} % | {:+.2} %",
                    e.mae,
                    e.rmse,
                    e.mae_relative * 100.0,
                    e.block_mae_relative * 100.0,
                    e.bias_relative * 100.0
                )),
                match (r.final_psnr_db, r.vs_reference) {
                    (Some(p), _) => format!("{p:.2} dB"),
                    (None, Some(_)) => "identical".to_string(),
                    (None, None) => "-".to_string(),
                },
                r.final_flip.map_or("-".to_string(), |f| format!("{f:.4}"))
            );
        }
        s += &stage_table(
            &["method", "RSM", "VALs", "view samples"],
            self.rows.iter().map(|r| {
                (
                    vec![
                        format!("{:?}", r.method),
                        format!("{}²", r.rsm_size),
                        r.val_count.map_or("all".to_string(), |v| v.to_string()),
                        r.view_samples.map_or("-".to_string(), |v| v.to_string()),
                    ],
                    &r.stages,
                )
            }),
        );
        s
    }
}

/// "Per-stage medians (ms)" as a markdown table: the `labels` columns, then one column per stage
/// any row timed, "-" where a row did not run it.
pub(crate) fn stage_table<'a>(
    labels: &[&str],
    rows: impl Iterator<Item = (Vec<String>, &'a BTreeMap<String, StageStats>)> + Clone,
) -> String {
    let names: std::collections::BTreeSet<&String> =
        rows.clone().flat_map(|(_, stages)| stages.keys()).collect();
    let mut s = format!("\nPer-stage medians (ms):\n\n| {} |", labels.join(" | "));
    for name in &names {
        s += &format!(" {name} |");
    }
    s += "\n|";
    s += &"---|".repeat(labels.len() + names.len());
    s += "\n";
    for (cells, stages) in rows {
        s += &format!("| {} |", cells.join(" | "));
        for name in &names {
            s += &stages
                .get(*name)
                .map_or(" - |".to_string(), |st| format!(" {:.3} |", st.median_ms));
        }
        s += "\n";
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_tables_have_a_column_per_stage_any_row_ran() {
        let stat = |ms| StageStats {
            median_ms: ms,
            p95_ms: ms,
        };
        let a = BTreeMap::from([("gbuffer".to_string(), stat(1.0))]);
        let b = BTreeMap::from([
            ("gbuffer".to_string(), stat(2.0)),
            ("tonemap".to_string(), stat(0.5)),
        ]);
        let rows = [(vec!["x".to_string()], &a), (vec!["y".to_string()], &b)];
        let table = stage_table(&["row"], rows.iter().cloned());
        assert_eq!(
            table,
            "\nPer-stage medians (ms):\n\n| row | gbuffer | tonemap |\n|---|---|---|\n\
             | x | 1.000 | - |\n| y | 2.000 | 0.500 |\n"
        );
    }

    #[test]
    fn percentiles_of_sorted_samples() {
        let s = stats(vec![5.0, 1.0, 3.0, 2.0, 4.0]);
        assert_eq!(s.median_ms, 3.0);
        assert_eq!(s.p95_ms, 5.0);
    }

    #[test]
    fn mean_absolute_difference_is_per_channel() {
        let a = [[1.0, 2.0, 3.0, 1.0]];
        let b = [[1.5, 2.0, 2.0, 0.0]];
        let (d, mean) = mad(&a, &b);
        assert!((d - 0.5).abs() < 1e-12);
        assert!((mean - 2.0).abs() < 1e-12);
    }
}
