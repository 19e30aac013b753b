//! The stages of `lightskin` and `brsm` (besides the shared `rsm`).

use crate::gpu::timing::Stage;

/// The frame's view samples gathered from its G-buffer (`brsm`, eq. 10–11; per session,
/// also where the light-side stages are shared, see `shared`).
pub const VIEW_SAMPLES: Stage = Stage::new(30, "view_samples");
/// Importance of every RSM texel from the view samples (`brsm`, eq. 10).
pub const IMPORTANCE: Stage = Stage::new(3, "importance");
/// Cumulative importance (`brsm`).
pub const CUMULATIVE_SUMS: Stage = Stage::new(4, "cumulative_sums");
/// VALs drawn from the importance (`brsm`, eq. 11–15).
pub const VAL_SELECT: Stage = Stage::new(5, "val_select");
/// Proxy lights per light cache (eq. 3–7).
pub const CACHE_LIGHTING: Stage = Stage::new(6, "cache_lighting");
/// Proxies dimmed by the caches in between.
pub const PROXY_OCCLUSION: Stage = Stage::new(7, "proxy_occlusion");
/// Proxy lights interpolated per pixel (eq. 8–9).
pub const INDIRECT_LIGHT: Stage = Stage::new(8, "indirect_light");

pub const ALL: &[Stage] = &[
    VIEW_SAMPLES,
    IMPORTANCE,
    CUMULATIVE_SUMS,
    VAL_SELECT,
    CACHE_LIGHTING,
    PROXY_OCCLUSION,
    INDIRECT_LIGHT,
];
