// The exposure chosen for a frame: written by exposure.wgsl (or the CPU for a manual exposure),
// read by tonemap.wgsl.

// Mirrored by `ExposureResult` in server/passes/src/passes/exposure.rs.
struct ExposureResult {
    scale: f32,
    mean_log2_luminance: f32,
    lit_pixels: f32,
    pad0: f32,
}
