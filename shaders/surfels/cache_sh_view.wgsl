// Debug view `cache-sh`: the SH radiance of the caches around each pixel's surface point,
// interpolated as the shading interpolates it (eq. 5) and evaluated along the pixel's normal,
// L(n) = Σ_i L_i·y_i(n) / Σ w: the light the caches say arrives from straight above the
// surface, before any lobe. Mirrors `cpu::radiance_along`.

@group(0) @binding(0) var g_position: texture_2d<f32>;
@group(0) @binding(1) var g_normal_roughness: texture_2d<f32>;
@group(0) @binding(2) var<storage, read> grid: GridUniform;
@group(0) @binding(3) var<storage, read> cache_usable: array<u32>;
@group(0) @binding(4) var<storage, read> cache_light: array<vec4<f32>>;
// Row-major, one RGB(A) value per pixel of the G-buffer.
@group(0) @binding(5) var<storage, read_write> view_out: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(g_position);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let out = id.y * size.x + id.x;
    let position = textureLoad(g_position, texel, 0);
    var radiance = vec3<f32>(0.0);
    if position.w != 0.0 {
        let n = normalize(textureLoad(g_normal_roughness, texel, 0).xyz);
        let caches = interpolate_caches(position.xyz, position.xyz, n);
        if caches.total > 0.0 {
            let y = sh_eval(n);
            for (var i = 0u; i < grid.coefficients; i++) {
                radiance += caches.radiance[i] * y[i];
            }
            radiance /= caches.total;
        }
    }
    view_out[out] = vec4<f32>(radiance, position.w);
}
