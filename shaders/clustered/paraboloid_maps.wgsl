// One paraboloid depth map per light (VAL for `cssm`, VPL for `vpl_shadows`) in a single
// instanced draw (seed paper 003, §6 "Paraboloid CSSM"): instance j renders the scene into
// tile j of the atlas. Straight edges do not stay straight under the paraboloid projection,
// so each triangle is drawn as a box bounding its projected edges and every fragment casts
// the ray of its own texel against the triangle: depths and coverage are exact per texel
// even for the two-triangle walls of a Cornell box. Depth is the distance over the scene's
// extent.

@group(0) @binding(0) var<storage, read> params: ClusteredParams;
@group(0) @binding(1) var<storage, read> centres: array<MapCentre>;
// The scene's triangle list and vertex positions (9 floats per vertex, position first).
@group(0) @binding(2) var<storage, read> indices: array<u32>;
@group(0) @binding(3) var<storage, read> vertices: array<f32>;

const VERTEX_FLOATS: u32 = 9u;
// Points per edge projected to bound it (its arc bulges less than the padding in between).
const EDGE_SAMPLES: u32 = 4u;

struct MapVaryings {
    @builtin(position) clip: vec4<f32>,
    // The triangle's corners relative to the light.
    @location(0) @interpolate(flat) a: vec3<f32>,
    @location(1) @interpolate(flat) b: vec3<f32>,
    @location(2) @interpolate(flat) c: vec3<f32>,
    @location(3) @interpolate(flat) light: u32,
}

fn corner(index: u32) -> vec3<f32> {
    let base = indices[index] * VERTEX_FLOATS;
    return vec3<f32>(vertices[base], vertices[base + 1u], vertices[base + 2u]);
}

// Distance along the unit ray from the origin in direction d to triangle abc (either side),
// or -1 where it misses (Möller–Trumbore).
fn ray_triangle(d: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> f32 {
    let e1 = b - a;
    let e2 = c - a;
    let p = cross(d, e2);
    let det = dot(e1, p);
    if abs(det) <= 1e-9 * length(e1) * length(e2) {
        return -1.0;
    }
    let inv = 1.0 / det;
    let s = -a;
    let u = dot(s, p) * inv;
    let q = cross(s, e1);
    let v = dot(d, q) * inv;
    let tolerance = 1e-6;
    if u < -tolerance || v < -tolerance || u + v > 1.0 + tolerance {
        return -1.0;
    }
    return dot(e2, q) * inv;
}

@vertex
fn vs_map(@builtin(vertex_index) index: u32, @builtin(instance_index) light: u32) -> MapVaryings {
    var out: MapVaryings;
    let centre = centres[light];
    let first = index - index % 3u;
    let origin = map_origin(params, centre);
    out.a = corner(first) - origin;
    out.b = corner(first + 1u) - origin;
    out.c = corner(first + 2u) - origin;
    out.light = light;
    // All three corners of a skipped triangle land here: no area, nothing drawn.
    out.clip = vec4<f32>(2.0, 2.0, 0.5, 1.0);
    if centre.used == 0u {
        return out;
    }
    let to_local = transpose(paraboloid_frame(centre.normal));
    let corners = array<vec3<f32>, 3>(out.a, out.b, out.c);
    var lo = vec2<f32>(1e9);
    var hi = vec2<f32>(-1e9);
    // A triangle reaching behind the light's plane (or through the light) can wrap around
    // the map's corners: it gets the whole tile and the per-texel rays sort it out.
    var whole = false;
    for (var e = 0u; e < 3u; e++) {
        for (var s = 0u; s < EDGE_SAMPLES; s++) {
            let p = mix(corners[e], corners[(e + 1u) % 3u], f32(s) / f32(EDGE_SAMPLES));
            let l = length(p);
            if l <= 1e-6 * params.extent {
                whole = true;
                continue;
            }
            let local = to_local * (p / l);
            if local.z < -0.05 {
                whole = true;
            } else {
                let uv = paraboloid_uv(local);
                lo = min(lo, uv);
                hi = max(hi, uv);
            }
        }
    }
    if whole {
        lo = vec2<f32>(-1.0);
        hi = vec2<f32>(1.0);
    } else {
        let pad = 0.05 * (hi - lo) + vec2<f32>(4.0 / f32(params.map_size));
        lo = max(lo - pad, vec2<f32>(-1.0));
        hi = min(hi + pad, vec2<f32>(1.0));
    }
    if any(lo >= hi) {
        return out;
    }
    // The right triangle with legs twice the box's sides covers the box.
    var uv = lo;
    let k = index % 3u;
    if k == 1u {
        uv.x = 2.0 * hi.x - lo.x;
    } else if k == 2u {
        uv.y = 2.0 * hi.y - lo.y;
    }
    let size = vec2<f32>(f32(params.atlas_columns), f32(params.atlas_rows)) * f32(params.map_size);
    let texel = atlas_position(params, light, uv) / size;
    out.clip = vec4<f32>(texel.x * 2.0 - 1.0, 1.0 - texel.y * 2.0, 0.5, 1.0);
    return out;
}

@fragment
fn fs_map(in: MapVaryings) -> @builtin(frag_depth) f32 {
    let local = (in.clip.xy - tile_origin(params, in.light)) / f32(params.map_size);
    if any(local < vec2<f32>(0.0)) || any(local > vec2<f32>(1.0)) {
        discard;
    }
    let d = paraboloid_frame(centres[in.light].normal) * paraboloid_direction(local * 2.0 - 1.0);
    let t = ray_triangle(d, in.a, in.b, in.c);
    if t <= 0.0 {
        discard;
    }
    return min(t / params.extent, 1.0);
}
