//! The parameter tables of `lightskin` and `brsm` (seed 004) and the struct both read them as.

use crate::gi::common::params::{LightFit, EMITTERS, LIGHT_FIT, RSM_SIZE, SENDERS};
use crate::gi::params::{read_for, Default, MethodTable, Param, Testing, SCALE_TOLERANCE};
use crate::gi::InvalidSetting;
use lightcast_protocol::GiParams;
use serde::Deserialize;

pub const OCCLUSION: Param = Param::boolean(
    "occlusion",
    true,
    "Dim proxy lights hidden behind other caches (the paper's double projection)",
);

pub const CACHE_VISIBILITY: Param = Param::integer(
    "cache_visibility",
    0,
    (0, 32),
    "Weigh every VAL by whether its cache sees it (beyond the paper): n > 0 traces (n + 1)² \
     rays per cache (an octahedral grid of n² cells) against the scene's BVH whenever the \
     caches are built or loaded, and keeps how far the cache sees in each direction; a VAL \
     beyond that (by more than half) lights the cache with nothing. Stops the light that \
     reaches caches through buildings; each cache's map counts against the cache budgets as \
     (n + 1)²/16 caches more. 0: off (the paper)",
)
.unit("cells per side");

pub const CACHE_DISTANCE: Param = Param::optional_number(
    "cache_distance",
    (0.0, f64::INFINITY),
    "Light caches: largest distance d_eps from a surface point to its cache; null: from the \
     scene's surface area (another value starts a precomputation of its own)",
)
.above_min()
.unit("scene units");

pub const CACHE_ANGLE: Param = Param::optional_number(
    "cache_angle",
    (0.0, 90.0),
    "Light caches: largest angle theta_eps between surface and cache normals; null: 30",
)
.above_min()
.unit("degrees");

/// The software profile's 512 VALs and 32 view samples (with the 112² RSM): the README's
/// `POST /v1/render -d '{}'` in about 0.5 s on lavapipe instead of 3.2 s.
pub const VAL_COUNT: Param = Param::integer(
    "val_count",
    8192,
    (1, super::limits::VAL_COUNT_CAP),
    "N_sVAL: VALs drawn from the importance distribution per frame (eq. 13)",
)
.limit(&super::limits::MAX_VAL_COUNT)
.software(Default::Int(512))
.unit("VALs");

pub const VIEW_SAMPLES: Param = Param::integer(
    "view_samples",
    512,
    (1, super::limits::VIEW_SAMPLES_CAP),
    "N_VS: view samples estimating each VAL's importance (eq. 10-11)",
)
.limit(&super::limits::MAX_VIEW_SAMPLES)
.software(Default::Int(32))
.unit("samples");

pub const DEFAULT_DEFENSIVE: f64 = 0.3;

/// The default α bounds the largest weight 1/(N·P) below 3.4·M/N for M RSM texels and N
/// VALs. Chosen by measurement (`bench --gi-param defensive=…`, lavapipe, RSM 256², 8,192 VALs, 512 view
/// samples, relative mean absolute difference to LightSkin): on the procedural street α = 0
/// gave 48 %, 0.1 gave 22 %, 0.3 gave 8.8 %; on the Cornell box 0.94 % and (α = 0.3) 0.58 %.
pub const DEFENSIVE: Param = Param::number(
    "defensive",
    DEFAULT_DEFENSIVE,
    (0.0, 1.0),
    "Weight alpha of a uniform pdf mixed into the selection pdf (defensive importance \
     sampling: bounds the weight of VALs the view samples barely see but caches do; 0: the \
     paper's plain importance sampling)",
);

pub const JITTER: Param = Param::number(
    "jitter",
    0.5,
    (0.0, 1.0),
    "Offset of the stratified VAL draws within their strata (eq. 13; 0.5: their centres)",
)
.below_max();

pub const UNIFORM_IMPORTANCE: Param = Param::boolean(
    "uniform_importance",
    false,
    "Give every RSM texel importance 1: plain stratified sampling of the VALs instead of eq. \
     10-11 (with one draw per texel it equals LightSkin)",
);

pub const LIGHTSKIN: MethodTable = MethodTable {
    method: crate::gi::lightskin::LIGHTSKIN,
    summary: "LightSkin (seed 004, eq. 3-9): every RSM texel lights every light cache; caches \
              are interpolated per pixel",
    progressive: false,
    params: &[
        &RSM_SIZE,
        &EMITTERS,
        &LIGHT_FIT,
        &SENDERS,
        &OCCLUSION,
        &CACHE_VISIBILITY,
        &CACHE_DISTANCE,
        &CACHE_ANGLE,
    ],
    views: super::views::LIGHTSKIN_VIEWS,
    testing: Testing {
        small: |facts| small(facts, crate::gi::lightskin::LIGHTSKIN),
        scale_tolerance: SCALE_TOLERANCE,
        // d_eps is derived (and rounded) from the surface area.
        exact_at_powers_of_two: false,
    },
    // `senders: diffuse` is the paper's diffuse VALs/VPLs; `full` adds their glossy lobes.
    senders: |gi| Settings::of(gi).map(|s| s.senders).unwrap_or_default(),
};

/// A 64² RSM and caches four times as far apart as the default (a few hundred on the Cornell
/// box, relative to its area so a scaled box gets scaled caches), with proxy occlusion; BRSM
/// at 1,024 VALs from 256 view samples, drawn from uniform importance: eq. 11 clamps the
/// squared VAL–view-sample distance to at least 1 in scene units, as the paper writes it, so
/// its sampling pdf (not the expectation, which the 1/(N·P) weights keep) depends on the
/// unit: with eq. 11's importance the BRSM buffers of the scaled Cornell box differed by
/// 1.4 % (×0.01) and 1.6 % (×1000), and by 0.02 % with the clamp removed. Uniform importance
/// still runs the whole BRSM path (cumulative sums, selection, weighted cache lighting).
fn small(
    facts: &crate::gi::precompute::SceneFacts,
    method: lightcast_protocol::GiMethod,
) -> GiParams {
    let d_eps = super::caches::CacheParams::for_area(facts.surface_area, facts.radius).d_eps;
    GiParams::new(method)
        .with(RSM_SIZE.name, 64)
        .with(OCCLUSION.name, true)
        .with(CACHE_DISTANCE.name, 4.0 * d_eps)
        .with(VIEW_SAMPLES.name, 256)
        .with(VAL_COUNT.name, 1024)
        .with(JITTER.name, 0.5)
        .with(UNIFORM_IMPORTANCE.name, true)
}

pub const BRSM: MethodTable = MethodTable {
    method: crate::gi::lightskin::BRSM,
    summary: "Bidirectional RSM (seed 004, eq. 10-15): LightSkin fed by an importance-sampled \
              subset of the RSM texels",
    progressive: false,
    params: &[
        &RSM_SIZE,
        &EMITTERS,
        &LIGHT_FIT,
        &SENDERS,
        &OCCLUSION,
        &CACHE_VISIBILITY,
        &CACHE_DISTANCE,
        &CACHE_ANGLE,
        &VAL_COUNT,
        &VIEW_SAMPLES,
        &DEFENSIVE,
        &JITTER,
        &UNIFORM_IMPORTANCE,
    ],
    views: super::views::BRSM_VIEWS,
    testing: Testing {
        small: |facts| small(facts, crate::gi::lightskin::BRSM),
        scale_tolerance: SCALE_TOLERANCE,
        exact_at_powers_of_two: false,
    },
    // `senders: diffuse` is the paper's diffuse VALs/VPLs; `full` adds their glossy lobes.
    senders: |gi| Settings::of(gi).map(|s| s.senders).unwrap_or_default(),
};

/// The parameters of both methods, as [`BRSM`]'s table (a superset of [`LIGHTSKIN`]'s)
/// describes them; `lightskin` leaves the sampling ones at their defaults.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    pub rsm_size: u32,
    pub emitters: Option<bool>,
    pub light_fit: LightFit,
    pub senders: crate::gi::params::Senders,
    pub occlusion: bool,
    pub cache_visibility: u32,
    pub cache_distance: Option<f32>,
    pub cache_angle: Option<f32>,
    pub val_count: u32,
    pub view_samples: u32,
    pub defensive: f32,
    pub jitter: f32,
    pub uniform_importance: bool,
}

impl Settings {
    pub fn of(gi: &GiParams) -> Result<Self, InvalidSetting> {
        let own = if gi.method == super::LIGHTSKIN {
            LIGHTSKIN.params
        } else {
            BRSM.params
        };
        read_for(BRSM.params, own, gi)
    }
}
