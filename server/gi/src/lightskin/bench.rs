//! Seed 004's evaluation (its Figures 3 and 5) as a `bench` sweep: for every RSM size,
//! LightSkin (every texel a VAL) and then every BRSM configuration (VAL count × view
//! samples) at that size, each BRSM row also compared with LightSkin's indirect light at the
//! same size: the error importance sampling adds to using every VAL.

use super::params::{VAL_COUNT, VIEW_SAMPLES};
use super::{BRSM, LIGHTSKIN};
use crate::gi::bench::{Configuration, Figure, Sweep, SweepAxis, SweepValues};
use crate::gi::common::params::RSM_SIZE;
use lightcast_protocol::GiParams;

pub static RSM_SIZES: SweepAxis = SweepAxis {
    flag: "rsm-sizes",
    default: &[128, 256, 512, 1024, 2048],
    may_be_empty: false,
    doc: "RSM sides (LightSkin and BRSM at each)",
};

pub static VALS: SweepAxis = SweepAxis {
    flag: "vals",
    default: &[2048, 4096, 8192],
    may_be_empty: false,
    doc: "BRSM's VAL counts N_sVAL",
};

pub static VIEW_SAMPLE_COUNTS: SweepAxis = SweepAxis {
    flag: "view-samples",
    default: &[256, 512],
    may_be_empty: false,
    doc: "BRSM's view-sample counts N_VS",
};

/// Figures 3 and 5: error and time over the RSM side, a line per configuration.
static BY_RSM: Figure = Figure {
    slug: "rsm-size",
    axis: "RSM side (texels)",
};

/// BRSM's error over its VAL count, a line per RSM size and view-sample count.
static BY_VALS: Figure = Figure {
    slug: "vals",
    axis: "VALs drawn per frame",
};

pub static SWEEP: Sweep = Sweep {
    summary: "Seed 004 (Figures 3, 5): at every RSM size, LightSkin and then BRSM at every VAL \
              count × view-sample count, each BRSM row also against LightSkin at the same RSM \
              size.",
    axes: &[&RSM_SIZES, &VALS, &VIEW_SAMPLE_COUNTS],
    configurations,
    bounces: &[1],
    ladder,
};

fn configurations(base: &GiParams, values: &SweepValues) -> Vec<Configuration> {
    let mut out = Vec::new();
    for &rsm_size in values.of(&RSM_SIZES) {
        let mut lightskin = base.clone().with(RSM_SIZE.name, rsm_size);
        lightskin.method = LIGHTSKIN;
        let baseline = out.len();
        out.push(
            Configuration::new(lightskin.clone(), vec![("RSM", format!("{rsm_size}²"))]).at(
                &BY_RSM,
                "LightSkin",
                f64::from(rsm_size),
            ),
        );
        for &vals in values.of(&VALS) {
            for &samples in values.of(&VIEW_SAMPLE_COUNTS) {
                let mut gi = lightskin
                    .clone()
                    .with(VAL_COUNT.name, vals)
                    .with(VIEW_SAMPLES.name, samples);
                gi.method = BRSM;
                let mut c = Configuration::new(
                    gi,
                    vec![
                        ("RSM", format!("{rsm_size}²")),
                        ("VALs", vals.to_string()),
                        ("view samples", samples.to_string()),
                    ],
                )
                .at(
                    &BY_RSM,
                    format!("BRSM {vals} VALs, {samples} view samples"),
                    f64::from(rsm_size),
                )
                .at(
                    &BY_VALS,
                    format!("RSM {rsm_size}², {samples} view samples"),
                    f64::from(vals),
                );
                c.baseline = Some(baseline);
                out.push(c);
            }
        }
    }
    // BRSM at the setting nearest the table's defaults stands for the pair at equal time.
    let defaults = [
        RSM_SIZE.u32(base),
        VAL_COUNT.u32(base),
        VIEW_SAMPLES.u32(base),
    ];
    let distance = |c: &Configuration| -> f64 {
        [
            RSM_SIZE.u32(&c.gi),
            VAL_COUNT.u32(&c.gi),
            VIEW_SAMPLES.u32(&c.gi),
        ]
        .iter()
        .zip(defaults)
        .map(|(&v, d)| (f64::from(v).log2() - f64::from(d).log2()).abs())
        .sum()
    };
    if let Some(c) = out
        .iter_mut()
        .filter(|c| c.gi.method == BRSM)
        .min_by(|a, b| distance(a).total_cmp(&distance(b)))
    {
        c.centre = true;
    }
    out
}

/// LightSkin at three RSM sizes, BRSM at three VAL counts with a 256² RSM.
fn ladder(base: &GiParams) -> Vec<Configuration> {
    let lightskin = [64, 128, 256].map(|rsm_size| {
        let mut gi = base.clone().with(RSM_SIZE.name, rsm_size);
        gi.method = LIGHTSKIN;
        Configuration::new(gi, vec![("RSM", format!("{rsm_size}²"))])
    });
    let brsm = [512, 2048, 8192].map(|vals| {
        let mut gi = base
            .clone()
            .with(RSM_SIZE.name, 256)
            .with(VAL_COUNT.name, vals);
        gi.method = BRSM;
        let samples = VIEW_SAMPLES.u32(&gi).to_string();
        Configuration::new(
            gi,
            vec![
                ("RSM", "256²".into()),
                ("VALs", vals.to_string()),
                ("view samples", samples),
            ],
        )
    });
    lightskin.into_iter().chain(brsm).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Per RSM size LightSkin first, then every VAL × view-sample pair compared with it.
    #[test]
    fn brsm_rows_follow_their_lightskin_baseline() {
        let values = SweepValues(
            [
                ("rsm-sizes".to_string(), vec![64, 128]),
                ("vals".to_string(), vec![512, 1024]),
                ("view-samples".to_string(), vec![32]),
            ]
            .into(),
        );
        let configs = configurations(&GiParams::new(BRSM), &values);
        let got: Vec<(String, u32, Option<usize>)> = configs
            .iter()
            .map(|c| (c.gi.method.to_string(), RSM_SIZE.u32(&c.gi), c.baseline))
            .collect();
        let row = |m: &str, r, b| (m.to_string(), r, b);
        assert_eq!(
            got,
            vec![
                row("lightskin", 64, None),
                row("brsm", 64, Some(0)),
                row("brsm", 64, Some(0)),
                row("lightskin", 128, None),
                row("brsm", 128, Some(3)),
                row("brsm", 128, Some(3)),
            ]
        );
        // The largest setting is nearest the defaults (1024², 8192 VALs, 512 view samples).
        let centre: Vec<usize> = (0..configs.len()).filter(|&i| configs[i].centre).collect();
        assert_eq!(centre, vec![5]);
    }
}
