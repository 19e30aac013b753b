// Indirect light per pixel from the SH caches (seed 001, eq. 5–8): the caches around the
// pixel's surface point interpolated trilinearly, then the diffuse lobe (ρ_d/π)·max(ω·n, 0)
// and the normalised Phong lobe about the mirror direction r projected by zonal rotation
// (eq. 8). The paper's lobe (k+1)/(2π)·cosᵏ is scaled by (k+2)/(k+1)·max(n·r, 0) so it is the
// normalised lobe (k+2)/(2π)·cosᵏ·cos θ_i, with cos θ_i taken at r. ρ_d, the lobe's colour and
// k are the paper's lobes fitted to the pixel's BRDF (brdf_eval.wgsl `phong_lobes`): the
// specular lobe as a Phong lobe is this method's approximation of it. Mirrors `cpu::shade`.

@group(0) @binding(0) var<storage, read> camera: CameraUniform;
@group(0) @binding(1) var g_position: texture_2d<f32>;
@group(0) @binding(2) var g_normal_roughness: texture_2d<f32>;
@group(0) @binding(3) var g_base_metallic: texture_2d<f32>;
@group(0) @binding(4) var g_emissive_specular: texture_2d<f32>;
@group(0) @binding(5) var<storage, read> grid: GridUniform;
@group(0) @binding(6) var<storage, read> cache_usable: array<u32>;
@group(0) @binding(7) var<storage, read> cache_light: array<vec4<f32>>;
@group(0) @binding(8) var indirect_out: texture_storage_2d<rgba16float, write>;
@group(0) @binding(9) var<storage, read> brdf_table: array<vec4<f32>>;

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
    let n = normalize(textureLoad(g_normal_roughness, texel, 0).xyz);
    let v = normalize(camera.position - position.xyz);
    let lobes = phong_lobes(gbuffer_brdf(texel), max(dot(n, v), 0.0));
    let k = lobes.exponent;
    let r = reflect(-v, n);
    let caches = interpolate_caches(position.xyz, position.xyz, n);
    var radiance = vec3<f32>(0.0);
    if caches.total > 0.0 {
        let e = irradiance_from(caches, n);
        let yr = sh_eval(r);
        let s = zonal_phong(k);
        var lobe = vec3<f32>(0.0);
        for (var i = 0u; i < grid.coefficients; i++) {
            lobe += caches.radiance[i] * (s[sh_band(i)] * yr[i]);
        }
        lobe /= caches.total;
        let scale = (k + 2.0) / (k + 1.0) * max(dot(n, r), 0.0);
        radiance = lobes.diffuse / PI * e + lobes.glossy * max(lobe * scale, vec3<f32>(0.0));
    }
    textureStore(indirect_out, texel, vec4<f32>(radiance, 1.0));
}
