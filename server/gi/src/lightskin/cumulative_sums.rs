//! Cumulative sums of the importance map (`shaders/cumulative_sums.wgsl`): down each column,
//! then across the column totals.

use crate::passes::bind::{self, bind_group};
use bytemuck::{Pod, Zeroable};

/// Mirrors `ScanParams` in `shaders/cumulative_sums.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ScanParams {
    pub width: u32,
    pub height: u32,
    pub pad0: u32,
    pub pad1: u32,
}

bind_group! {
    /// Group 0 of `shaders/lightskin/cumulative_sums.wgsl`.
    pub struct Resources as GROUP("cumulative sums", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        importance: bind::STORAGE,
        column_sums: bind::STORAGE_RW,
        row_sums: bind::STORAGE_RW,
    }
}

pub struct CumulativeSumsPass {
    columns: wgpu::ComputePipeline,
    rows: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
}

impl CumulativeSumsPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = GROUP.layout(device);
        let module = super::shaders::CUMULATIVE_SUMS.create_module(device);
        Self {
            columns: crate::passes::compute_pipeline(
                device,
                "scan columns",
                &layout,
                &module,
                "scan_columns",
            ),
            rows: crate::passes::compute_pipeline(
                device,
                "scan rows",
                &layout,
                &module,
                "scan_rows",
            ),
            layout,
            params: crate::passes::params_buffer(
                device,
                "scan params",
                std::mem::size_of::<ScanParams>(),
            ),
        }
    }

    pub fn bind(
        &self,
        device: &wgpu::Device,
        importance: &wgpu::Buffer,
        column_sums: &wgpu::Buffer,
        row_sums: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        Resources {
            params: &self.params,
            importance,
            column_sums,
            row_sums,
        }
        .bind(device, &self.layout)
    }

    pub fn prepare(&self, queue: &wgpu::Queue, width: u32, height: u32) {
        let params = ScanParams {
            width,
            height,
            pad0: 0,
            pad1: 0,
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        width: u32,
    ) {
        let mut pass = crate::passes::begin_compute(encoder, "cumulative sums");
        pass.set_bind_group(0, bind_group, &[]);
        pass.set_pipeline(&self.columns);
        pass.dispatch_workgroups(width, 1, 1);
        pass.set_pipeline(&self.rows);
        pass.dispatch_workgroups(1, 1, 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::lightskin::shaders::CUMULATIVE_SUMS;
    use crate::gpu::shaders::layout_check::assert_struct;
    use std::mem::{offset_of, size_of};

    #[test]
    fn scan_params_match_wgsl() {
        assert_struct(
            &CUMULATIVE_SUMS,
            "ScanParams",
            size_of::<ScanParams>(),
            &[
                ("width", offset_of!(ScanParams, width)),
                ("height", offset_of!(ScanParams, height)),
                ("pad0", offset_of!(ScanParams, pad0)),
                ("pad1", offset_of!(ScanParams, pad1)),
            ],
        );
    }
}
