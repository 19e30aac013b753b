//! The WGSL modules of the reference (`shaders/`), each the concatenation of its files.

use crate::gpu::shaders::{wgsl, ShaderSource};

/// The reference path tracer (`gi::reference`).
pub const REFERENCE_PATH_TRACE: ShaderSource = ShaderSource {
    name: "reference_path_trace",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("brdf_eval.wgsl"),
        wgsl!("lights.wgsl"),
        wgsl!("environment.wgsl"),
        wgsl!("material_model.wgsl"),
        wgsl!("bvh.wgsl"),
        wgsl!("reference/surfaces.wgsl"),
        wgsl!("reference/path_trace.wgsl"),
    ],
};

/// The reference's accumulation into the indirect buffer, with its convergence sums.
pub const REFERENCE_RESOLVE: ShaderSource = ShaderSource {
    name: "reference_resolve",
    files: &[wgsl!("reference/resolve.wgsl")],
};
