// The scene's surfaces as the reference reads them (group 1, after the BVH): vertices,
// indices, one record per material and the texels of every base-colour texture, so that a hit
// is shaded and alpha-tested like the G-buffer and the RSM shade and discard its fragment.

// Mirrored by `SurfaceGpu` in server/gi/src/reference/mod.rs: a material as the reference
// shades it.
struct SurfaceGpu {
    // The material's factors, as the rasterising passes read them.
    material: MaterialGpu,
    // The base-colour texture: its first texel in `texels` and its size. Untextured materials
    // use the white texel at 0 (1×1), as the raster passes bind a 1×1 white texture.
    texture_offset: u32,
    texture_width: u32,
    texture_height: u32,
    pad0: u32,
}

// Nine floats per vertex (`scene::Vertex`): position, normal, uv, material bits.
@group(1) @binding(4) var<storage, read> vertices: array<f32>;
@group(1) @binding(5) var<storage, read> indices: array<u32>;
@group(1) @binding(6) var<storage, read> surfaces: array<SurfaceGpu>;
// Every texture's texels, rows top to bottom: RGBA8 in sRGB, red in the low byte (packed by
// `gi::reference::PackedTextures`).
@group(1) @binding(7) var<storage, read> texels: array<u32>;
// `scene::brdf::BrdfTable`, for brdf_eval.wgsl.
@group(1) @binding(8) var<storage, read> brdf_table: array<vec4<f32>>;

fn vertex_position(i: u32) -> vec3<f32> {
    return vec3<f32>(vertices[9u * i], vertices[9u * i + 1u], vertices[9u * i + 2u]);
}

fn vertex_normal(i: u32) -> vec3<f32> {
    return vec3<f32>(vertices[9u * i + 3u], vertices[9u * i + 4u], vertices[9u * i + 5u]);
}

fn vertex_uv(i: u32) -> vec2<f32> {
    return vec2<f32>(vertices[9u * i + 6u], vertices[9u * i + 7u]);
}

// The material of a triangle is its first vertex's, as the raster passes take it from the
// provoking vertex (`@interpolate(flat)`).
fn triangle_surface(triangle: u32) -> SurfaceGpu {
    return surfaces[bitcast<u32>(vertices[9u * indices[3u * triangle] + 8u])];
}

// The sRGB transfer function's inverse, as sampling an `Rgba8UnormSrgb` texture applies it.
fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    return select(pow((c + 0.055) / 1.055, vec3<f32>(2.4)), c / 12.92, c <= vec3<f32>(0.04045));
}

fn texel(s: SurfaceGpu, x: u32, y: u32) -> vec4<f32> {
    let c = unpack4x8unorm(texels[s.texture_offset + y * s.texture_width + x]);
    return vec4<f32>(srgb_to_linear(c.rgb), c.a);
}

// The base colour texture at `uv` as the raster passes' sampler reads it (scene_buffers.rs):
// one mip level, bilinear, repeat on both axes, texels decoded to linear before blending.
fn sample_texture(s: SurfaceGpu, uv: vec2<f32>) -> vec4<f32> {
    let size = vec2<u32>(s.texture_width, s.texture_height);
    // Wrapping uv first is the same repeat and keeps far-out uvs precise.
    let p = fract(uv) * vec2<f32>(size) - 0.5;
    let f = p - floor(p);
    // floor(p) is in [-1, size - 1]: adding size before the modulo keeps it unsigned.
    let lo = (vec2<u32>(vec2<i32>(floor(p)) + vec2<i32>(size))) % size;
    let hi = (lo + 1u) % size;
    return mix(
        mix(texel(s, lo.x, lo.y), texel(s, hi.x, lo.y), f.x),
        mix(texel(s, lo.x, hi.y), texel(s, hi.x, hi.y), f.x),
        f.y,
    );
}

// The material of `triangle` at barycentric coordinates `b` (of its second and third vertex).
fn material_at(triangle: u32, b: vec2<f32>) -> MaterialSample {
    let s = triangle_surface(triangle);
    let i0 = indices[3u * triangle];
    let i1 = indices[3u * triangle + 1u];
    let i2 = indices[3u * triangle + 2u];
    let uv = vertex_uv(i0) * (1.0 - b.x - b.y) + vertex_uv(i1) * b.x + vertex_uv(i2) * b.y;
    return shade_material(s.material, sample_texture(s, uv));
}

// Whether an alpha mask cuts `triangle` away at `b`: the traversal (bvh.wgsl) skips such hits,
// so rays pass where the G-buffer and the RSM discard fragments. It asks only for triangles
// whose material has an alpha cutoff.
fn hit_masked(triangle: u32, b: vec2<f32>) -> bool {
    return !material_at(triangle, b).covered;
}
