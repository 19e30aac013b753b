//! The WGSL module of `rsm_gather` (`shaders/`), the concatenation of its files.

use crate::gpu::shaders::{wgsl, ShaderSource};

/// Every pixel's gather of RSM texels.
pub const GATHER: ShaderSource = ShaderSource {
    name: "rsm_gather",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("brdf_eval.wgsl"),
        wgsl!("gbuffer_surface.wgsl"),
        wgsl!("octahedral.wgsl"),
        wgsl!("rsm_glossy.wgsl"),
        wgsl!("vpl_light.wgsl"),
        wgsl!("rsm_gather/gather.wgsl"),
    ],
};
