//! The GPU passes of `clustered` (`shaders/clustered/`): VPL generation and k-means
//! clustering ([`ClusteringPass`]), interleaved shading and the geometry-aware blur (two
//! [`ImagePass`]es), with the buffers between them ([`ClusterBuffers`]).

use crate::gpu::shaders::{self, ShaderSource};
use crate::passes::bind::{self, bind_group, BindGroupDesc};
use crate::passes::{self, rsm::Rsm, Target, INDIRECT_FORMAT};
use bytemuck::{Pod, Zeroable};

/// Format of the interleaved shading before the blur: values are B² times a pixel's share
/// of the light, beyond f16's range for bright lights.
pub const INTERLEAVED_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
/// Threads of the 1D dispatches (VPLs, clusters), and of each cluster's reduction.
const GROUP: u32 = 64;

/// Mirrors `ClusteredParams` in `shaders/clustered/vpls.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ClusteredParams {
    pub rsm_width: u32,
    pub rsm_height: u32,
    pub vpl_count: u32,
    pub cluster_count: u32,
    /// w_x over the scene's extent.
    pub position_weight: f32,
    pub normal_weight: f32,
    pub interleave: u32,
    pub width: u32,
    pub height: u32,
    /// In scene units.
    pub blur_distance: f32,
    pub blur_normal: f32,
    pub pad0: u32,
}

/// Mirrors `Vpl` in `shaders/clustered/vpls.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Vpl {
    pub position: [f32; 3],
    /// Disk area of the RSM texels the VPL stands for.
    pub area: f32,
    pub normal: [f32; 3],
    /// 1 where the texel reflects light, 0: no VPL.
    pub lit: u32,
    /// Φ_i, the flux of the RSM texels the VPL stands for.
    pub flux: [f32; 3],
    /// Row-major RSM texel it was fetched from.
    pub texel: u32,
}

/// Mirrors `Val` in `shaders/clustered/vpls.wgsl`: a cluster centre during k-means, the
/// virtual area light after it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Val {
    pub position: [f32; 3],
    /// Bounding rectangle of its VPLs in the plane of its normal (§6).
    pub area: f32,
    pub normal: [f32; 3],
    /// VPLs mapped to it.
    pub count: u32,
    /// 1 once seeded (§5.2).
    pub centred: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// C(i) of a VPL without light.
pub const NO_VAL: u32 = u32::MAX;

bind_group! {
    /// Group 0 of the clustering module (`shaders/clustered/kmeans.wgsl`).
    pub struct ClusteringResources as CLUSTERING_GROUP("clustering", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        rsm_position: bind::TEXTURE,
        rsm_normal: bind::TEXTURE,
        rsm_flux_area: bind::TEXTURE,
        vpls: bind::STORAGE_RW,
        vals: bind::STORAGE_RW,
        mapping: bind::STORAGE_RW,
    }
}

bind_group! {
    /// Group 0 of `shaders/clustered/indirect.wgsl`.
    pub struct IndirectResources as INDIRECT_GROUP(
        "clustered indirect",
        wgpu::ShaderStages::COMPUTE
    ) {
        params: bind::PARAMS,
        camera: bind::PARAMS,
        g_position: bind::TEXTURE,
        g_normal_exponent: bind::TEXTURE,
        g_diffuse: bind::TEXTURE,
        g_glossy: bind::TEXTURE,
        vpls: bind::STORAGE,
        interleaved_out: bind::storage_texture(INTERLEAVED_FORMAT),
    }
}

bind_group! {
    /// Group 0 of `shaders/clustered/blur.wgsl`.
    pub struct BlurResources as BLUR_GROUP("geometry blur", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        g_position: bind::TEXTURE,
        g_normal_exponent: bind::TEXTURE,
        interleaved: bind::TEXTURE,
        indirect_out: bind::storage_texture(INDIRECT_FORMAT),
    }
}

/// The VPLs, the clusters and the mapping C of one (N, M).
pub struct ClusterBuffers {
    pub vpl_count: u32,
    pub cluster_count: u32,
    pub vpls: wgpu::Buffer,
    pub vals: wgpu::Buffer,
    pub mapping: wgpu::Buffer,
}

fn storage(device: &wgpu::Device, label: &str, bytes: usize) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

impl ClusterBuffers {
    /// `vpl_count` and `cluster_count` are the validated N and M (see `validate`), so the
    /// buffers stay within a few MiB.
    pub fn new(device: &wgpu::Device, vpl_count: u32, cluster_count: u32) -> Self {
        let (n, m) = (vpl_count as usize, cluster_count as usize);
        Self {
            vpl_count,
            cluster_count,
            vpls: storage(device, "clustered vpls", n * size_of::<Vpl>()),
            vals: storage(device, "clustered vals", m * size_of::<Val>()),
            mapping: storage(device, "clustered mapping", n * size_of::<u32>()),
        }
    }
}

/// VPL generation, seeding, k-means iterations, the final mapping and the VALs.
pub struct ClusteringPass {
    layout: wgpu::BindGroupLayout,
    generate: wgpu::ComputePipeline,
    seed: wgpu::ComputePipeline,
    assign: wgpu::ComputePipeline,
    update: wgpu::ComputePipeline,
    finalize: wgpu::ComputePipeline,
}

impl ClusteringPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = CLUSTERING_GROUP.layout(device);
        let module = shaders::CLUSTERING.create_module(device);
        let pipeline =
            |entry: &str| passes::compute_pipeline(device, entry, &layout, &module, entry);
        Self {
            generate: pipeline("generate_vpls"),
            seed: pipeline("seed_clusters"),
            assign: pipeline("assign"),
            update: pipeline("update"),
            finalize: pipeline("finalize"),
            layout,
        }
    }

    pub fn bind(
        &self,
        device: &wgpu::Device,
        params: &wgpu::Buffer,
        rsm: &Rsm,
        buffers: &ClusterBuffers,
    ) -> wgpu::BindGroup {
        ClusteringResources {
            params,
            rsm_position: &rsm.position,
            rsm_normal: &rsm.normal,
            rsm_flux_area: &rsm.flux_area,
            vpls: &buffers.vpls,
            vals: &buffers.vals,
            mapping: &buffers.mapping,
        }
        .bind(device, &self.layout)
    }

    /// §6 "VPL Generation".
    pub fn encode_vpls(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        group: &wgpu::BindGroup,
        vpl_count: u32,
    ) {
        let mut pass = passes::begin_compute(encoder, "vpl generation");
        pass.set_bind_group(0, group, &[]);
        pass.set_pipeline(&self.generate);
        pass.dispatch_workgroups(vpl_count.div_ceil(GROUP), 1, 1);
    }

    /// §5 and §6 "Clustering": seeds, `iterations` × (assign, update), the final mapping C
    /// and the VALs with their areas.
    pub fn encode_clustering(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        group: &wgpu::BindGroup,
        buffers: &ClusterBuffers,
        iterations: u32,
    ) {
        let vpl_groups = buffers.vpl_count.div_ceil(GROUP);
        let mut pass = passes::begin_compute(encoder, "clustering");
        pass.set_bind_group(0, group, &[]);
        pass.set_pipeline(&self.seed);
        pass.dispatch_workgroups(buffers.cluster_count.div_ceil(GROUP), 1, 1);
        for _ in 0..iterations {
            pass.set_pipeline(&self.assign);
            pass.dispatch_workgroups(vpl_groups, 1, 1);
            pass.set_pipeline(&self.update);
            pass.dispatch_workgroups(buffers.cluster_count, 1, 1);
        }
        pass.set_pipeline(&self.assign);
        pass.dispatch_workgroups(vpl_groups, 1, 1);
        pass.set_pipeline(&self.finalize);
        pass.dispatch_workgroups(buffers.cluster_count, 1, 1);
    }
}

/// A compute pass with one thread per pixel and one bind group: the interleaved shading
/// ([`INDIRECT_GROUP`], `shade`) and the geometry-aware blur ([`BLUR_GROUP`], `blur`).
pub struct ImagePass {
    label: &'static str,
    pub layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl ImagePass {
    pub fn new(
        device: &wgpu::Device,
        group: &BindGroupDesc,
        source: &ShaderSource,
        entry: &str,
    ) -> Self {
        let layout = group.layout(device);
        let module = source.create_module(device);
        Self {
            label: group.label,
            pipeline: passes::compute_pipeline(device, group.label, &layout, &module, entry),
            layout,
        }
    }

    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        group: &wgpu::BindGroup,
        width: u32,
        height: u32,
    ) {
        passes::dispatch_2d(encoder, self.label, &self.pipeline, group, width, height);
    }
}

/// The interleaved-shading texture of one output size.
pub fn interleaved_target(device: &wgpu::Device, width: u32, height: u32) -> Target {
    Target::new(
        device,
        "clustered interleaved",
        width,
        height,
        INTERLEAVED_FORMAT,
        wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shaders::{layout_check::assert_struct, CLUSTERING};
    use std::mem::{offset_of, size_of};

    #[test]
    fn clustered_structs_match_wgsl() {
        assert_struct(
            &CLUSTERING,
            "ClusteredParams",
            size_of::<ClusteredParams>(),
            &[
                ("rsm_width", offset_of!(ClusteredParams, rsm_width)),
                ("rsm_height", offset_of!(ClusteredParams, rsm_height)),
                ("vpl_count", offset_of!(ClusteredParams, vpl_count)),
                ("cluster_count", offset_of!(ClusteredParams, cluster_count)),
                (
                    "position_weight",
                    offset_of!(ClusteredParams, position_weight),
                ),
                ("normal_weight", offset_of!(ClusteredParams, normal_weight)),
                ("interleave", offset_of!(ClusteredParams, interleave)),
                ("width", offset_of!(ClusteredParams, width)),
                ("height", offset_of!(ClusteredParams, height)),
                ("blur_distance", offset_of!(ClusteredParams, blur_distance)),
                ("blur_normal", offset_of!(ClusteredParams, blur_normal)),
                ("pad0", offset_of!(ClusteredParams, pad0)),
            ],
        );
        assert_struct(
            &CLUSTERING,
            "Vpl",
            size_of::<Vpl>(),
            &[
                ("position", offset_of!(Vpl, position)),
                ("area", offset_of!(Vpl, area)),
                ("normal", offset_of!(Vpl, normal)),
                ("lit", offset_of!(Vpl, lit)),
                ("flux", offset_of!(Vpl, flux)),
                ("texel", offset_of!(Vpl, texel)),
            ],
        );
        assert_struct(
            &CLUSTERING,
            "Val",
            size_of::<Val>(),
            &[
                ("position", offset_of!(Val, position)),
                ("area", offset_of!(Val, area)),
                ("normal", offset_of!(Val, normal)),
                ("count", offset_of!(Val, count)),
                ("centred", offset_of!(Val, centred)),
                ("pad0", offset_of!(Val, pad0)),
                ("pad1", offset_of!(Val, pad1)),
                ("pad2", offset_of!(Val, pad2)),
            ],
        );
    }
}
