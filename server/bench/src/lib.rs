//! `lightcast-server bench`: a method's evaluation after its seed paper, on our scenes.
//!
//! What is swept is the method's ([`crate::gi::bench`], declared in `gi/<method>/bench.rs`);
//! how is the same for every method: the path-traced reference first renders the indirect
//! light at the scene's camera and light at every bounce count; then every configuration is
//! checked like a request, precomputed where its method needs it (afresh, timed, unless
//! `--cache-dir` names a store to load from), timed for `--frames` frames after `--warmup`
//! under a moving light (each frame's light differs from the last by a millionth of its
//! intensity, so nothing that depends on the light is reused, as in a session while the light
//! moves), and its indirect light measured against the reference at every bounce count and,
//! where its sweep says, against an earlier configuration. All configurations run in one
//! process on one GPU, so ratios between them are fair. `--compare-methods` adds every other
//! method's ladder at equal time.
//!
//! [`stream`] is `bench-stream` (the stream codecs), [`plots`] draws a report.

// Paths as when the layers were modules of one crate: `crate::bench::…`, `crate::gi::…`.
use crate as bench;
use lightcast_gi as gi;
use lightcast_passes::{gpu, passes};
use lightcast_render::{debug_views, offline, quality, renderer};
use lightcast_scene as scene;
use lightcast_service as service;

pub mod report;
pub mod stream;

#[cfg(feature = "plots")]
pub mod plots;

use crate::gi::bench::{Configuration, Sweep, SweepArgs};
use crate::gi::params::Senders;
use crate::gi::precompute::PrecomputeKey;
use crate::gi::{reference::ReferenceImage, GiMethod};
use crate::gpu::{context::AdapterSummary, BackendChoice, GpuContext};
use crate::offline::{ExposureArg, GiArgs, DEFAULT_SCENE};
use crate::passes::frame_uniforms::MAX_LIGHTS;
use crate::passes::tonemap::luminance;
use crate::quality::{errors, final_errors, ErrorStats};
use crate::renderer::{RenderSettings, Renderer};
use crate::scene::{
    default_light::{default_camera, default_lights},
    Scene,
};
use lightcast_protocol::{GiParams, Light, LightKind};
pub use report::{
    stats, BenchReport, BenchRow, BounceError, Cell, MethodRow, Precomputed, ReferenceSummary,
    StageStats,
};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

/// Options of `lightcast-server bench`.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchArgs {
    /// The method whose evaluation runs (its sweep's flags are below, each naming the methods
    /// that read it). `lightcast-server bench-sweeps` lists every method's.
    #[arg(long, default_value = "brsm", value_parser = crate::gi::parse_method)]
    pub gi: GiMethod,
    /// Scene: a .gltf/.glb file or a procedural scene (see `render --help`).
    #[arg(long)]
    pub scene: Option<String>,
    #[arg(long, default_value_t = 1920)]
    pub width: u32,
    #[arg(long, default_value_t = 1080)]
    pub height: u32,
    #[command(flatten)]
    pub sweep: SweepArgs,
    /// Bounce counts the error is measured at, each against a reference traced with as many
    /// (comma-separated; default: the sweep's, see `bench-sweeps`).
    #[arg(long, value_delimiter = ',')]
    pub bounces: Vec<u32>,
    /// Samples per pixel of the path-traced reference every configuration is compared with.
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u32).range(1..))]
    pub reference_spp: u32,
    /// Also run every other method's ladder of settings and compare every method's
    /// single-bounce error at about the GI time of the sweep's centre (equal time).
    #[arg(long)]
    pub compare_methods: bool,
    /// Measure every configuration with the scene's first light split into each of these
    /// numbers of lights (comma-separated, 1 … 16): N lights of 1/N of its intensity around
    /// its place (see [`split_light`]), so the scene receives about the same light and GI
    /// time and error show what more lights cost. Each row names its count and its GI time
    /// over the same configuration's with one light. Default: the scene's own lights.
    #[arg(long, value_delimiter = ',', conflicts_with = "compare_methods")]
    pub light_counts: Vec<usize>,
    /// Timed frames per configuration.
    #[arg(long, default_value_t = 30)]
    pub frames: u32,
    /// Untimed frames before timing each configuration.
    #[arg(long, default_value_t = 5)]
    pub warmup: u32,
    /// The parameters every configuration starts from (`--gi-param NAME=VALUE`), and
    /// `--cache-dir`: load precomputed sets from that store instead of building them afresh.
    /// `emitters` is off unless given: the built-in scenes' light stands in for their
    /// emitters, and the methods without them are measured against a reference without them.
    #[command(flatten)]
    pub gi_args: GiArgs,
    /// Write the results as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the results as a markdown table here.
    #[arg(long)]
    pub markdown: Option<PathBuf>,
    /// Write PNG plots to PREFIX-error-by-<axis>.png, PREFIX-gi-ms-by-<axis>.png (and
    /// PREFIX-error-vs-baseline-by-<axis>.png), the reference's indirect light and every
    /// configuration's difference from it. Needs a build with `--features plots`.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// An environment every frame and its reference are lit by besides the scene's lights.
    #[command(flatten)]
    pub environment: crate::offline::EnvironmentArgs,
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
    /// The G-buffer and the RSM as visibility buffers and their `gbuffer_resolve` and
    /// `rsm_resolve` (`on`, needs triangle ids) or every target rasterised (`off`); `auto`: on
    /// except on a CPU adapter, as the service renders by default.
    /// `bench/visibility-buffer.sh` runs both to measure what it saves.
    #[arg(long, value_enum, default_value = "auto")]
    pub visibility_buffer: crate::renderer::VisibilityBuffer,
}

/// See [`BenchArgs::stage_clock`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum StageClock {
    Auto,
    Gpu,
    Wall,
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
    Offline(#[from] crate::offline::OfflineError),
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
    #[error(transparent)]
    Render(#[from] crate::renderer::RenderError),
    #[error("--{flag} is empty")]
    EmptyList { flag: String },
    #[error("--{flag} is not a flag of `bench --gi {method}`; its sweep's flags are {flags}")]
    ForeignFlag {
        flag: String,
        method: GiMethod,
        flags: String,
    },
    #[error("--frames must be at least 1")]
    NoFrames,
    #[error(transparent)]
    NoVisibilityBuffer(#[from] crate::renderer::NoVisibilityBuffer),
    #[error("--environment: {0}")]
    Environment(String),
    #[error("reference: {0}")]
    Reference(#[from] crate::gi::reference::ReferenceError),
    #[error("bench --gi {method}: the method has no evaluation; those with one: {with}")]
    NoEvaluation { method: GiMethod, with: String },
    #[error("{configuration}: {reason}")]
    Configuration {
        configuration: String,
        reason: String,
    },
    #[error("--compare-methods needs 1 in --bounces (the comparison is at one bounce)")]
    NoSingleBounce,
    #[error("--light-counts: {count} is outside 1..={max}")]
    LightCount { count: usize, max: usize },
}

/// The adapter of `backend`, logged, with its stages timed as `clock` says.
pub fn open_adapter(
    backend: BackendChoice,
    clock: StageClock,
    log: &mut dyn FnMut(&str),
) -> Result<GpuContext, BenchError> {
    let mut ctx = GpuContext::new(backend)?;
    let wall = match clock {
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

fn mean(image: &[[f32; 3]]) -> f64 {
    let sum: f64 = image.iter().flatten().map(|&c| f64::from(c)).sum();
    sum / (image.len() * 3).max(1) as f64
}

/// The frame every configuration renders: the scene's camera and light at the bench's size
/// and exposure, a 2048² shadow map, indirect light by `gi`.
fn base_settings(args: &BenchArgs, scene: &Scene, gi: GiParams) -> RenderSettings {
    RenderSettings {
        width: args.width,
        height: args.height,
        camera: default_camera(scene),
        lights: default_lights(scene, MAX_LIGHTS),
        environment: args.environment.environment(),
        exposure: args.exposure.0,
        shadow_map_size: 2048,
        capture_hdr: false,
        debug_view: lightcast_protocol::View::FINAL,
        gi,
        history: None,
        still: false,
        yuv420: false,
        poses: Vec::new(),
        pick: None,
    }
}

/// Timings of one configuration's frames.
struct Timed {
    stages: BTreeMap<String, StageStats>,
    gi: StageStats,
    frame: StageStats,
}

/// The indirect light (and the final image it is part of) of one frame.
struct Captured {
    indirect: Vec<[f32; 4]>,
    hdr: Vec<[f32; 4]>,
    exposure: f32,
}

/// One run's GPU state and what it has rendered so far.
struct Bench<'a> {
    args: &'a BenchArgs,
    scene: Scene,
    renderer: Renderer,
    base: RenderSettings,
    /// The references by (bounces, emitters, senders), rendered when first needed.
    references: Vec<(ReferenceKey, ReferenceImage)>,
    /// The precomputed set each registry entry's renderer holds, by its key.
    installed: BTreeMap<usize, (PrecomputeKey, Precomputed)>,
    /// Where built sets go (afresh: a directory of this run, removed at the end).
    store: GiArgs,
    log: &'a mut dyn FnMut(&str),
    progress: &'a mut dyn FnMut(u64, u64, &str),
}

/// What tells the references of a run apart.
#[derive(Clone, Copy, Debug, PartialEq)]
struct ReferenceKey {
    bounces: u32,
    emitters: bool,
    senders: Senders,
}

impl Bench<'_> {
    /// The reference for frames of `gi` at `bounces`: lit by emissive surfaces only for a
    /// method that lights from them and has `emitters` on, so both see the same sources;
    /// reflecting direct light on as `senders` says (full: the truth).
    fn reference(
        &mut self,
        gi: &GiParams,
        bounces: u32,
        senders: Senders,
    ) -> Result<usize, BenchError> {
        use crate::gi::reference::{PathTracer, ReferenceSettings};
        let emitters = crate::gi::reference_emitters(gi);
        let key = ReferenceKey {
            bounces,
            emitters,
            senders,
        };
        if let Some(i) = self.references.iter().position(|(k, _)| *k == key) {
            return Ok(i);
        }
        let mut tracer = PathTracer::new(self.renderer.context().clone(), &self.scene)?;
        let settings = ReferenceSettings {
            bounces,
            seed: 0,
            roughness: crate::gi::common::params::roughness_override(gi),
            emitters,
            senders,
        };
        // Small calls keep each submission short (lavapipe drops long ones) and show progress.
        let (spp, per_call) = (self.args.reference_spp, 4);
        let label = format!(
            "reference path tracing, {bounces} bounce(s){}{}: samples per pixel",
            if emitters { " with emitters" } else { "" },
            if senders == Senders::Diffuse {
                ", diffuse senders"
            } else {
                ""
            }
        );
        let b = &self.base;
        let environment = match &b.environment {
            Some(e) => Some(std::sync::Arc::new(
                crate::passes::environment::FrameEnvironment::new(
                    e,
                    &b.lights,
                    self.renderer.scene().environment_image.as_deref(),
                )
                .map_err(|e| BenchError::Environment(e.to_string()))?,
            )),
            None => None,
        };
        let mut done = 0;
        while done < spp {
            let n = per_call.min(spp - done);
            tracer.accumulate(
                b.width,
                b.height,
                &b.camera,
                &b.lights,
                environment.as_ref(),
                &settings,
                n,
            )?;
            done += n;
            (self.progress)(u64::from(done), u64::from(spp), &label);
        }
        let image = tracer
            .read()?
            .expect("the reference has accumulated samples");
        (self.log)(&format!(
            "reference: {} spp, {bounces} bounce(s), {} senders, relative standard error {:.2} %",
            image.samples,
            senders.name(),
            image.relative_standard_error * 100.0
        ));
        self.references.push((key, image));
        Ok(self.references.len() - 1)
    }

    /// The references frames of `gi` at `bounces` are measured against: the full one, and the
    /// one of the light transport the method models where that differs.
    fn references_of(
        &mut self,
        gi: &GiParams,
        bounces: u32,
    ) -> Result<(usize, Option<usize>), BenchError> {
        let full = self.reference(gi, bounces, Senders::Full)?;
        let modelled = match crate::gi::reference_senders(gi) {
            Senders::Full => None,
            senders => Some(self.reference(gi, bounces, senders)?),
        };
        Ok((full, modelled))
    }

    /// `indirect`'s errors against the full reference and the modelled one (if any).
    fn errors_of(
        &self,
        (full, modelled): (usize, Option<usize>),
        indirect: &[[f32; 4]],
    ) -> (ErrorStats, Option<ErrorStats>) {
        let width = self.args.width as usize;
        let against = |i: usize| errors(&self.references[i].1.indirect, indirect, width);
        (against(full), modelled.map(against))
    }

    /// Gives the renderer the set `gi`'s frames read, building it when its key differs from
    /// the one it holds; what the rows report of it.
    fn precompute(&mut self, gi: &GiParams) -> Result<Option<Precomputed>, BenchError> {
        let (index, entry) = crate::gi::entry(gi.method);
        let Some(pre) = entry.precompute else {
            return Ok(None);
        };
        let facts = crate::gi::precompute::SceneFacts::of(&self.scene);
        let key = (pre.key)(gi, &facts).map_err(|e| BenchError::Configuration {
            configuration: gi.method.to_string(),
            reason: e.to_string(),
        })?;
        if let Some((held, stats)) = self.installed.get(&index) {
            if *held == key {
                return Ok(Some(stats.clone()));
            }
        }
        let started = Instant::now();
        let ctx = self.renderer.context().clone();
        let built = self
            .store
            .precompute(gi, &self.scene, Some(&ctx), self.log)?
            .expect("the method has a precomputation");
        let stats = Precomputed {
            what: format!("{} {key}", pre.label),
            size: pre
                .budget
                .as_ref()
                .map(|b| format!("{} {}", built.units, b.unit)),
            seconds: started.elapsed().as_secs_f64(),
            from_store: built.from_store,
        };
        self.renderer.set_scene_data(gi.method, &built.data)?;
        self.installed.insert(index, (key, stats.clone()));
        Ok(Some(stats))
    }

    /// `warmup + frames` frames of `gi` under a moving light, with a history, so a method
    /// that converges over frames runs one step of it per frame, as a session does.
    fn time(&mut self, gi: &GiParams, what: &str) -> Result<Timed, BenchError> {
        let args = self.args;
        let total = u64::from(args.warmup + args.frames);
        let label = format!("{what}: frames");
        let mut per_stage: BTreeMap<String, Vec<f64>> = BTreeMap::new();
        let (mut gi_ms, mut frame_ms) = (Vec::new(), Vec::new());
        for i in 0..args.warmup + args.frames {
            let mut s = RenderSettings {
                gi: gi.clone(),
                history: Some(1),
                ..self.base.clone()
            };
            for light in &mut s.lights {
                light.intensity *= 1.0 + 1e-6 * (i % 2) as f32;
            }
            let frame = self.renderer.render(&s)?;
            (self.progress)(u64::from(i + 1), total, &label);
            if i < args.warmup {
                continue;
            }
            let timed = frame
                .timings
                .iter()
                .filter(|t| t.stage != crate::passes::stages::READBACK_COPY);
            for t in timed.clone() {
                per_stage.entry(t.stage.to_string()).or_default().push(t.ms);
            }
            gi_ms.push(
                timed
                    .clone()
                    .filter(|t| crate::passes::stages::is_gi(t.stage))
                    .map(|t| t.ms)
                    .sum(),
            );
            frame_ms.push(timed.map(|t| t.ms).sum());
        }
        Ok(Timed {
            stages: per_stage.into_iter().map(|(k, v)| (k, stats(v))).collect(),
            gi: stats(gi_ms),
            frame: stats(frame_ms),
        })
    }

    /// One frame of `gi` at `bounces`, its indirect light and final image captured (afresh:
    /// a method that converges over frames shows its converged result).
    fn capture(&mut self, gi: &GiParams, bounces: u32) -> Result<Captured, BenchError> {
        let s = RenderSettings {
            gi: gi
                .clone()
                .with(crate::gi::common::params::BOUNCES.name, bounces),
            capture_hdr: true,
            ..self.base.clone()
        };
        let frame = self.renderer.render(&s)?;
        Ok(Captured {
            indirect: frame.indirect.unwrap_or_default(),
            hdr: frame.hdr.unwrap_or_default(),
            exposure: frame.exposure_scale,
        })
    }

    /// Checks `c` as a request would be checked at every bounce count, before the long steps.
    fn check(&self, c: &Configuration, bounces: &[u32]) -> Result<(), BenchError> {
        let refuse = |reason: String| BenchError::Configuration {
            configuration: c.label(),
            reason,
        };
        for &b in bounces {
            let gi =
                c.gi.clone()
                    .with(crate::gi::common::params::BOUNCES.name, b);
            let settings = RenderSettings {
                gi,
                ..self.base.clone()
            };
            settings
                .validate(self.renderer.context())
                .map_err(|e| refuse(e.to_string()))?;
        }
        if let Some(pre) = crate::gi::entry(c.gi.method).1.precompute {
            let facts = crate::gi::precompute::SceneFacts::of(&self.scene);
            (pre.key)(&c.gi, &facts).map_err(|e| refuse(e.to_string()))?;
        }
        Ok(())
    }
}

/// The sweep of `args.gi` and the values of its axes; a flag of another method's sweep, or an
/// empty list where the sweep needs values, is refused.
fn sweep_of(args: &BenchArgs) -> Result<&'static Sweep, BenchError> {
    let sweep = crate::gi::bench::of(args.gi).ok_or_else(|| BenchError::NoEvaluation {
        method: args.gi,
        with: crate::gi::bench::methods()
            .iter()
            .map(|m| m.to_string())
            .collect::<Vec<_>>()
            .join(", "),
    })?;
    for (flag, values) in &args.sweep.0 .0 {
        let Some(axis) = sweep.axes.iter().find(|a| a.flag == flag) else {
            let flags: Vec<String> = sweep.axes.iter().map(|a| format!("--{}", a.flag)).collect();
            return Err(BenchError::ForeignFlag {
                flag: flag.clone(),
                method: args.gi,
                flags: flags.join(", "),
            });
        };
        if values.is_empty() && !axis.may_be_empty {
            return Err(BenchError::EmptyList { flag: flag.clone() });
        }
    }
    Ok(sweep)
}

/// Runs `args.gi`'s evaluation, reporting progress through `progress(done, total, label)`.
pub fn run(
    args: &BenchArgs,
    log: &mut dyn FnMut(&str),
    progress: &mut dyn FnMut(u64, u64, &str),
) -> Result<BenchReport, BenchError> {
    if args.frames == 0 {
        return Err(BenchError::NoFrames);
    }
    let sweep = sweep_of(args)?;
    let bounces = if args.bounces.is_empty() {
        sweep.bounces.to_vec()
    } else {
        args.bounces.clone()
    };
    if args.compare_methods && !bounces.contains(&1) {
        return Err(BenchError::NoSingleBounce);
    }
    let spec = args.scene.as_deref().unwrap_or(DEFAULT_SCENE);
    let mut scene = Scene::open(spec).map_err(|error| BenchError::Scene {
        scene: spec.to_string(),
        error,
    })?;
    args.environment.attach_image(&mut scene)?;
    let mut base_gi = args.gi_args.gi(args.gi);
    let emitters = crate::gi::common::params::EMITTERS.name;
    if base_gi.get(emitters).is_none() {
        base_gi.set(emitters, false);
    }
    let configs = (sweep.configurations)(&base_gi, &args.sweep.0);
    let ladders: Vec<Configuration> = if args.compare_methods {
        crate::gi::REGISTRY
            .iter()
            .filter_map(|e| e.bench)
            .flat_map(|s| (s.ladder)(&base_gi))
            .collect()
    } else {
        Vec::new()
    };
    log(&format!(
        "scene {}: {} triangles; {} configurations{}",
        scene.name,
        scene.triangle_count(),
        configs.len(),
        if ladders.is_empty() {
            String::new()
        } else {
            format!(
                ", {} settings of other methods at equal time",
                ladders.len()
            )
        }
    ));
    let ctx = open_adapter(args.backend, args.stage_clock, log)?;
    let adapter = AdapterSummary(&ctx.info).to_string();
    // Built afresh in a directory of this run (so the time is the build's), unless a store
    // was named.
    let fresh = args
        .gi_args
        .cache_dir
        .is_none()
        .then(|| std::env::temp_dir().join(format!("lightcast-bench-{}", std::process::id())));
    let store = GiArgs {
        cache_dir: fresh.clone().or(args.gi_args.cache_dir.clone()),
        ..args.gi_args.clone()
    };
    let base = base_settings(args, &scene, base_gi.clone());
    let (name, triangles) = (scene.name.clone(), scene.triangle_count());
    let mut renderer = Renderer::new(ctx, scene.clone());
    renderer.choose_visibility_buffer(args.visibility_buffer)?;
    let timing_source = renderer.timing_source();
    let mut bench = Bench {
        args,
        scene,
        renderer,
        base,
        references: Vec::new(),
        installed: BTreeMap::new(),
        store,
        log,
        progress,
    };
    let result = if args.light_counts.is_empty() {
        run_configurations(&mut bench, &configs, &ladders, &bounces)
    } else {
        run_light_counts(&mut bench, &configs, &bounces)
    };
    if let Some(dir) = fresh {
        // Best effort: a failed removal leaves a temporary directory, not a wrong result.
        let _ = std::fs::remove_dir_all(dir);
    }
    let (rows, methods) = result?;
    let pictures = args.plots.is_some();
    let first = bench.references.first();
    Ok(BenchReport {
        method: args.gi,
        adapter,
        timing_source,
        cpu_threads: rayon::current_num_threads(),
        scene: name,
        triangles,
        width: args.width,
        height: args.height,
        frames: args.frames,
        warmup: args.warmup,
        base: base_gi.values.clone(),
        reference_image: first
            .filter(|_| pictures)
            .map(|(_, r)| reference_picture(&r.indirect, mean(&r.indirect))),
        references: bench
            .references
            .iter()
            .map(|(key, r)| ReferenceSummary {
                bounces: key.bounces,
                emitters: key.emitters,
                senders: key.senders,
                spp: r.samples,
                relative_standard_error: r.relative_standard_error,
                mean: mean(&r.indirect),
            })
            .collect(),
        rows,
        methods,
    })
}

/// `count` lights in place of `light`, each of 1/`count` of its intensity: directional lights
/// tilted by up to 5° around its direction, spot and point lights on a circle of 5 % of the
/// scene's radius around its position (across its direction), evenly spaced.
pub fn split_light(light: &Light, count: usize, radius: f32) -> Vec<Light> {
    if count <= 1 {
        return vec![light.clone()];
    }
    let direction = glam::Vec3::from(light.direction).normalize_or(glam::Vec3::NEG_Y);
    let (u, v) = direction.any_orthonormal_pair();
    (0..count)
        .map(|i| {
            let angle = std::f32::consts::TAU * i as f32 / count as f32;
            let across = u * angle.cos() + v * angle.sin();
            let mut l = light.clone();
            l.intensity /= count as f32;
            if l.kind == LightKind::Directional {
                l.direction = (direction + across * 5f32.to_radians().tan())
                    .normalize()
                    .to_array();
            } else {
                l.position = (glam::Vec3::from(light.position) + across * 0.05 * radius).to_array();
            }
            l
        })
        .collect()
}

/// `--light-counts`: every configuration at every light count, each count with its own
/// references; rows name their count and their GI time over the one-light row's.
fn run_light_counts(
    bench: &mut Bench,
    configs: &[Configuration],
    bounces: &[u32],
) -> Result<(Vec<BenchRow>, Vec<MethodRow>), BenchError> {
    let Some(first) = bench.base.lights.first().cloned() else {
        return Ok((Vec::new(), Vec::new()));
    };
    let radius = bench.scene.bounds.radius();
    let mut rows: Vec<BenchRow> = Vec::new();
    let mut one_light: BTreeMap<usize, f64> = BTreeMap::new();
    for &count in &bench.args.light_counts.clone() {
        if !(1..=MAX_LIGHTS).contains(&count) {
            return Err(BenchError::LightCount {
                count,
                max: MAX_LIGHTS,
            });
        }
        bench.base.lights = split_light(&first, count, radius);
        bench.references.clear();
        (bench.log)(&format!("{count} light(s)"));
        let (counted, _) = run_configurations(bench, configs, &[], bounces)?;
        for (i, mut row) in counted.into_iter().enumerate() {
            let gi_ms = row.gi.median_ms;
            if count == 1 {
                one_light.insert(i, gi_ms);
            }
            let ratio = one_light
                .get(&i)
                .map_or("–".to_string(), |one| format!("{:.2}", gi_ms / one));
            row.cells.splice(
                0..0,
                [
                    Cell {
                        column: "lights".into(),
                        value: count.to_string(),
                    },
                    Cell {
                        column: "GI time / 1 light".into(),
                        value: ratio,
                    },
                ],
            );
            // A baseline index points into this count's rows.
            row.baseline = row.baseline.map(|b| b + rows.len() - i);
            rows.push(row);
        }
    }
    Ok((rows, Vec::new()))
}

/// Checks every configuration, then measures each; then the equal-time comparison.
fn run_configurations(
    bench: &mut Bench,
    configs: &[Configuration],
    ladders: &[Configuration],
    bounces: &[u32],
) -> Result<(Vec<BenchRow>, Vec<MethodRow>), BenchError> {
    for c in configs.iter().chain(ladders) {
        bench.check(c, bounces)?;
    }
    for c in configs.iter().chain(ladders) {
        for &b in bounces {
            bench.references_of(&c.gi, b)?;
        }
    }
    // The indirect light of configurations a later one is compared with.
    let mut baselines: BTreeMap<usize, Vec<[f32; 3]>> = BTreeMap::new();
    let mut rows: Vec<BenchRow> = Vec::new();
    let pictures = bench.args.plots.is_some();
    let width = bench.args.width;
    for (i, c) in configs.iter().enumerate() {
        let what = format!("{} ({} of {})", c.label(), i + 1, configs.len());
        let precomputed = bench.precompute(&c.gi)?;
        let timed = bench.time(&c.gi, &what)?;
        let mut errors_by_bounce = Vec::new();
        let mut first: Option<Captured> = None;
        for &b in bounces {
            let shot = bench.capture(&c.gi, b)?;
            let refs = bench.references_of(&c.gi, b)?;
            let (vs_reference, vs_modelled) = bench.errors_of(refs, &shot.indirect);
            let truth = &bench.references[refs.0].1.indirect;
            let finals = final_errors(&shot.hdr, &shot.indirect, truth, shot.exposure, width);
            errors_by_bounce.push(BounceError {
                bounces: b,
                vs_reference,
                vs_modelled,
                final_psnr_db: finals.psnr_db,
                final_flip: finals.flip_mean,
            });
            first.get_or_insert(shot);
        }
        let shot = first.expect("at least one bounce count");
        let r = bench.reference(&c.gi, bounces[0], Senders::Full)?;
        let truth = &bench.references[r].1.indirect;
        let difference_image =
            pictures.then(|| difference_picture(truth, &shot.indirect, mean(truth)));
        let vs_baseline: Option<ErrorStats> = c
            .baseline
            .and_then(|b| baselines.get(&b))
            .map(|image| errors(image, &shot.indirect, width as usize));
        if configs.iter().any(|o| o.baseline == Some(i)) {
            baselines.insert(
                i,
                shot.indirect.iter().map(|p| [p[0], p[1], p[2]]).collect(),
            );
        }
        let first_error = errors_by_bounce[0].vs_reference;
        (bench.log)(&format!(
            "{what}: GI {:.2} ms, error against the reference {:.2} % (8×8 blocks {:.2} %){}",
            timed.gi.median_ms,
            first_error.mae_relative * 100.0,
            first_error.block_mae_relative * 100.0,
            errors_by_bounce[0]
                .vs_modelled
                .map_or(String::new(), |e| format!(
                    ", against the modelled transport {:.2} % (8×8 blocks)",
                    e.block_mae_relative * 100.0
                ))
        ));
        rows.push(BenchRow {
            method: c.gi.method,
            cells: c
                .cells
                .iter()
                .map(|(column, value)| Cell {
                    column: column.to_string(),
                    value: value.clone(),
                })
                .collect(),
            params: c.gi.clone(),
            precomputed,
            fps: 1e3 / timed.frame.median_ms,
            speedup_vs_baseline: vs_baseline
                .and(c.baseline)
                .map(|b| rows[b].frame.median_ms / timed.frame.median_ms),
            stages: timed.stages,
            gi: timed.gi,
            frame: timed.frame,
            errors: errors_by_bounce,
            baseline: c.baseline.filter(|_| vs_baseline.is_some()),
            vs_baseline,
            points: c.points.clone(),
            difference_image,
        });
    }
    let methods = if ladders.is_empty() {
        Vec::new()
    } else {
        equal_time(bench, configs, &rows, ladders)?
    };
    Ok((rows, methods))
}

/// The equal-time comparison: the sweep's centre (its GI time and single-bounce error) first,
/// then every other method's ladder, each rung's error against the single-bounce reference;
/// per method the rung nearest the centre's GI time is marked.
fn equal_time(
    bench: &mut Bench,
    configs: &[Configuration],
    rows: &[BenchRow],
    ladders: &[Configuration],
) -> Result<Vec<MethodRow>, BenchError> {
    let centre = configs.iter().position(|c| c.centre).unwrap_or(0);
    let row = &rows[centre];
    let single = row
        .errors
        .iter()
        .find(|e| e.bounces == 1)
        .ok_or(BenchError::NoSingleBounce)?;
    let skip = row.method;
    let target = row.gi.median_ms;
    let cells = |c: &Configuration| {
        c.cells
            .iter()
            .map(|(column, value)| format!("{column} {value}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut out = vec![MethodRow {
        method: skip,
        setting: cells(&configs[centre]),
        gi: row.gi,
        vs_reference: single.vs_reference,
        vs_modelled: single.vs_modelled,
        nearest_equal_time: true,
    }];
    for rung in ladders.iter().filter(|c| c.gi.method != skip) {
        let gi = rung
            .gi
            .clone()
            .with(crate::gi::common::params::BOUNCES.name, 1);
        bench.precompute(&gi)?;
        let timed = bench.time(&gi, &rung.label())?;
        let shot = bench.capture(&gi, 1)?;
        let refs = bench.references_of(&gi, 1)?;
        let (vs_reference, vs_modelled) = bench.errors_of(refs, &shot.indirect);
        out.push(MethodRow {
            method: gi.method,
            setting: cells(rung),
            gi: timed.gi,
            vs_reference,
            vs_modelled,
            nearest_equal_time: false,
        });
    }
    let methods: Vec<GiMethod> = out.iter().skip(1).map(|r| r.method).collect();
    for method in methods {
        let nearest = out
            .iter_mut()
            .skip(1)
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        bench: BenchArgs,
    }

    /// Every sweep's flags and the bench's own make one valid command line (clap checks
    /// that no flag is declared twice).
    #[test]
    fn the_bench_command_line_is_valid() {
        use clap::CommandFactory;
        Cli::command().debug_assert();
    }

    /// A flag of another method's sweep is refused naming the method's own; so is an empty
    /// list where the sweep needs values, and a method without a sweep.
    #[test]
    fn flags_of_other_sweeps_are_refused() {
        let parse = |line: &[&str]| {
            let args = Cli::try_parse_from(std::iter::once("bench").chain(line.iter().copied()))
                .expect("parses")
                .bench;
            sweep_of(&args).map(drop).map_err(|e| e.to_string())
        };
        let sweeps = crate::gi::bench::all();
        let [(own, methods), (other, others), ..] = &sweeps[..] else {
            panic!("fewer than two sweeps");
        };
        let (method, other_method) = (methods[0].to_string(), others[0].to_string());
        let flag = format!("--{}", own.axes[0].flag);
        assert_eq!(parse(&["--gi", &method, &flag, "64"]), Ok(()));
        let foreign = parse(&["--gi", &other_method, &flag, "64"]).expect_err("foreign");
        let expected = format!(
            "{flag} is not a flag of `bench --gi {other_method}`; its sweep's flags are --{}",
            other.axes[0].flag
        );
        assert!(foreign.starts_with(&expected), "{foreign}");
        let required = own.axes.iter().find(|a| !a.may_be_empty).expect("a list");
        assert_eq!(
            parse(&["--gi", &method, &format!("--{}", required.flag)]),
            Err(format!("--{} is empty", required.flag))
        );
        let without = crate::gi::methods()
            .find(|&m| crate::gi::bench::of(m).is_none())
            .expect("a method without a sweep");
        let none = parse(&["--gi", without.name()]).expect_err("no sweep");
        assert!(
            none.contains("has no evaluation; those with one: "),
            "{none}"
        );
    }

    #[test]
    fn split_lights_share_the_light_around_its_place() {
        use lightcast_protocol::{Light, LightKind};
        let spot = Light {
            kind: LightKind::Spot,
            position: [1.0, 2.0, 3.0],
            direction: [0.0, -1.0, 0.0],
            color: [1.0; 3],
            intensity: 8.0,
            inner_cone: 0.3,
            outer_cone: 0.5,
        };
        assert_eq!(super::split_light(&spot, 1, 10.0), vec![spot.clone()]);
        for kind in [LightKind::Spot, LightKind::Directional] {
            let light = Light {
                kind,
                ..spot.clone()
            };
            let split = super::split_light(&light, 5, 10.0);
            assert_eq!(split.len(), 5);
            let total: f32 = split.iter().map(|l| l.intensity).sum();
            assert!((total - 8.0).abs() < 1e-5);
            for l in &split {
                let off = glam::Vec3::from(l.position).distance(glam::Vec3::from(light.position));
                let tilt = glam::Vec3::from(l.direction).angle_between(glam::Vec3::NEG_Y);
                match kind {
                    LightKind::Directional => assert!((tilt.to_degrees() - 5.0).abs() < 0.01),
                    _ => assert!((off - 0.5).abs() < 1e-4, "{off}"),
                }
            }
        }
    }

    #[test]
    fn difference_pictures_are_red_where_brighter_and_blue_where_darker() {
        let truth = [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0]];
        let other = [
            [3.0, 3.0, 3.0, 1.0],
            [0.0, 0.0, 0.0, 1.0],
            [1.0, 1.0, 1.0, 1.0],
        ];
        let rgb = difference_picture(&truth, &other, 1.0);
        assert_eq!(rgb, vec![255, 0, 0, 0, 0, 186, 0, 0, 0]);
    }
}
