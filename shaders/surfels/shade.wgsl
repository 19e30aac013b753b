// Indirect light per pixel from the SH caches (seed 001, eq. 5–8): the caches around the
// pixel's surface point interpolated trilinearly, then the diffuse lobe (ρ_d/π)·max(ω·n, 0)
// and the normalised Phong lobe about the mirror direction r projected by zonal rotation
// (eq. 8). The paper's lobe (k+1)/(2π)·cosᵏ is scaled by (k+2)/(k+1)·max(n·r, 0) so it is the
// lobe our direct light uses, (k+2)/(2π)·cosᵏ·cos θ_i, with cos θ_i taken at r.
// Mirrors `cpu::shade`.

@group(0) @binding(0) var<storage, read> camera: CameraUniform;
@group(0) @binding(1) var g_position: texture_2d<f32>;
@group(0) @binding(2) var g_normal_exponent: texture_2d<f32>;
@group(0) @binding(3) var g_diffuse: texture_2d<f32>;
@group(0) @binding(4) var g_glossy: texture_2d<f32>;
@group(0) @binding(5) var<storage, read> grid: GridUniform;
@group(0) @binding(6) var<storage, read> cache_usable: array<u32>;
@group(0) @binding(7) var<storage, read> cache_light: array<vec4<f32>>;
@group(0) @binding(8) var indirect_out: texture_storage_2d<rgba16float, write>;

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
    let ne = textureLoad(g_normal_exponent, texel, 0);
    let n = normalize(ne.xyz);
    let k = ne.w;
    let v = normalize(camera.position - position.xyz);
    let r = reflect(-v, n);
    let caches = interpolate_caches(position.xyz, position.xyz, n);
    var radiance = vec3<f32>(0.0);
    if caches.total > 0.0 {
        let diffuse = textureLoad(g_diffuse, texel, 0).rgb;
        let glossy = textureLoad(g_glossy, texel, 0).rgb;
        let e = irradiance_from(caches, n);
        let yr = sh_eval(r);
        let s = zonal_phong(k);
        var lobe = vec3<f32>(0.0);
        for (var i = 0u; i < grid.coefficients; i++) {
            lobe += caches.radiance[i] * (s[sh_band(i)] * yr[i]);
        }
        lobe /= caches.total;
        let scale = (k + 2.0) / (k + 1.0) * max(dot(n, r), 0.0);
        radiance = diffuse / PI * e + glossy * max(lobe * scale, vec3<f32>(0.0));
    }
    textureStore(indirect_out, texel, vec4<f32>(radiance, 1.0));
}
