//! Server limits of `lightskin` and `brsm` (see `gi::limits`): their per-frame counts and the
//! budget their light caches are counted in.

use crate::gi::limits::GiLimit;

/// Most view samples for the importance estimate any configuration allows.
pub const VIEW_SAMPLES_CAP: u32 = 4096;
/// Most VALs drawn per frame any configuration allows.
pub const VAL_COUNT_CAP: u32 = 1 << 20;

pub static MAX_VAL_COUNT: GiLimit = GiLimit {
    name: "max_val_count",
    flag: "--max-val-count",
    env: "LIGHTCAST_MAX_VAL_COUNT",
    default: 65536,
    min: 1,
    max: VAL_COUNT_CAP as u64,
    at_least: None,
    doc: "Most VALs per frame (`val_count`).",
};

pub static MAX_VIEW_SAMPLES: GiLimit = GiLimit {
    name: "max_view_samples",
    flag: "--max-view-samples",
    env: "LIGHTCAST_MAX_VIEW_SAMPLES",
    default: 4096,
    min: 1,
    max: VIEW_SAMPLES_CAP as u64,
    at_least: None,
    doc: "Most view samples per frame (`view_samples`).",
};

pub static MAX_CACHES_PER_SET: GiLimit = GiLimit {
    name: "max_caches_per_set",
    flag: "--max-caches-per-set",
    env: "LIGHTCAST_MAX_CACHES_PER_SET",
    default: 250_000,
    min: 1,
    max: super::caches::MAX_CACHES,
    at_least: None,
    doc: "Light caches of one parameter set, estimated from the cache distance and the \
          scene's surface area before they are built.",
};

pub static MAX_TOTAL_CACHES: GiLimit = GiLimit {
    name: "max_total_caches",
    flag: "--max-total-caches",
    env: "LIGHTCAST_MAX_TOTAL_CACHES",
    default: 1_000_000,
    min: 1,
    max: u64::MAX,
    at_least: Some(&MAX_CACHES_PER_SET),
    doc: "Light caches over every parameter set of every scene held.",
};

pub const LIMITS: &[&GiLimit] = &[
    &crate::gi::common::limits::MAX_RSM_SIZE,
    &MAX_VAL_COUNT,
    &MAX_VIEW_SAMPLES,
    &MAX_CACHES_PER_SET,
    &MAX_TOTAL_CACHES,
];
