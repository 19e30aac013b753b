// Exposure, filmic tone curve and sRGB encoding into the 8-bit output image.

@group(0) @binding(0) var hdr: texture_2d<f32>;
@group(0) @binding(1) var<storage, read> exposure: ExposureResult;
@group(0) @binding(2) var ldr_out: texture_storage_2d<rgba8unorm, write>;

// Linear colour of pixels no geometry covers.
const BACKGROUND: vec3<f32> = vec3<f32>(0.02, 0.025, 0.035);

// Narkowicz's fit of the ACES filmic curve: keeps highlights from clipping abruptly.
fn aces(x: vec3<f32>) -> vec3<f32> {
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), vec3<f32>(0.0), vec3<f32>(1.0));
}

fn linear_to_srgb(c: vec3<f32>) -> vec3<f32> {
    let low = c * 12.92;
    let high = 1.055 * pow(c, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(high, low, c <= vec3<f32>(0.0031308));
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(ldr_out);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let c = textureLoad(hdr, texel, 0);
    var mapped = BACKGROUND;
    if c.a > 0.0 {
        mapped = aces(c.rgb * exposure.scale);
    }
    textureStore(ldr_out, texel, vec4<f32>(linear_to_srgb(mapped), 1.0));
}
