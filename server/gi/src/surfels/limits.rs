//! Server limits of `surfels` (see `gi::limits`): the budget its links are counted in.

use crate::gi::limits::GiLimit;

pub static MAX_TOTAL_SURFEL_LINKS: GiLimit = GiLimit {
    name: "max_total_surfel_links",
    flag: "--max-total-surfel-links",
    env: "LIGHTCAST_MAX_TOTAL_SURFEL_LINKS",
    default: 4 << 20,
    min: 1,
    max: u64::MAX,
    at_least: None,
    doc: "Surfel links (SH caches × links per cache, about 40 bytes each at 3 bands) over \
          every parameter set of every scene held.",
};

pub const LIMITS: &[&GiLimit] = &[
    &crate::gi::common::limits::MAX_BOUNCES,
    &MAX_TOTAL_SURFEL_LINKS,
];
