//! The WGSL test harnesses of shared code (`shaders/`), each the concatenation of its files.

use crate::gpu::shaders::{wgsl, ShaderSource};
use crate::passes::ShaderPass;

/// Nearest hits of a list of rays, to test the BVH traversal against the CPU.
pub const BVH_TEST: ShaderSource = ShaderSource {
    name: "bvh_test",
    files: &[wgsl!("bvh.wgsl"), wgsl!("bvh_test.wgsl")],
};

/// The BRDF and its fitted lobes for a list of cases, to test them against `scene::brdf`.
pub const BRDF_TEST: ShaderSource = ShaderSource {
    name: "brdf_test",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("brdf_eval.wgsl"),
        wgsl!("brdf_test.wgsl"),
    ],
};

/// The harnesses (integration tests) take their pipelines' layouts from the WGSL.
pub const PASSES: &[ShaderPass] = &[
    ShaderPass {
        source: &BVH_TEST,
        groups: None,
    },
    ShaderPass {
        source: &BRDF_TEST,
        groups: None,
    },
];
