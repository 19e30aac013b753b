//! Seed 003's evaluation (its Tables 1–2 and Figure 10) as a `bench` sweep: for every VPL
//! count N, visibility `off` (Figure 10's "without visibility"), instant radiosity with a
//! hard-shadow paraboloid map per VPL (`vpl_shadows`, only for the N of `--baseline-vpls`: its
//! maps grow with N) and CSSM at every VAL count M ≤ N, each CSSM row also against the
//! per-VPL shadows of the same N where those ran (the error clustering adds to exact
//! visibility). The per-stage times are the paper's Table 2 rows (deferred = G-buffer, VPL
//! generation, clustering, CSSM = paraboloid maps + basis, indirect, blur).

use super::params::{
    Visibility, CLUSTER_COUNT, MIN_PARABOLOID_SIZE, PARABOLOID_SIZE, VISIBILITY, VPL_COUNT,
};
use super::passes::AtlasLayout;
use super::CLUSTERED;
use crate::gi::bench::{Configuration, Figure, Sweep, SweepAxis, SweepValues};
use lightcast_protocol::GiParams;

pub static VPLS: SweepAxis = SweepAxis {
    flag: "sweep-vpls",
    default: &[1024, 4096, 16384],
    may_be_empty: false,
    doc: "VPL counts N",
};

pub static CLUSTERS: SweepAxis = SweepAxis {
    flag: "sweep-clusters",
    default: &[5, 10, 20, 30, 64, 128],
    may_be_empty: false,
    doc: "VAL counts M for CSSM, at every N (those above N are left out)",
};

pub static BASELINE_VPLS: SweepAxis = SweepAxis {
    flag: "baseline-vpls",
    default: &[1024],
    may_be_empty: true,
    doc: "the VPL counts that also run per-VPL hard shadows (one map per VPL, so small N)",
};

pub static MAP_SIZES: SweepAxis = SweepAxis {
    flag: "paraboloid-size",
    default: &[256],
    may_be_empty: false,
    doc: "sides of each VAL's paraboloid map for CSSM (halved where the maps exceed the budget)",
};

pub static BASELINE_MAP_SIZES: SweepAxis = SweepAxis {
    flag: "baseline-paraboloid-size",
    default: &[128],
    may_be_empty: false,
    doc: "sides of each VPL's paraboloid map for per-VPL shadows",
};

/// Figure 10: error and time over M, a line per N (visibility off and per-VPL shadows as
/// flat lines at their N).
static BY_VALS: Figure = Figure {
    slug: "vals",
    axis: "VALs M",
};

pub static SWEEP: Sweep = Sweep {
    summary: "Seed 003 (Tables 1–2, Figure 10): at every VPL count N, visibility off, per-VPL \
              hard shadows (`vpl_shadows`, the N of `--baseline-vpls`) and CSSM at every VAL \
              count M ≤ N, CSSM rows also against per-VPL shadows at the same N. The RSM side \
              is `--gi-param rsm_size`.",
    axes: &[
        &VPLS,
        &CLUSTERS,
        &BASELINE_VPLS,
        &MAP_SIZES,
        &BASELINE_MAP_SIZES,
    ],
    configurations,
    bounces: &[1],
    ladder,
};

/// The largest map side up to `requested` (halving it) whose maps fit the server's budget, so
/// that large VAL counts still run; the row names the side it used.
fn fitting_map_size(visibility: Visibility, requested: u32, vpls: u32, vals: u32) -> u32 {
    let fits = |size: u32| AtlasLayout::of(visibility, size, vpls, vals).fits();
    let mut size = requested;
    while size > MIN_PARABOLOID_SIZE && !fits(size) {
        size /= 2;
    }
    size
}

/// `base` as `clustered` with N VPLs, M VALs and `visibility` at a map side that fits.
fn at(base: &GiParams, visibility: Visibility, n: u32, m: u32, map: u32) -> GiParams {
    let mut gi = base
        .clone()
        .with(VPL_COUNT.name, n)
        .with(CLUSTER_COUNT.name, m)
        .with(VISIBILITY.name, visibility.name())
        .with(
            PARABOLOID_SIZE.name,
            fitting_map_size(visibility, map, n, m),
        );
    gi.method = CLUSTERED;
    gi
}

fn cells(gi: &GiParams) -> Vec<(&'static str, String)> {
    let visibility = VISIBILITY
        .value(gi)
        .as_str()
        .unwrap_or_default()
        .to_string();
    let mut cells = vec![("VPLs", VPL_COUNT.u32(gi).to_string())];
    if visibility == Visibility::Cssm.name() {
        cells.push(("VALs", CLUSTER_COUNT.u32(gi).to_string()));
    }
    if visibility != Visibility::Off.name() {
        cells.push(("map", format!("{}²", PARABOLOID_SIZE.u32(gi))));
    }
    cells.insert(1, ("visibility", visibility));
    cells
}

fn configurations(base: &GiParams, values: &SweepValues) -> Vec<Configuration> {
    let mut out = Vec::new();
    let (base_m, base_map) = (CLUSTER_COUNT.u32(base), PARABOLOID_SIZE.u32(base));
    for &n in values.of(&VPLS) {
        let ms: Vec<u32> = values
            .of(&CLUSTERS)
            .iter()
            .copied()
            .filter(|&m| m <= n)
            .collect();
        let flat = |mut c: Configuration, line: String| {
            for &m in &ms {
                c = c.at(&BY_VALS, line.clone(), f64::from(m));
            }
            c
        };
        let off = at(base, Visibility::Off, n, base_m, base_map);
        out.push(flat(
            Configuration::new(off.clone(), cells(&off)),
            format!("{n} VPLs, no visibility"),
        ));
        let mut exact = None;
        if values.of(&BASELINE_VPLS).contains(&n) {
            for &map in values.of(&BASELINE_MAP_SIZES) {
                let gi = at(base, Visibility::VplShadows, n, base_m, map);
                exact.get_or_insert(out.len());
                let line = format!("{n} VPLs, per-VPL shadows {}²", PARABOLOID_SIZE.u32(&gi));
                out.push(flat(Configuration::new(gi.clone(), cells(&gi)), line));
            }
        }
        for &map in values.of(&MAP_SIZES) {
            for &m in &ms {
                let gi = at(base, Visibility::Cssm, n, m, map);
                let mut c = Configuration::new(gi.clone(), cells(&gi)).at(
                    &BY_VALS,
                    format!("{n} VPLs, CSSM {map}²"),
                    f64::from(m),
                );
                c.baseline = exact;
                out.push(c);
            }
        }
    }
    // The CSSM row nearest the paper's setting (1,024 VPLs, 30 VALs) stands for the method.
    let paper = |c: &Configuration| {
        (
            VPL_COUNT.u32(&c.gi).abs_diff(1024),
            CLUSTER_COUNT.u32(&c.gi).abs_diff(30),
        )
    };
    if let Some(c) = out
        .iter_mut()
        .filter(|c| VISIBILITY.value(&c.gi).as_str() == Some(Visibility::Cssm.name()))
        .min_by_key(|c| paper(c))
    {
        c.centre = true;
    }
    out
}

/// CSSM at three VPL counts with the base's VAL count.
fn ladder(base: &GiParams) -> Vec<Configuration> {
    [256, 1024, 4096]
        .map(|n| {
            let gi = at(
                base,
                Visibility::Cssm,
                n,
                CLUSTER_COUNT.u32(base),
                PARABOLOID_SIZE.u32(base),
            );
            Configuration::new(gi.clone(), cells(&gi))
        })
        .into()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values(vpls: &[u32], clusters: &[u32], baseline: &[u32], map: u32) -> SweepValues {
        SweepValues(
            [
                ("sweep-vpls", vpls.to_vec()),
                ("sweep-clusters", clusters.to_vec()),
                ("baseline-vpls", baseline.to_vec()),
                ("paraboloid-size", vec![map]),
                ("baseline-paraboloid-size", vec![32]),
            ]
            .map(|(k, v)| (k.to_string(), v))
            .into(),
        )
    }

    /// Per N: off, the per-VPL baseline where asked for, then every M that is at most N, the
    /// CSSM rows compared with the baseline of their N; maps halved where they do not fit.
    #[test]
    fn configurations_cover_every_n_and_m() {
        let base = GiParams::new(CLUSTERED);
        // 128 VALs do not fit at 256² (480 MiB): they get 128².
        let sizes: Vec<u32> = configurations(&base, &values(&[1024], &[64, 128], &[], 256))
            .iter()
            .map(|c| PARABOLOID_SIZE.u32(&c.gi))
            .collect();
        assert_eq!(sizes, vec![PARABOLOID_SIZE.u32(&base), 256, 128]);
        let configs = configurations(&base, &values(&[256, 1024], &[10, 512], &[256], 64));
        let got: Vec<(u32, u32, u32, Option<usize>)> = configs
            .iter()
            .map(|c| {
                (
                    VPL_COUNT.u32(&c.gi),
                    CLUSTER_COUNT.u32(&c.gi),
                    PARABOLOID_SIZE.u32(&c.gi),
                    c.baseline,
                )
            })
            .collect();
        let visibilities: Vec<String> = configs
            .iter()
            .map(|c| VISIBILITY.value(&c.gi).as_str().unwrap_or("").to_string())
            .collect();
        let (m, map) = (CLUSTER_COUNT.u32(&base), PARABOLOID_SIZE.u32(&base));
        assert_eq!(
            got,
            vec![
                (256, m, map, None),
                (256, m, 32, None),
                (256, 10, 64, Some(1)),
                (1024, m, map, None),
                (1024, 10, 64, None),
                (1024, 512, 64, None),
            ]
        );
        assert_eq!(
            visibilities,
            ["off", "vpl_shadows", "cssm", "off", "cssm", "cssm"]
        );
        // The bench checks every row like a request before it starts: 512 VALs are refused.
        assert!((super::super::ENTRY.validate)(&configs[5].gi, 6).is_err());
        assert!((super::super::ENTRY.validate)(&configs[4].gi, 6).is_ok());
        // Of the CSSM rows, (1024 VPLs, 10 VALs) is nearest the paper's (1024, 30).
        let centres: Vec<usize> = (0..configs.len()).filter(|&i| configs[i].centre).collect();
        assert_eq!(centres, vec![4]);
    }
}
