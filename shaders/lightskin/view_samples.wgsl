// View samples for importance estimation (eq. 10): G-buffer positions and normals at N_VS
// Halton-distributed pixel positions.

// Mirrored by `ViewSample` in server/passes/src/passes/importance.rs.
struct ViewSample {
    position: vec3<f32>,
    // 1 where the sample hit geometry, 0 on background.
    valid: f32,
    normal: vec3<f32>,
    pad0: f32,
}
