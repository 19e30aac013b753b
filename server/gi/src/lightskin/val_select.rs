//! VAL selection (`shaders/val_select.wgsl`): N_sVAL stratified draws from the importance
//! distribution by binary search on the cumulative sums, each with its Monte Carlo weight.

use crate::passes::bind::{self, bind_group};
use crate::passes::rsm::{GlossySender, Rsm};
use bytemuck::{Pod, Zeroable};

/// Mirrors `SelectParams` in `shaders/val_select.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct SelectParams {
    pub width: u32,
    pub height: u32,
    pub count: u32,
    pub row_pitch: u32,
    pub jitter: f32,
    pub defensive: f32,
    pub pad0: f32,
    pub pad1: f32,
}

/// Mirrors `Val` in `shaders/vals.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Val {
    pub position: [f32; 3],
    pub area: f32,
    pub normal: [f32; 3],
    pub weight: f32,
    pub flux: [f32; 3],
    pub texel: u32,
    /// The texel's glossy lobe.
    pub glossy: GlossySender,
}

const WORKGROUP: u32 = 64;
/// Workgroups per dispatch row (wgpu's per-dimension limit).
const MAX_GROUPS_X: u32 = 65_535;

bind_group! {
    /// Group 0 of `shaders/lightskin/val_select.wgsl`.
    pub struct Resources as GROUP("val select", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        importance_map: bind::STORAGE,
        column_sums: bind::STORAGE,
        row_sums: bind::STORAGE,
        rsm_position: bind::TEXTURE,
        rsm_normal: bind::TEXTURE,
        rsm_flux_area: bind::TEXTURE,
        vals: bind::STORAGE_RW,
        rsm_glossy: bind::UINT_TEXTURE,
    }
}

pub struct ValSelectPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
}

/// The buffers VAL selection reads and writes.
pub struct SelectionBuffers<'a> {
    pub importance: &'a wgpu::Buffer,
    pub column_sums: &'a wgpu::Buffer,
    pub row_sums: &'a wgpu::Buffer,
    pub vals: &'a wgpu::Buffer,
}

impl ValSelectPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = GROUP.layout(device);
        let module = super::shaders::VAL_SELECT.create_module(device);
        Self {
            pipeline: crate::passes::compute_pipeline(
                device,
                "val select",
                &layout,
                &module,
                "select_vals",
            ),
            layout,
            params: crate::passes::params_buffer(
                device,
                "val select params",
                std::mem::size_of::<SelectParams>(),
            ),
        }
    }

    pub fn bind(
        &self,
        device: &wgpu::Device,
        rsm: &Rsm,
        buffers: &SelectionBuffers,
    ) -> wgpu::BindGroup {
        Resources {
            params: &self.params,
            importance_map: buffers.importance,
            column_sums: buffers.column_sums,
            row_sums: buffers.row_sums,
            rsm_position: &rsm.position,
            rsm_normal: &rsm.normal,
            rsm_flux_area: &rsm.flux_area,
            vals: buffers.vals,
            rsm_glossy: &rsm.glossy,
        }
        .bind(device, &self.layout)
    }

    /// Dispatch grid for `count` VALs: (groups per row, rows).
    fn grid(count: u32) -> (u32, u32) {
        let groups = count.div_ceil(WORKGROUP).max(1);
        let x = groups.min(MAX_GROUPS_X);
        (x, groups.div_ceil(x))
    }

    /// `defensive` is the weight α of the uniform part of the selection pdf.
    pub fn prepare(&self, queue: &wgpu::Queue, rsm: &Rsm, count: u32, jitter: f32, defensive: f32) {
        let params = SelectParams {
            width: rsm.width(),
            height: rsm.height(),
            count,
            row_pitch: Self::grid(count).0 * WORKGROUP,
            jitter,
            defensive,
            pad0: 0.0,
            pad1: 0.0,
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        count: u32,
    ) {
        let (x, y) = Self::grid(count);
        let mut pass = crate::passes::begin_compute(encoder, "val select");
        pass.set_bind_group(0, bind_group, &[]);
        pass.set_pipeline(&self.pipeline);
        pass.dispatch_workgroups(x, y, 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::lightskin::shaders::VAL_SELECT;
    use crate::gpu::shaders::layout_check::assert_struct;
    use std::mem::{offset_of, size_of};

    #[test]
    fn select_structs_match_wgsl() {
        assert_struct(
            &VAL_SELECT,
            "SelectParams",
            size_of::<SelectParams>(),
            &[
                ("width", offset_of!(SelectParams, width)),
                ("height", offset_of!(SelectParams, height)),
                ("count", offset_of!(SelectParams, count)),
                ("row_pitch", offset_of!(SelectParams, row_pitch)),
                ("jitter", offset_of!(SelectParams, jitter)),
                ("defensive", offset_of!(SelectParams, defensive)),
                ("pad0", offset_of!(SelectParams, pad0)),
                ("pad1", offset_of!(SelectParams, pad1)),
            ],
        );
        assert_struct(
            &VAL_SELECT,
            "Val",
            size_of::<Val>(),
            &[
                ("position", offset_of!(Val, position)),
                ("area", offset_of!(Val, area)),
                ("normal", offset_of!(Val, normal)),
                ("weight", offset_of!(Val, weight)),
                ("flux", offset_of!(Val, flux)),
                ("texel", offset_of!(Val, texel)),
                ("glossy", offset_of!(Val, glossy)),
            ],
        );
    }

    #[test]
    fn large_counts_use_a_two_dimensional_grid() {
        assert_eq!(ValSelectPass::grid(1), (1, 1));
        assert_eq!(ValSelectPass::grid(8192), (128, 1));
        let (x, y) = ValSelectPass::grid(16_777_216);
        assert!(x <= MAX_GROUPS_X && u64::from(x) * u64::from(y) * 64 >= 16_777_216);
    }
}
