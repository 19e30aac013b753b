//! The WGSL modules of the shared BVH (`shaders/`), each the concatenation of its files.

use crate::gpu::shaders::{wgsl, ShaderSource};
use crate::passes::ShaderPass;

/// Nearest hits of a list of rays, to test the BVH traversal against the CPU.
pub const BVH_TEST: ShaderSource = ShaderSource {
    name: "bvh_test",
    files: &[wgsl!("bvh.wgsl"), wgsl!("bvh_test.wgsl")],
};

/// The shared modules; the BVH test's pipeline (an integration-test harness) takes its layout
/// from the WGSL.
pub const PASSES: &[ShaderPass] = &[ShaderPass {
    source: &BVH_TEST,
    groups: None,
}];
