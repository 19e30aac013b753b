// The reference: progressive path tracing of the indirect light leaving each pixel's surface
// point towards the camera, with the same materials (the BRDF of brdf_eval.wgsl with the
// textured base colour, alpha masks; surfaces.wgsl), punctual lights and emitters as the other methods
// but exact visibility (BVH rays instead of shadow maps or caches).
//
// A path starts at the surface the pixel centre sees (the point the G-buffer rasterises) and
// reflects `bounces` times. At each vertex y it reached it adds y's emission (unless
// `emitters` is off: methods that light from the punctual lights alone are compared without
// it) and, by next-event estimation with a shadow ray, each punctual light y reflects. So
// `bounces` = 1 is the single-bounce light seed 004 approximates; more add inter-reflections
// (seed 001).
//
// An environment (environment.wgsl) lights every vertex x, y1 … y_bounces, from x on (its
// light at x is the sky's direct light, which the other methods also count with their
// indirect light): by next-event estimation (a direction sampled by the environment's power,
// one shadow ray) combined with the BRDF-sampled bounce ray that leaves the scene, each
// weighted by the power heuristic (Veach 1997, §9.2.4), so that neither a small bright
// region nor a glossy lobe makes fireflies. The last vertex has no bounce ray after it: its
// next-event estimate counts whole.
//
// With `diffuse_senders` a vertex y1 … y_bounces reflects the light it receives straight from
// a light (punctual or the environment) by its BRDF's diffuse lobe alone: the light transport
// of the methods whose VPLs/VALs/surfels are diffuse. The environment then reaches those
// vertices by next-event estimation only (a BRDF-sampled ray that leaves the scene there
// carries the whole BRDF's weight, which this transport does not have), which stays unbiased.

// Mirrored by `TraceParams` in server/gi/src/reference/mod.rs.
struct TraceParams {
    inv_view_proj: mat4x4<f32>,
    camera_position: vec3<f32>,
    width: u32,
    height: u32,
    // Index of this dispatch's sample among all accumulated so far (decorrelates the streams).
    sample_index: u32,
    bounces: u32,
    seed: u32,
    // Offset of continuation rays along the geometric normal, in scene units.
    ray_epsilon: f32,
    // Roughness for every material (the `glossy_exponent` override); 0 keeps their own.
    roughness: f32,
    // 1: add the emission of the surfaces a path reaches (emissive surfaces as area lights).
    emitters: u32,
    // First row of this dispatch's band of the image (a sample is traced in bands of rows).
    row_offset: u32,
    // 1: y1 … y_bounces reflect direct light by their diffuse lobe alone (see above).
    diffuse_senders: u32,
}

@group(0) @binding(0) var<storage, read> params: TraceParams;
@group(0) @binding(1) var<storage, read> lights: Lights;
// Per pixel: the sum of the samples' indirect radiance (rgb) and of their squared luminance (w).
@group(0) @binding(2) var<storage, read_write> accum: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> environment: array<f32>;

// PCG hash (Jarzynski & Olano 2020): the random stream of a path is a pure function of the
// pixel, the sample index and the seed, so the same request gives the same pixels.
fn pcg(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

fn rand(state: ptr<function, u32>) -> f32 {
    *state = pcg(*state);
    return f32(*state >> 8u) * (1.0 / 16777216.0);
}

struct SurfaceHit {
    position: vec3<f32>,
    // Shading normal on the side the ray came from.
    normal: vec3<f32>,
    // Geometric normal on the side the ray came from.
    geometric: vec3<f32>,
    brdf: SurfaceBrdf,
    emissive: vec3<f32>,
}

fn surface_at(hit: RayHit, origin: vec3<f32>, dir: vec3<f32>) -> SurfaceHit {
    let i0 = indices[3u * hit.triangle];
    let i1 = indices[3u * hit.triangle + 1u];
    let i2 = indices[3u * hit.triangle + 2u];
    let p0 = vertex_position(i0);
    let g = normalize(cross(vertex_position(i1) - p0, vertex_position(i2) - p0));
    let w = vec3<f32>(1.0 - hit.uv.x - hit.uv.y, hit.uv.x, hit.uv.y);
    let interpolated = vertex_normal(i0) * w.x + vertex_normal(i1) * w.y + vertex_normal(i2) * w.z;
    // Two-sided like the G-buffer: the side facing the ray (by winding) is the front.
    let front = dot(g, dir) < 0.0;
    let geometric = select(-g, g, front);
    var normal = select(-interpolated, interpolated, front);
    let len = length(normal);
    normal = select(geometric, normal / len, len > 1e-12);
    let m = material_at(hit.triangle, hit.uv);
    var brdf = m.brdf;
    if params.roughness > 0.0 {
        brdf.roughness = params.roughness;
    }
    // An emitter emits from the side its vertex normals face (glTF's front; Mitsuba's area
    // emitters are one-sided too), as the real-time methods' emitter samples do
    // (scene/src/emitters.rs): a bare lamp quad's back does not light the ceiling above it.
    let emissive = select(vec3<f32>(0.0), m.emissive, dot(interpolated, dir) < 0.0);
    return SurfaceHit(origin + dir * hit.t, normal, geometric, brdf, emissive);
}

// An orthonormal basis around unit `n` (Duff et al. 2017).
fn basis(n: vec3<f32>) -> mat3x3<f32> {
    let sign = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    return mat3x3<f32>(
        vec3<f32>(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        vec3<f32>(b, sign + n.y * n.y * a, -n.y),
        n,
    );
}

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

// Probability of sampling the diffuse lobe rather than the specular one: in proportion to
// their albedos' luminance seen from `wo`.
fn diffuse_probability(s: SurfaceBrdf, n: vec3<f32>, wo: vec3<f32>) -> f32 {
    let mu = max(dot(n, wo), 0.0);
    let d = luminance(diffuse_albedo(s, mu));
    let total = d + luminance(specular_albedo(s, mu));
    return select(0.0, d / total, total > 0.0);
}

// The view specular sampling uses: `wo`, lifted just above the shading normal's horizon where an
// interpolated normal faces slightly away from it (visible normals are undefined there).
// Sampling and `brdf_pdf` both use it, so the density stays exact.
fn sampling_view(n: vec3<f32>, wo: vec3<f32>) -> vec3<f32> {
    let c = dot(n, wo);
    return select(wo, normalize(wo + n * (1e-4 - c)), c < 1e-4);
}

// Density (per solid angle) of `sample_brdf` choosing `wi`: cosine-weighted for the diffuse
// lobe, and for the specular one a visible normal h mirrored, G₁(wo)·D(h)/(4·n·wo) per solid
// angle of wi (Heitz 2018, "Sampling the GGX Distribution of Visible Normals", eq. 17 with
// the reflection's Jacobian 1/(4·wo·h)).
fn brdf_pdf(s: SurfaceBrdf, n: vec3<f32>, wo: vec3<f32>, wi: vec3<f32>) -> f32 {
    let p_d = diffuse_probability(s, n, wo);
    let view = sampling_view(n, wo);
    let h = normalize(view + wi);
    let alpha = s.roughness * s.roughness;
    let a2 = alpha * alpha;
    let nv = dot(n, view);
    let g1 = 2.0 * nv / (nv + sqrt(a2 + (1.0 - a2) * nv * nv));
    let specular = select(0.0, g1 * ggx_d(dot(n, h), a2) / (4.0 * nv), dot(view, h) > 0.0);
    return p_d * max(dot(n, wi), 0.0) / PI + (1.0 - p_d) * specular;
}

fn sample_brdf(s: SurfaceBrdf, n: vec3<f32>, wo: vec3<f32>, state: ptr<function, u32>) -> vec3<f32> {
    let u0 = rand(state);
    let u1 = rand(state);
    let u2 = rand(state);
    let frame = basis(n);
    if u0 < diffuse_probability(s, n, wo) {
        let phi = 2.0 * PI * u1;
        let r = sqrt(u2);
        return frame * vec3<f32>(r * cos(phi), r * sin(phi), sqrt(max(1.0 - u2, 0.0)));
    }
    // Heitz 2018 (listing 1): the view in the frame where the GGX of roughness α is the unit
    // hemisphere, a point of the projected visible half disk, back to GGX's frame. The same
    // sampling as `scene::brdf::specular_albedo` builds the albedo table with.
    let alpha = s.roughness * s.roughness;
    let view = sampling_view(n, wo);
    let local = transpose(frame) * view;
    let v = normalize(vec3<f32>(alpha * local.x, alpha * local.y, local.z));
    let len2 = v.x * v.x + v.y * v.y;
    let t1 = select(vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(-v.y, v.x, 0.0) * inverseSqrt(len2), len2 > 0.0);
    let t2 = cross(v, t1);
    let r = sqrt(u1);
    let phi = 2.0 * PI * u2;
    let p1 = r * cos(phi);
    let blend = 0.5 * (1.0 + v.z);
    let p2 = (1.0 - blend) * sqrt(max(1.0 - p1 * p1, 0.0)) + blend * r * sin(phi);
    let m = p1 * t1 + p2 * t2 + sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0)) * v;
    let h = frame * normalize(vec3<f32>(alpha * m.x, alpha * m.y, max(m.z, 1e-6)));
    return reflect(-view, h);
}

// Most emissive surfaces a shadow ray passes through before it counts as blocked.
const MAX_EMITTER_CROSSINGS: u32 = 4u;

// Whether nothing blocks the segment from `p` (already offset) towards `light`. Emissive
// surfaces do not: they stand for light sources, and the shadow maps and RSMs leave them out
// too (`SceneBuffers::shadow_casting`), so a punctual light standing in for a lamp shines
// through the lamp's own geometry here as in every other method (a spot just above a ceiling
// lamp's quad would otherwise light nothing beyond the visible surface).
fn light_visible(light: LightUniform, p: vec3<f32>, to_light: vec3<f32>) -> bool {
    var t_max = 3.4e38;
    if light.kind != LIGHT_DIRECTIONAL {
        t_max = distance(light.position, p) * (1.0 - 1e-4);
    }
    var origin = p;
    for (var crossed = 0u; crossed <= MAX_EMITTER_CROSSINGS; crossed++) {
        let hit = trace(origin, to_light, t_max);
        if hit.triangle == NO_HIT {
            return true;
        }
        if all(triangle_surface(hit.triangle).material.emissive <= vec3<f32>(0.0)) {
            return false;
        }
        let step = hit.t + params.ray_epsilon;
        origin += to_light * step;
        t_max -= step;
        if t_max <= 0.0 {
            return true;
        }
    }
    return false;
}

// Power-heuristic weight of a sample drawn with density `a` against the other strategy's `b`.
fn power_heuristic(a: f32, b: f32) -> f32 {
    let a2 = a * a;
    return select(0.0, a2 / (a2 + b * b), a2 > 0.0);
}

// f_r of a vertex reflecting direct light: the whole BRDF at x (the pixel's surface, lit
// directly) and wherever senders are full, the diffuse lobe alone at y1 … with
// `diffuse_senders`.
fn sender_brdf(s: SurfaceBrdf, n: vec3<f32>, to_light: vec3<f32>, wo: vec3<f32>, first: bool) -> vec3<f32> {
    if params.diffuse_senders != 0u && !first {
        return eval_diffuse(s, n, to_light, wo);
    }
    return eval_brdf(s, n, to_light, wo);
}

// The environment's light reflected at `surface` towards `wo`, by one direction sampled from
// the environment; weighted against BRDF sampling when `mis` (a bounce ray follows, whose
// escape counts the environment too). `first`: `surface` is the pixel's.
fn environment_next_event(surface: SurfaceHit, wo: vec3<f32>, mis: bool, first: bool, state: ptr<function, u32>) -> vec3<f32> {
    let u = vec3<f32>(rand(state), rand(state), rand(state));
    let s = env_sample(u);
    let cos_y = dot(surface.normal, s.direction);
    if s.pdf <= 0.0 || cos_y <= 0.0 || dot(surface.geometric, s.direction) <= 0.0 {
        return vec3<f32>(0.0);
    }
    let lifted = surface.position + surface.geometric * params.ray_epsilon;
    if trace(lifted, s.direction, 3.4e38).triangle != NO_HIT {
        return vec3<f32>(0.0);
    }
    var weight = 1.0;
    if mis {
        weight = power_heuristic(s.pdf, brdf_pdf(surface.brdf, surface.normal, wo, s.direction));
    }
    return sender_brdf(surface.brdf, surface.normal, s.direction, wo, first) * s.radiance * cos_y / s.pdf * weight;
}

// Indirect radiance leaving `x` towards `wo` along one path.
fn indirect_sample(x: SurfaceHit, wo_in: vec3<f32>, state: ptr<function, u32>) -> vec3<f32> {
    var radiance = vec3<f32>(0.0);
    var throughput = vec3<f32>(1.0);
    var surface = x;
    var wo = wo_in;
    let sky = env_enabled();
    for (var bounce = 0u; bounce < params.bounces; bounce++) {
        let n = surface.normal;
        // Whether the environment at this vertex is shared between next-event estimation
        // and the escaping bounce ray (not at a diffuse sender: see the top).
        let mis = bounce == 0u || params.diffuse_senders == 0u;
        if sky {
            radiance += throughput * environment_next_event(surface, wo, mis, bounce == 0u, state);
        }
        let wi = sample_brdf(surface.brdf, n, wo, state);
        let cos_i = dot(n, wi);
        let pdf = brdf_pdf(surface.brdf, n, wo, wi);
        if cos_i <= 0.0 || dot(surface.geometric, wi) <= 0.0 || pdf <= 0.0 {
            return radiance;
        }
        throughput *= eval_brdf(surface.brdf, n, wi, wo) * cos_i / pdf;
        let origin = surface.position + surface.geometric * params.ray_epsilon;
        let hit = trace(origin, wi, 3.4e38);
        if hit.triangle == NO_HIT {
            if sky && mis {
                radiance += throughput * env_radiance(wi) * power_heuristic(pdf, env_pdf(wi));
            }
            return radiance;
        }
        surface = surface_at(hit, origin, wi);
        wo = -wi;
        if params.emitters != 0u {
            radiance += throughput * surface.emissive;
        }
        let lifted = surface.position + surface.geometric * params.ray_epsilon;
        // Next-event estimation sums every light, one shadow ray each: exact in the light
        // count (no light is sampled), so the noise stays that of the paths.
        for (var i = 0u; i < lights.count; i++) {
            let light = lights.list[i];
            let incident = light_incident(light, surface.position);
            let cos_y = dot(surface.normal, incident.to_light);
            // The shadow ray last: only where the light could reach (cone, facing, intensity).
            if cos_y > 0.0 && dot(surface.geometric, incident.to_light) > 0.0
                && any(incident.irradiance > vec3<f32>(0.0))
                && light_visible(light, lifted, incident.to_light) {
                radiance += throughput * sender_brdf(surface.brdf, surface.normal, incident.to_light, wo, false)
                    * incident.irradiance * cos_y;
            }
        }
    }
    if sky {
        radiance += throughput * environment_next_event(surface, wo, false, params.bounces == 0u, state);
    }
    return radiance;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let row = id.y + params.row_offset;
    if id.x >= params.width || row >= params.height {
        return;
    }
    let pixel = row * params.width + id.x;
    // The pixel centre, as rasterisation samples it.
    let ndc = vec2<f32>(
        (f32(id.x) + 0.5) / f32(params.width) * 2.0 - 1.0,
        1.0 - (f32(row) + 0.5) / f32(params.height) * 2.0,
    );
    let far = params.inv_view_proj * vec4<f32>(ndc, 1.0, 1.0);
    let dir = normalize(far.xyz / far.w - params.camera_position);
    let primary = trace(params.camera_position, dir, 3.4e38);
    if primary.triangle == NO_HIT {
        return;
    }
    let x = surface_at(primary, params.camera_position, dir);
    var state = pcg(pixel ^ pcg(params.sample_index ^ pcg(params.seed)));
    let l = indirect_sample(x, -dir, &state);
    let y = luminance(l);
    accum[pixel] += vec4<f32>(l, y * y);
}
