//! The stages of `surfels`.

use crate::gpu::timing::Stage;

/// Every surfel's radiosity from the light, its emission and the previous bounce (per bounce
/// a frame adds). Index 22 was `surfel_bounce` (this and the next two together) until
/// 2026-11-27.
pub const SURFEL_LIGHT: Stage = Stage::new(22, "surfel_light");
/// Per-pixel indirect light from the SH caches.
pub const SURFEL_SHADE: Stage = Stage::new(23, "surfel_shade");
/// Surfel flux pulled up the hierarchy, one dispatch per level.
pub const SURFEL_PULL: Stage = Stage::new(27, "surfel_pull");
/// Every SH cache's radiance over its links, eq. 4.
pub const SURFEL_CACHE_LIGHT: Stage = Stage::new(28, "surfel_cache_light");

pub const ALL: &[Stage] = &[SURFEL_LIGHT, SURFEL_SHADE, SURFEL_PULL, SURFEL_CACHE_LIGHT];
