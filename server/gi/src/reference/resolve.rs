//! The reference's frame output (`shaders/reference/resolve.wgsl`): the accumulated sums
//! divided by the sample count into the indirect buffer, and the convergence sums of
//! [`ProgressSums`] reduced over the image on the GPU, so the renderer reads them back with
//! the frame instead of waiting.

use crate::gi::ProgressSums;
use crate::passes::bind::{self, bind_group};
use crate::passes::{self, gbuffer::GBuffer, Target, INDIRECT_FORMAT, TILE};
use bytemuck::{Pod, Zeroable};

/// Mirrors `ResolveParams` in `shaders/reference/resolve.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ResolveParams {
    pub width: u32,
    pub height: u32,
    pub samples: u32,
    pub partial_count: u32,
}

bind_group! {
    /// Group 0 of `shaders/reference/resolve.wgsl`.
    pub struct Resources as GROUP("reference resolve", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        accum: bind::STORAGE,
        g_position: bind::TEXTURE,
        indirect_out: bind::storage_texture(INDIRECT_FORMAT),
        partials: bind::STORAGE_RW,
        progress: bind::STORAGE_RW,
    }
}

pub struct ResolvePass {
    layout: wgpu::BindGroupLayout,
    resolve: wgpu::ComputePipeline,
    reduce: wgpu::ComputePipeline,
    params: wgpu::Buffer,
    /// Per-workgroup sums; grown to the largest image resolved.
    partials: wgpu::Buffer,
    /// One [`ProgressSums`], copied into the frame's readback.
    pub progress: wgpu::Buffer,
}

fn partials_buffer(device: &wgpu::Device, groups: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("reference partial sums"),
        size: groups.max(1) * 8,
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    })
}

impl ResolvePass {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = GROUP.layout(device);
        let module = super::shaders::REFERENCE_RESOLVE.create_module(device);
        Self {
            resolve: passes::compute_pipeline(
                device,
                "reference resolve",
                &layout,
                &module,
                "resolve",
            ),
            reduce: passes::compute_pipeline(
                device,
                "reference reduce",
                &layout,
                &module,
                "reduce",
            ),
            layout,
            params: passes::params_buffer(
                device,
                "reference resolve params",
                std::mem::size_of::<ResolveParams>(),
            ),
            partials: partials_buffer(device, 0),
            progress: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("reference progress"),
                size: std::mem::size_of::<ProgressSums>() as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
        }
    }

    /// Writes the parameters and binds this frame's buffers.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        accum: &wgpu::Buffer,
        samples: u32,
        gbuffer: &GBuffer,
        indirect: &Target,
    ) -> wgpu::BindGroup {
        let size = indirect.texture.size();
        let groups = size.width.div_ceil(TILE) * size.height.div_ceil(TILE);
        if self.partials.size() < u64::from(groups) * 8 {
            self.partials = partials_buffer(device, groups.into());
        }
        let params = ResolveParams {
            width: size.width,
            height: size.height,
            samples,
            partial_count: groups,
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        Resources {
            params: &self.params,
            accum,
            g_position: &gbuffer.position,
            indirect_out: indirect,
            partials: &self.partials,
            progress: &self.progress,
        }
        .bind(device, &self.layout)
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        group: &wgpu::BindGroup,
        width: u32,
        height: u32,
    ) {
        let mut pass = passes::begin_compute(encoder, "reference resolve");
        pass.set_bind_group(0, group, &[]);
        pass.set_pipeline(&self.resolve);
        pass.dispatch_workgroups(width.div_ceil(TILE), height.div_ceil(TILE), 1);
        pass.set_pipeline(&self.reduce);
        pass.dispatch_workgroups(1, 1, 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::reference::shaders::REFERENCE_RESOLVE;
    use crate::gpu::shaders::layout_check::assert_struct;
    use std::mem::{offset_of, size_of};

    #[test]
    fn resolve_structs_match_wgsl() {
        assert_struct(
            &REFERENCE_RESOLVE,
            "ResolveParams",
            size_of::<ResolveParams>(),
            &[
                ("width", offset_of!(ResolveParams, width)),
                ("height", offset_of!(ResolveParams, height)),
                ("samples", offset_of!(ResolveParams, samples)),
                ("partial_count", offset_of!(ResolveParams, partial_count)),
            ],
        );
        assert_struct(
            &REFERENCE_RESOLVE,
            "ProgressSums",
            size_of::<ProgressSums>(),
            &[
                (
                    "variance_of_mean",
                    offset_of!(ProgressSums, variance_of_mean),
                ),
                ("luminance", offset_of!(ProgressSums, luminance)),
                ("pixels", offset_of!(ProgressSums, pixels)),
                ("pad0", offset_of!(ProgressSums, pad0)),
            ],
        );
    }
}
