//! Server limits the GI methods declare: the largest values of their parameters an operator
//! allows (`--max-val-count`) and the budgets their precomputations are counted in
//! (`--max-total-surfel-links`). Each is one [`GiLimit`] in its method's folder (the shared
//! ones in `gi/common/limits.rs`), listed by its [`super::MethodEntry::limits`]; from them come
//! the `serve` flags and their environment variables, their checks, `/v1/server`'s `limits`
//! (flattened, so the field names are the ones clients read) and the budget pools
//! (`service::budget`).

use lightcast_protocol::Limits;
use std::collections::BTreeMap;

/// One limit.
#[derive(Debug)]
pub struct GiLimit {
    /// The field of `/v1/server`'s `limits` (`max_val_count`).
    pub name: &'static str,
    /// The `serve` flag that sets it (`--max-val-count`: the name with hyphens).
    pub flag: &'static str,
    /// Its environment variable (`LIGHTCAST_MAX_VAL_COUNT`).
    pub env: &'static str,
    pub default: u64,
    /// What an operator may set.
    pub min: u64,
    pub max: u64,
    /// A limit this one may not be below (a total is at least one set's).
    pub at_least: Option<&'static GiLimit>,
    /// The flag's help, for people.
    pub doc: &'static str,
}

impl GiLimit {
    /// The value on a server with `limits` (the default where `limits` lack it, as from an
    /// older server).
    pub fn of(&self, limits: &Limits) -> u64 {
        limits
            .gi
            .get(self.name)
            .and_then(serde_json::Value::as_u64)
            .unwrap_or(self.default)
    }
}

/// Every declared limit, once each, in registry order.
pub fn all() -> Vec<&'static GiLimit> {
    let mut all: Vec<&'static GiLimit> = Vec::new();
    for limit in super::REGISTRY.iter().flat_map(|e| e.limits) {
        if !all.iter().any(|l| l.name == limit.name) {
            all.push(limit);
        }
    }
    all
}

/// Checks `values` (every limit's, by name) against the declared ranges; the error names
/// the flag.
pub fn check(values: &BTreeMap<String, u64>) -> Result<(), (&'static str, String)> {
    let value = |l: &GiLimit| values.get(l.name).copied().unwrap_or(l.default);
    for l in all() {
        let v = value(l);
        let lo = l.at_least.map_or(l.min, |other| value(other).max(l.min));
        if !(lo..=l.max).contains(&v) {
            return Err((l.flag, format!("{v} is outside {lo}..={}", l.max)));
        }
    }
    Ok(())
}

/// The `serve` flags of every declared limit (clap's derive cannot loop over a registry).
#[derive(Clone, Debug, Default)]
pub struct GiLimitArgs(pub BTreeMap<String, u64>);

impl clap::FromArgMatches for GiLimitArgs {
    fn from_arg_matches(matches: &clap::ArgMatches) -> Result<Self, clap::Error> {
        let mut args = Self(
            all()
                .iter()
                .map(|l| (l.name.to_string(), l.default))
                .collect(),
        );
        args.update_from_arg_matches(matches)?;
        Ok(args)
    }

    fn update_from_arg_matches(&mut self, matches: &clap::ArgMatches) -> Result<(), clap::Error> {
        for l in all() {
            if let Some(&v) = matches.get_one::<u64>(l.name) {
                self.0.insert(l.name.to_string(), v);
            }
        }
        Ok(())
    }
}

impl clap::Args for GiLimitArgs {
    fn augment_args(mut cmd: clap::Command) -> clap::Command {
        for l in all() {
            cmd = cmd.arg(
                clap::Arg::new(l.name)
                    .long(&l.flag[2..])
                    .env(l.env)
                    .value_parser(clap::value_parser!(u64))
                    // A default given as a value would need clap's `string` feature for an
                    // owned text; [`FromArgMatches`] fills it in instead.
                    .help(format!("{} [default: {}]", l.doc, l.default)),
            );
        }
        cmd
    }

    fn augment_args_for_update(cmd: clap::Command) -> clap::Command {
        Self::augment_args(cmd)
    }
}

/// A server's limits with every GI limit at its default (for this crate's tests; the service
/// has the real ones).
#[cfg(test)]
pub(crate) fn default_limits() -> Limits {
    let mut limits: Limits = serde_json::from_value(serde_json::json!({
        "max_width": 3840, "max_height": 2160, "max_shadow_map_size": 4096, "max_fps": 60.0,
        "max_sessions": 8, "max_scenes": 16, "max_upload_bytes": 268_435_456u64,
        "max_triangles": 4_000_000u64, "max_message_bytes": 65_536u64,
        "max_messages_per_second": 120, "request_timeout_ms": 60_000u64
    }))
    .expect("the protocol's limits");
    limits.gi = all()
        .iter()
        .map(|l| (l.name.to_string(), l.default.into()))
        .collect();
    limits
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A name means one declaration; flags and variables are the name's; defaults are in
    /// range.
    #[test]
    fn limits_are_declared_once_with_their_flag_and_variable() {
        for entry in super::super::REGISTRY {
            for l in entry.limits {
                let declared = all().into_iter().find(|o| o.name == l.name);
                assert!(
                    declared.is_some_and(|d| std::ptr::eq(d, *l)),
                    "{} declared twice",
                    l.name
                );
            }
        }
        for l in all() {
            assert_eq!(l.flag, format!("--{}", l.name.replace('_', "-")));
            assert_eq!(l.env, format!("LIGHTCAST_{}", l.name.to_uppercase()));
            assert!((l.min..=l.max).contains(&l.default), "{}", l.name);
        }
        let defaults: BTreeMap<String, u64> =
            all().iter().map(|l| (l.name.into(), l.default)).collect();
        assert_eq!(check(&defaults), Ok(()));
    }

    /// A precomputation's pool is sized by limits its method declares (else no flag sets
    /// them and `/v1/server` does not list them).
    #[test]
    fn budget_pools_are_sized_by_declared_limits() {
        use crate::gi::precompute::BudgetPool;
        for entry in super::super::REGISTRY {
            let Some(budget) = entry.precompute.and_then(|p| p.budget.as_ref()) else {
                continue;
            };
            if let BudgetPool::Declared { total, per_set } = budget.pool {
                for l in std::iter::once(total).chain(per_set) {
                    assert!(
                        entry.limits.iter().any(|o| std::ptr::eq(*o, l)),
                        "{} is not in its method's limits",
                        l.name
                    );
                }
            }
        }
    }
}
