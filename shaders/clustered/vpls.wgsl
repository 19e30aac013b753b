// Virtual point lights and the virtual area lights they are clustered into (seed paper 003,
// §4–6), shared by the clustering, shading and blur passes.

// Mirrored by `ClusteredParams` in server/gi/src/clustered/passes.rs.
struct ClusteredParams {
    rsm_width: u32,
    rsm_height: u32,
    // N.
    vpl_count: u32,
    // M.
    cluster_count: u32,
    // w_x of §5.1 divided by the scene's extent, so that Δx is measured in extents.
    position_weight: f32,
    // w_α of §5.1, per radian.
    normal_weight: f32,
    // Side of the interleaved-sampling block (§6 "Indirect Lighting").
    interleave: u32,
    width: u32,
    height: u32,
    // Largest distance between the surface points of blurred pixels, in scene units.
    blur_distance: f32,
    // Smallest cosine between the normals of blurred pixels.
    blur_normal: f32,
    // VISIBILITY_OFF, VISIBILITY_CSSM or VISIBILITY_VPL_SHADOWS (clustered/paraboloid.wgsl).
    visibility: u32,
    // Side S of one paraboloid map in texels (a power of two).
    map_size: u32,
    // The maps' atlas: tile j is at column j % atlas_columns, row j / atlas_columns.
    atlas_columns: u32,
    atlas_rows: u32,
    // K of the convolution soft shadow maps (§4.1), 1 to FOURIER_MAX_TERMS.
    fourier_terms: u32,
    // The scene's extent (bounding-box diagonal): depths in the maps are distances over it.
    extent: f32,
    // The light whose visibility the `val-shadow` debug view shows.
    shadow_light: u32,
    // 1: k-means starts from the VALs already in `vals` (a previous frame's) instead of the
    // seeds; only for comparing with §5.2's restart.
    keep_centres: u32,
    pad2: u32,
}

// Mirrored by `Vpl` in server/gi/src/clustered/passes.rs.
struct Vpl {
    position: vec3<f32>,
    // Disk area of the RSM texels the VPL stands for (bounds its form factor near it).
    area: f32,
    normal: vec3<f32>,
    // 1 where the RSM texel holds a surface that reflects light; 0: no VPL.
    lit: u32,
    // Reflected flux Φ_i of the RSM texels the VPL stands for.
    flux: vec3<f32>,
    // Row-major RSM texel it was fetched from.
    texel: u32,
}

// Mirrored by `Val` in server/gi/src/clustered/passes.rs. During k-means it holds a cluster
// centre; after the final pass the VAL: the mean position and normal of its VPLs (§5) and
// the area of their bounding rectangle in the plane of that normal (§6).
struct Val {
    position: vec3<f32>,
    area: f32,
    normal: vec3<f32>,
    // VPLs mapped to it.
    count: u32,
    // 1 once seeded (§5.2); a cluster whose seed range holds no lit VPL has no centre.
    centred: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

// C(i) of a VPL without light.
const NO_VAL: u32 = 0xffffffffu;

// The clustering distance d = w_x·Δx + w_α·Δα of §5.1.
fn cluster_distance(p: ClusteredParams, vpl: Vpl, centre: Val) -> f32 {
    let angle = acos(clamp(dot(vpl.normal, centre.normal), -1.0, 1.0));
    return p.position_weight * distance(vpl.position, centre.position) + p.normal_weight * angle;
}

// An orthonormal tangent basis of unit `n` (Duff et al. 2017, "Building an Orthonormal
// Basis, Revisited", listing 3): continuous except at n.z = 0 with n.z's sign.
fn tangent_basis(n: vec3<f32>) -> mat2x3<f32> {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    return mat2x3<f32>(
        vec3<f32>(1.0 + s * n.x * n.x * a, s * b, -s * n.x),
        vec3<f32>(b, s + n.y * n.y * a, -n.y),
    );
}
