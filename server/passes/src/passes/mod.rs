//! The render pipeline, one module per GPU pass, in frame order:
//!
//! 1. [`shadow_map`]: depth from the light (1 or 6 faces).
//! 2. [`gbuffer`]: position, normal, materials and triangle id from the camera.
//! 3. The frame's GI method (`gi/<method>/`) fills the indirect buffer; the RSM-based ones
//!    start with [`rsm`], the reflective shadow map, every texel a virtual light.
//! 4. [`direct_light`]: emission + direct light with PCF shadows + indirect, into HDR.
//! 5. [`exposure`]: automatic exposure from the HDR image.
//! 6. [`tonemap`]: exposure, filmic curve, sRGB into the 8-bit output.
//! 7. [`yuv420`]: for video, the 8-bit output as Y'CbCr 4:2:0 (read back instead of RGBA).
//!
//! With `gi.indirect_downscale` > 1, [`indirect_resolution`] reduces the G-buffer before the
//! GI method's stages and upsamples their result after them.
//!
//! [`frame_uniforms`] holds the uniforms they share and [`scene_buffers`] the scene geometry
//! and materials. Every pass, here and in `gi/`, declares each bind group once with
//! `bind_group!` ([`bind`]). `gi/` builds on this module, never the other way round.

pub mod bind;
pub mod direct_light;
pub mod environment;
pub mod exposure;
pub mod frame_uniforms;
pub mod gbuffer;
pub mod indirect_resolution;
pub mod reuse;
pub mod rsm;
pub mod scene_buffers;
pub mod shadow_map;
pub mod stages;
pub mod tonemap;
pub mod yuv420;

use crate::gpu::shaders::{self, ShaderSource};

/// Format of the indirect-light buffer every GI method writes and direct light adds in.
pub const INDIRECT_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// Workgroup edge of the 2D compute passes (8×8 threads).
pub const TILE: u32 = 8;

/// A 2D texture with one view, as most passes create them.
pub struct Target {
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
}

impl Target {
    pub fn new(
        device: &wgpu::Device,
        label: &str,
        width: u32,
        height: u32,
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> Self {
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        Self { texture, view }
    }
}

/// A colour attachment cleared to zero and stored.
pub fn cleared_attachment(view: &wgpu::TextureView) -> wgpu::RenderPassColorAttachment<'_> {
    wgpu::RenderPassColorAttachment {
        view,
        depth_slice: None,
        resolve_target: None,
        ops: wgpu::Operations {
            load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
            store: wgpu::StoreOp::Store,
        },
    }
}

/// A compute pipeline for `entry_point` of `module` with one bind group layout.
pub fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    module: &wgpu::ShaderModule,
    entry_point: &str,
) -> wgpu::ComputePipeline {
    compute_pipeline_with_groups(device, label, &[layout], module, entry_point)
}

/// A compute pipeline for `entry_point` of `module` whose bind group `i` has `layouts[i]`.
pub fn compute_pipeline_with_groups(
    device: &wgpu::Device,
    label: &str,
    layouts: &[&wgpu::BindGroupLayout],
    module: &wgpu::ShaderModule,
    entry_point: &str,
) -> wgpu::ComputePipeline {
    compute_pipeline_with_constants(device, label, layouts, module, entry_point, &[])
}

/// [`compute_pipeline_with_groups`] with values for the module's `override` constants.
pub fn compute_pipeline_with_constants(
    device: &wgpu::Device,
    label: &str,
    layouts: &[&wgpu::BindGroupLayout],
    module: &wgpu::ShaderModule,
    entry_point: &str,
    constants: &[(&str, f64)],
) -> wgpu::ComputePipeline {
    let layouts: Vec<Option<&wgpu::BindGroupLayout>> = layouts.iter().copied().map(Some).collect();
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &layouts,
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&pipeline_layout),
        module,
        entry_point: Some(entry_point),
        compilation_options: wgpu::PipelineCompilationOptions {
            constants,
            ..Default::default()
        },
        cache: None,
    })
}

/// Dispatches one 8×8 workgroup per tile of a `width`×`height` image.
pub fn dispatch_2d(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
    width: u32,
    height: u32,
) {
    let mut pass = begin_compute(encoder, label);
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, bind_group, &[]);
    pass.dispatch_workgroups(width.div_ceil(TILE), height.div_ceil(TILE), 1);
}

/// How per-frame parameters (camera, light, pass parameters) are bound: as read-only storage
/// buffers, not uniform buffers. lavapipe (Mesa 22.3, the driver of CI and GPU-less machines)
/// inlines uniform-buffer values that steer branches or loops into the shader and JIT-compiles
/// a new variant at every dispatch, never freeing the old one: with uniform buffers the server
/// grew by ~450 KiB per frame without GI and ~1.3 MiB with it (issue 15;
/// `server/examples/memory_probe.rs` reproduces it). Storage loads are never inlined, and on
/// real GPUs these small read-only structs are served by the same caches.
pub const PARAMS_BINDING: wgpu::BufferBindingType =
    wgpu::BufferBindingType::Storage { read_only: true };
/// Usage of a parameter buffer bound with [`PARAMS_BINDING`] and written by the queue.
pub const PARAMS_USAGE: wgpu::BufferUsages =
    wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_DST);

/// Distance between parameter slots addressed by dynamic offsets (wgpu's largest alignment).
pub const PARAM_SLOT: u64 = 256;

/// A parameter buffer of equally sized slots, each bound through a dynamic offset: lets one
/// command buffer run a pass several times with different parameters (for example one
/// dispatch per chunk of work, so no single dispatch runs long enough to trip a driver's
/// watchdog).
pub struct ParamSlots {
    pub buffer: wgpu::Buffer,
    slots: u32,
    slot_size: u64,
}

impl ParamSlots {
    /// `slots` slots (at least one) of one `T` each.
    pub fn new<T>(device: &wgpu::Device, label: &str, slots: u32) -> Self {
        Self {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: PARAM_SLOT * u64::from(slots.max(1)),
                usage: PARAMS_USAGE,
                mapped_at_creation: false,
            }),
            slots: slots.max(1),
            slot_size: std::mem::size_of::<T>() as u64,
        }
    }

    pub fn slots(&self) -> u32 {
        self.slots
    }

    /// Writes `values` into consecutive slots from slot 0 (at most [`Self::slots`]).
    pub fn write<T: bytemuck::Pod>(&self, queue: &wgpu::Queue, values: &[T]) {
        for (i, v) in values.iter().enumerate().take(self.slots as usize) {
            queue.write_buffer(&self.buffer, i as u64 * PARAM_SLOT, bytemuck::bytes_of(v));
        }
    }

    /// Dynamic offset of slot `i`.
    pub fn offset(i: u32) -> u32 {
        i * PARAM_SLOT as u32
    }
}

/// Evaluations (item × inner-loop step) per dispatch for passes that split their work:
/// about half a second on lavapipe, which was seen to stop dispatches of a few seconds early
/// and return partial results; far below any watchdog on a real GPU.
pub const DISPATCH_BUDGET: u64 = 1 << 26;
/// Most dispatches one pass splits into (a huge job then exceeds the budget per dispatch).
pub const MAX_CHUNKS: u32 = 1024;

/// Splits `total` work items into consecutive ranges of whole `granule`s such that
/// `cost_per_item` × range length stays within [`DISPATCH_BUDGET`] where possible, using at
/// most [`MAX_CHUNKS`] ranges. Always returns at least one range (empty when `total` is 0).
pub fn chunk_ranges(total: u32, cost_per_item: u64, granule: u32) -> Vec<std::ops::Range<u32>> {
    let granule = granule.max(1);
    let by_budget = (DISPATCH_BUDGET / cost_per_item.max(1)).clamp(1, u64::from(u32::MAX)) as u32;
    let within_budget = (by_budget / granule).max(1) * granule;
    let by_count = total.div_ceil(MAX_CHUNKS).div_ceil(granule) * granule;
    let size = within_budget.max(by_count);
    let count = total.div_ceil(size).max(1);
    (0..count)
        .map(|k| k * size..((k + 1) * size).min(total))
        .collect()
}

/// A parameter buffer of `size` bytes written with `queue.write_buffer`.
pub fn params_buffer(device: &wgpu::Device, label: &str, size: usize) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size as u64,
        usage: PARAMS_USAGE,
        mapped_at_creation: false,
    })
}

/// A render pass that only writes depth into `view`, cleared to 1 (the far plane).
pub fn begin_depth_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    view: &wgpu::TextureView,
) -> wgpu::RenderPass<'e> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view,
            depth_ops: Some(wgpu::Operations {
                load: wgpu::LoadOp::Clear(1.0),
                store: wgpu::StoreOp::Store,
            }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// A compute pass without timestamp writes (stages are timed on the encoder).
pub fn begin_compute<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
) -> wgpu::ComputePass<'e> {
    encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: None,
    })
}

/// The chunked-reduction pattern: `accumulate` once per chunk (slot k of the bind group's
/// [`ParamSlots`] describes chunk k), then `finish` once (slot 0), each over `groups`
/// workgroups.
pub fn dispatch_chunked(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    pipelines: (&wgpu::ComputePipeline, &wgpu::ComputePipeline),
    bind_group: &wgpu::BindGroup,
    groups: u32,
    chunks: u32,
) {
    let (accumulate, finish) = pipelines;
    let mut pass = begin_compute(encoder, label);
    pass.set_pipeline(accumulate);
    for k in 0..chunks {
        pass.set_bind_group(0, bind_group, &[ParamSlots::offset(k)]);
        pass.dispatch_workgroups(groups, 1, 1);
    }
    pass.set_pipeline(finish);
    pass.set_bind_group(0, bind_group, &[ParamSlots::offset(0)]);
    pass.dispatch_workgroups(groups, 1, 1);
}

/// A shader module and the bind groups of the pipeline that runs it, group i at index i. A
/// test over every pass (the shared ones, [`SHADERS`], and each GI method's) validates the
/// module with naga and checks the groups against its WGSL. `None`: the pipeline takes its
/// layout from the WGSL (a test harness's).
pub struct ShaderPass {
    pub source: &'static ShaderSource,
    pub groups: Option<&'static [&'static bind::BindGroupDesc]>,
}

impl ShaderPass {
    /// `source` run by a pipeline with `groups`.
    pub const fn new(
        source: &'static ShaderSource,
        groups: &'static [&'static bind::BindGroupDesc],
    ) -> Self {
        Self {
            source,
            groups: Some(groups),
        }
    }
}

/// The shared passes' modules with their bind groups.
pub const SHADERS: &[ShaderPass] = &[
    ShaderPass::new(
        &shaders::GBUFFER,
        &[&gbuffer::CAMERA_GROUP, &scene_buffers::MATERIAL_GROUP],
    ),
    ShaderPass::new(
        &shaders::GBUFFER_TRIANGLE_IDS,
        &[&gbuffer::CAMERA_GROUP, &scene_buffers::MATERIAL_GROUP],
    ),
    ShaderPass::new(
        &shaders::GBUFFER_VISIBILITY,
        &[&gbuffer::CAMERA_GROUP, &scene_buffers::MATERIAL_GROUP],
    ),
    ShaderPass::new(&shaders::GBUFFER_RESOLVE, &[&gbuffer::RESOLVE_GROUP]),
    ShaderPass::new(
        &shaders::SHADOW_MAP,
        &[&shadow_map::GROUP, &scene_buffers::MATERIAL_GROUP],
    ),
    ShaderPass::new(&shaders::DIRECT_LIGHT, &[&direct_light::GROUP]),
    ShaderPass::new(&shaders::EXPOSURE, &[&exposure::GROUP]),
    ShaderPass::new(&shaders::TONEMAP, &[&tonemap::GROUP]),
    ShaderPass::new(&shaders::YUV420, &[&yuv420::GROUP]),
    ShaderPass::new(
        &shaders::GBUFFER_REDUCE,
        &[&indirect_resolution::REDUCE_GROUP],
    ),
    ShaderPass::new(
        &shaders::INDIRECT_UPSAMPLE,
        &[&indirect_resolution::UPSAMPLE_GROUP],
    ),
    ShaderPass::new(
        &shaders::RSM,
        &[&rsm::GROUP, &scene_buffers::MATERIAL_GROUP],
    ),
    ShaderPass::new(
        &shaders::RSM_VISIBILITY,
        &[&rsm::GROUP, &scene_buffers::MATERIAL_GROUP],
    ),
    ShaderPass::new(&shaders::RSM_RESOLVE, &[&rsm::RESOLVE_GROUP]),
];

#[cfg(test)]
mod tests {
    use super::{chunk_ranges, MAX_CHUNKS};

    #[test]
    fn chunks_respect_budget_granule_and_count() {
        // 6,600 caches × 65,536 VALs with a 2^26 budget: 7 ranges of ≤ 10,168 VALs.
        let r = chunk_ranges(65_536, 6_600, 64);
        assert!(
            r.iter().all(|c| c.start % 64 == 0 && c.len() <= 10_168),
            "{r:?}"
        );
        assert_eq!(r.first().map(|c| c.start), Some(0));
        assert_eq!(r.last().map(|c| c.end), Some(65_536));
        assert!(r.windows(2).all(|w| w[0].end == w[1].start));
        // A tiny job is one range; an empty one is one empty range.
        assert_eq!(chunk_ranges(10, 1, 64), vec![0..10]);
        assert_eq!(chunk_ranges(0, 1, 64), vec![0..0]);
        // The count cap wins over the budget.
        assert!(chunk_ranges(1 << 24, 1 << 20, 64).len() <= MAX_CHUNKS as usize);
    }
}
