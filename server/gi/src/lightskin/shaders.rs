//! The WGSL modules of LightSkin and BRSM (`shaders/`), each the concatenation of its files.

use crate::gpu::shaders::{wgsl, ShaderSource};

pub const IMPORTANCE: ShaderSource = ShaderSource {
    name: "importance",
    files: &[
        wgsl!("halton.wgsl"),
        wgsl!("lightskin/view_samples.wgsl"),
        wgsl!("octahedral.wgsl"),
        wgsl!("rsm_glossy.wgsl"),
        wgsl!("lightskin/importance.wgsl"),
    ],
};

pub const CUMULATIVE_SUMS: ShaderSource = ShaderSource {
    name: "cumulative_sums",
    files: &[wgsl!("lightskin/cumulative_sums.wgsl")],
};

pub const VAL_SELECT: ShaderSource = ShaderSource {
    name: "val_select",
    files: &[
        wgsl!("octahedral.wgsl"),
        wgsl!("rsm_glossy.wgsl"),
        wgsl!("lightskin/vals.wgsl"),
        wgsl!("lightskin/val_select.wgsl"),
    ],
};

pub const CACHE_LIGHTING: ShaderSource = ShaderSource {
    name: "cache_lighting",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("octahedral.wgsl"),
        wgsl!("rsm_glossy.wgsl"),
        wgsl!("lightskin/vals.wgsl"),
        wgsl!("lightskin/light_caches.wgsl"),
        wgsl!("lightskin/cache_lighting.wgsl"),
    ],
};

pub const INDIRECT_LIGHT: ShaderSource = ShaderSource {
    name: "indirect_light",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("brdf.wgsl"),
        wgsl!("brdf_eval.wgsl"),
        wgsl!("gbuffer_surface.wgsl"),
        wgsl!("lightskin/light_caches.wgsl"),
        wgsl!("lightskin/indirect_light.wgsl"),
    ],
};

pub const PROXY_OCCLUSION: ShaderSource = ShaderSource {
    name: "proxy_occlusion",
    files: &[
        wgsl!("common.wgsl"),
        wgsl!("lightskin/light_caches.wgsl"),
        wgsl!("lightskin/proxy_occlusion.wgsl"),
    ],
};
