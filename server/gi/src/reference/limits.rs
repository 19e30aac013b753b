//! Server limits of `reference` (see `gi::limits`).

use crate::gi::limits::GiLimit;

pub static MAX_SPP: GiLimit = GiLimit {
    name: "max_spp",
    flag: "--max-spp",
    env: "LIGHTCAST_MAX_SPP",
    default: 256,
    min: 1,
    max: super::MAX_SAMPLES_PER_CALL as u64,
    at_least: None,
    doc: "Most samples per pixel a path-traced frame (or one-shot render) may take (`spp`).",
};

pub const LIMITS: &[&GiLimit] = &[&crate::gi::common::limits::MAX_BOUNCES, &MAX_SPP];
