//! The evaluation of `rsm_gather` as a `bench` sweep: every sample count × every gather radius
//! (the paper's two knobs), each against the path-traced reference. The RSM side is
//! `--gi-param rsm_size`.

use super::params::{GATHER_RADIUS, GATHER_SAMPLES};
use super::RSM_GATHER;
use crate::gi::bench::{Configuration, Figure, Sweep, SweepAxis, SweepValues};
use lightcast_protocol::GiParams;

pub static SAMPLES: SweepAxis = SweepAxis {
    flag: "gather-samples",
    default: &[100, 400, 1600],
    may_be_empty: false,
    doc: "samples per pixel (the paper's 400 in the middle)",
};

pub static RADII: SweepAxis = SweepAxis {
    flag: "gather-radii",
    default: &[10, 30, 100],
    may_be_empty: false,
    doc: "gather radii r_max in percent of the RSM's side",
};

/// Error and time over the sample count, a line per radius.
static BY_SAMPLES: Figure = Figure {
    slug: "samples",
    axis: "samples per pixel",
};

pub static SWEEP: Sweep = Sweep {
    summary: "Reflective shadow maps (Dachsbacher & Stamminger 2005): every sample count × \
              gather radius; the RSM side is `--gi-param rsm_size`.",
    axes: &[&SAMPLES, &RADII],
    configurations,
    bounces: &[1],
    ladder,
};

fn at(base: &GiParams, samples: u32, radius_percent: u32) -> Configuration {
    let mut gi = base
        .clone()
        .with(GATHER_SAMPLES.name, samples)
        .with(GATHER_RADIUS.name, f64::from(radius_percent) / 100.0);
    gi.method = RSM_GATHER;
    Configuration::new(
        gi,
        vec![
            ("samples", samples.to_string()),
            ("radius", format!("{radius_percent} %")),
        ],
    )
    .at(
        &BY_SAMPLES,
        format!("r_max {radius_percent} %"),
        f64::from(samples),
    )
}

fn configurations(base: &GiParams, values: &SweepValues) -> Vec<Configuration> {
    let mut out = Vec::new();
    for &r in values.of(&RADII) {
        for &n in values.of(&SAMPLES) {
            out.push(at(base, n, r));
        }
    }
    // The paper's 400 samples at the table's radius (or the nearest) stand for the method.
    let radius = (GATHER_RADIUS.value(base).as_f64().unwrap_or(1.0) * 100.0).round();
    if let Some(c) = out.iter_mut().min_by_key(|c| {
        let n = GATHER_SAMPLES.u32(&c.gi).abs_diff(400);
        let r = GATHER_RADIUS.value(&c.gi).as_f64().unwrap_or(0.0) * 100.0;
        (n, (r - radius).abs() as u32)
    }) {
        c.centre = true;
    }
    out
}

/// 100, 400 and 1,600 samples at the base's radius.
fn ladder(base: &GiParams) -> Vec<Configuration> {
    let radius = (GATHER_RADIUS.value(base).as_f64().unwrap_or(1.0) * 100.0).round() as u32;
    [100, 400, 1600].map(|n| at(base, n, radius)).into()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every radius × every count, radius-major; the paper's 400 at the default radius is the
    /// centre.
    #[test]
    fn configurations_cross_samples_and_radii() {
        let values = SweepValues(
            [
                ("gather-samples", vec![100, 400]),
                ("gather-radii", vec![10, 30]),
            ]
            .map(|(k, v)| (k.to_string(), v))
            .into(),
        );
        let configs = configurations(&GiParams::new(RSM_GATHER), &values);
        let got: Vec<(u32, f64)> = configs
            .iter()
            .map(|c| {
                (
                    GATHER_SAMPLES.u32(&c.gi),
                    GATHER_RADIUS.value(&c.gi).as_f64().unwrap_or(0.0),
                )
            })
            .collect();
        assert_eq!(got, vec![(100, 0.1), (400, 0.1), (100, 0.3), (400, 0.3)]);
        // The nearest to 400 samples at the default radius (1.0): 400 at 0.3.
        let centres: Vec<usize> = (0..4).filter(|&i| configs[i].centre).collect();
        assert_eq!(centres, vec![3]);
    }
}
