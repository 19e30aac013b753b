//! `lightcast-server bench --gi clustered`: seed 003's evaluation (its Tables 1–2 and
//! Figure 10) on our scenes.
//!
//! For every VPL count of `--sweep-vpls` it times, under a moving light, and measures against
//! the path-traced reference:
//!
//! - `clustered` with visibility off (Figure 10's "without visibility");
//! - instant radiosity with a hard-shadow paraboloid map per VPL (`vpl_shadows`), for the VPL
//!   counts of `--baseline-vpls` (its maps grow with N), at `--baseline-paraboloid-size`;
//! - `clustered` with its convolution soft shadow maps for every VAL count of
//!   `--sweep-clusters`, at `--paraboloid-size`, each also measured against the per-VPL
//!   shadows of the same N where those ran (the error clustering adds to exact visibility).
//!
//! Per-stage GPU times are the paper's Table 2 rows (deferred = G-buffer, VPL generation,
//! clustering, CSSM = paraboloid maps + basis, indirect, blur). `--compare-methods` adds the
//! other methods' ladders at equal time.

use crate::bench::{
    render_reference, time_moving_light, BenchArgs, BenchError, MethodRow, StageStats,
};
use crate::gi::clustered::params::{Settings, CLUSTER_COUNT, PARABOLOID_SIZE};
use crate::gi::clustered::passes::AtlasLayout;
use crate::gi::clustered::Visibility;
use crate::gi::clustered::MAX_VISIBILITY_BYTES;
use crate::gi::common::params::RSM_SIZE;

use crate::gpu::context::AdapterSummary;
use crate::offline::DEFAULT_SCENE;
use crate::quality::{errors, ErrorStats};
use crate::renderer::{RenderSettings, Renderer};
use crate::scene::Scene;
use lightcast_protocol::GiParams;
use std::collections::BTreeMap;

/// The sweep's lists (`bench --gi clustered`).
#[derive(Clone, Debug, clap::Args)]
pub struct ClusteredSweep {
    /// `--gi clustered`: VPL counts N (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = [1024, 4096, 16384])]
    pub sweep_vpls: Vec<u32>,
    /// `--gi clustered`: VAL counts M, at every N (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = [5, 10, 20, 30, 64, 128])]
    pub sweep_clusters: Vec<u32>,
    /// `--gi clustered`: the VPL counts that also run per-VPL hard shadows (`vpl_shadows`;
    /// one map per VPL, so only small N).
    #[arg(long, value_delimiter = ',', default_values_t = [1024])]
    pub baseline_vpls: Vec<u32>,
    /// `--gi clustered`: side of each VAL's paraboloid map.
    #[arg(long, default_value_t = 256)]
    pub paraboloid_size: u32,
    /// `--gi clustered`: side of each VPL's paraboloid map in the per-VPL baseline.
    #[arg(long, default_value_t = 128)]
    pub baseline_paraboloid_size: u32,
}

/// One configuration's results.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ClusteredRow {
    pub vpls: u32,
    pub visibility: Visibility,
    /// M (`cssm` only).
    pub clusters: Option<u32>,
    pub paraboloid_size: Option<u32>,
    pub stages: BTreeMap<String, StageStats>,
    pub gi: StageStats,
    pub frame: StageStats,
    pub fps: f64,
    pub vs_reference: ErrorStats,
    /// Against `vpl_shadows` at the same N, where it ran.
    pub vs_vpl_shadows: Option<ErrorStats>,
}

/// The whole run.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ClusteredReport {
    pub adapter: String,
    pub timing_source: crate::gpu::timing::TimingSource,
    pub scene: String,
    pub triangles: usize,
    pub width: u32,
    pub height: u32,
    pub frames: u32,
    pub warmup: u32,
    pub reference_spp: u32,
    pub reference_relative_standard_error: f32,
    pub rows: Vec<ClusteredRow>,
    /// With `--compare-methods`: the other methods' ladders against the configuration nearest
    /// the paper's (1,024 VPLs, 30 VALs).
    pub methods: Vec<MethodRow>,
}

/// The largest map side up to `requested` (halving it) whose maps fit the server's budget, so
/// that large VAL counts still run; the row reports the side it used.
fn fitting_map_size(visibility: Visibility, requested: u32, vpls: u32, vals: u32) -> u32 {
    let fits = |size: u32| AtlasLayout::of(visibility, size, vpls, vals).fits();
    let mut size = requested;
    while size > crate::gi::clustered::params::MIN_PARABOLOID_SIZE && !fits(size) {
        size /= 2;
    }
    size
}

/// The settings of every row, in order: per N, visibility off, the per-VPL baseline where
/// asked for, then CSSM at every M (M ≤ N); maps as large as asked for where they fit.
pub fn configurations(base: &GiParams, sweep: &ClusteredSweep) -> Vec<GiParams> {
    let mut out = Vec::new();
    let (base_clusters, base_size) = (CLUSTER_COUNT.u32(base), PARABOLOID_SIZE.u32(base));
    for &vpl_count in &sweep.sweep_vpls {
        let at = |visibility: Visibility, cluster_count, requested| {
            let mut gi = base
                .clone()
                .with("vpl_count", vpl_count)
                .with("cluster_count", cluster_count)
                .with("visibility", visibility.name())
                .with(
                    "paraboloid_size",
                    fitting_map_size(visibility, requested, vpl_count, cluster_count),
                );
            gi.method = crate::gi::clustered::CLUSTERED;
            gi
        };
        out.push(at(Visibility::Off, base_clusters, base_size));
        if sweep.baseline_vpls.contains(&vpl_count) {
            out.push(at(
                Visibility::VplShadows,
                base_clusters,
                sweep.baseline_paraboloid_size,
            ));
        }
        for &m in sweep.sweep_clusters.iter().filter(|&&m| m <= vpl_count) {
            out.push(at(Visibility::Cssm, m, sweep.paraboloid_size));
        }
    }
    out
}

/// Checks every configuration as a request would be checked, before the long steps start.
fn validate(configs: &[GiParams]) -> Result<(), BenchError> {
    for gi in configs {
        let g = typed(gi)?;
        (crate::gi::clustered::ENTRY.validate)(gi, 6).map_err(|e| {
            let atlas = AtlasLayout::of(
                g.visibility,
                g.paraboloid_size,
                g.vpl_count,
                g.cluster_count,
            );
            BenchError::Clustered(format!(
                "{} VPLs, {} VALs, {} {}²: {e} ({} MiB of maps, limit {} MiB)",
                g.vpl_count,
                g.cluster_count,
                g.visibility.name(),
                g.paraboloid_size,
                atlas.bytes() >> 20,
                MAX_VISIBILITY_BYTES >> 20
            ))
        })?;
    }
    Ok(())
}

/// A configuration's parameters as `clustered` reads them.
fn typed(gi: &GiParams) -> Result<Settings, BenchError> {
    Settings::of(gi).map_err(|e| BenchError::Clustered(e.to_string()))
}

/// Runs the clustered evaluation, reporting progress through `progress(done, total, label)`.
pub fn run(
    args: &BenchArgs,
    log: &mut dyn FnMut(&str),
    progress: &mut dyn FnMut(u64, u64, &str),
) -> Result<ClusteredReport, BenchError> {
    if args.frames == 0 {
        return Err(BenchError::NoFrames);
    }
    let sweep = &args.clustered;
    for (list, what) in [
        (&sweep.sweep_vpls, "--sweep-vpls"),
        (&sweep.sweep_clusters, "--sweep-clusters"),
    ] {
        if list.is_empty() {
            return Err(BenchError::EmptyList { what });
        }
    }
    if args.reference_spp == 0 {
        return Err(BenchError::Clustered(
            "needs a reference (--reference-spp > 0): every row is measured against it".into(),
        ));
    }
    let spec = args.scene.as_deref().unwrap_or(DEFAULT_SCENE);
    let scene = Scene::open(spec).map_err(|error| BenchError::Scene {
        scene: spec.to_string(),
        error,
    })?;
    let base = crate::bench::base_settings(args, &scene, {
        let mut gi = GiParams::new(crate::gi::clustered::CLUSTERED)
            .with("indirect_downscale", args.indirect_downscale)
            .with("rsm_size", args.rsm_sizes.first().copied().unwrap_or(1024));
        if let Some(k) = args.glossy_exponent {
            gi.set("glossy_exponent", k);
        }
        gi
    });
    let configs = configurations(&base.gi, sweep);
    validate(&configs)?;
    log(&format!(
        "scene {}: {} triangles; {} configurations, RSM {}²",
        scene.name,
        scene.triangle_count(),
        configs.len(),
        RSM_SIZE.u32(&base.gi)
    ));
    let ctx = crate::bench::open_adapter(args, log)?;
    let adapter = AdapterSummary(&ctx.info).to_string();
    let reference = render_reference(&ctx, &scene, &base, args, 1, progress)?;
    log(&format!(
        "reference: {} spp, relative standard error {:.2} %",
        reference.samples,
        reference.relative_standard_error * 100.0
    ));
    let truth = &reference.indirect;
    let (name, triangles) = (scene.name.clone(), scene.triangle_count());
    let mut renderer = Renderer::new(ctx, scene.clone());
    let timing_source = renderer.timing_source();
    let mut rows: Vec<ClusteredRow> = Vec::new();
    let mut exact: Option<(u32, Vec<[f32; 3]>)> = None;
    for (i, params) in configs.iter().enumerate() {
        let gi = typed(params)?;
        let what = format!(
            "{} VPLs, {}{} ({} of {})",
            gi.vpl_count,
            gi.visibility.name(),
            if gi.visibility == Visibility::Cssm {
                format!(", {} VALs", gi.cluster_count)
            } else {
                String::new()
            },
            i + 1,
            configs.len()
        );
        let settings = RenderSettings {
            gi: params.clone(),
            ..base.clone()
        };
        let timed = time_moving_light(&mut renderer, &settings, args, &what, progress)?;
        let rgb: Vec<[f32; 3]> = timed.indirect.iter().map(|p| [p[0], p[1], p[2]]).collect();
        let vs_reference = errors(truth, &timed.indirect, args.width as usize);
        if gi.visibility == Visibility::VplShadows {
            exact = Some((gi.vpl_count, rgb));
        }
        let vs_vpl_shadows = exact
            .as_ref()
            .filter(|(n, _)| *n == gi.vpl_count && gi.visibility != Visibility::VplShadows)
            .map(|(_, image)| errors(image, &timed.indirect, args.width as usize));
        log(&format!(
            "{what}: GI {:.2} ms, error against the reference {:.2} %",
            timed.gi.median_ms,
            vs_reference.mae_relative * 100.0
        ));
        let cssm = gi.visibility == Visibility::Cssm;
        rows.push(ClusteredRow {
            vpls: gi.vpl_count,
            visibility: gi.visibility,
            clusters: cssm.then_some(gi.cluster_count),
            paraboloid_size: (gi.visibility != Visibility::Off).then_some(gi.paraboloid_size),
            fps: 1e3 / timed.frame.median_ms,
            stages: timed.stages,
            gi: timed.gi,
            frame: timed.frame,
            vs_reference,
            vs_vpl_shadows,
        });
    }
    let methods = if args.surfels.compare_methods {
        // The row nearest the paper's setting (1,024 VPLs, 30 VALs) stands for `clustered`.
        let centre = rows
            .iter()
            .filter_map(|r| Some((r, r.clusters?)))
            .min_by_key(|(r, m)| (r.vpls.abs_diff(1024), m.abs_diff(30)))
            .map(|(r, m)| MethodRow {
                method: crate::gi::clustered::CLUSTERED,
                setting: format!("{} VPLs, {m} VALs, cssm", r.vpls),
                gi: r.gi,
                vs_reference: r.vs_reference,
                nearest_equal_time: true,
            })
            .ok_or(BenchError::Clustered("no cssm row to compare with".into()))?;
        crate::bench::equal_time(
            &mut renderer,
            &scene,
            &base,
            args,
            centre,
            truth,
            log,
            progress,
        )?
    } else {
        Vec::new()
    };
    Ok(ClusteredReport {
        adapter,
        timing_source,
        scene: name,
        triangles,
        width: args.width,
        height: args.height,
        frames: args.frames,
        warmup: args.warmup,
        reference_spp: reference.samples,
        reference_relative_standard_error: reference.relative_standard_error,
        rows,
        methods,
    })
}

impl ClusteredReport {
    /// Markdown tables: one row per configuration, the equal-time comparison, then per-stage
    /// medians.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "Scene `{}` ({} triangles), {}×{}, adapter {}, {:?}, {} frames after {} warm-up under a moving light. Reference: {} spp, relative standard error {:.2} %.\n\n| VPLs | visibility | VALs | map | GI ms (median / p95) | frame ms (median / p95) | fps | MAE / mean | 8×8-block MAE / mean | bias | MAE / mean against per-VPL shadows |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
            self.scene,
            self.triangles,
            self.width,
            self.height,
            self.adapter,
            self.timing_source,
            self.frames,
            self.warmup,
            self.reference_spp,
            self.reference_relative_standard_error * 100.0
        );
        let dash = || "-".to_string();
        for r in &self.rows {
            s += &format!(
                "| {} | {} | {} | {} | {:.3} / {:.3} | {:.3} / {:.3} | {:.1} | {:.2} % | {:.2} % | {:+.2} % | {} |\n",
                r.vpls,
                r.visibility.name(),
                r.clusters.map_or_else(dash, |m| m.to_string()),
                r.paraboloid_size.map_or_else(dash, |p| format!("{p}²")),
                r.gi.median_ms,
                r.gi.p95_ms,
                r.frame.median_ms,
                r.frame.p95_ms,
                r.fps,
                r.vs_reference.mae_relative * 100.0,
                r.vs_reference.block_mae_relative * 100.0,
                r.vs_reference.bias_relative * 100.0,
                r.vs_vpl_shadows
                    .map_or_else(dash, |e| format!("{:.2} %", e.mae_relative * 100.0)),
            );
        }
        if !self.methods.is_empty() {
            s += &crate::bench::equal_time_table(&self.methods, "clustered");
        }
        s += &crate::bench::stage_table(
            &["VPLs", "visibility", "VALs"],
            self.rows.iter().map(|r| {
                (
                    vec![
                        r.vpls.to_string(),
                        r.visibility.name().to_string(),
                        r.clusters
                            .map_or_else(|| "-".to_string(), |m| m.to_string()),
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

    /// Per N: off, the baseline where asked for, then every M that is at most N.
    #[test]
    fn configurations_cover_every_n_and_m() {
        let sweep = ClusteredSweep {
            sweep_vpls: vec![256, 1024],
            sweep_clusters: vec![10, 512],
            baseline_vpls: vec![256],
            paraboloid_size: 64,
            baseline_paraboloid_size: 32,
        };
        // 128 VALs do not fit at 256² (480 MiB): they get 128².
        let big = ClusteredSweep {
            sweep_vpls: vec![1024],
            sweep_clusters: vec![64, 128],
            baseline_vpls: vec![],
            paraboloid_size: 256,
            baseline_paraboloid_size: 128,
        };
        let base = GiParams::new(crate::gi::clustered::CLUSTERED);
        let sizes: Vec<u32> = configurations(&base, &big)
            .iter()
            .map(|g| PARABOLOID_SIZE.u32(g))
            .collect();
        assert_eq!(sizes, vec![PARABOLOID_SIZE.u32(&base), 256, 128]);
        assert!(validate(&configurations(&base, &big)).is_ok());
        let got: Vec<(u32, Visibility, u32, u32)> = configurations(&base, &sweep)
            .iter()
            .map(|g| {
                let visibility = serde_json::from_value(VISIBILITY.value(g).into_owned());
                (
                    VPL_COUNT.u32(g),
                    visibility.expect("a visibility"),
                    CLUSTER_COUNT.u32(g),
                    PARABOLOID_SIZE.u32(g),
                )
            })
            .collect();
        use crate::gi::clustered::params::{VISIBILITY, VPL_COUNT};
        use Visibility::*;
        let d = typed(&base).expect("the defaults");
        assert_eq!(
            got,
            vec![
                (256, Off, d.cluster_count, d.paraboloid_size),
                (256, VplShadows, d.cluster_count, 32),
                (256, Cssm, 10, 64),
                (1024, Off, d.cluster_count, d.paraboloid_size),
                (1024, Cssm, 10, 64),
                (1024, Cssm, 512, 64),
            ]
        );
        assert!(
            validate(&configurations(&base, &sweep)).is_err(),
            "512 VALs"
        );
    }
}
