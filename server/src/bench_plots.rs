//! PNG plots of a [`BenchReport`]: relative error against LightSkin, against the path-traced
//! reference (when the run had one) and frames per second, over the RSM size, one line per
//! configuration (the paper's Figures 3 and 5); of a [`SurfelReport`], seed 001's Figure 8;
//! and of a [`ClusteredReport`], seed 003's Figure 10.

use crate::bench::{BenchReport, BenchRow};
use crate::bench_clustered::ClusteredReport;
use crate::bench_surfels::{SurfelReport, SurfelRow, Varied};
use crate::gi::clustered::Visibility;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Fonts tried in order for the plots' text (Debian's fonts-dejavu-core provides the first).
const FONT_CANDIDATES: [&str; 2] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
];

#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("no font for the plot text found (install fonts-dejavu-core); looked for {0:?}")]
    NoFont(Vec<&'static str>),
    #[error("drawing {path}: {message}")]
    Draw { path: PathBuf, message: String },
    #[error("writing {path}: {error}")]
    Image {
        path: PathBuf,
        error: image::ImageError,
    },
}

/// Writes an RGB8 picture `width` × `height` as PNG.
fn write_rgb(path: PathBuf, rgb: &[u8], width: u32, height: u32) -> Result<PathBuf, PlotError> {
    image::save_buffer(&path, rgb, width, height, image::ExtendedColorType::Rgb8).map_err(
        |error| PlotError::Image {
            path: path.clone(),
            error,
        },
    )?;
    Ok(path)
}

/// Size of the plots in pixels.
const PLOT_SIZE: (u32, u32) = (960, 600);

/// Registers the plot font once per process.
fn ensure_font() -> Result<(), PlotError> {
    static REGISTERED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        FONT_CANDIDATES.iter().any(|path| {
            std::fs::read(path).ok().is_some_and(|bytes| {
                // The font must live for the rest of the process; it is loaded once.
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_ok()
            })
        })
    });
    if ok {
        Ok(())
    } else {
        Err(PlotError::NoFont(FONT_CANDIDATES.to_vec()))
    }
}

fn label(row: &BenchRow) -> String {
    match row.method {
        crate::gi::lightskin::BRSM => format!(
            "BRSM {} VALs, {} view samples",
            row.val_count.unwrap_or(0),
            row.view_samples.unwrap_or(0)
        ),
        _ => "LightSkin".to_string(),
    }
}

/// One line per configuration: (label, [(log2 of the RSM side, value)]).
fn series(
    report: &BenchReport,
    value: impl Fn(&BenchRow) -> f64,
) -> Vec<(String, Vec<(f64, f64)>)> {
    lines_by(
        report,
        |r| Some(label(r)),
        |r| f64::from(r.rsm_size).log2(),
        value,
    )
}

/// One line per name `line` gives a row (rows it gives none are left out), with points
/// (`x`, `value`) in row order.
fn lines_by(
    report: &BenchReport,
    line: impl Fn(&BenchRow) -> Option<String>,
    x: impl Fn(&BenchRow) -> f64,
    value: impl Fn(&BenchRow) -> f64,
) -> Vec<(String, Vec<(f64, f64)>)> {
    let mut out: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for row in &report.rows {
        let Some(name) = line(row) else { continue };
        let point = (x(row), value(row));
        match out.iter_mut().find(|(n, _)| *n == name) {
            Some((_, points)) => points.push(point),
            None => out.push((name, vec![point])),
        }
    }
    out
}

/// The x axis of a plot: log2 of what it names.
struct Axis(&'static str);

const RSM_AXIS: Axis = Axis("RSM side (texels)");

fn draw(
    path: &Path,
    title: &str,
    y_label: &str,
    lines: &[(String, Vec<(f64, f64)>)],
) -> Result<(), PlotError> {
    draw_over(path, title, &RSM_AXIS, y_label, lines)
}

fn draw_over(
    path: &Path,
    title: &str,
    axis: &Axis,
    y_label: &str,
    lines: &[(String, Vec<(f64, f64)>)],
) -> Result<(), PlotError> {
    let err = |e: &dyn std::fmt::Display| PlotError::Draw {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let points = lines.iter().flat_map(|(_, p)| p.iter());
    let x_max = points.clone().map(|p| p.0).fold(0.0, f64::max);
    let x_min = points.clone().map(|p| p.0).fold(x_max, f64::min);
    let y_max = points.map(|p| p.1).fold(0.0, f64::max).max(1e-9) * 1.1;
    // Drawn into memory and encoded with the `image` the server already uses: plotters' own
    // encoder would pull in a second, older `image`.
    let mut rgb = vec![0u8; (PLOT_SIZE.0 * PLOT_SIZE.1 * 3) as usize];
    let root = BitMapBackend::with_buffer(&mut rgb, PLOT_SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d(x_min - 0.25..x_max + 0.25, 0.0..y_max)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc(axis.0)
        .x_labels(((x_max - x_min) as usize + 1).max(2))
        .x_label_formatter(&|v| format!("{}", v.exp2().round()))
        .y_desc(y_label)
        .label_style(("sans-serif", 16))
        .draw()
        .map_err(|e| err(&e))?;
    for (i, (name, points)) in lines.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(
                points.iter().copied(),
                colour.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label(name.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
        chart
            .draw_series(points.iter().map(|&p| Circle::new(p, 4, colour.filled())))
            .map_err(|e| err(&e))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    drop(chart);
    drop(root);
    write_rgb(path.to_path_buf(), &rgb, PLOT_SIZE.0, PLOT_SIZE.1)?;
    Ok(())
}

/// Writes `<prefix>-error.png`, `<prefix>-fps.png` and, when the report has a reference,
/// `<prefix>-error-vs-reference.png`, the reference's indirect light
/// (`<prefix>-reference.png`) and each configuration's difference from it
/// (`<prefix>-diff-<method>-<rsm>[-<vals>].png`, the paper's Figure 6 right column); returns
/// their paths.
pub fn write_plots(report: &BenchReport, prefix: &Path) -> Result<Vec<PathBuf>, PlotError> {
    ensure_font()?;
    let with_suffix = |suffix: &str| {
        let mut name = prefix.as_os_str().to_owned();
        name.push(suffix);
        PathBuf::from(name)
    };
    let error_path = with_suffix("-error.png");
    let brsm_only: Vec<_> = series(report, |r| r.mad_relative * 100.0)
        .into_iter()
        .filter(|(name, _)| name != "LightSkin")
        .collect();
    draw(
        &error_path,
        "Indirect light: mean absolute difference to LightSkin",
        "MAD / LightSkin mean (%)",
        &brsm_only,
    )?;
    let fps_path = with_suffix("-fps.png");
    draw(
        &fps_path,
        &format!("Frames per second ({})", report.adapter),
        "fps (median frame time)",
        &series(report, |r| r.fps),
    )?;
    let mut paths = vec![error_path, fps_path];
    if report.reference.is_some() {
        let path = with_suffix("-error-vs-reference.png");
        let block_error = |r: &BenchRow| r.vs_reference.map_or(0.0, |e| e.block_mae_relative);
        draw(
            &path,
            "Indirect light: error against the path-traced reference",
            "8×8-block MAE / reference mean (%)",
            &series(report, |r| block_error(r) * 100.0),
        )?;
        paths.push(path);
        // The same error over the number of VALs BRSM draws, one line per RSM size.
        let path = with_suffix("-error-vs-reference-by-vals.png");
        draw_over(
            &path,
            "BRSM indirect light: error against the reference by VAL count",
            &Axis("VALs drawn per frame"),
            "8×8-block MAE / reference mean (%)",
            &lines_by(
                report,
                |r| {
                    (r.method == crate::gi::lightskin::BRSM).then(|| {
                        format!(
                            "RSM {}², {} view samples",
                            r.rsm_size,
                            r.view_samples.unwrap_or(0)
                        )
                    })
                },
                |r| f64::from(r.val_count.unwrap_or(1)).log2(),
                |r| block_error(r) * 100.0,
            ),
        )?;
        paths.push(path);
    }
    if let Some(rgb) = &report.reference_image {
        paths.push(write_rgb(
            with_suffix("-reference.png"),
            rgb,
            report.width,
            report.height,
        )?);
    }
    for row in &report.rows {
        if let Some(rgb) = &row.difference_image {
            let mut name = format!("-diff-{:?}-{}", row.method, row.rsm_size).to_lowercase();
            if let (Some(v), Some(s)) = (row.val_count, row.view_samples) {
                name += &format!("-{v}-{s}");
            }
            paths.push(write_rgb(
                with_suffix(&format!("{name}.png")),
                rgb,
                report.width,
                report.height,
            )?);
        }
    }
    Ok(paths)
}

/// Writes `<prefix>-error-by-surfels.png` and `<prefix>-error-by-links.png` (seed 001's
/// Figure 8: the error against the reference over n_S and over n_L, the other parameters at
/// the sweep's centre, one line per bounce count) and `<prefix>-gi-ms-by-surfels.png`;
/// returns their paths.
pub fn write_surfel_plots(report: &SurfelReport, prefix: &Path) -> Result<Vec<PathBuf>, PlotError> {
    ensure_font()?;
    let path_for = |suffix: &str| {
        let mut name = prefix.as_os_str().to_owned();
        name.push(suffix);
        PathBuf::from(name)
    };
    let lines = |what, x, y: &dyn Fn(&SurfelRow, usize) -> f64| surfel_lines(report, what, x, y);
    let error = |r: &SurfelRow, b: usize| {
        r.errors
            .get(b)
            .map_or(0.0, |e| e.vs_reference.mae_relative * 100.0)
    };
    let y_label = "MAE / reference mean (%)";
    let mut paths = Vec::new();
    let path = path_for("-error-by-surfels.png");
    draw_over(
        &path,
        "surfels: error against the reference by surfel count",
        &Axis("surfels n_S"),
        y_label,
        &lines(Varied::Surfels, |r| r.surfels, &error),
    )?;
    paths.push(path);
    let path = path_for("-error-by-links.png");
    draw_over(
        &path,
        "surfels: error against the reference by links per cache",
        &Axis("links per cache n_L"),
        y_label,
        &lines(Varied::Links, |r| r.links, &error),
    )?;
    paths.push(path);
    let path = path_for("-gi-ms-by-surfels.png");
    let gi_ms = lines(Varied::Surfels, |r| r.surfels, &|r, _| r.gi.median_ms);
    draw_over(
        &path,
        &format!(
            "surfels: GPU time of the GI stages per frame ({})",
            report.adapter
        ),
        &Axis("surfels n_S"),
        "GI ms (median)",
        &gi_ms[..gi_ms.len().min(1)]
            .iter()
            .map(|(_, points)| ("moving light".to_string(), points.clone()))
            .collect::<Vec<_>>(),
    )?;
    paths.push(path);
    Ok(paths)
}

/// Writes `<prefix>-error-by-vals.png` (seed 003's Figure 10: error against the reference by
/// VAL count, one line per VPL count, with visibility off and per-VPL shadows as flat lines
/// at each N) and `<prefix>-error-vs-vpl-shadows.png` (the error clustering adds to exact
/// per-VPL visibility), and `<prefix>-gi-ms-by-vals.png`; returns their paths.
pub fn write_clustered_plots(
    report: &ClusteredReport,
    prefix: &Path,
) -> Result<Vec<PathBuf>, PlotError> {
    ensure_font()?;
    let path_for = |suffix: &str| {
        let mut name = prefix.as_os_str().to_owned();
        name.push(suffix);
        PathBuf::from(name)
    };
    let mut vpl_counts: Vec<u32> = report.rows.iter().map(|r| r.vpls).collect();
    vpl_counts.dedup();
    let cssm = |n: u32| {
        report
            .rows
            .iter()
            .filter(move |r| r.vpls == n && r.visibility == Visibility::Cssm)
    };
    let m_range = |n: u32| {
        let xs: Vec<f64> = cssm(n)
            .filter_map(|r| r.clusters)
            .map(|m| f64::from(m).log2())
            .collect();
        let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
        (lo, xs.iter().copied().fold(lo, f64::max))
    };
    let mut by_reference = Vec::new();
    let mut by_exact = Vec::new();
    let mut gi_ms = Vec::new();
    for &n in &vpl_counts {
        let line =
            |y: &dyn Fn(&crate::bench_clustered::ClusteredRow) -> Option<f64>| -> Vec<(f64, f64)> {
                cssm(n)
                    .filter_map(|r| Some((f64::from(r.clusters?).log2(), y(r)?)))
                    .collect()
            };
        by_reference.push((
            format!("{n} VPLs, CSSM"),
            line(&|r| Some(r.vs_reference.mae_relative * 100.0)),
        ));
        let (lo, hi) = m_range(n);
        for r in report
            .rows
            .iter()
            .filter(|r| r.vpls == n && r.visibility != Visibility::Cssm)
        {
            let y = r.vs_reference.mae_relative * 100.0;
            by_reference.push((
                format!("{n} VPLs, {}", r.visibility.name()),
                vec![(lo, y), (hi, y)],
            ));
        }
        let exact = line(&|r| Some(r.vs_vpl_shadows?.mae_relative * 100.0));
        if !exact.is_empty() {
            by_exact.push((format!("{n} VPLs, CSSM"), exact));
        }
        gi_ms.push((format!("{n} VPLs, CSSM"), line(&|r| Some(r.gi.median_ms))));
    }
    let mut paths = Vec::new();
    let axis = Axis("VALs M");
    let path = path_for("-error-by-vals.png");
    draw_over(
        &path,
        "clustered: error against the reference by VAL count (Figure 10)",
        &axis,
        "MAE / reference mean (%)",
        &by_reference,
    )?;
    paths.push(path);
    if !by_exact.is_empty() {
        let path = path_for("-error-vs-vpl-shadows.png");
        draw_over(
            &path,
            "clustered: difference from per-VPL hard shadows by VAL count",
            &axis,
            "MAE / per-VPL-shadow mean (%)",
            &by_exact,
        )?;
        paths.push(path);
    }
    let path = path_for("-gi-ms-by-vals.png");
    draw_over(
        &path,
        &format!(
            "clustered: GPU time of the GI stages per frame ({})",
            report.adapter
        ),
        &axis,
        "GI ms (median)",
        &gi_ms,
    )?;
    paths.push(path);
    Ok(paths)
}

/// One line per bounce count of `report` over the rows that vary `what` (and the centre):
/// points (log2 of `x`, `y(row, bounce index)`) by increasing x.
fn surfel_lines(
    report: &SurfelReport,
    what: Varied,
    x: fn(&SurfelRow) -> u32,
    y: &dyn Fn(&SurfelRow, usize) -> f64,
) -> Vec<(String, Vec<(f64, f64)>)> {
    let mut rows: Vec<&SurfelRow> = report
        .rows
        .iter()
        .filter(|r| r.varied == what || r.varied == Varied::Centre)
        .collect();
    rows.sort_by_key(|r| x(r));
    report
        .references
        .iter()
        .enumerate()
        .map(|(b, reference)| {
            let points = rows
                .iter()
                .map(|r| (f64::from(x(r)).log2(), y(r, b)))
                .collect();
            (format!("{} bounce(s)", reference.bounces), points)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::StageStats;
    use crate::gpu::timing::TimingSource;

    fn row(
        method: crate::gi::GiMethod,
        rsm_size: u32,
        vals: Option<u32>,
        fps: f64,
        mad: f64,
    ) -> BenchRow {
        let stats = StageStats {
            median_ms: 1000.0 / fps,
            p95_ms: 1000.0 / fps,
        };
        BenchRow {
            method,
            rsm_size,
            val_count: vals,
            view_samples: vals.map(|_| 512),
            stages: Default::default(),
            gi: stats,
            frame: stats,
            fps,
            mad,
            mad_relative: mad,
            speedup_vs_lightskin: 1.0,
            vs_reference: Some(crate::quality::ErrorStats {
                mae: mad,
                rmse: mad,
                mae_relative: mad,
                block_mae_relative: mad,
                bias_relative: 0.0,
            }),
            final_psnr_db: Some(30.0),
            final_flip: Some(0.1),
            difference_image: Some(vec![0; 3]),
        }
    }

    #[test]
    fn plots_are_written_as_png_images() {
        let rows = [128, 256, 512]
            .iter()
            .flat_map(|&s| {
                [
                    row(
                        crate::gi::lightskin::LIGHTSKIN,
                        s,
                        None,
                        1e5 / f64::from(s),
                        0.0,
                    ),
                    row(crate::gi::lightskin::BRSM, s, Some(2048), 500.0, 0.1),
                    row(crate::gi::lightskin::BRSM, s, Some(8192), 300.0, 0.05),
                ]
            })
            .collect();
        let report = BenchReport {
            adapter: "test".into(),
            timing_source: TimingSource::GpuTimestamps,
            scene: "t".into(),
            triangles: 1,
            caches: 1,
            width: 1,
            height: 1,
            frames: 1,
            warmup: 0,
            defensive: 0.1,
            glossy_exponent: None,
            occlusion: true,
            reference: Some(crate::bench::ReferenceSummary {
                spp: 1,
                bounces: 1,
                relative_standard_error: 0.1,
                mean: 1.0,
            }),
            reference_image: Some(vec![255; 3]),
            rows,
        };
        // Two configurations of BRSM plus LightSkin: three lines in the fps plot.
        assert_eq!(series(&report, |r| r.fps).len(), 3);
        // By VAL count: one BRSM line per RSM size, two points each.
        let by_vals = lines_by(
            &report,
            |r| (r.method == crate::gi::lightskin::BRSM).then(|| r.rsm_size.to_string()),
            |r| f64::from(r.val_count.unwrap_or(1)).log2(),
            |r| r.fps,
        );
        assert_eq!(by_vals.len(), 3);
        assert!(by_vals
            .iter()
            .all(|(_, p)| p.iter().map(|q| q.0).eq([11.0, 13.0])));
        let dir = tempfile::tempdir().expect("temp dir");
        let paths = write_plots(&report, &dir.path().join("bench")).expect("plots");
        // Four plots, the reference picture and one difference picture per row.
        assert_eq!(paths.len(), 5 + 9);
        let (plots, pictures) = paths.split_at(4);
        for path in pictures {
            let image = image::open(path).expect("a PNG");
            assert_eq!(
                (image.width(), image.height()),
                (1, 1),
                "{}",
                path.display()
            );
        }
        for path in plots {
            let image = image::open(path).expect("a PNG");
            assert_eq!((image.width(), image.height()), (960, 600));
            // Not a blank canvas: some pixels are not white.
            let rgb = image.to_rgb8();
            assert!(rgb.pixels().filter(|p| p.0 != [255, 255, 255]).count() > 1000);
        }
        std::fs::remove_dir_all(&dir).expect("remove temp dir");
    }

    /// The Figure 8 lines: one per bounce count, over the rows that vary n_S (or n_L) and the
    /// centre, by increasing count; the three plots are written.
    #[test]
    fn surfel_plots_draw_one_line_per_bounce_count_over_the_varied_rows() {
        use crate::bench_surfels::{BounceError, SurfelReference};
        let stats = StageStats {
            median_ms: 2.0,
            p95_ms: 3.0,
        };
        let row = |varied, surfels, links, error: f64| SurfelRow {
            varied,
            surfels,
            links,
            bands: 3,
            caches: 8,
            usable_caches: 4,
            precompute_s: 1.0,
            stages: Default::default(),
            gi: stats,
            frame: stats,
            fps: 500.0,
            errors: [1, 3]
                .map(|bounces| BounceError {
                    bounces,
                    vs_reference: crate::quality::ErrorStats {
                        mae: error,
                        rmse: error,
                        mae_relative: error * f64::from(bounces),
                        block_mae_relative: error,
                        bias_relative: 0.0,
                    },
                })
                .to_vec(),
        };
        let report = SurfelReport {
            adapter: "test".into(),
            timing_source: crate::gpu::timing::TimingSource::GpuTimestamps,
            cpu_threads: 2,
            link_rays_on_gpu: false,
            scene: "t".into(),
            triangles: 1,
            width: 1,
            height: 1,
            frames: 1,
            warmup: 0,
            cache_spacing: 0.5,
            references: [1, 3]
                .map(|bounces| SurfelReference {
                    bounces,
                    spp: 1,
                    relative_standard_error: 0.1,
                })
                .to_vec(),
            rows: vec![
                row(Varied::Centre, 2048, 64, 0.2),
                row(Varied::Surfels, 8192, 64, 0.1),
                row(Varied::Surfels, 1024, 64, 0.4),
                row(Varied::Links, 2048, 16, 0.5),
            ],
            methods: Vec::new(),
        };
        let error = |r: &SurfelRow, b: usize| r.errors[b].vs_reference.mae_relative;
        let by_surfels = surfel_lines(&report, Varied::Surfels, |r| r.surfels, &error);
        assert_eq!(by_surfels.len(), 2);
        assert_eq!(by_surfels[0].0, "1 bounce(s)");
        assert_eq!(by_surfels[0].1, vec![(10.0, 0.4), (11.0, 0.2), (13.0, 0.1)]);
        assert_eq!(by_surfels[1].1[0], (10.0, 0.4 * 3.0));
        let by_links = surfel_lines(&report, Varied::Links, |r| r.links, &error);
        assert_eq!(by_links[0].1, vec![(4.0, 0.5), (6.0, 0.2)]);
        let dir = tempfile::tempdir().expect("temp dir");
        let paths = write_surfel_plots(&report, &dir.path().join("s")).expect("plots");
        assert_eq!(paths.len(), 3);
        for path in &paths {
            let image = image::open(path).expect("a PNG");
            assert_eq!((image.width(), image.height()), (960, 600));
        }
    }
}
