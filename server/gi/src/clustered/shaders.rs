//! The WGSL modules of `clustered` (`shaders/`), each the concatenation of its files.

use crate::gpu::shaders::{wgsl, ShaderSource};

/// VPL generation and k-means clustering of `clustered` (`gi::clustered`).
pub const CLUSTERING: ShaderSource = ShaderSource {
    name: "clustering",
    files: &[
        wgsl!("halton.wgsl"),
        wgsl!("octahedral.wgsl"),
        wgsl!("rsm_glossy.wgsl"),
        wgsl!("clustered/vpls.wgsl"),
        wgsl!("clustered/kmeans.wgsl"),
    ],
};

/// Interleaved shading from the VPLs of `clustered`.
pub const CLUSTERED_INDIRECT: ShaderSource = ShaderSource {
    name: "clustered_indirect",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("brdf_eval.wgsl"),
        wgsl!("gbuffer_surface.wgsl"),
        wgsl!("octahedral.wgsl"),
        wgsl!("rsm_glossy.wgsl"),
        wgsl!("vpl_light.wgsl"),
        wgsl!("clustered/vpls.wgsl"),
        wgsl!("clustered/paraboloid.wgsl"),
        wgsl!("clustered/visibility.wgsl"),
        wgsl!("clustered/indirect.wgsl"),
    ],
};

/// `clustered`: one paraboloid depth map per VAL or VPL, all in one instanced draw.
pub const PARABOLOID_MAPS: ShaderSource = ShaderSource {
    name: "paraboloid_maps",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("clustered/vpls.wgsl"),
        wgsl!("clustered/paraboloid.wgsl"),
        wgsl!("clustered/paraboloid_maps.wgsl"),
    ],
};

/// `clustered`: the Fourier basis of the paraboloid depth maps.
pub const CSSM_BASIS: ShaderSource = ShaderSource {
    name: "cssm_basis",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("clustered/vpls.wgsl"),
        wgsl!("clustered/paraboloid.wgsl"),
        wgsl!("clustered/cssm_basis.wgsl"),
    ],
};

/// `clustered`: one mip level of the basis textures.
pub const CSSM_MIPS: ShaderSource = ShaderSource {
    name: "cssm_mips",
    files: &[wgsl!("clustered/cssm_mips.wgsl")],
};

/// The geometry-aware blur of `clustered`.
pub const GEOMETRY_BLUR: ShaderSource = ShaderSource {
    name: "geometry_blur",
    files: &[wgsl!("clustered/vpls.wgsl"), wgsl!("clustered/blur.wgsl")],
};
