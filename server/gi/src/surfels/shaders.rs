//! The WGSL modules of `surfels` (`shaders/`), each the concatenation of its files.

use crate::gpu::shaders::{wgsl, ShaderSource};

/// `surfels`: every surfel's radiosity from the light, emission and the previous bounce.
pub const SURFEL_LIGHT: ShaderSource = ShaderSource {
    name: "surfel_light",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("lights.wgsl"),
        wgsl!("surfels/sh.wgsl"),
        wgsl!("surfels/caches.wgsl"),
        wgsl!("surfels/surfel_light.wgsl"),
    ],
};

/// `surfels`: flux pulled up one level of the hierarchy.
pub const SURFEL_PULL: ShaderSource = ShaderSource {
    name: "surfel_pull",
    files: &[wgsl!("surfels/pull.wgsl")],
};

/// `surfels`: every cache's SH radiance over its links (eq. 4).
pub const SURFEL_CACHE_LIGHT: ShaderSource = ShaderSource {
    name: "surfel_cache_light",
    files: &[wgsl!("surfels/cache_light.wgsl")],
};

/// `surfels`: per-pixel indirect light from the caches (eq. 5–8).
pub const SURFEL_SHADE: ShaderSource = ShaderSource {
    name: "surfel_shade",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("brdf_eval.wgsl"),
        wgsl!("gbuffer_surface.wgsl"),
        wgsl!("surfels/sh.wgsl"),
        wgsl!("surfels/caches.wgsl"),
        wgsl!("surfels/shade.wgsl"),
    ],
};

/// `surfels`: debug view `cache-sh`, the caches' SH radiance along each pixel's normal.
pub const SURFEL_CACHE_SH_VIEW: ShaderSource = ShaderSource {
    name: "surfel_cache_sh_view",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("surfels/sh.wgsl"),
        wgsl!("surfels/caches.wgsl"),
        wgsl!("surfels/cache_sh_view.wgsl"),
    ],
};

/// Eq. 3's visibility rays of the surfels' links, from caches to surfels (precomputation).
pub const SURFEL_LINK_RAYS: ShaderSource = ShaderSource {
    name: "surfel_link_rays",
    files: &[wgsl!("bvh.wgsl"), wgsl!("surfels/link_rays.wgsl")],
};
