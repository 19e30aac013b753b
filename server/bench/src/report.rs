//! What `lightcast-server bench` reports, for every method's sweep alike, and its markdown.

use crate::gi::bench::Point;
use crate::gi::GiMethod;
use crate::quality::ErrorStats;
use lightcast_protocol::GiParams;
use std::collections::BTreeMap;

/// Median and 95th percentile of a stage's time.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct StageStats {
    pub median_ms: f64,
    pub p95_ms: f64,
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// Median and 95th percentile of `v` (0 for no samples).
pub fn stats(mut v: Vec<f64>) -> StageStats {
    if v.is_empty() {
        return StageStats {
            median_ms: 0.0,
            p95_ms: 0.0,
        };
    }
    v.sort_by(f64::total_cmp);
    StageStats {
        median_ms: percentile(&v, 0.5),
        p95_ms: percentile(&v, 0.95),
    }
}

/// One cell of a row: the sweep's column and the configuration's value.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Cell {
    pub column: String,
    pub value: String,
}

/// A configuration's error against the reference at one bounce count.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct BounceError {
    pub bounces: u32,
    /// Errors of the indirect buffer.
    pub vs_reference: ErrorStats,
    /// Errors against a reference that models the same light transport as the method (its
    /// table's `senders`), where that differs from the full one: what is left of the error
    /// is the error in what the method models; the difference is what it leaves out.
    pub vs_modelled: Option<ErrorStats>,
    /// PSNR in dB of the final image against the same frame with the reference's indirect
    /// light (see [`crate::quality::final_errors`]); `None` when identical.
    pub final_psnr_db: Option<f64>,
    /// Mean LDR-FLIP error of the same two images.
    pub final_flip: f64,
}

/// The per-scene precomputation a configuration's frames read.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Precomputed {
    /// What it is (`light caches`) and its key.
    pub what: String,
    /// Its size in its budget's unit, where it has one (`6596 caches`).
    pub size: Option<String>,
    /// Wall time of the build on this machine (or of loading it, with `from_store`).
    pub seconds: f64,
    pub from_store: bool,
}

/// One configuration's results.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchRow {
    pub method: GiMethod,
    pub cells: Vec<Cell>,
    /// Every GI parameter of its frames.
    pub params: GiParams,
    pub precomputed: Option<Precomputed>,
    pub stages: BTreeMap<String, StageStats>,
    /// The GI stages' total.
    pub gi: StageStats,
    pub frame: StageStats,
    pub fps: f64,
    /// At every bounce count of the run.
    pub errors: Vec<BounceError>,
    /// The row (index) it is also compared with, as its sweep declares.
    pub baseline: Option<usize>,
    /// Errors of its indirect buffer against the baseline's (first bounce count).
    pub vs_baseline: Option<ErrorStats>,
    /// The baseline's median frame time over this row's.
    pub speedup_vs_baseline: Option<f64>,
    /// Where the plots draw it.
    #[serde(skip)]
    pub points: Vec<Point>,
    /// RGB8 difference image against the reference (red: too bright, blue: too dark), when
    /// plots were asked for.
    #[serde(skip)]
    pub difference_image: Option<Vec<u8>>,
}

impl BenchRow {
    /// `method, cell, cell, …`.
    pub fn label(&self) -> String {
        std::iter::once(self.method.to_string())
            .chain(
                self.cells
                    .iter()
                    .map(|c| format!("{} {}", c.column, c.value)),
            )
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// A reference the rows were compared with.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ReferenceSummary {
    pub bounces: u32,
    /// Whether emissive surfaces lit it (for the methods that light from them).
    pub emitters: bool,
    /// How it reflects direct light on (`full`: the truth; `diffuse`: the diffuse lobe alone,
    /// what the RSM-based methods model).
    pub senders: crate::gi::params::Senders,
    pub spp: u32,
    /// Its own convergence estimate (relative standard error).
    pub relative_standard_error: f32,
    /// Mean of its indirect buffer, per channel.
    pub mean: f64,
}

/// One method at one setting of the equal-time comparison.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MethodRow {
    pub method: GiMethod,
    /// The setting, e.g. `RSM 256², VALs 2048`.
    pub setting: String,
    pub gi: StageStats,
    /// Error against the single-bounce reference.
    pub vs_reference: ErrorStats,
    /// Error against the single-bounce reference of the light transport it models, where
    /// that is not the full one ([`BounceError::vs_modelled`]).
    pub vs_modelled: Option<ErrorStats>,
    /// The method's setting whose GI time is nearest the centre's.
    pub nearest_equal_time: bool,
}

/// The whole run.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchReport {
    /// `bench --gi`.
    pub method: GiMethod,
    pub adapter: String,
    pub timing_source: crate::gpu::timing::TimingSource,
    /// CPU threads the precomputations ran on.
    pub cpu_threads: usize,
    pub scene: String,
    pub triangles: usize,
    pub width: u32,
    pub height: u32,
    pub frames: u32,
    pub warmup: u32,
    /// The parameters every configuration starts from (`--gi-param`).
    pub base: BTreeMap<String, serde_json::Value>,
    pub references: Vec<ReferenceSummary>,
    pub rows: Vec<BenchRow>,
    /// With `--compare-methods`: the sweep's centre, then the other methods' ladders.
    pub methods: Vec<MethodRow>,
    /// RGB8 picture of the first reference's indirect light, when plots were asked for.
    #[serde(skip)]
    pub reference_image: Option<Vec<u8>>,
}

/// `a | b | c` of a row's cells under `columns` ("-" where it has none).
fn cells_under(row: &BenchRow, columns: &[String]) -> Vec<String> {
    columns
        .iter()
        .map(|col| {
            row.cells
                .iter()
                .find(|c| &c.column == col)
                .map_or("-".to_string(), |c| c.value.clone())
        })
        .collect()
}

impl BenchReport {
    /// The sweep's columns: each new one right after the column before it in the row that
    /// first has it (so rows that lack some columns keep the others' order).
    pub fn columns(&self) -> Vec<String> {
        let mut columns: Vec<String> = Vec::new();
        for row in &self.rows {
            for (j, c) in row.cells.iter().enumerate() {
                if columns.contains(&c.column) {
                    continue;
                }
                let after = j
                    .checked_sub(1)
                    .and_then(|p| columns.iter().position(|k| *k == row.cells[p].column));
                columns.insert(after.map_or(columns.len(), |p| p + 1), c.column.clone());
            }
        }
        columns
    }

    /// Markdown: the run, one row per configuration, the equal-time comparison, per-stage
    /// medians.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "`bench --gi {}`: scene `{}` ({} triangles), {}×{}, adapter {}, {:?}, {} frames after {} warm-up under a moving light, precomputations on {} CPU threads.",
            self.method,
            self.scene,
            self.triangles,
            self.width,
            self.height,
            self.adapter,
            self.timing_source,
            self.frames,
            self.warmup,
            self.cpu_threads
        );
        if !self.base.is_empty() {
            let base: Vec<String> = self.base.iter().map(|(k, v)| format!("{k}={v}")).collect();
            s += &format!(" Base parameters: `{}`.", base.join(" "));
        }
        for r in &self.references {
            s += &format!(
                " Reference at {} bounce(s){}{}: path traced, {} spp, relative standard error {:.2} %, mean {:.4e}.",
                r.bounces,
                if r.emitters { " with emitters" } else { "" },
                match r.senders {
                    crate::gi::params::Senders::Full => "",
                    crate::gi::params::Senders::Diffuse => " of diffuse senders (the transport the method models)",
                },
                r.spp,
                r.relative_standard_error * 100.0,
                r.mean
            );
        }
        let columns = self.columns();
        let bounces: Vec<u32> = self
            .rows
            .first()
            .map(|r| r.errors.iter().map(|e| e.bounces).collect())
            .unwrap_or_default();
        let modelled = self
            .rows
            .iter()
            .any(|r| r.errors.iter().any(|e| e.vs_modelled.is_some()));
        let precomputed = self.rows.iter().any(|r| r.precomputed.is_some());
        let baselines = self.rows.iter().any(|r| r.baseline.is_some());
        let mut header = vec!["method".to_string()];
        header.extend(columns.iter().cloned());
        header.extend(["GI ms (median / p95)", "frame ms (median / p95)", "fps"].map(String::from));
        if precomputed {
            header.push("precomputation (s)".into());
        }
        for b in &bounces {
            header.extend(
                [
                    "MAE / mean",
                    "8×8-block MAE / mean",
                    "bias",
                    "final PSNR",
                    "final FLIP",
                ]
                .map(|h| format!("{h}, {b} bounce(s)")),
            );
            if modelled {
                header.extend(
                    ["8×8-block MAE / mean", "bias"]
                        .map(|h| format!("{h} vs modelled transport, {b} bounce(s)")),
                );
            }
        }
        if baselines {
            header.extend(
                [
                    "compared with",
                    "MAE / mean vs it",
                    "8×8-block MAE / mean vs it",
                    "speed-up vs it",
                ]
                .map(String::from),
            );
        }
        s += &format!(
            "\n\n| {} |\n|{}\n",
            header.join(" | "),
            "---|".repeat(header.len())
        );
        for r in &self.rows {
            let mut cells = vec![r.method.to_string()];
            cells.extend(cells_under(r, &columns));
            cells.push(format!("{:.3} / {:.3}", r.gi.median_ms, r.gi.p95_ms));
            cells.push(format!("{:.3} / {:.3}", r.frame.median_ms, r.frame.p95_ms));
            cells.push(format!("{:.1}", r.fps));
            if precomputed {
                cells.push(r.precomputed.as_ref().map_or("-".into(), |p| {
                    format!(
                        "{}{:.1}{}",
                        p.size.as_ref().map_or(String::new(), |s| format!("{s}: ")),
                        p.seconds,
                        if p.from_store { " (loaded)" } else { "" }
                    )
                }));
            }
            for e in &r.errors {
                cells.push(format!("{:.2} %", e.vs_reference.mae_relative * 100.0));
                cells.push(format!(
                    "{:.2} %",
                    e.vs_reference.block_mae_relative * 100.0
                ));
                cells.push(format!("{:+.2} %", e.vs_reference.bias_relative * 100.0));
                cells.push(
                    e.final_psnr_db
                        .map_or("identical".into(), |p| format!("{p:.2} dB")),
                );
                cells.push(format!("{:.4}", e.final_flip));
                if modelled {
                    cells.extend(modelled_cells(e.vs_modelled));
                }
            }
            if baselines {
                match (r.baseline, r.vs_baseline, r.speedup_vs_baseline) {
                    (Some(b), Some(e), Some(speedup)) => {
                        cells.push(self.rows[b].label());
                        cells.push(format!("{:.2} %", e.mae_relative * 100.0));
                        cells.push(format!("{:.2} %", e.block_mae_relative * 100.0));
                        cells.push(format!("{speedup:.2}×"));
                    }
                    _ => cells.extend(["-"; 4].map(String::from)),
                }
            }
            s += &format!("| {} |\n", cells.join(" | "));
        }
        if !self.methods.is_empty() {
            s += &equal_time_table(&self.methods, self.method);
        }
        let mut labels = vec!["method".to_string()];
        labels.extend(columns.iter().cloned());
        s += &stage_table(
            &labels,
            self.rows.iter().map(|r| {
                let mut cells = vec![r.method.to_string()];
                cells.extend(cells_under(r, &columns));
                (cells, &r.stages)
            }),
        );
        s
    }
}

/// Block error and bias against the modelled transport's reference, "-" where the method
/// models the full one.
fn modelled_cells(e: Option<ErrorStats>) -> [String; 2] {
    match e {
        Some(e) => [
            format!("{:.2} %", e.block_mae_relative * 100.0),
            format!("{:+.2} %", e.bias_relative * 100.0),
        ],
        None => ["-".into(), "-".into()],
    }
}

/// The equal-time table; `against` is the centre's method.
fn equal_time_table(rows: &[MethodRow], against: GiMethod) -> String {
    let mut s = format!(
        "\nAll GI methods at one bounce against the same reference (and against the reference of the light transport each models, diffuse senders for `surfels` and the RSM-based ones with `senders: diffuse`); ✓ marks each method's setting whose GI time is nearest {against}'s (equal time):\n\n| method | setting | GI ms (median / p95) | MAE / mean | 8×8-block MAE / mean | bias | 8×8-block MAE / mean vs modelled | bias vs modelled | equal time |\n|---|---|---|---|---|---|---|---|---|\n"
    );
    for m in rows {
        let [block, bias] = modelled_cells(m.vs_modelled);
        s += &format!(
            "| {} | {} | {:.3} / {:.3} | {:.2} % | {:.2} % | {:+.2} % | {block} | {bias} | {} |\n",
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

/// "Per-stage medians (ms)" as a markdown table: the `labels` columns, then one column per stage
/// any row timed, "-" where a row did not run it.
pub fn stage_table<'a>(
    labels: &[String],
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
pub(crate) mod tests {
    use super::*;

    fn stat(ms: f64) -> StageStats {
        StageStats {
            median_ms: ms,
            p95_ms: ms,
        }
    }

    fn error(e: f64) -> ErrorStats {
        ErrorStats {
            mae: e,
            rmse: e,
            mae_relative: e,
            block_mae_relative: e,
            bias_relative: -e,
        }
    }

    /// A row of `method` with `cells`, GI time `ms`, error `e` at one bounce.
    pub(crate) fn row(method: &str, cells: &[(&str, &str)], ms: f64, e: f64) -> BenchRow {
        BenchRow {
            method: GiMethod::new(method),
            cells: cells
                .iter()
                .map(|(c, v)| Cell {
                    column: c.to_string(),
                    value: v.to_string(),
                })
                .collect(),
            params: GiParams::new(GiMethod::new(method)),
            precomputed: None,
            stages: BTreeMap::from([("gbuffer".to_string(), stat(ms / 2.0))]),
            gi: stat(ms),
            frame: stat(2.0 * ms),
            fps: 500.0 / ms,
            errors: vec![BounceError {
                bounces: 1,
                vs_reference: error(e),
                vs_modelled: None,
                final_psnr_db: Some(30.0),
                final_flip: 0.1,
            }],
            baseline: None,
            vs_baseline: None,
            speedup_vs_baseline: None,
            points: Vec::new(),
            difference_image: Some(vec![0; 3]),
        }
    }

    pub(crate) fn report(rows: Vec<BenchRow>) -> BenchReport {
        BenchReport {
            method: GiMethod::new("brsm"),
            adapter: "test".into(),
            timing_source: crate::gpu::timing::TimingSource::GpuTimestamps,
            cpu_threads: 2,
            scene: "t".into(),
            triangles: 1,
            width: 1,
            height: 1,
            frames: 1,
            warmup: 0,
            base: BTreeMap::new(),
            references: vec![ReferenceSummary {
                bounces: 1,
                emitters: false,
                senders: crate::gi::params::Senders::Full,
                spp: 4,
                relative_standard_error: 0.1,
                mean: 1.0,
            }],
            rows,
            methods: Vec::new(),
            reference_image: Some(vec![255; 3]),
        }
    }

    #[test]
    fn stage_tables_have_a_column_per_stage_any_row_ran() {
        let a = BTreeMap::from([("gbuffer".to_string(), stat(1.0))]);
        let b = BTreeMap::from([
            ("gbuffer".to_string(), stat(2.0)),
            ("tonemap".to_string(), stat(0.5)),
        ]);
        let rows = [(vec!["x".to_string()], &a), (vec!["y".to_string()], &b)];
        let table = stage_table(&["row".to_string()], rows.iter().cloned());
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

    /// Columns are the union of the rows' cells, "-" where a row has none; a row with a
    /// baseline names it and its speed-up.
    #[test]
    fn markdown_rows_have_every_column() {
        let mut brsm = row("brsm", &[("RSM", "64²"), ("VALs", "512")], 2.0, 0.2);
        brsm.baseline = Some(0);
        brsm.vs_baseline = Some(error(0.05));
        brsm.speedup_vs_baseline = Some(1.5);
        let md = report(vec![row("lightskin", &[("RSM", "64²")], 3.0, 0.1), brsm]).markdown();
        let lines: Vec<&str> = md.lines().filter(|l| l.starts_with("| ")).collect();
        assert!(
            lines[0].starts_with("| method | RSM | VALs | GI ms"),
            "{}",
            lines[0]
        );
        assert!(lines[0].ends_with(
            "| compared with | MAE / mean vs it | 8×8-block MAE / mean vs it | speed-up vs it |"
        ));
        assert!(
            lines[1].starts_with("| lightskin | 64² | - | 3.000 / 3.000 |"),
            "{}",
            lines[1]
        );
        assert!(lines[1].ends_with("| - | - | - | - |"));
        assert!(lines[2].contains("| 20.00 % | 20.00 % | -20.00 % | 30.00 dB | 0.1000 |"));
        assert!(
            lines[2].ends_with("| lightskin, RSM 64² | 5.00 % | 5.00 % | 1.50× |"),
            "{}",
            lines[2]
        );
    }

    /// Errors against the modelled transport get their own columns once any row has them,
    /// "-" in the rows of methods that model the whole transport.
    #[test]
    fn modelled_transport_errors_have_their_columns() {
        let without = report(vec![row("brsm", &[("RSM", "64²")], 2.0, 0.2)]).markdown();
        assert!(!without.contains("vs modelled"), "{without}");
        let mut brsm = row("brsm", &[("RSM", "64²")], 2.0, 0.2);
        brsm.errors[0].vs_modelled = Some(error(0.07));
        let md = report(vec![brsm, row("reference", &[], 9.0, 0.01)]).markdown();
        let lines: Vec<&str> = md.lines().filter(|l| l.starts_with("| ")).collect();
        assert!(
            lines[0].contains(
                "| final FLIP, 1 bounce(s) | 8×8-block MAE / mean vs modelled transport, 1 bounce(s) | bias vs modelled transport, 1 bounce(s) |"
            ),
            "{}",
            lines[0]
        );
        assert!(
            lines[1].ends_with("| 0.1000 | 7.00 % | -7.00 % |"),
            "{}",
            lines[1]
        );
        assert!(lines[2].ends_with("| 0.1000 | - | - |"), "{}", lines[2]);
    }

    /// A column first seen in a later row goes after its neighbour in that row.
    #[test]
    fn columns_keep_each_rows_order() {
        let rows = vec![
            row(
                "clustered",
                &[("VPLs", "1"), ("visibility", "off")],
                1.0,
                0.1,
            ),
            row(
                "clustered",
                &[("VPLs", "1"), ("visibility", "vpl_shadows"), ("map", "32²")],
                1.0,
                0.1,
            ),
            row(
                "clustered",
                &[
                    ("VPLs", "1"),
                    ("visibility", "cssm"),
                    ("VALs", "5"),
                    ("map", "32²"),
                ],
                1.0,
                0.1,
            ),
        ];
        assert_eq!(
            report(rows).columns(),
            ["VPLs", "visibility", "VALs", "map"]
        );
    }
}
