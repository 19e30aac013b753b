//! What several GI methods use and none owns: the scene's BVH (the reference's path tracing,
//! the surfels' link rays), the Halton sequence and the triangle helpers of the
//! precomputations. Shared GPU passes live in `passes/`.

pub mod bvh;
pub mod halton;
pub mod limits;
pub mod params;
pub mod shaders;
pub mod triangles;
pub mod views;
