// G-buffer: rasterises the scene from the camera into world position, normal + glossy
// exponent, diffuse albedo, glossy colour and emission.

// Mirrored by `MaterialGpu` in server/src/passes/gbuffer.rs.
struct MaterialGpu {
    base_color: vec4<f32>,
    emissive: vec3<f32>,
    metallic: f32,
    roughness: f32,
    // Alpha below this is discarded; 0 for opaque materials.
    alpha_cutoff: f32,
    pad0: f32,
    pad1: f32,
}

@group(0) @binding(0) var<uniform> camera: CameraUniform;
@group(0) @binding(1) var<storage, read> materials: array<MaterialGpu>;
@group(1) @binding(0) var base_color_texture: texture_2d<f32>;
@group(1) @binding(1) var base_color_sampler: sampler;

// Mirrored by `scene::Vertex`.
struct VertexInput {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) material: u32,
}

struct VertexOutput {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) @interpolate(flat) material: u32,
}

@vertex
fn vs_main(v: VertexInput) -> VertexOutput {
    var out: VertexOutput;
    out.clip = camera.view_proj * vec4<f32>(v.position, 1.0);
    out.world = v.position;
    out.normal = v.normal;
    out.uv = v.uv;
    out.material = v.material;
    return out;
}

struct GBufferOut {
    @location(0) position: vec4<f32>,
    @location(1) normal_exponent: vec4<f32>,
    @location(2) diffuse: vec4<f32>,
    @location(3) glossy: vec4<f32>,
    @location(4) emissive: vec4<f32>,
}

@fragment
fn fs_main(in: VertexOutput, @builtin(front_facing) front: bool) -> GBufferOut {
    let m = materials[in.material];
    // Untextured materials are bound to a 1×1 white texture, so sampling stays uniform.
    let base = m.base_color * textureSample(base_color_texture, base_color_sampler, in.uv);
    if base.a < m.alpha_cutoff {
        discard;
    }
    // Culling is off (glTF allows double-sided materials); back faces shade with the flipped normal.
    var n = normalize(in.normal);
    if !front {
        n = -n;
    }
    let s = split_material(base.rgb, m.metallic, m.roughness);
    var out: GBufferOut;
    // w = 1 marks covered pixels; the clear value 0 marks background.
    out.position = vec4<f32>(in.world, 1.0);
    out.normal_exponent = vec4<f32>(n, s.exponent);
    out.diffuse = vec4<f32>(s.diffuse, 1.0);
    out.glossy = vec4<f32>(s.glossy, 1.0);
    out.emissive = vec4<f32>(m.emissive, 1.0);
    return out;
}
