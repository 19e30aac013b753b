// Joint bilateral upsampling (Kopf et al. 2007) of indirect light computed at 1/factor of the
// output's resolution: each output pixel blends the four reduced samples around it with
// bilinear weights times how well each sample's surface matches the pixel's (normal and
// distance from the pixel's tangent plane), so light does not bleed across edges. Texture
// detail finer than the reduced grid is kept by dividing each sample's radiance by its
// material's reflectance and multiplying the blend by the pixel's own (demodulation).

// Mirrored by `UpsampleParams` in server/passes/src/passes/indirect_resolution.rs.
struct UpsampleParams {
    factor: u32,
    // Side of a reduced pixel in scene units per unit of distance from the camera.
    footprint: f32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<storage, read> camera: CameraUniform;
@group(0) @binding(1) var<storage, read> params: UpsampleParams;
@group(0) @binding(2) var g_position: texture_2d<f32>;
@group(0) @binding(3) var g_normal_roughness: texture_2d<f32>;
@group(0) @binding(4) var g_base_metallic: texture_2d<f32>;
@group(0) @binding(5) var r_position: texture_2d<f32>;
@group(0) @binding(6) var r_normal_roughness: texture_2d<f32>;
@group(0) @binding(7) var r_base_metallic: texture_2d<f32>;
@group(0) @binding(8) var r_indirect: texture_2d<f32>;
@group(0) @binding(9) var indirect_out: texture_storage_2d<rgba16float, write>;

// Reflectance floor of the demodulation: any positive value is exact on a uniform material;
// the floor only keeps black texels from dividing by zero.
const MIN_REFLECTANCE: f32 = 0.02;
// Normal agreement exponent: 16 halves the weight at 17° and removes perpendicular walls.
const NORMAL_POWER: f32 = 16.0;
// Distance from the pixel's tangent plane, in reduced-pixel footprints, at which a sample's
// weight falls to 1/e.
const PLANE_FOOTPRINTS: f32 = 1.0;
// Below this total weight no sample of the bilinear four is on the pixel's surface.
const MIN_WEIGHT: f32 = 1e-3;

struct Pixel {
    x: vec3<f32>,
    n: vec3<f32>,
    // Plane-distance scale at the pixel's distance from the camera.
    tolerance: f32,
}

// A material's reflectance from its base colour and metallic (a G-buffer texel): what carries
// its texture detail, the base colour, plus a dielectric's 4 % specular reflection, which the
// base colour does not tint (dividing that by a dark texel's base colour would inflate it).
fn reflectance(base_metallic: vec4<f32>) -> vec3<f32> {
    let base = base_metallic.rgb;
    return max(mix(base + vec3<f32>(0.04), base, base_metallic.a), vec3<f32>(MIN_REFLECTANCE));
}

// How well reduced sample `q` stands for the pixel's surface: x in [0, 1] for the blend,
// y > 0 for every covered sample (heavy-tailed, to rank candidates when x is 0 for all);
// both 0 for background.
fn match_weight(p: Pixel, q: vec2<i32>) -> vec2<f32> {
    let s = textureLoad(r_position, q, 0);
    if s.w == 0.0 {
        return vec2<f32>(0.0);
    }
    let n = normalize(textureLoad(r_normal_roughness, q, 0).xyz);
    let plane = dot(p.n, s.xyz - p.x) / p.tolerance;
    let facing = max(dot(p.n, n), 0.0);
    return vec2<f32>(
        pow(facing, NORMAL_POWER) * exp(-plane * plane),
        (facing + 0.01) / (1.0 + plane * plane),
    );
}

// The sample's indirect radiance per unit reflectance.
fn demodulated(q: vec2<i32>) -> vec3<f32> {
    let m = reflectance(textureLoad(r_base_metallic, q, 0));
    return textureLoad(r_indirect, q, 0).rgb / m;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(indirect_out);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let position = textureLoad(g_position, texel, 0);
    if position.w == 0.0 {
        textureStore(indirect_out, texel, vec4<f32>(0.0));
        return;
    }
    let p = Pixel(
        position.xyz,
        normalize(textureLoad(g_normal_roughness, texel, 0).xyz),
        PLANE_FOOTPRINTS * params.footprint * max(distance(camera.position, position.xyz), 1e-6),
    );
    let last = vec2<i32>(textureDimensions(r_indirect)) - vec2<i32>(1);
    // Reduced pixel (i, j) holds the full-resolution pixel at its block's centre.
    let f = f32(params.factor);
    let u = (vec2<f32>(texel) - f32(params.factor / 2u)) / f;
    let base = vec2<i32>(floor(u));
    let t = u - floor(u);
    var sum = vec3<f32>(0.0);
    var total = 0.0;
    for (var dy = 0; dy < 2; dy++) {
        for (var dx = 0; dx < 2; dx++) {
            let q = clamp(base + vec2<i32>(dx, dy), vec2<i32>(0), last);
            let bx = select(1.0 - t.x, t.x, dx == 1);
            let by = select(1.0 - t.y, t.y, dy == 1);
            let w = bx * by * match_weight(p, q).x;
            sum += w * demodulated(q);
            total += w;
        }
    }
    var radiance = vec3<f32>(0.0);
    if total >= MIN_WEIGHT {
        radiance = sum / total;
    } else {
        // None of the four is on this surface (a feature thinner than the reduced grid):
        // the closest match among the 3×3 samples around the nearest one, if any is covered.
        let nearest = clamp(vec2<i32>(floor(u + 0.5)), vec2<i32>(0), last);
        var best = 0.0;
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                let q = clamp(nearest + vec2<i32>(dx, dy), vec2<i32>(0), last);
                let w = match_weight(p, q).y;
                if w > best {
                    best = w;
                    radiance = demodulated(q);
                }
            }
        }
    }
    let m = reflectance(textureLoad(g_base_metallic, texel, 0));
    textureStore(indirect_out, texel, vec4<f32>(radiance * m, 1.0));
}
