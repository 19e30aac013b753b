//! The GPU passes of `clustered` (`shaders/clustered/`): VPL generation and k-means
//! clustering ([`ClusteringPass`]), the paraboloid depth maps and their convolution soft
//! shadow basis ([`VisibilityPass`] into [`VisibilityTargets`]), interleaved shading and the
//! geometry-aware blur (two [`ImagePass`]es), with the buffers between them
//! ([`ClusterBuffers`]).

use super::Visibility;
use crate::gpu::shaders::ShaderSource;
use crate::passes::bind::BindKind;
use crate::passes::bind::{self, bind_group, BindGroupDesc};
use crate::passes::rsm::{GlossySender, Rsm};
use crate::passes::scene_buffers::SceneBuffers;
use crate::passes::{self, Target, INDIRECT_FORMAT};
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
    /// [`visibility_code`] of the frame's mode.
    pub visibility: u32,
    pub map_size: u32,
    pub atlas_columns: u32,
    pub atlas_rows: u32,
    pub fourier_terms: u32,
    /// The scene's extent: depths in the maps are distances over it.
    pub extent: f32,
    /// The light the `val-shadow` view shows.
    pub shadow_light: u32,
    /// 1: k-means starts from the VALs already in the buffer (a previous frame's, see
    /// [`super::Clustered::start_next_frame_from`]) instead of the seeds.
    pub keep_centres: u32,
    pub pad2: u32,
}

/// `params.visibility` of `shaders/clustered/paraboloid.wgsl`.
pub fn visibility_code(v: Visibility) -> u32 {
    match v {
        Visibility::Off => 0,
        Visibility::Cssm => 1,
        Visibility::VplShadows => 2,
    }
}

/// Depth of the paraboloid maps: distance over the scene's extent.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Format of the Fourier basis bands (`CSSM_BANDS` in `paraboloid.wgsl`).
pub const BASIS_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
/// RGBA bands of the basis: cos/sin of terms 0–1 and 2–3, the same times z, and z.
pub const CSSM_BANDS: u32 = 5;
/// Largest K (`FOURIER_MAX_TERMS`): two bands of cos/sin pairs.
pub const FOURIER_MAX_TERMS: u32 = 4;
/// Largest atlas side: wgpu's default `max_texture_dimension_2d`, which every adapter meets.
pub const MAX_ATLAS_SIDE: u32 = 8192;

/// Where the paraboloid maps of a frame lie: one S×S tile per light, row by row, in an atlas
/// at most [`MAX_ATLAS_SIDE`] wide; with `cssm` the basis texture stacks its
/// [`CSSM_BANDS`] bands of the atlas's height below one another.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AtlasLayout {
    pub map_size: u32,
    pub tiles: u32,
    pub columns: u32,
    pub rows: u32,
    /// Whether the basis textures exist (`cssm`).
    pub basis: bool,
}

impl AtlasLayout {
    /// The atlas of `tiles` maps of side `map_size` (≥ 1 each).
    pub fn new(map_size: u32, tiles: u32, basis: bool) -> Self {
        let columns = (MAX_ATLAS_SIDE / map_size).clamp(1, tiles.max(1));
        Self {
            map_size,
            tiles,
            columns,
            rows: tiles.max(1).div_ceil(columns),
            basis,
        }
    }

    /// The atlas of a frame's settings: one map per VAL for `cssm`, per VPL for
    /// `vpl_shadows`, and a 1×1 stand-in with visibility off (its bindings must exist).
    pub fn of(visibility: Visibility, map_size: u32, vpls: u32, vals: u32) -> Self {
        match visibility {
            Visibility::Off => Self::new(1, 1, false),
            Visibility::Cssm => Self::new(map_size, vals, true),
            Visibility::VplShadows => Self::new(map_size, vpls, false),
        }
    }

    pub fn width(&self) -> u32 {
        self.columns * self.map_size
    }

    pub fn height(&self) -> u32 {
        self.rows * self.map_size
    }

    /// Height of the basis texture (all bands).
    pub fn basis_height(&self) -> u32 {
        self.height() * CSSM_BANDS
    }

    /// Mip levels of the basis: down to one texel per map.
    pub fn mip_levels(&self) -> u32 {
        self.map_size.ilog2() + 1
    }

    /// The texture side the budget limits: the basis's stacked bands with `cssm`, else the
    /// depth atlas's height.
    pub fn tallest_side(&self) -> u32 {
        if self.basis {
            self.basis_height()
        } else {
            self.height()
        }
    }

    /// Whether the maps fit [`super::MAX_VISIBILITY_BYTES`] and [`MAX_ATLAS_SIDE`].
    pub fn fits(&self) -> bool {
        self.bytes() <= super::MAX_VISIBILITY_BYTES && self.tallest_side() <= MAX_ATLAS_SIDE
    }

    /// Bytes of the depth atlas and, with `cssm`, the basis with its mips (4/3 of level 0).
    pub fn bytes(&self) -> u64 {
        let texels = u64::from(self.width()) * u64::from(self.height());
        let basis = if self.basis {
            texels * u64::from(CSSM_BANDS) * 8 * 4 / 3
        } else {
            0
        };
        texels * 4 + basis
    }
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
        rsm_glossy: bind::UINT_TEXTURE,
        vpl_glossy: bind::STORAGE_RW,
    }
}

/// A filterable `texture_2d<f32>` (the basis, sampled with a level of detail).
const FILTERABLE: BindKind = BindKind::Texture {
    sample_type: wgpu::TextureSampleType::Float { filterable: true },
    dimension: wgpu::TextureViewDimension::D2,
};
/// The depth atlas, read with `textureLoad`.
const DEPTH: BindKind = BindKind::Texture {
    sample_type: wgpu::TextureSampleType::Depth,
    dimension: wgpu::TextureViewDimension::D2,
};

bind_group! {
    /// Group 0 of `shaders/clustered/paraboloid_maps.wgsl`.
    pub struct MapsResources as MAPS_GROUP(
        "paraboloid maps",
        wgpu::ShaderStages::VERTEX_FRAGMENT
    ) {
        params: bind::PARAMS,
        centres: bind::STORAGE,
        indices: bind::STORAGE,
        vertices: bind::STORAGE,
    }
}

bind_group! {
    /// Group 0 of `shaders/clustered/cssm_basis.wgsl`.
    pub struct BasisResources as BASIS_GROUP("cssm basis", wgpu::ShaderStages::COMPUTE) {
        depth_atlas: DEPTH,
        basis_out: bind::storage_texture(BASIS_FORMAT),
    }
}

bind_group! {
    /// Group 0 of `shaders/clustered/cssm_mips.wgsl`.
    pub struct MipsResources as MIPS_GROUP("cssm mips", wgpu::ShaderStages::COMPUTE) {
        finer: bind::TEXTURE,
        coarser: bind::storage_texture(BASIS_FORMAT),
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
        g_normal_roughness: bind::TEXTURE,
        g_base_metallic: bind::TEXTURE,
        g_emissive_specular: bind::TEXTURE,
        vpls: bind::STORAGE,
        interleaved_out: bind::storage_texture(INTERLEAVED_FORMAT),
        centres: bind::STORAGE,
        mapping: bind::STORAGE,
        depth_atlas: DEPTH,
        basis: FILTERABLE,
        basis_sampler: BindKind::Sampler(wgpu::SamplerBindingType::Filtering),
        brdf_table: bind::STORAGE,
        vpl_glossy: bind::STORAGE,
    }
}

bind_group! {
    /// Group 0 of `shaders/clustered/blur.wgsl`.
    pub struct BlurResources as BLUR_GROUP("geometry blur", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        g_position: bind::TEXTURE,
        g_normal_roughness: bind::TEXTURE,
        interleaved: bind::TEXTURE,
        indirect_out: bind::storage_texture(INDIRECT_FORMAT),
    }
}

/// The VPLs, the clusters and the mapping C of one (N, M).
pub struct ClusterBuffers {
    pub vpl_count: u32,
    pub cluster_count: u32,
    pub vpls: wgpu::Buffer,
    /// Each VPL's [`GlossySender`], beside `vpls` (whose layout the paraboloid maps share
    /// with the VALs').
    pub vpl_glossy: wgpu::Buffer,
    pub vals: wgpu::Buffer,
    pub mapping: wgpu::Buffer,
}

/// A storage buffer the tests can read back (`COPY_SRC`) and, for the VALs a frame may start
/// from, write (`COPY_DST`).
fn storage(device: &wgpu::Device, label: &str, bytes: usize) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes as u64,
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
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
            vpl_glossy: storage(
                device,
                "clustered vpl glossy",
                n * size_of::<GlossySender>(),
            ),
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
        let module = super::shaders::CLUSTERING.create_module(device);
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
            rsm_glossy: &rsm.glossy,
            vpl_glossy: &buffers.vpl_glossy,
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

/// The paraboloid depth atlas and the basis texture of one [`AtlasLayout`].
pub struct VisibilityTargets {
    pub layout: AtlasLayout,
    pub depth: Target,
    pub basis: wgpu::Texture,
    /// Every level, for the shading's sampler.
    pub basis_view: wgpu::TextureView,
    /// Level 0 as a storage target, then one bind group per further level.
    basis_group: wgpu::BindGroup,
    mip_groups: Vec<wgpu::BindGroup>,
    pub sampler: wgpu::Sampler,
}

impl VisibilityTargets {
    /// `layout` has passed `validate`'s budget ([`AtlasLayout::bytes`] and
    /// [`MAX_ATLAS_SIDE`]).
    pub fn new(device: &wgpu::Device, pass: &VisibilityPass, layout: AtlasLayout) -> Self {
        let depth = Target::new(
            device,
            "paraboloid maps",
            layout.width(),
            layout.height(),
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        // Without `cssm` a 1×1 stand-in keeps the shading's bindings valid.
        let (levels, width, height) = if layout.basis {
            (layout.mip_levels(), layout.width(), layout.basis_height())
        } else {
            (1, 1, 1)
        };
        let basis = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("cssm basis"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: levels,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: BASIS_FORMAT,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let level = |l: u32| {
            basis.create_view(&wgpu::TextureViewDescriptor {
                label: Some("cssm basis level"),
                base_mip_level: l,
                mip_level_count: Some(1),
                ..Default::default()
            })
        };
        let basis_group = BasisResources {
            depth_atlas: &depth.view,
            basis_out: &level(0),
        }
        .bind(device, &pass.basis_layout);
        let mip_groups = (1..levels)
            .map(|l| {
                MipsResources {
                    finer: &level(l - 1),
                    coarser: &level(l),
                }
                .bind(device, &pass.mips_layout)
            })
            .collect();
        Self {
            layout,
            basis_view: basis.create_view(&wgpu::TextureViewDescriptor::default()),
            basis,
            depth,
            basis_group,
            mip_groups,
            sampler: device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("cssm basis"),
                mag_filter: wgpu::FilterMode::Linear,
                min_filter: wgpu::FilterMode::Linear,
                mipmap_filter: wgpu::MipmapFilterMode::Linear,
                ..Default::default()
            }),
        }
    }
}

/// The paraboloid maps (one instanced draw over the lights) and the CSSM basis with its mips.
pub struct VisibilityPass {
    maps_layout: wgpu::BindGroupLayout,
    maps: wgpu::RenderPipeline,
    basis_layout: wgpu::BindGroupLayout,
    basis: wgpu::ComputePipeline,
    mips_layout: wgpu::BindGroupLayout,
    mips: wgpu::ComputePipeline,
}

impl VisibilityPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let maps_layout = MAPS_GROUP.layout(device);
        let module = super::shaders::PARABOLOID_MAPS.create_module(device);
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("paraboloid maps"),
            bind_group_layouts: &[Some(&maps_layout)],
            immediate_size: 0,
        });
        let maps = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("paraboloid maps"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_map"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_map"),
                compilation_options: Default::default(),
                targets: &[],
            }),
            multiview_mask: None,
            cache: None,
        });
        let basis_layout = BASIS_GROUP.layout(device);
        let mips_layout = MIPS_GROUP.layout(device);
        Self {
            basis: passes::compute_pipeline(
                device,
                "cssm basis",
                &basis_layout,
                &super::shaders::CSSM_BASIS.create_module(device),
                "basis",
            ),
            mips: passes::compute_pipeline(
                device,
                "cssm mips",
                &mips_layout,
                &super::shaders::CSSM_MIPS.create_module(device),
                "downsample",
            ),
            maps_layout,
            maps,
            basis_layout,
            mips_layout,
        }
    }

    /// §6 "Paraboloid CSSM": every shadow-casting triangle into the map of every light in
    /// `centres` (VALs or VPLs, one instance each).
    pub fn encode_maps(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        params: &wgpu::Buffer,
        centres: &wgpu::Buffer,
        scene: &SceneBuffers,
        targets: &VisibilityTargets,
    ) {
        let group = MapsResources {
            params,
            centres,
            indices: &scene.indices,
            vertices: &scene.vertices,
        }
        .bind(device, &self.maps_layout);
        let mut pass = passes::begin_depth_pass(encoder, "paraboloid maps", &targets.depth.view);
        pass.set_pipeline(&self.maps);
        pass.set_bind_group(0, &group, &[]);
        for range in &scene.shadow_casting {
            pass.draw(
                range.first_index..range.first_index + range.index_count,
                0..targets.layout.tiles,
            );
        }
    }

    /// The basis of every depth texel (§4.1), then its mip chain.
    pub fn encode_basis(&self, encoder: &mut wgpu::CommandEncoder, targets: &VisibilityTargets) {
        let layout = targets.layout;
        passes::dispatch_2d(
            encoder,
            "cssm basis",
            &self.basis,
            &targets.basis_group,
            layout.width(),
            layout.height(),
        );
        for (l, group) in (1..).zip(&targets.mip_groups) {
            passes::dispatch_2d(
                encoder,
                "cssm mips",
                &self.mips,
                group,
                layout.width() >> l,
                layout.basis_height() >> l,
            );
        }
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
    use crate::gi::clustered::shaders::{CLUSTERING, PARABOLOID_MAPS};
    use crate::gpu::shaders::layout_check::assert_struct;
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
                ("visibility", offset_of!(ClusteredParams, visibility)),
                ("map_size", offset_of!(ClusteredParams, map_size)),
                ("atlas_columns", offset_of!(ClusteredParams, atlas_columns)),
                ("atlas_rows", offset_of!(ClusteredParams, atlas_rows)),
                ("fourier_terms", offset_of!(ClusteredParams, fourier_terms)),
                ("extent", offset_of!(ClusteredParams, extent)),
                ("shadow_light", offset_of!(ClusteredParams, shadow_light)),
                ("keep_centres", offset_of!(ClusteredParams, keep_centres)),
                ("pad2", offset_of!(ClusteredParams, pad2)),
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

    #[test]
    fn vpls_and_vals_share_the_map_centre_prefix() {
        // The maps and the lookups bind either buffer as `array<MapCentre>`.
        let members = [
            ("position", 0),
            ("area", 12),
            ("normal", 16),
            ("used", 28),
            ("rest", 32),
        ];
        assert_struct(&PARABOLOID_MAPS, "MapCentre", 48, &members);
        assert_eq!(size_of::<Vpl>(), 48);
        assert_eq!(size_of::<Val>(), 48);
        for (field, vpl, val) in [
            (
                "position",
                offset_of!(Vpl, position),
                offset_of!(Val, position),
            ),
            ("area", offset_of!(Vpl, area), offset_of!(Val, area)),
            ("normal", offset_of!(Vpl, normal), offset_of!(Val, normal)),
            ("used", offset_of!(Vpl, lit), offset_of!(Val, count)),
        ] {
            let expected = members.iter().find(|m| m.0 == field).map(|m| m.1);
            assert_eq!(Some(vpl), expected, "Vpl {field}");
            assert_eq!(Some(val), expected, "Val {field}");
        }
    }

    #[test]
    fn atlas_layouts_wrap_rows_and_count_their_bytes() {
        let a = AtlasLayout::new(256, 30, true);
        assert_eq!(
            (a.columns, a.rows, a.width(), a.height()),
            (30, 1, 7680, 256)
        );
        assert_eq!(a.basis_height(), 1280);
        assert_eq!(a.mip_levels(), 9);
        assert_eq!(a.bytes(), 7680 * 256 * 4 + 7680 * 256 * 5 * 8 * 4 / 3);
        let b = AtlasLayout::new(128, 1000, false);
        assert_eq!((b.columns, b.rows), (64, 16));
        assert_eq!(b.bytes(), 8192 * 2048 * 4);
        let off = AtlasLayout::of(Visibility::Off, 256, 1024, 30);
        assert_eq!((off.width(), off.height(), off.basis), (1, 1, false));
        assert_eq!(
            AtlasLayout::of(Visibility::VplShadows, 64, 1024, 30).tiles,
            1024
        );
    }
}
