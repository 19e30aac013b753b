//! `clustered`'s parameter table (seed 003) and the struct its passes read it as.

use super::passes::FOURIER_MAX_TERMS;
use crate::gi::common::params::{LightFit, EMITTERS, LIGHT_FIT, RSM_SIZE, SENDERS};
use crate::gi::params::{read, Default, MethodTable, Param};
use crate::gi::InvalidSetting;
use lightcast_protocol::GiParams;
use serde::Deserialize;

/// Fewest VPLs (the lower bound: at least four per pixel with 8×8 interleaving).
pub const MIN_VPL_COUNT: u32 = 256;
/// Most VPLs: 3 MiB of VPLs and mapping, and N/B² VPLs per pixel.
pub const MAX_VPL_COUNT: u32 = 65_536;
/// Most VALs: each will own a paraboloid depth map and its Fourier basis textures.
pub const MAX_CLUSTER_COUNT: u32 = 256;
/// Most k-means iterations per frame (each costs O(N·M)).
pub const MAX_KMEANS_ITERATIONS: u32 = 64;
/// Largest interleaving block side (the blur reads B² pixels per pixel).
pub const MAX_INTERLEAVE: u32 = 16;
/// Smallest and largest side of a paraboloid map.
pub const MIN_PARABOLOID_SIZE: u32 = 16;
pub const MAX_PARABOLOID_SIZE: u32 = 1024;

pub const VPL_COUNT: Param = Param::integer(
    "vpl_count",
    1024,
    (MIN_VPL_COUNT, MAX_VPL_COUNT),
    "N: virtual point lights fetched from the RSM at Halton positions (§6)",
)
.unit("VPLs");

pub const CLUSTER_COUNT: Param = Param::integer(
    "cluster_count",
    30,
    (1, MAX_CLUSTER_COUNT),
    "M: virtual area lights, k-means clusters of the VPLs (§5)",
)
.unit("VALs");

pub const KMEANS_ITERATIONS: Param = Param::integer(
    "kmeans_iterations",
    4,
    (0, MAX_KMEANS_ITERATIONS),
    "k-means iterations per frame, restarted every frame from the same seeds, VPL k for \
     cluster k (§5.2)",
);

pub const CLUSTER_POSITION_WEIGHT: Param = Param::number(
    "cluster_position_weight",
    0.7,
    (0.0, 1.0),
    "w_x of the clustering distance (§5.1), per scene extent (bounding-box diagonal)",
);

pub const CLUSTER_NORMAL_WEIGHT: Param = Param::number(
    "cluster_normal_weight",
    0.3,
    (0.0, 1.0),
    "w_alpha of the clustering distance (§5.1), per radian between normals",
);

/// The software profile's 4, with its indirect light at half resolution: 4×4 blocks there
/// cover the 8×8 pixels of the paper's blocks at full resolution (§6: 8×8 with 1,024 VPLs).
/// With 8×8 blocks at half resolution (16×16 pixels, 16 VPLs per class) the blur left the
/// blocks visible (issue 31); 4×4 costs ~65 ms more at 320×240 on lavapipe (345 → 410 ms).
pub const INTERLEAVE: Param = Param::integer(
    "interleave",
    8,
    (1, MAX_INTERLEAVE),
    "Interleaved-sampling block side B: each pixel shades N/B^2 VPLs (§6)",
)
.software(Default::Int(4))
.unit("pixels");

pub const BLUR_DISTANCE: Param = Param::number(
    "blur_distance",
    0.1,
    (0.0, 1.0),
    "Geometry-aware blur: largest distance between blurred surface points, as a fraction of \
     the scene extent (§6: 10 %)",
);

pub const BLUR_NORMAL: Param = Param::number(
    "blur_normal",
    0.8,
    (-1.0, 1.0),
    "Geometry-aware blur: smallest cosine between blurred normals (§6: 0.8)",
);

pub const VISIBILITY: Param = Param::choice(
    "visibility",
    "cssm",
    &["off", "cssm", "vpl_shadows"],
    "VPL visibility: cssm (each VPL shares its VAL's soft shadow from a paraboloid \
     convolution soft shadow map, §4.1-4.2), vpl_shadows (a hard-shadow paraboloid map per \
     VPL: instant radiosity, Figure 10's baseline) or off (every VPL sees every point)",
);

/// The software profile's 64²: the 30 maps at 256² take ~0.7 s a frame on lavapipe; at 64²
/// the GI stages of a 128×96 frame take ~90 ms (`bench --gi clustered`).
pub const PARABOLOID_SIZE: Param = Param::integer(
    "paraboloid_size",
    256,
    (MIN_PARABOLOID_SIZE, MAX_PARABOLOID_SIZE),
    "Side of each paraboloid depth map, a power of two; with the map count (M for cssm, N \
     for vpl_shadows) within 256 MiB",
)
.software(Default::Int(64))
.unit("texels");

pub const FOURIER_TERMS: Param = Param::integer(
    "fourier_terms",
    4,
    (1, FOURIER_MAX_TERMS),
    "K: Fourier terms of the convolution soft shadow maps (§4.1); fewer terms soften every \
     shadow",
);

pub const SHADOW_LIGHT: Param = Param::integer(
    "shadow_light",
    0,
    (0, MAX_VPL_COUNT - 1),
    "The light whose shadow the val-shadow view shows: a VAL below cluster_count, or with \
     vpl_shadows a VPL below vpl_count",
);

pub const TABLE: MethodTable = MethodTable {
    method: crate::gi::clustered::CLUSTERED,
    summary: "Clustered visibility (seed 003, §4-6): N VPLs from the RSM, k-means into M \
              virtual area lights, one paraboloid convolution soft shadow map per VAL, \
              interleaved shading and a geometry-aware blur",
    progressive: false,
    params: &[
        &RSM_SIZE,
        &EMITTERS,
        &LIGHT_FIT,
        &SENDERS,
        &VPL_COUNT,
        &CLUSTER_COUNT,
        &KMEANS_ITERATIONS,
        &CLUSTER_POSITION_WEIGHT,
        &CLUSTER_NORMAL_WEIGHT,
        &INTERLEAVE,
        &BLUR_DISTANCE,
        &BLUR_NORMAL,
        &VISIBILITY,
        &PARABOLOID_SIZE,
        &FOURIER_TERMS,
        &SHADOW_LIGHT,
    ],
    views: super::views::VIEWS,
    // Δx and the blur distance are in units of the scene's extent, and a VPL's disk area
    // bounds its form factor: no length constant, so power-of-two scales are exact. CSSM with
    // 10 VALs at 64² maps keeps every pass at a tenth of the default's cost.
    testing: crate::gi::params::Testing {
        small: |_| {
            GiParams::new(crate::gi::clustered::CLUSTERED)
                .with(RSM_SIZE.name, 64)
                .with(VPL_COUNT.name, 1024)
                .with(CLUSTER_COUNT.name, 10)
                .with(PARABOLOID_SIZE.name, 64)
        },
        scale_tolerance: crate::gi::params::SCALE_TOLERANCE,
        exact_at_powers_of_two: true,
    },
    // `senders: diffuse` is the paper's diffuse VALs/VPLs; `full` adds their glossy lobes.
    senders: |gi| Settings::of(gi).map(|s| s.senders).unwrap_or_default(),
};

/// How each VPL's visibility is found (`visibility`).
#[derive(
    Clone,
    Copy,
    Debug,
    std::default::Default,
    PartialEq,
    Eq,
    Hash,
    serde::Serialize,
    Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum Visibility {
    /// Every VPL sees every point (the paper's "without visibility" baseline, Figure 10).
    Off,
    /// The paper's method (§4.1–4.2): one paraboloid depth map per VAL, convolution soft
    /// shadow maps give each VPL the fractional visibility of its VAL.
    #[default]
    Cssm,
    /// Instant radiosity with one hard-shadow paraboloid map per VPL: exact from-point
    /// visibility up to the map's resolution, the baseline clustering is measured against
    /// (Figure 10's "instant radiosity"; for small N).
    #[value(name = "vpl_shadows")]
    VplShadows,
}

impl Visibility {
    /// The name requests use.
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Cssm => "cssm",
            Self::VplShadows => "vpl_shadows",
        }
    }
}

/// `clustered`'s parameters, as [`TABLE`] describes them.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    pub rsm_size: u32,
    pub emitters: Option<bool>,
    pub light_fit: LightFit,
    pub senders: crate::gi::params::Senders,
    pub vpl_count: u32,
    pub cluster_count: u32,
    pub kmeans_iterations: u32,
    pub cluster_position_weight: f32,
    pub cluster_normal_weight: f32,
    pub interleave: u32,
    pub blur_distance: f32,
    pub blur_normal: f32,
    pub visibility: Visibility,
    pub paraboloid_size: u32,
    pub fourier_terms: u32,
    pub shadow_light: u32,
}

impl Settings {
    pub fn of(gi: &GiParams) -> Result<Self, InvalidSetting> {
        read(TABLE.params, gi)
    }
}
