// Shared by every pass: constants and the per-frame camera.

const PI: f32 = 3.14159265358979;

// Mirrored by `CameraUniform` in server/passes/src/passes/frame_uniforms.rs.
struct CameraUniform {
    view_proj: mat4x4<f32>,
    position: vec3<f32>,
    // Roughness for every material, overriding theirs (the `glossy_exponent` parameter); 0
    // keeps the materials' own.
    roughness: f32,
    // Clip to world: the ray through a pixel (the environment behind the geometry).
    inv_view_proj: mat4x4<f32>,
}
