//! What several GI methods use and none owns: the scene's BVH (path tracing, visibility rays
//! of precomputations), the Halton sequence, the triangle helpers of the precomputations, the
//! light of a virtual point light, the facts about a scene precomputations read, the shared parameters, limits and shader modules, and the
//! debug views' drawing kit. Shared GPU
//! passes live in `passes/`.

pub mod bvh;
pub mod halton;
pub mod kdtree;
pub mod limits;
pub mod params;
pub mod scene_facts;
pub mod shaders;
pub mod triangles;
pub mod views;
pub mod vpl;
