//! Server limits of the parameters several methods share (see `gi::limits`).

use crate::gi::limits::GiLimit;

/// Most bounces a multi-bounce method computes, whatever the configuration.
pub const BOUNCES_CAP: u32 = 16;

pub static MAX_RSM_SIZE: GiLimit = GiLimit {
    name: "max_rsm_size",
    flag: "--max-rsm-size",
    env: "LIGHTCAST_MAX_RSM_SIZE",
    default: 2048,
    min: 16,
    max: crate::passes::rsm::MAX_RSM_SIZE as u64,
    at_least: None,
    doc: "Largest RSM side (`rsm_size`).",
};

pub static MAX_BOUNCES: GiLimit = GiLimit {
    name: "max_bounces",
    flag: "--max-bounces",
    env: "LIGHTCAST_MAX_BOUNCES",
    default: BOUNCES_CAP as u64,
    min: 1,
    max: BOUNCES_CAP as u64,
    at_least: None,
    doc: "Most bounces of indirect light a frame may ask for (`bounces`).",
};
