//! `rsm_gather`'s parameter table and the struct its pass reads it as.

use crate::gi::common::params::{LightFit, EMITTERS, LIGHT_FIT, RSM_SIZE, SENDERS};
use crate::gi::params::{read, Default, MethodTable, Param, Testing, SCALE_TOLERANCE};
use crate::gi::InvalidSetting;
use lightcast_protocol::GiParams;
use serde::Deserialize;

/// Most samples per pixel: each is an RSM fetch and a VPL's light.
pub const MAX_GATHER_SAMPLES: u32 = 4096;

/// The paper's 400 samples per pixel; the software profile's 100 keep a 128×96 frame at
/// about 60 ms on lavapipe.
pub const GATHER_SAMPLES: Param = Param::integer(
    "gather_samples",
    400,
    (1, MAX_GATHER_SAMPLES),
    "RSM texels each pixel gathers as pixel lights in every light face (a point light's six), \
     the same pattern for every pixel, denser near the pixel's own texel",
)
.software(Default::Int(100))
.unit("samples");

/// See `pattern.rs` for why texels beyond the radius are left out and how the samples are
/// weighted. Measured on the Cornell box (128×96, RSM 256², 400 samples, lavapipe, `bench
/// --gi rsm_gather`): 8×8-block error against the reference 77 % at 0.1 (bias −77 %), 59 % at
/// 0.3 (−50 %), 18 % at 1.0 (+1.8 %): light comes from the whole lit floor, so a disk much
/// smaller than the map misses most of it.
pub const GATHER_RADIUS: Param = Param::number(
    "gather_radius",
    1.0,
    (0.0, 1.5),
    "r_max: radius of the disk of RSM texels a pixel gathers from, around the texel it \
     projects to in each light face (the nearest border point where it lies outside), as a \
     fraction of the RSM's side (1.5 covers every texel of a face from anywhere on it)",
)
.above_min();

pub const TABLE: MethodTable = MethodTable {
    method: super::RSM_GATHER,
    summary: "Reflective shadow maps (Dachsbacher & Stamminger 2005): every pixel gathers a \
              fixed pattern of RSM texels around its own as pixel lights, without visibility; \
              the ancestor of the seed methods",
    progressive: false,
    params: &[
        &RSM_SIZE,
        &EMITTERS,
        &LIGHT_FIT,
        &SENDERS,
        &GATHER_SAMPLES,
        &GATHER_RADIUS,
    ],
    views: super::views::VIEWS,
    // The radius is a fraction of the RSM, the pattern has no length in it and a pixel light's
    // disk area bounds its form factor: no length constant, so power-of-two scales are exact.
    testing: Testing {
        small: |_| {
            GiParams::new(super::RSM_GATHER)
                .with(RSM_SIZE.name, 64)
                .with(GATHER_SAMPLES.name, 100)
        },
        scale_tolerance: SCALE_TOLERANCE,
        exact_at_powers_of_two: true,
    },
    // `senders: diffuse` is the paper's diffuse VALs/VPLs; `full` adds their glossy lobes.
    senders: |gi| Settings::of(gi).map(|s| s.senders).unwrap_or_default(),
};

/// `rsm_gather`'s parameters, as [`TABLE`] describes them.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    pub rsm_size: u32,
    pub emitters: Option<bool>,
    pub light_fit: LightFit,
    pub senders: crate::gi::params::Senders,
    pub gather_samples: u32,
    pub gather_radius: f32,
}

impl Settings {
    pub fn of(gi: &GiParams) -> Result<Self, InvalidSetting> {
        read(TABLE.params, gi)
    }
}
