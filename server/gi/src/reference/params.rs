//! The reference's parameter table and the struct it reads it as.

use super::MAX_SAMPLES_PER_CALL;
use crate::gi::common::params::{BOUNCES, EMITTERS, SENDERS};
use crate::gi::params::{read, Default, MethodTable, Param, Senders};
use crate::gi::InvalidSetting;
use lightcast_protocol::GiParams;
use serde::Deserialize;

/// The software profile's 1: a session's frame at the viewer's software size (800×450) is
/// ~1.3 s per sample on lavapipe, so one sample per frame keeps it within the 2 s frame limit
/// (4 were refused, and switching the viewer to `reference` failed). One-shots that name no
/// `spp` take what their budget buys (`service::cost::one_shot_spp`).
pub const SPP: Param = Param::integer(
    "spp",
    4,
    (1, MAX_SAMPLES_PER_CALL),
    "Samples per pixel added each frame; sessions keep accumulating while nothing changes. A \
     one-shot render takes exactly this many when it names spp, else as many as half the \
     server's request budget buys (its report says how many and how noisy the image is)",
)
.limit(&super::limits::MAX_SPP)
.software(Default::Int(1))
.unit("samples");

pub const TABLE: MethodTable = MethodTable {
    method: crate::gi::reference::REFERENCE,
    summary: "Path-traced reference: the converged indirect light (exact visibility, the same \
              BRDF and light), accumulated while nothing changes",
    progressive: true,
    params: &[&BOUNCES, &EMITTERS, &SENDERS, &SPP],
    views: &[&crate::gi::common::views::INDIRECT],
    // Two bounces test the ray offsets of the second surface too. The same random numbers at
    // every scale (the seed and sample indices are equal), so paths differ only where a
    // rounded coordinate flips a hit, and that path then carries a different 8-sample
    // estimate: measured on lavapipe 0.9 % (×0.01) and 0.65 % (×1000) on the indirect buffer;
    // at power-of-two scales, where no rounding differs, exactly 0.
    testing: crate::gi::params::Testing {
        small: |_| {
            GiParams::new(crate::gi::reference::REFERENCE)
                .with(BOUNCES.name, 2)
                .with(SPP.name, 8)
        },
        scale_tolerance: 0.02,
        exact_at_powers_of_two: true,
    },
    senders: |gi| Settings::of(gi).map(|s| s.senders).unwrap_or(Senders::Full),
};

/// The reference's parameters, as [`TABLE`] describes them.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    pub bounces: u32,
    pub emitters: Option<bool>,
    pub senders: Senders,
    pub spp: u32,
}

impl Settings {
    pub fn of(gi: &GiParams) -> Result<Self, InvalidSetting> {
        read(TABLE.params, gi)
    }
}
