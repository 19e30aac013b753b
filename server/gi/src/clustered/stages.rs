//! The stages of `clustered` (besides the shared `rsm`).

use crate::gpu::timing::Stage;

/// N VPLs fetched from the RSM at Halton positions.
pub const VPL_GENERATION: Stage = Stage::new(16, "vpl_generation");
/// k-means of the VPLs into M VALs, the final mapping and each VAL's area.
pub const CLUSTERING: Stage = Stage::new(17, "clustering");
/// Interleaved shading of every pixel by its share of the VPLs.
pub const CLUSTERED_INDIRECT: Stage = Stage::new(18, "clustered_indirect");
/// Geometry-aware blur of the interleaved shading.
pub const GEOMETRY_BLUR: Stage = Stage::new(19, "geometry_blur");
/// One paraboloid depth map per VAL (`cssm`) or per VPL (`vpl_shadows`).
pub const PARABOLOID_MAPS: Stage = Stage::new(24, "paraboloid_maps");
/// The depth maps' Fourier basis textures and their mip chains (`cssm`).
pub const CSSM_BASIS: Stage = Stage::new(25, "cssm_basis");

pub const ALL: &[Stage] = &[
    VPL_GENERATION,
    CLUSTERING,
    CLUSTERED_INDIRECT,
    GEOMETRY_BLUR,
    PARABOLOID_MAPS,
    CSSM_BASIS,
];
