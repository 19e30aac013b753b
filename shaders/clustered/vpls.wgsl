// Virtual point lights and the virtual area lights they are clustered into (seed paper 003,
// §4–6), shared by the clustering, shading and blur passes.

// Mirrored by `ClusteredParams` in server/src/gi/clustered/passes.rs.
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
    pad0: u32,
}

// Mirrored by `Vpl` in server/src/gi/clustered/passes.rs.
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

// Mirrored by `Val` in server/src/gi/clustered/passes.rs. During k-means it holds a cluster
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
