// Deferred lighting: emission, every punctual light with PCF shadows, and the indirect light
// computed before, into HDR. Lights after the punctual ones are the directional lights the
// method split the environment into: their light goes with the indirect light into
// `indirect_out` (what the frame reports as the light beyond the punctual lights' direct
// light, as the reference's indirect buffer holds the environment's light). Where no
// geometry covers a pixel the environment shows (alpha 1), or nothing (alpha 0).
// `indirect_out`'s alpha is the surface's specular share seen from the camera
// (`specular_share`), −1 where no geometry covers the pixel: what sorts a comparison's
// pixels into diffuse and specular receivers (`quality::receiver_errors`).

@group(0) @binding(0) var<storage, read> camera: CameraUniform;
@group(0) @binding(1) var<storage, read> lights: Lights;
@group(0) @binding(2) var g_position: texture_2d<f32>;
@group(0) @binding(3) var g_normal_roughness: texture_2d<f32>;
@group(0) @binding(4) var g_base_metallic: texture_2d<f32>;
@group(0) @binding(5) var g_emissive_specular: texture_2d<f32>;
@group(0) @binding(6) var shadow_map: texture_depth_2d_array;
@group(0) @binding(7) var shadow_sampler: sampler_comparison;
@group(0) @binding(8) var hdr_out: texture_storage_2d<rgba16float, write>;
@group(0) @binding(9) var indirect: texture_2d<f32>;
@group(0) @binding(10) var<storage, read> environment: array<f32>;
@group(0) @binding(11) var indirect_out: texture_storage_2d<rgba16float, write>;
@group(0) @binding(12) var<storage, read> brdf_table: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(hdr_out);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let position = textureLoad(g_position, texel, 0);
    let indirect_in = textureLoad(indirect, texel, 0);
    if position.w == 0.0 {
        textureStore(indirect_out, texel, vec4<f32>(indirect_in.rgb, -1.0));
        if env_enabled() {
            let ndc = vec2<f32>(
                (f32(id.x) + 0.5) / f32(size.x) * 2.0 - 1.0,
                1.0 - (f32(id.y) + 0.5) / f32(size.y) * 2.0,
            );
            let far = camera.inv_view_proj * vec4<f32>(ndc, 1.0, 1.0);
            let dir = normalize(far.xyz / far.w - camera.position);
            textureStore(hdr_out, texel, vec4<f32>(env_radiance(dir), 1.0));
        } else {
            // Background keeps alpha 0 so exposure and tone mapping can tell it apart.
            textureStore(hdr_out, texel, vec4<f32>(0.0));
        }
        return;
    }
    let p = position.xyz;
    let n = normalize(textureLoad(g_normal_roughness, texel, 0).xyz);
    let v = normalize(camera.position - p);
    let surface = view_brdf(gbuffer_brdf(texel), n, v);
    var punctual = vec3<f32>(0.0);
    var beyond = indirect_in.rgb;
    for (var i = 0u; i < lights.count; i++) {
        let light = lights.list[i];
        let incident = light_incident(light, p);
        let cos_x = max(dot(n, incident.to_light), 0.0);
        if cos_x > 0.0 {
            let visibility = shadow_visibility(light, shadow_map, shadow_sampler, p, n, cos_x);
            let l = eval_viewed(surface, incident.to_light) * incident.irradiance * cos_x * visibility;
            if i < lights.punctual {
                punctual += l;
            } else {
                beyond += l;
            }
        }
    }
    let radiance = textureLoad(g_emissive_specular, texel, 0).rgb + punctual + beyond;
    textureStore(hdr_out, texel, vec4<f32>(radiance, 1.0));
    textureStore(indirect_out, texel, vec4<f32>(beyond, specular_share(surface.brdf, surface.nv)));
}
