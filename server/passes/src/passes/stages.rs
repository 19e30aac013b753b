//! The stages of the shared passes (the GI methods declare their own in
//! `gi/<method>/stages.rs`; `gi::stages` gathers them). Indices are frame headers' and never
//! change: a new stage takes the next free index.

use crate::gpu::timing::Stage;

/// Depth from the light (1 or 6 faces).
pub const SHADOW_MAP: Stage = Stage::new(0, "shadow_map");
/// Position, normal, material and triangle id from the camera.
pub const GBUFFER: Stage = Stage::new(1, "gbuffer");
/// The visibility buffer (triangle id, base colour) resolved into position, normal and
/// material terms (`gbuffer` then rasterises only those two; needs triangle ids).
pub const GBUFFER_RESOLVE: Stage = Stage::new(31, "gbuffer_resolve");
/// The reflective shadow map (the RSM-based methods).
pub const RSM: Stage = Stage::new(2, "rsm");
/// The RSM's visibility buffer (triangle id, base colour) resolved into its targets (`rsm`
/// then rasterises only those two; needs triangle ids), and the emitter face copied in.
pub const RSM_RESOLVE: Stage = Stage::new(32, "rsm_resolve");
/// Emission, direct light with shadows, plus the indirect buffer.
pub const DIRECT_LIGHT: Stage = Stage::new(10, "direct_light");
/// Automatic exposure.
pub const EXPOSURE: Stage = Stage::new(11, "exposure");
/// Tone curve into the 8-bit output.
pub const TONEMAP: Stage = Stage::new(12, "tonemap");
/// Copies of the results into the read-back buffers.
pub const READBACK_COPY: Stage = Stage::new(13, "readback_copy");
/// The G-buffer reduced for indirect light at a lower resolution (`indirect_downscale`).
pub const GBUFFER_REDUCE: Stage = Stage::new(20, "gbuffer_reduce");
/// Indirect light brought back to the output's resolution (`indirect_downscale`).
pub const INDIRECT_UPSAMPLE: Stage = Stage::new(21, "indirect_upsample");
/// The 8-bit output converted to Y'CbCr 4:2:0 for the video encoder (`h264` streams).
pub const YUV420: Stage = Stage::new(26, "yuv420");

/// The stages every frame runs whatever its GI method.
pub const EVERY_FRAME: &[Stage] = &[
    SHADOW_MAP,
    GBUFFER,
    GBUFFER_RESOLVE,
    DIRECT_LIGHT,
    EXPOSURE,
    TONEMAP,
    YUV420,
    READBACK_COPY,
];

/// Every shared stage: the frame's and those that serve the GI methods.
pub const ALL: &[Stage] = &[
    SHADOW_MAP,
    GBUFFER,
    GBUFFER_RESOLVE,
    RSM,
    RSM_RESOLVE,
    DIRECT_LIGHT,
    EXPOSURE,
    TONEMAP,
    READBACK_COPY,
    GBUFFER_REDUCE,
    INDIRECT_UPSAMPLE,
    YUV420,
];

/// Whether `stage` belongs to the frame's GI method rather than to the stages every frame
/// runs.
pub fn is_gi(stage: Stage) -> bool {
    !EVERY_FRAME.contains(&stage)
}
