// Depth-only rendering of the scene from one light face (dynamic offset selects the face).

@group(0) @binding(0) var<storage, read> face_view_proj: mat4x4<f32>;

@vertex
fn vs_main(@location(0) position: vec3<f32>) -> @builtin(position) vec4<f32> {
    return face_view_proj * vec4<f32>(position, 1.0);
}
