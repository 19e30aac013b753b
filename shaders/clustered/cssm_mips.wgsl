// One level of the basis textures' mip chain: the mean of 2×2 texels of the level below, the
// box filter the soft-shadow lookups approximate by their level of detail (§4.1). Map sides
// are powers of two, so a texel of any level never mixes two maps or two bands.

@group(0) @binding(0) var finer: texture_2d<f32>;
@group(0) @binding(1) var coarser: texture_storage_2d<rgba16float, write>;

@compute @workgroup_size(8, 8)
fn downsample(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(coarser);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let p = vec2<i32>(id.xy) * 2;
    let sum = textureLoad(finer, p, 0) + textureLoad(finer, p + vec2<i32>(1, 0), 0)
        + textureLoad(finer, p + vec2<i32>(0, 1), 0) + textureLoad(finer, p + vec2<i32>(1, 1), 0);
    textureStore(coarser, id.xy, sum * 0.25);
}
