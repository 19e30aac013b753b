//! The gather pass's parameters and bindings (`shaders/rsm_gather/gather.wgsl`).

use crate::passes::bind::{self, bind_group};
use bytemuck::{Pod, Zeroable};

/// Mirrors `GatherParams` in `shaders/rsm_gather/gather.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GatherParams {
    pub width: u32,
    pub height: u32,
    pub rsm_size: u32,
    pub faces: u32,
    pub sample_count: u32,
    /// r_max in texels.
    pub radius: f32,
    pub probe_x: u32,
    pub probe_y: u32,
}

/// One face of the atlas as the gather reads it (mirrors `GatherFace` in
/// `shaders/rsm_gather/gather.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GatherFace {
    pub view_proj: [[f32; 4]; 4],
    /// The face's light: a light's faces follow each other in the atlas.
    pub light: u32,
    /// The emitter face's samples (`passes::rsm::emitter_samples`), in its first texels; 0 on
    /// a light's face.
    pub emitter_samples: u32,
    pub pad1: u32,
    pub pad2: u32,
}

bind_group! {
    /// Group 0 of `shaders/rsm_gather/gather.wgsl`.
    pub struct GatherResources as GATHER_GROUP("rsm gather", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        camera: bind::PARAMS,
        g_position: bind::TEXTURE,
        g_normal_roughness: bind::TEXTURE,
        g_base_metallic: bind::TEXTURE,
        g_emissive_specular: bind::TEXTURE,
        rsm_position: bind::TEXTURE,
        rsm_normal: bind::TEXTURE,
        rsm_flux_area: bind::TEXTURE,
        faces: bind::STORAGE,
        samples: bind::STORAGE,
        probe: bind::STORAGE_RW,
        indirect_out: bind::storage_texture(crate::passes::INDIRECT_FORMAT),
        brdf_table: bind::STORAGE,
        rsm_glossy: bind::UINT_TEXTURE,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::rsm_gather::pattern::GatherSample;
    use crate::gi::rsm_gather::shaders::GATHER;
    use crate::gpu::shaders::layout_check::assert_struct;
    use std::mem::{offset_of, size_of};

    #[test]
    fn gather_structs_match_wgsl() {
        assert_struct(
            &GATHER,
            "GatherParams",
            size_of::<GatherParams>(),
            &[
                ("width", offset_of!(GatherParams, width)),
                ("height", offset_of!(GatherParams, height)),
                ("rsm_size", offset_of!(GatherParams, rsm_size)),
                ("faces", offset_of!(GatherParams, faces)),
                ("sample_count", offset_of!(GatherParams, sample_count)),
                ("radius", offset_of!(GatherParams, radius)),
                ("probe_x", offset_of!(GatherParams, probe_x)),
                ("probe_y", offset_of!(GatherParams, probe_y)),
            ],
        );
        assert_struct(
            &GATHER,
            "GatherFace",
            size_of::<GatherFace>(),
            &[
                ("view_proj", offset_of!(GatherFace, view_proj)),
                ("light", offset_of!(GatherFace, light)),
                ("emitter_samples", offset_of!(GatherFace, emitter_samples)),
                ("pad1", offset_of!(GatherFace, pad1)),
                ("pad2", offset_of!(GatherFace, pad2)),
            ],
        );
        assert_struct(
            &GATHER,
            "GatherSample",
            size_of::<GatherSample>(),
            &[
                ("offset", offset_of!(GatherSample, offset)),
                ("weight", offset_of!(GatherSample, weight)),
                ("pad0", offset_of!(GatherSample, pad0)),
            ],
        );
    }
}
