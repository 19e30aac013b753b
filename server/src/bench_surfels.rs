//! `lightcast-server bench --gi surfels`: seed 001's evaluation (its Figure 8 and timing
//! table) on our scenes.
//!
//! The sweep varies one parameter at a time around a centre (`--gi-param`'s `surfel_count`,
//! `surfel_links` and `sh_bands`, by default the table's 32,768 surfels, 128 links and 3
//! bands): every surfel count of
//! `--sweep-surfels`, every link count of `--sweep-links` and every band count of
//! `--sweep-bands`, the others at the centre. For each configuration it reports
//!
//! - the precomputation's wall time on this machine's CPU (surfels, hierarchy, lattice, links;
//!   built afresh, not taken from the store);
//! - the per-frame GPU time under a moving light, by stage: the light's intensity changes by a
//!   millionth every frame, so every frame relights the surfels, pulls their flux up and relights
//!   the caches (one bounce) before shading, as the paper's dynamic scenes do;
//! - the error of the indirect light against the path-traced reference at every bounce count
//!   of `--bounces` (the reference traced with as many bounces, the surfels converged to them).

use crate::bench::{render_reference, BenchArgs, BenchError, MethodRow, StageStats, Timed};
use crate::gi::precompute::{BuildEnv, Store};
use crate::gi::surfels::{self, SurfelParams, Surfels};

use crate::gpu::context::AdapterSummary;
use crate::offline::DEFAULT_SCENE;
use crate::quality::{errors, ErrorStats};
use crate::renderer::{RenderSettings, Renderer};
use crate::scene::Scene;
use lightcast_protocol::GiParams;
use std::collections::BTreeMap;
use std::time::Instant;

/// The sweep's lists (`bench --gi surfels`).
#[derive(Clone, Debug, clap::Args)]
pub struct SurfelSweep {
    /// `--gi surfels`: surfel counts n_S to sweep, with links and bands at the centre
    /// (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = [8192, 32768, 131072])]
    pub sweep_surfels: Vec<u32>,
    /// `--gi surfels`: links per cache n_L to sweep, with surfels and bands at the centre.
    #[arg(long, value_delimiter = ',', default_values_t = [32, 64, 128, 256])]
    pub sweep_links: Vec<u32>,
    /// `--gi surfels`: SH bands to sweep, with surfels and links at the centre.
    #[arg(long, value_delimiter = ',', default_values_t = [2, 3, 4])]
    pub sweep_bands: Vec<u32>,
    /// `--gi surfels`: bounce counts the error is measured at, each against a reference
    /// traced with as many bounces (replaces `--reference-bounces`).
    #[arg(long, value_delimiter = ',', default_values_t = [1, 3])]
    pub bounces: Vec<u32>,
    /// `--gi surfels`: also run LightSkin, BRSM and `clustered` over a ladder of settings each
    /// and compare every method's single-bounce error at about the GI time of the sweep's
    /// centre (the comparison of all GI methods at equal time).
    #[arg(long)]
    pub compare_methods: bool,
}

/// Which parameter a row varies from the centre.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Varied {
    Centre,
    Surfels,
    Links,
    Bands,
}

/// The error against the reference at one bounce count.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct BounceError {
    pub bounces: u32,
    pub vs_reference: ErrorStats,
}

/// One configuration's results.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SurfelRow {
    pub varied: Varied,
    pub surfels: u32,
    pub links: u32,
    pub bands: u32,
    /// SH caches in the lattice, and those the shading interpolates (the others lie inside
    /// geometry or outside the scene).
    pub caches: usize,
    pub usable_caches: usize,
    /// Wall time of the precomputation on this machine's CPU.
    pub precompute_s: f64,
    pub stages: BTreeMap<String, StageStats>,
    pub gi: StageStats,
    pub frame: StageStats,
    pub fps: f64,
    pub errors: Vec<BounceError>,
}

/// The reference at one bounce count.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct SurfelReference {
    pub bounces: u32,
    pub spp: u32,
    pub relative_standard_error: f32,
}

/// The whole run.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SurfelReport {
    pub adapter: String,
    pub timing_source: crate::gpu::timing::TimingSource,
    /// CPU threads the precomputation ran on.
    pub cpu_threads: usize,
    /// Where the links' rays were traced: on the GPU adapter, or on the CPU for a CPU one
    /// (`links::RayDevice::for_adapter`).
    pub link_rays_on_gpu: bool,
    pub scene: String,
    pub triangles: usize,
    pub width: u32,
    pub height: u32,
    pub frames: u32,
    pub warmup: u32,
    /// Distance between caches (scene units).
    pub cache_spacing: f32,
    pub references: Vec<SurfelReference>,
    pub rows: Vec<SurfelRow>,
    /// With `--compare-methods`: every method's ladder at one bounce, surfels' centre first.
    pub methods: Vec<MethodRow>,
}

/// The configurations of the sweep: the centre, then each list with the other two
/// parameters at the centre (the centre itself only once).
pub fn configurations(centre: SurfelParams, sweep: &SurfelSweep) -> Vec<(Varied, SurfelParams)> {
    let mut out = vec![(Varied::Centre, centre)];
    let varied = sweep
        .sweep_surfels
        .iter()
        .map(|&surfels| (Varied::Surfels, SurfelParams { surfels, ..centre }))
        .chain(
            sweep
                .sweep_links
                .iter()
                .map(|&links| (Varied::Links, SurfelParams { links, ..centre })),
        )
        .chain(
            sweep
                .sweep_bands
                .iter()
                .map(|&bands| (Varied::Bands, SurfelParams { bands, ..centre })),
        );
    for (what, params) in varied {
        if !out.iter().any(|(_, p)| *p == params) {
            out.push((what, params));
        }
    }
    out
}

/// Runs the surfels' evaluation, reporting progress through `progress(done, total, label)`.
pub fn run(
    args: &BenchArgs,
    log: &mut dyn FnMut(&str),
    progress: &mut dyn FnMut(u64, u64, &str),
) -> Result<SurfelReport, BenchError> {
    if args.frames == 0 {
        return Err(BenchError::NoFrames);
    }
    if args.surfels.bounces.is_empty() {
        return Err(BenchError::EmptyList { what: "--bounces" });
    }
    let spec = args.scene.as_deref().unwrap_or(DEFAULT_SCENE);
    let scene = Scene::open(spec).map_err(|error| BenchError::Scene {
        scene: spec.to_string(),
        error,
    })?;
    let named = surfels::Settings::of(&args.caches.gi(crate::gi::surfels::SURFELS))
        .map_err(|e| BenchError::Surfels(e.to_string()))?;
    let extent = scene.bounds.max - scene.bounds.min;
    let spacing = named
        .surfel_cache_spacing
        .unwrap_or_else(|| surfels::grid::CacheGrid::default_spacing(extent));
    let centre = SurfelParams {
        surfels: named.surfel_count,
        cache_spacing: Some(spacing),
        links: named.surfel_links,
        bands: named.sh_bands,
    };
    let configs = configurations(centre, &args.surfels);
    // Every configuration is checked as a request would be before the long steps start.
    let facts = crate::gi::precompute::SceneFacts::of(&scene);
    for (_, p) in &configs {
        let mut gi = GiParams::new(crate::gi::surfels::SURFELS)
            .with("surfel_count", p.surfels)
            .with("surfel_links", p.links)
            .with("sh_bands", p.bands);
        if let Some(spacing) = p.cache_spacing {
            gi.set("surfel_cache_spacing", spacing);
        }
        (surfels::PRECOMPUTE.key)(&gi, &facts).map_err(|e| {
            BenchError::Surfels(format!(
                "{} surfels, {} links, {} bands: {e}",
                p.surfels, p.links, p.bands
            ))
        })?;
    }
    log(&format!(
        "scene {}: {} triangles; {} configurations around {} surfels, {} links, {} bands, caches {spacing} apart",
        scene.name,
        scene.triangle_count(),
        configs.len(),
        centre.surfels,
        centre.links,
        centre.bands
    ));
    let ctx = crate::bench::open_adapter(args, log)?;
    let adapter = AdapterSummary(&ctx.info).to_string();
    let base = crate::bench::base_settings(args, &scene, {
        let mut gi = GiParams::new(crate::gi::surfels::SURFELS)
            .with("indirect_downscale", args.indirect_downscale)
            .with("emitters", args.emitters);
        if let Some(k) = args.glossy_exponent {
            gi.set("glossy_exponent", k);
        }
        gi
    });
    let mut references = Vec::new();
    let mut truths = Vec::new();
    for &bounces in &args.surfels.bounces {
        let image = render_reference(&ctx, &scene, &base, args, bounces, progress)?;
        log(&format!(
            "reference: {} spp, {bounces} bounce(s), relative standard error {:.2} %",
            image.samples,
            image.relative_standard_error * 100.0
        ));
        references.push(SurfelReference {
            bounces,
            spp: image.samples,
            relative_standard_error: image.relative_standard_error,
        });
        truths.push(image.indirect);
    }
    let (name, triangles) = (scene.name.clone(), scene.triangle_count());
    let gpu = ctx.clone();
    let mut renderer = Renderer::new(ctx, scene.clone());
    let timing_source = renderer.timing_source();
    // Precomputed afresh (this store is never read): the bench measures the build.
    let store = Store::new(std::env::temp_dir());
    let mut rows = Vec::new();
    for (i, &(varied, params)) in configs.iter().enumerate() {
        let what = format!(
            "{} surfels, {} links, {} bands ({} of {})",
            params.surfels,
            params.links,
            params.bands,
            i + 1,
            configs.len()
        );
        let started = Instant::now();
        let mut env = BuildEnv {
            store: &store,
            progress: &mut |p| progress(p.done, p.total, &format!("{what}: {}", p.step)),
            cancelled: &|| false,
            gpu: Some(&gpu),
        };
        let set = surfels::precompute(&scene, &params, &mut env)
            .map_err(|e| BenchError::Surfels(e.to_string()))?;
        let precompute_s = started.elapsed().as_secs_f64();
        let usable_caches = (0..set.grid.count())
            .filter(|&c| surfels::cpu::usable(&set, c))
            .count();
        log(&format!(
            "{what}: precomputed in {precompute_s:.1} s, {} caches ({usable_caches} usable)",
            set.grid.count()
        ));
        renderer
            .gi::<Surfels>()?
            .set_surfels(&set)
            .map_err(crate::renderer::RenderError::from)?;
        let timed = time_moving_light(&mut renderer, &base, args, &what, progress)?;
        let mut errors_by_bounce = Vec::new();
        for (&bounces, truth) in args.surfels.bounces.iter().zip(&truths) {
            let mut s = base.clone();
            s.gi.set("bounces", bounces);
            s.capture_hdr = true;
            let frame = renderer.render(&s)?;
            let indirect = frame.indirect.unwrap_or_default();
            errors_by_bounce.push(BounceError {
                bounces,
                vs_reference: errors(truth, &indirect, args.width as usize),
            });
        }
        rows.push(SurfelRow {
            varied,
            surfels: params.surfels,
            links: params.links,
            bands: params.bands,
            caches: set.grid.count(),
            usable_caches,
            precompute_s,
            fps: 1e3 / timed.frame.median_ms,
            stages: timed.stages,
            gi: timed.gi,
            frame: timed.frame,
            errors: errors_by_bounce,
        });
    }
    let methods = if args.surfels.compare_methods {
        let single =
            args.surfels
                .bounces
                .iter()
                .position(|&b| b == 1)
                .ok_or(BenchError::Surfels(
                    "--compare-methods needs 1 in --bounces".into(),
                ))?;
        // The other methods light from the punctual light alone: measure them against the
        // same sources.
        let without_emitters = if args.emitters {
            let mut s = base.clone();
            s.gi.set("emitters", false);
            render_reference(renderer.context(), &scene, &s, args, 1, progress)?.indirect
        } else {
            truths[single].clone()
        };
        compare_methods(
            &mut renderer,
            &scene,
            &base,
            args,
            &rows,
            &without_emitters,
            log,
            progress,
        )?
    } else {
        Vec::new()
    };
    Ok(SurfelReport {
        adapter,
        timing_source,
        cpu_threads: rayon::current_num_threads(),
        link_rays_on_gpu: matches!(
            surfels::links::RayDevice::for_adapter(Some(&gpu)),
            surfels::links::RayDevice::Gpu(_)
        ),
        scene: name,
        triangles,
        width: args.width,
        height: args.height,
        frames: args.frames,
        warmup: args.warmup,
        cache_spacing: spacing,
        references,
        rows,
        methods,
    })
}

/// The equal-time comparison: the sweep's centre (its GI time under a moving light, its
/// single-bounce error), then every other method's ladder (see [`crate::bench::equal_time`]).
#[allow(clippy::too_many_arguments)]
fn compare_methods(
    renderer: &mut Renderer,
    scene: &Scene,
    base: &RenderSettings,
    args: &BenchArgs,
    rows: &[SurfelRow],
    truth: &[[f32; 3]],
    log: &mut dyn FnMut(&str),
    progress: &mut dyn FnMut(u64, u64, &str),
) -> Result<Vec<MethodRow>, BenchError> {
    let centre = rows
        .iter()
        .find(|r| r.varied == Varied::Centre)
        .ok_or(BenchError::Surfels("the sweep has no centre".into()))?;
    let single = centre
        .errors
        .iter()
        .find(|e| e.bounces == 1)
        .ok_or(BenchError::Surfels("no single-bounce error".into()))?;
    let centre = MethodRow {
        method: crate::gi::surfels::SURFELS,
        setting: format!(
            "{} surfels, {} links, {} bands",
            centre.surfels, centre.links, centre.bands
        ),
        gi: centre.gi,
        vs_reference: single.vs_reference,
        nearest_equal_time: true,
    };
    crate::bench::equal_time(renderer, scene, base, args, centre, truth, log, progress)
}

/// [`crate::bench::time_moving_light`] with a history, so every frame runs a full bounce
/// (surfel light, pull-up, cache light) and the shading, as a session does while the light
/// moves.
fn time_moving_light(
    renderer: &mut Renderer,
    base: &RenderSettings,
    args: &BenchArgs,
    what: &str,
    progress: &mut dyn FnMut(u64, u64, &str),
) -> Result<Timed, BenchError> {
    let settings = RenderSettings {
        history: Some(1),
        ..base.clone()
    };
    crate::bench::time_moving_light(renderer, &settings, args, what, progress)
}

impl SurfelReport {
    /// Markdown tables: one row per configuration, then per-stage medians.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "Scene `{}` ({} triangles), {}×{}, adapter {}, {:?}, {} frames after {} warm-up under a moving light, caches {} apart, precomputation on {} CPU threads with the link rays on the {}.",
            self.scene,
            self.triangles,
            self.width,
            self.height,
            self.adapter,
            self.timing_source,
            self.frames,
            self.warmup,
            self.cache_spacing,
            self.cpu_threads,
            if self.link_rays_on_gpu { "GPU" } else { "CPU" }
        );
        for r in &self.references {
            s += &format!(
                " Reference at {} bounce(s): {} spp, relative standard error {:.2} %.",
                r.bounces,
                r.spp,
                r.relative_standard_error * 100.0
            );
        }
        s += "\n\n| varied | surfels | links | bands | caches (usable) | precompute s | GI ms (median / p95) | frame ms (median / p95) | fps |";
        for r in &self.references {
            s += &format!(
                " MAE / mean, {b} bounce(s) | 8×8-block MAE / mean, {b} bounce(s) | bias, {b} bounce(s) |",
                b = r.bounces
            );
        }
        s += "\n|---|---|---|---|---|---|---|---|---|";
        s += &"---|---|---|".repeat(self.references.len());
        s += "\n";
        for r in &self.rows {
            s += &format!(
                "| {:?} | {} | {} | {} | {} ({}) | {:.1} | {:.3} / {:.3} | {:.3} / {:.3} | {:.1} |",
                r.varied,
                r.surfels,
                r.links,
                r.bands,
                r.caches,
                r.usable_caches,
                r.precompute_s,
                r.gi.median_ms,
                r.gi.p95_ms,
                r.frame.median_ms,
                r.frame.p95_ms,
                r.fps
            );
            for e in &r.errors {
                s += &format!(
                    " {:.2} % | {:.2} % | {:+.2} % |",
                    e.vs_reference.mae_relative * 100.0,
                    e.vs_reference.block_mae_relative * 100.0,
                    e.vs_reference.bias_relative * 100.0
                );
            }
            s += "\n";
        }
        if !self.methods.is_empty() {
            s += &crate::bench::equal_time_table(&self.methods, "the surfels");
        }
        s += &crate::bench::stage_table(
            &["surfels", "links", "bands"],
            self.rows.iter().map(|r| {
                (
                    vec![
                        r.surfels.to_string(),
                        r.links.to_string(),
                        r.bands.to_string(),
                    ],
                    &r.stages,
                )
            }),
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sweep(surfels: &[u32], links: &[u32], bands: &[u32]) -> SurfelSweep {
        SurfelSweep {
            sweep_surfels: surfels.to_vec(),
            sweep_links: links.to_vec(),
            sweep_bands: bands.to_vec(),
            bounces: vec![1],
            compare_methods: false,
        }
    }

    /// One parameter at a time around the centre, the centre once, in list order.
    #[test]
    fn the_sweep_varies_one_parameter_at_a_time() {
        let centre = SurfelParams {
            surfels: 32768,
            cache_spacing: Some(0.2),
            links: 128,
            bands: 3,
        };
        let configs = configurations(centre, &sweep(&[8192, 32768], &[64, 128], &[2, 3, 4]));
        let got: Vec<(Varied, u32, u32, u32)> = configs
            .iter()
            .map(|(v, p)| (*v, p.surfels, p.links, p.bands))
            .collect();
        assert_eq!(
            got,
            vec![
                (Varied::Centre, 32768, 128, 3),
                (Varied::Surfels, 8192, 128, 3),
                (Varied::Links, 32768, 64, 3),
                (Varied::Bands, 32768, 128, 2),
                (Varied::Bands, 32768, 128, 4),
            ]
        );
        assert!(configs.iter().all(|(_, p)| p.cache_spacing == Some(0.2)));
        assert_eq!(configurations(centre, &sweep(&[], &[], &[])).len(), 1);
    }
}
