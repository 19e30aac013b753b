//! Seed 001's evaluation (its Figure 8 and timing table) as a `bench` sweep: one parameter at
//! a time around a centre (`--gi-param`'s `surfel_count`, `surfel_links` and `sh_bands`, by
//! default the table's 32,768 surfels, 128 links and 3 bands): every surfel count of
//! `--sweep-surfels` with the centre's links and bands, then every link count, then every
//! band count. Each is a precomputation of its own, which the bench builds afresh and times;
//! the frames run a full bounce each under the bench's moving light (surfel light, pull-up,
//! cache light, shading), as in the paper's dynamic scenes.

use super::params::{SH_BANDS, SURFEL_COUNT, SURFEL_LINKS};
use super::SURFELS;
use crate::gi::bench::{no_ladder, Configuration, Figure, Sweep, SweepAxis, SweepValues};
use crate::gi::params::Param;
use lightcast_protocol::GiParams;

pub static SURFEL_COUNTS: SweepAxis = SweepAxis {
    flag: "sweep-surfels",
    default: &[8192, 32768, 131072],
    may_be_empty: true,
    doc: "surfel counts n_S, with links and bands at the centre",
};

pub static LINK_COUNTS: SweepAxis = SweepAxis {
    flag: "sweep-links",
    default: &[32, 64, 128, 256],
    may_be_empty: true,
    doc: "links per cache n_L, with surfels and bands at the centre",
};

pub static BAND_COUNTS: SweepAxis = SweepAxis {
    flag: "sweep-bands",
    default: &[2, 3, 4],
    may_be_empty: true,
    doc: "SH bands, with surfels and links at the centre",
};

/// Figure 8: error over n_S and over n_L; and over the bands.
static BY_SURFELS: Figure = Figure {
    slug: "surfels",
    axis: "surfels n_S",
};
static BY_LINKS: Figure = Figure {
    slug: "links",
    axis: "links per cache n_L",
};
static BY_BANDS: Figure = Figure {
    slug: "bands",
    axis: "SH bands",
};

pub static SWEEP: Sweep = Sweep {
    summary: "Seed 001 (Figure 8, timing table): one parameter at a time around the centre \
              given by `--gi-param` `surfel_count`, `surfel_links` and `sh_bands`; every \
              configuration precomputed afresh and timed.",
    axes: &[&SURFEL_COUNTS, &LINK_COUNTS, &BAND_COUNTS],
    configurations,
    bounces: &[1, 3],
    ladder: no_ladder,
};

/// The varied parameters, with their axes and figures, in the order the rows vary them.
const VARIED: [(&Param, &SweepAxis, &Figure); 3] = [
    (&SURFEL_COUNT, &SURFEL_COUNTS, &BY_SURFELS),
    (&SURFEL_LINKS, &LINK_COUNTS, &BY_LINKS),
    (&SH_BANDS, &BAND_COUNTS, &BY_BANDS),
];

fn cells(varied: &str, gi: &GiParams) -> Vec<(&'static str, String)> {
    let mut cells = vec![("varied", varied.to_string())];
    cells.extend([
        ("surfels", SURFEL_COUNT.u32(gi).to_string()),
        ("links", SURFEL_LINKS.u32(gi).to_string()),
        ("bands", SH_BANDS.u32(gi).to_string()),
    ]);
    cells
}

/// The centre, then each list with the other two parameters at the centre (the centre itself
/// only once), each drawn over the parameter it varies.
fn configurations(base: &GiParams, values: &SweepValues) -> Vec<Configuration> {
    let mut centre = base.clone();
    centre.method = SURFELS;
    let mut first = Configuration::new(centre.clone(), cells("centre", &centre));
    for (param, _, figure) in VARIED {
        first = first.at(
            figure,
            "the others at the centre",
            f64::from(param.u32(&centre)),
        );
    }
    first.centre = true;
    let mut out = vec![first];
    for (param, axis, figure) in VARIED {
        for &v in values.of(axis) {
            if v == param.u32(&centre) {
                continue;
            }
            let gi = centre.clone().with(param.name, v);
            out.push(Configuration::new(gi.clone(), cells(param.name, &gi)).at(
                figure,
                "the others at the centre",
                f64::from(v),
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One parameter at a time around the centre, the centre once, in list order.
    #[test]
    fn the_sweep_varies_one_parameter_at_a_time() {
        let base = GiParams::new(SURFELS)
            .with("surfel_count", 32768)
            .with("surfel_links", 128)
            .with("sh_bands", 3)
            .with("surfel_cache_spacing", 0.2);
        let values = |s: &[u32], l: &[u32], b: &[u32]| {
            SweepValues(
                [
                    ("sweep-surfels", s.to_vec()),
                    ("sweep-links", l.to_vec()),
                    ("sweep-bands", b.to_vec()),
                ]
                .map(|(k, v)| (k.to_string(), v))
                .into(),
            )
        };
        let configs = configurations(&base, &values(&[8192, 32768], &[64, 128], &[2, 3, 4]));
        let got: Vec<(String, u32, u32, u32)> = configs
            .iter()
            .map(|c| {
                (
                    c.cells[0].1.clone(),
                    SURFEL_COUNT.u32(&c.gi),
                    SURFEL_LINKS.u32(&c.gi),
                    SH_BANDS.u32(&c.gi),
                )
            })
            .collect();
        let row = |v: &str, s, l, b| (v.to_string(), s, l, b);
        assert_eq!(
            got,
            vec![
                row("centre", 32768, 128, 3),
                row("surfel_count", 8192, 128, 3),
                row("surfel_links", 32768, 64, 3),
                row("sh_bands", 32768, 128, 2),
                row("sh_bands", 32768, 128, 4),
            ]
        );
        assert!(configs
            .iter()
            .all(|c| c.gi.get("surfel_cache_spacing") == Some(&0.2.into())));
        assert_eq!(configs[0].points.len(), 3, "the centre is on every figure");
        assert_eq!(configurations(&base, &values(&[], &[], &[])).len(), 1);
    }
}
