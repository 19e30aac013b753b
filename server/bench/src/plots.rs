//! PNG plots of a [`BenchReport`], for every method's sweep alike: per figure its sweep
//! declares (seed 004's Figures 3 and 5 over the RSM side, seed 001's Figure 8 over n_S and
//! n_L, seed 003's Figure 10 over M), the error against the reference and the GI time over
//! the figure's axis, one line per line name and bounce count, and the error against each
//! row's baseline where rows have one; the reference's indirect light and every row's
//! difference from it (seed 004's Figure 6, right column).

use super::report::{BenchReport, BenchRow};
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

/// The x axis of a plot: log2 of what it names.
struct Axis(&'static str);

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

/// Points of one line: (log2 of x, y).
type Line = (String, Vec<(f64, f64)>);

/// The lines of `figure` (its slug): for every row on it and every line name the row gives,
/// the point `(log2 x, value(row))`, sorted by x; rows `value` gives nothing are left out.
fn lines_on(
    report: &BenchReport,
    figure: &str,
    value: impl Fn(&BenchRow) -> Option<f64>,
) -> Vec<Line> {
    let mut out: Vec<Line> = Vec::new();
    for row in &report.rows {
        let Some(y) = value(row) else { continue };
        for p in row.points.iter().filter(|p| p.figure.slug == figure) {
            let point = (p.x.max(1e-9).log2(), y);
            match out.iter_mut().find(|(n, _)| *n == p.line) {
                Some((_, points)) => points.push(point),
                None => out.push((p.line.clone(), vec![point])),
            }
        }
    }
    for (_, points) in &mut out {
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    out
}

/// Writes, for every figure the rows are drawn on, `<prefix>-error-by-<figure>.png` (8×8-block
/// error against the reference, a line per line name and bounce count),
/// `<prefix>-gi-ms-by-<figure>.png` and, where rows on it have a baseline,
/// `<prefix>-error-vs-baseline-by-<figure>.png`; then the reference's indirect light
/// (`<prefix>-reference.png`) and every row's difference from it
/// (`<prefix>-diff-<method>-<cells>.png`). Returns their paths.
pub fn write_plots(report: &BenchReport, prefix: &Path) -> Result<Vec<PathBuf>, PlotError> {
    ensure_font()?;
    let with_suffix = |suffix: &str| {
        let mut name = prefix.as_os_str().to_owned();
        name.push(suffix);
        PathBuf::from(name)
    };
    let mut figures: Vec<&'static crate::gi::bench::Figure> = Vec::new();
    for p in report.rows.iter().flat_map(|r| &r.points) {
        if !figures.iter().any(|f| f.slug == p.figure.slug) {
            figures.push(p.figure);
        }
    }
    let bounces: Vec<u32> = report.references.iter().map(|r| r.bounces).collect();
    let mut paths = Vec::new();
    for figure in figures {
        let axis = Axis(figure.axis);
        let mut error_lines = Vec::new();
        for (b, &count) in report
            .rows
            .first()
            .map(|r| r.errors.iter().map(|e| e.bounces).collect::<Vec<_>>())
            .unwrap_or_default()
            .iter()
            .enumerate()
        {
            for (name, points) in lines_on(report, figure.slug, |r| {
                r.errors
                    .get(b)
                    .map(|e| e.vs_reference.block_mae_relative * 100.0)
            }) {
                let name = if bounces.len() > 1 {
                    format!("{name}, {count} bounce(s)")
                } else {
                    name
                };
                error_lines.push((name, points));
            }
        }
        let path = with_suffix(&format!("-error-by-{}.png", figure.slug));
        draw_over(
            &path,
            "Indirect light: error against the path-traced reference",
            &axis,
            "8×8-block MAE / reference mean (%)",
            &error_lines,
        )?;
        paths.push(path);
        let path = with_suffix(&format!("-gi-ms-by-{}.png", figure.slug));
        draw_over(
            &path,
            &format!("GI time per frame ({})", report.adapter),
            &axis,
            "GI ms (median)",
            &lines_on(report, figure.slug, |r| Some(r.gi.median_ms)),
        )?;
        paths.push(path);
        let against = lines_on(report, figure.slug, |r| {
            r.vs_baseline.map(|e| e.mae_relative * 100.0)
        });
        if !against.is_empty() {
            let path = with_suffix(&format!("-error-vs-baseline-by-{}.png", figure.slug));
            draw_over(
                &path,
                "Indirect light: difference from the configuration each row is compared with",
                &axis,
                "MAE / its mean (%)",
                &against,
            )?;
            paths.push(path);
        }
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
            let name: String = std::iter::once(row.method.to_string())
                .chain(row.cells.iter().map(|c| c.value.clone()))
                .collect::<Vec<_>>()
                .join("-")
                .chars()
                .filter(|c| c.is_ascii_alphanumeric() || *c == '-' || *c == '_')
                .collect();
            paths.push(write_rgb(
                with_suffix(&format!("-diff-{name}.png")),
                rgb,
                report.width,
                report.height,
            )?);
        }
    }
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::report::tests::{report, row};
    use crate::gi::bench::{Figure, Point};

    static BY_SIZE: Figure = Figure {
        slug: "size",
        axis: "size",
    };

    fn at(mut r: BenchRow, line: &str, x: f64) -> BenchRow {
        r.points.push(Point {
            figure: &BY_SIZE,
            line: line.into(),
            x,
        });
        r
    }

    /// A line per name, its points sorted by x on a log2 scale; rows without a value left out.
    #[test]
    fn lines_are_sorted_by_x_per_name() {
        let report = report(vec![
            at(row("brsm", &[("RSM", "256²")], 2.0, 0.2), "a", 256.0),
            at(row("brsm", &[("RSM", "64²")], 1.0, 0.4), "a", 64.0),
            at(row("lightskin", &[("RSM", "64²")], 3.0, 0.1), "b", 64.0),
        ]);
        let lines = lines_on(&report, "size", |r| Some(r.gi.median_ms));
        assert_eq!(
            lines,
            vec![
                ("a".to_string(), vec![(6.0, 1.0), (8.0, 2.0)]),
                ("b".to_string(), vec![(6.0, 3.0)]),
            ]
        );
        assert!(lines_on(&report, "size", |_| None).is_empty());
        assert!(lines_on(&report, "other", |r| Some(r.fps)).is_empty());
    }

    #[test]
    fn plots_are_written_as_png_images() {
        let mut rows: Vec<BenchRow> = [64.0, 128.0, 256.0]
            .iter()
            .flat_map(|&s| {
                [
                    at(
                        row("lightskin", &[("RSM", "x")], s / 64.0, 0.0),
                        "LightSkin",
                        s,
                    ),
                    at(
                        row("brsm", &[("RSM", "x"), ("VALs", "2048")], 1.0, 0.1),
                        "2048",
                        s,
                    ),
                ]
            })
            .collect();
        rows[1].vs_baseline = Some(rows[1].errors[0].vs_reference);
        let dir = tempfile::tempdir().expect("temp dir");
        let paths = write_plots(&report(rows), &dir.path().join("bench")).expect("plots");
        // Three plots (error, GI time, against the baseline), the reference picture and one
        // difference picture per row.
        assert_eq!(paths.len(), 3 + 1 + 6);
        let (plots, pictures) = paths.split_at(3);
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
    }
}
