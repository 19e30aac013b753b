//! VAL importance (`shaders/importance.wgsl`, eq. 10–11): view samples gathered from the
//! G-buffer at Halton positions, then one importance value per RSM texel.

use crate::passes::bind::{self, bind_group};
use crate::passes::{gbuffer::GBuffer, rsm::Rsm};
use bytemuck::{Pod, Zeroable};

/// Mirrors `ViewSample` in `shaders/view_samples.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ViewSample {
    pub position: [f32; 3],
    pub valid: f32,
    pub normal: [f32; 3],
    pub pad0: f32,
}

/// Mirrors `ImportanceParams` in `shaders/importance.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ImportanceParams {
    pub rsm_width: u32,
    pub rsm_height: u32,
    pub sample_count: u32,
    pub uniform_importance: u32,
    pub first_row: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

bind_group! {
    /// Group 0 of `shaders/lightskin/importance.wgsl`.
    pub struct Resources as GROUP("importance", wgpu::ShaderStages::COMPUTE) {
        params: bind::param_slot::<ImportanceParams>(),
        g_position: bind::TEXTURE,
        g_normal_roughness: bind::TEXTURE,
        samples: bind::STORAGE_RW,
        rsm_position: bind::TEXTURE,
        rsm_normal: bind::TEXTURE,
        rsm_flux_area: bind::TEXTURE,
        importance: bind::STORAGE_RW,
        rsm_glossy: bind::UINT_TEXTURE,
    }
}

pub struct ImportancePass {
    gather: wgpu::ComputePipeline,
    estimate: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: crate::passes::ParamSlots,
}

impl ImportancePass {
    pub fn new(device: &wgpu::Device) -> Self {
        let params = crate::passes::ParamSlots::new::<ImportanceParams>(
            device,
            "importance params",
            crate::passes::MAX_CHUNKS,
        );
        let layout = GROUP.layout(device);
        let module = super::shaders::IMPORTANCE.create_module(device);
        Self {
            gather: crate::passes::compute_pipeline(
                device,
                "view samples",
                &layout,
                &module,
                "gather_view_samples",
            ),
            estimate: crate::passes::compute_pipeline(
                device,
                "importance",
                &layout,
                &module,
                "estimate_importance",
            ),
            layout,
            params,
        }
    }

    pub fn bind(
        &self,
        device: &wgpu::Device,
        gbuffer: &GBuffer,
        rsm: &Rsm,
        samples: &wgpu::Buffer,
        importance: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        Resources {
            params: &self.params,
            g_position: &gbuffer.position,
            g_normal_roughness: &gbuffer.normal_roughness,
            samples,
            rsm_position: &rsm.position,
            rsm_normal: &rsm.normal,
            rsm_flux_area: &rsm.flux_area,
            importance,
            rsm_glossy: &rsm.glossy,
        }
        .bind(device, &self.layout)
    }

    /// Writes one parameter slot per band of RSM rows; returns the bands.
    pub fn prepare(
        &self,
        queue: &wgpu::Queue,
        params: &ImportanceParams,
    ) -> Vec<std::ops::Range<u32>> {
        let bands = crate::passes::chunk_ranges(
            params.rsm_height,
            u64::from(params.rsm_width) * u64::from(params.sample_count.max(1)),
            crate::passes::TILE,
        );
        let slots: Vec<ImportanceParams> = bands
            .iter()
            .map(|rows| ImportanceParams {
                first_row: rows.start,
                ..*params
            })
            .collect();
        self.params.write(queue, &slots);
        bands
    }

    /// Gathers the view samples from the G-buffer into the bind group's `samples`.
    pub fn encode_gather(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        sample_count: u32,
    ) {
        let mut pass = crate::passes::begin_compute(encoder, "view samples");
        pass.set_bind_group(0, bind_group, &[crate::passes::ParamSlots::offset(0)]);
        pass.set_pipeline(&self.gather);
        pass.dispatch_workgroups(sample_count.div_ceil(64), 1, 1);
    }

    /// Estimates importance from the bind group's `samples`, band by band.
    pub fn encode_estimate(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        params: &ImportanceParams,
        bands: &[std::ops::Range<u32>],
    ) {
        let mut pass = crate::passes::begin_compute(encoder, "importance");
        pass.set_pipeline(&self.estimate);
        for (b, rows) in bands.iter().enumerate() {
            pass.set_bind_group(
                0,
                bind_group,
                &[crate::passes::ParamSlots::offset(b as u32)],
            );
            pass.dispatch_workgroups(
                params.rsm_width.div_ceil(crate::passes::TILE),
                rows.len().div_ceil(crate::passes::TILE as usize) as u32,
                1,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::lightskin::shaders::IMPORTANCE;
    use crate::gpu::shaders::layout_check::assert_struct;
    use std::mem::{offset_of, size_of};

    #[test]
    fn importance_structs_match_wgsl() {
        assert_struct(
            &IMPORTANCE,
            "ViewSample",
            size_of::<ViewSample>(),
            &[
                ("position", offset_of!(ViewSample, position)),
                ("valid", offset_of!(ViewSample, valid)),
                ("normal", offset_of!(ViewSample, normal)),
                ("pad0", offset_of!(ViewSample, pad0)),
            ],
        );
        assert_struct(
            &IMPORTANCE,
            "ImportanceParams",
            size_of::<ImportanceParams>(),
            &[
                ("rsm_width", offset_of!(ImportanceParams, rsm_width)),
                ("rsm_height", offset_of!(ImportanceParams, rsm_height)),
                ("sample_count", offset_of!(ImportanceParams, sample_count)),
                (
                    "uniform_importance",
                    offset_of!(ImportanceParams, uniform_importance),
                ),
                ("first_row", offset_of!(ImportanceParams, first_row)),
                ("pad0", offset_of!(ImportanceParams, pad0)),
                ("pad1", offset_of!(ImportanceParams, pad1)),
                ("pad2", offset_of!(ImportanceParams, pad2)),
            ],
        );
    }
}
