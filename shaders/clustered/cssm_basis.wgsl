// The Fourier basis of every depth map texel (seed paper 003, §4.1 and §6 "Paraboloid
// CSSM"): band b of the texel at (x, y) is stored at (x, y + b·H), H being the depth atlas's
// height, so that one texture and one mip chain hold all five bands.

@group(0) @binding(0) var depth_atlas: texture_depth_2d;
@group(0) @binding(1) var basis_out: texture_storage_2d<rgba16float, write>;

@compute @workgroup_size(8, 8)
fn basis(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(depth_atlas);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let z = textureLoad(depth_atlas, id.xy, 0);
    for (var band = 0u; band < CSSM_BANDS; band++) {
        textureStore(basis_out, vec2<u32>(id.x, id.y + band * size.y), cssm_basis(z, band));
    }
}
