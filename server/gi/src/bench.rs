//! What `lightcast-server bench` measures of a method: its sweep, declared in its folder
//! (`gi/<method>/bench.rs`) and listed by its [`super::MethodEntry::bench`].
//!
//! A sweep is data, not a loop: the lists it varies ([`SweepAxis`], each a `bench` flag with
//! its default values) and a function that turns their values into the configurations to run,
//! in order, each with the cells of its report row, the points it adds to the plots and,
//! optionally, an earlier configuration it is also compared with (BRSM against LightSkin at
//! the same RSM size, CSSM against per-VPL shadows at the same VPL count). The bench
//! (`crate::bench`) renders, times and measures them all the same way against the
//! path-traced reference, so a method's evaluation needs no code outside its folder.

use super::{GiMethod, GiParams};
use std::collections::BTreeMap;

/// One list a sweep varies: a `bench` flag taking comma-separated values.
#[derive(Debug)]
pub struct SweepAxis {
    /// The flag without its dashes (`vals` for `--vals`).
    pub flag: &'static str,
    /// Its values when the flag is not given.
    pub default: &'static [u32],
    /// Whether an empty list is allowed (a list of optional extras); else it is refused.
    pub may_be_empty: bool,
    /// The flag's help, for people.
    pub doc: &'static str,
}

/// A plot a sweep's configurations are drawn on: the error and GI time over `axis`, one line
/// per name the configurations give ([`Point::line`]), on a log2 scale.
#[derive(Debug)]
pub struct Figure {
    /// The file-name part (`<prefix>-error-by-<slug>.png`).
    pub slug: &'static str,
    /// The x axis's label.
    pub axis: &'static str,
}

/// Where a configuration is drawn on one figure.
#[derive(Clone, Debug)]
pub struct Point {
    pub figure: &'static Figure,
    /// The line it belongs to.
    pub line: String,
    /// Its x value (drawn on a log2 scale).
    pub x: f64,
}

/// One configuration of a sweep.
#[derive(Clone, Debug)]
pub struct Configuration {
    /// The frame's GI method and parameters.
    pub gi: GiParams,
    /// Its report row's cells, by column (`("VALs", "2048")`); columns are shown in the
    /// order they first appear.
    pub cells: Vec<(&'static str, String)>,
    /// Where it is drawn.
    pub points: Vec<Point>,
    /// An earlier configuration (its index) this one is also compared with.
    pub baseline: Option<usize>,
    /// Stands for its method in the equal-time comparison (`--compare-methods`); where no
    /// configuration does, the first.
    pub centre: bool,
}

impl Configuration {
    /// A configuration with only its parameters and cells.
    pub fn new(gi: GiParams, cells: Vec<(&'static str, String)>) -> Self {
        Self {
            gi,
            cells,
            points: Vec::new(),
            baseline: None,
            centre: false,
        }
    }

    /// Also drawn on `figure`, on `line` at `x`.
    pub fn at(mut self, figure: &'static Figure, line: impl Into<String>, x: f64) -> Self {
        self.points.push(Point {
            figure,
            line: line.into(),
            x,
        });
        self
    }

    /// `method: cell, cell, …` (progress lines, error messages, legends).
    pub fn label(&self) -> String {
        let cells: Vec<String> = self
            .cells
            .iter()
            .map(|(column, value)| format!("{column} {value}"))
            .collect();
        format!("{}: {}", self.gi.method, cells.join(", "))
    }
}

/// The values of every axis of a sweep, by flag.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SweepValues(pub BTreeMap<String, Vec<u32>>);

impl SweepValues {
    /// `axis`' values (its default where none were given).
    pub fn of(&self, axis: &SweepAxis) -> &[u32] {
        self.0.get(axis.flag).map_or(axis.default, Vec::as_slice)
    }

    /// Every axis at its default.
    pub fn defaults(sweep: &Sweep) -> Self {
        Self(
            sweep
                .axes
                .iter()
                .map(|a| (a.flag.to_string(), a.default.to_vec()))
                .collect(),
        )
    }
}

/// A method's evaluation.
#[derive(Debug)]
pub struct Sweep {
    /// What it measures and after which paper figure (the README's bench table).
    pub summary: &'static str,
    /// The lists it varies.
    pub axes: &'static [&'static SweepAxis],
    /// The configurations, in order, from the base parameters (`--gi-param`, the method of
    /// `bench --gi`) and the axes' values.
    pub configurations: fn(base: &GiParams, values: &SweepValues) -> Vec<Configuration>,
    /// The bounce counts the error is measured at unless `--bounces` says otherwise (each
    /// against a reference traced with as many).
    pub bounces: &'static [u32],
    /// The method's settings in the equal-time comparison, cheapest first, from the base
    /// parameters of another method's bench (empty: left out of it, e.g. where each setting
    /// is a precomputation of its own).
    pub ladder: fn(base: &GiParams) -> Vec<Configuration>,
}

/// No ladder.
pub fn no_ladder(_: &GiParams) -> Vec<Configuration> {
    Vec::new()
}

/// The sweep of `method`, if its entry declares one.
pub fn of(method: GiMethod) -> Option<&'static Sweep> {
    super::find(method).and_then(|(_, e)| e.bench)
}

/// The methods with a sweep, in registry order.
pub fn methods() -> Vec<GiMethod> {
    super::methods().filter(|&m| of(m).is_some()).collect()
}

/// Every declared sweep once, with the methods it serves.
pub fn all() -> Vec<(&'static Sweep, Vec<GiMethod>)> {
    super::REGISTRY
        .iter()
        .filter_map(|e| Some((e.bench?, e.tables.iter().map(|t| t.method).collect())))
        .collect()
}

/// Every sweep's axes, as `bench` flags (clap's derive cannot loop over a registry). The
/// values given are kept by flag; [`SweepValues::of`] falls back to each axis' default.
#[derive(Clone, Debug, Default)]
pub struct SweepArgs(pub SweepValues);

/// Every axis of every sweep with the methods whose sweep has it.
fn axes() -> Vec<(&'static SweepAxis, Vec<GiMethod>)> {
    let mut out: Vec<(&'static SweepAxis, Vec<GiMethod>)> = Vec::new();
    for (sweep, methods) in all() {
        for &axis in sweep.axes {
            match out.iter_mut().find(|(a, _)| a.flag == axis.flag) {
                Some((_, m)) => m.extend(methods.iter().copied()),
                None => out.push((axis, methods.clone())),
            }
        }
    }
    out
}

impl clap::FromArgMatches for SweepArgs {
    fn from_arg_matches(matches: &clap::ArgMatches) -> Result<Self, clap::Error> {
        let mut args = Self::default();
        args.update_from_arg_matches(matches)?;
        Ok(args)
    }

    fn update_from_arg_matches(&mut self, matches: &clap::ArgMatches) -> Result<(), clap::Error> {
        for (axis, _) in axes() {
            if let Some(values) = matches.get_many::<u32>(axis.flag) {
                self.0
                     .0
                    .insert(axis.flag.to_string(), values.copied().collect());
            }
        }
        Ok(())
    }
}

impl clap::Args for SweepArgs {
    fn augment_args(mut cmd: clap::Command) -> clap::Command {
        for (axis, methods) in axes() {
            let methods: Vec<String> = methods.iter().map(|m| m.to_string()).collect();
            let default: Vec<String> = axis.default.iter().map(u32::to_string).collect();
            cmd = cmd.arg(
                clap::Arg::new(axis.flag)
                    .long(axis.flag)
                    .value_delimiter(',')
                    .num_args(0..)
                    .value_parser(clap::value_parser!(u32))
                    .help(format!(
                        "`--gi {}`: {} [default: {}]",
                        methods.join("|"),
                        axis.doc,
                        default.join(",")
                    )),
            );
        }
        cmd
    }

    fn augment_args_for_update(cmd: clap::Command) -> clap::Command {
        Self::augment_args(cmd)
    }
}

/// The README's table of every sweep: its methods, what it measures and its flags with their
/// defaults (`lightcast-server bench-sweeps`; a test keeps the README equal).
pub fn markdown_table() -> String {
    let mut s = String::from("| `--gi` | evaluation | flags (default) |\n|---|---|---|\n");
    for (sweep, methods) in all() {
        let methods: Vec<String> = methods.iter().map(|m| format!("`{m}`")).collect();
        let flags: Vec<String> = sweep
            .axes
            .iter()
            .map(|a| {
                let default: Vec<String> = a.default.iter().map(u32::to_string).collect();
                format!("`--{}` ({}): {}", a.flag, default.join(","), a.doc)
            })
            .collect();
        let bounces: Vec<String> = sweep.bounces.iter().map(u32::to_string).collect();
        s += &format!(
            "| {} | {} Bounces measured by default: {}. | {} |\n",
            methods.join(", "),
            sweep.summary,
            bounces.join(", "),
            flags.join("<br>")
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At their defaults, every sweep makes configurations a request could ask for: each is a
    /// registered method with parameters its table accepts and its checks pass, baselines
    /// point backwards, and the ladders are valid too. (Flags are checked against the bench's
    /// own by `crate::bench`'s command-line test.)
    #[test]
    fn every_sweep_makes_valid_configurations() {
        let limits = crate::gi::limits::default_limits();
        for (sweep, methods) in all() {
            for &method in &methods {
                let base = GiParams::new(method);
                let configs = (sweep.configurations)(&base, &SweepValues::defaults(sweep));
                assert!(!configs.is_empty(), "{method}: no configurations");
                for (i, c) in configs.iter().chain(&(sweep.ladder)(&base)).enumerate() {
                    let (_, entry) = super::super::entry(c.gi.method);
                    crate::gi::params::check_request(&c.gi, &limits)
                        .unwrap_or_else(|e| panic!("{}: {e:?}", c.label()));
                    // One light face (a spot or directional light): the bench checks again
                    // with its scene's light.
                    (entry.validate)(&c.gi, 1).unwrap_or_else(|e| panic!("{}: {e}", c.label()));
                    assert!(c.baseline.is_none_or(|b| b < i), "{}", c.label());
                    assert!(
                        !c.cells.is_empty(),
                        "{method}: a configuration without cells"
                    );
                }
            }
        }
        assert!(!methods().is_empty());
    }

    /// A flag is one axis (two sweeps may share it only as the same declaration), and an
    /// axis that must have values has default values.
    #[test]
    fn axis_flags_are_declared_once() {
        for (sweep, _) in all() {
            for a in sweep.axes {
                let declared = axes().into_iter().find(|(o, _)| o.flag == a.flag);
                assert!(
                    declared.is_some_and(|(d, _)| std::ptr::eq(d, *a)),
                    "--{}",
                    a.flag
                );
                assert!(a.may_be_empty || !a.default.is_empty(), "--{}", a.flag);
            }
        }
    }

    /// The README's sweep table is the sweeps' (`lightcast-server bench-sweeps` prints it).
    #[test]
    fn the_readme_lists_the_sweeps() {
        let readme = include_str!("../../../README.md");
        let (begin, end) = ("<!-- bench-sweeps:begin -->\n", "<!-- bench-sweeps:end -->");
        let start = readme.find(begin).expect("the README marks its table") + begin.len();
        let len = readme[start..].find(end).expect("and its end");
        let table = markdown_table();
        assert!(
            readme[start..start + len] == table,
            "the README's sweep table is stale; replace it with `lightcast-server bench-sweeps`:\n{table}"
        );
    }

    /// Given flags are read back by name; the others fall back to their defaults.
    #[test]
    fn sweep_flags_parse() {
        let (axis, _) = axes().into_iter().next().expect("an axis");
        let cmd = <SweepArgs as clap::Args>::augment_args(clap::Command::new("bench"));
        let matches = cmd
            .try_get_matches_from(["bench", &format!("--{}", axis.flag), "3,5"])
            .expect("parses");
        let args = <SweepArgs as clap::FromArgMatches>::from_arg_matches(&matches).expect("reads");
        assert_eq!(args.0.of(axis), &[3, 5]);
        for (other, _) in axes().into_iter().skip(1) {
            assert_eq!(args.0.of(other), other.default);
        }
    }
}
