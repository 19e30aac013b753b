//! Eq. 3's visibility V on the GPU (`shaders/surfels/link_rays.wgsl`): one shadow ray from
//! every cache to every surfel, through the reference tracer's BVH (`shaders/bvh.wgsl`
//! and [`crate::gi::common::bvh::SceneBvh`]). These rays are almost all of the links' cost (3.5·10⁸ of them for the
//! Cornell box at the defaults); the rest of [`super::links`] (the weights, the cut, the SH
//! coefficients) stays on the CPU and reads the bits back.
//!
//! Caches go in batches, two in flight: while the CPU turns one batch's bits into links, the
//! GPU traces the next. The CPU port of the shader is the `occluded` test of
//! `links::cache_links`, which the integration tests compare it with.

use super::senders::Senders;
use crate::gpu::readback::PendingMap;
use crate::gpu::{GpuContext, GpuError};
use crate::passes::bind::{self, bind_group};
use crate::passes::{compute_pipeline_with_constants, params_buffer};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use wgpu::util::DeviceExt;

/// Mirrors `LinkRayParams` in `shaders/surfels/link_rays.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct LinkRayParams {
    pub surfels: u32,
    pub caches: u32,
    pub words: u32,
    pub epsilon: f32,
}

bind_group! {
    /// Group 0 of `shaders/surfels/link_rays.wgsl`.
    pub struct RayResources as RAY_GROUP("surfel link rays", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        caches: bind::STORAGE,
        surfels: bind::STORAGE,
        visible: bind::STORAGE_RW,
    }
}

bind_group! {
    /// Group 1 of `shaders/surfels/link_rays.wgsl`: the scene's BVH (`bvh.wgsl`).
    pub struct BvhResources as BVH_GROUP("surfel link bvh", wgpu::ShaderStages::COMPUTE) {
        bvh_nodes: bind::STORAGE,
        bvh_triangles: bind::STORAGE,
        tlas_nodes: bind::STORAGE,
        bvh_instances: bind::STORAGE,
    }
}

/// Rays per submission on a GPU: 512 KiB of bits, and short enough (milliseconds) that the
/// frames of sessions sharing the queue are not held up behind a batch for long.
const GPU_BATCH_RAYS: u64 = 1 << 22;
/// Rays per submission on a CPU adapter: lavapipe silently drops work of a submission that runs
/// longer than about 2.8 s, and traces a few million of these rays a second on two cores.
const CPU_ADAPTER_BATCH_RAYS: u64 = 1 << 20;
/// Most caches of one batch: the y dimension of a dispatch.
const MAX_BATCH_CACHES: u64 = 65_535;

/// Why the GPU cannot trace the links (the CPU does then).
#[derive(Debug, thiserror::Error)]
pub enum LinkRayError {
    #[error("the {what} need {bytes} bytes in one buffer, over the device's {limit}")]
    TooLarge {
        what: &'static str,
        bytes: u64,
        limit: u64,
    },
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// The pipeline and buffers tracing one surfel set's link rays.
pub struct LinkRays {
    ctx: GpuContext,
    pipeline: wgpu::ComputePipeline,
    bvh_group: wgpu::BindGroup,
    slots: [Slot; 2],
    surfels: u32,
    words: u32,
    batch: usize,
    epsilon: f32,
}

/// The buffers of one batch in flight.
struct Slot {
    params: wgpu::Buffer,
    caches: wgpu::Buffer,
    visible: wgpu::Buffer,
    readback: wgpu::Buffer,
    group: wgpu::BindGroup,
}

/// Which surfels every cache of a batch sees: bit k of word `c·words + k/32`.
pub struct Visibility {
    words: usize,
    bits: Vec<u32>,
}

impl Visibility {
    /// Whether surfel `k` faces cache `c` of the batch with nothing between them.
    pub fn sees(&self, c: usize, k: usize) -> bool {
        self.bits[c * self.words + k / 32] & (1 << (k % 32)) != 0
    }
}

/// A batch submitted to the GPU.
pub struct Pending {
    map: PendingMap,
    submission: wgpu::SubmissionIndex,
    words: usize,
    caches: usize,
}

impl LinkRays {
    /// Uploads the surfels and the BVH of `senders`.
    pub fn new(ctx: &GpuContext, senders: &Senders) -> Result<Self, LinkRayError> {
        let device = &ctx.device;
        let bvh = senders.bvh;
        let surfels = senders.surfels.len() as u32;
        let words = surfels.div_ceil(32);
        let per_batch = if ctx.info.device_type == wgpu::DeviceType::Cpu {
            CPU_ADAPTER_BATCH_RAYS
        } else {
            GPU_BATCH_RAYS
        };
        let batch = (per_batch / u64::from(surfels.max(1))).clamp(1, MAX_BATCH_CACHES) as usize;
        let limit = device.limits().max_storage_buffer_binding_size;
        let surfel_data: Vec<[f32; 4]> = senders
            .surfels
            .iter()
            .flat_map(|s| [s.position.extend(1.0), s.normal.extend(0.0)])
            .map(|v| v.to_array())
            .collect();
        for (what, bytes) in [
            ("surfels", std::mem::size_of_val(surfel_data.as_slice())),
            ("BVH nodes", std::mem::size_of_val(bvh.nodes.as_slice())),
            (
                "BVH triangles",
                std::mem::size_of_val(bvh.triangles.as_slice()),
            ),
        ] {
            if bytes as u64 > limit {
                return Err(LinkRayError::TooLarge {
                    what,
                    bytes: bytes as u64,
                    limit,
                });
            }
        }
        let storage = |label: &str, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let surfel_buffer = storage("link ray surfels", bytemuck::cast_slice(&surfel_data));
        let ray_layout = RAY_GROUP.layout(device);
        let bvh_layout = BVH_GROUP.layout(device);
        let bvh_group = BvhResources {
            bvh_nodes: &storage("link ray bvh nodes", bytemuck::cast_slice(&bvh.nodes)),
            bvh_triangles: &storage(
                "link ray bvh triangles",
                bytemuck::cast_slice(&bvh.triangles),
            ),
            // Surfel links are built at rest: the BVH's own top level.
            tlas_nodes: &storage("link ray tlas nodes", bytemuck::cast_slice(&bvh.top.nodes)),
            bvh_instances: &storage(
                "link ray bvh instances",
                bytemuck::cast_slice(&bvh.top.instances),
            ),
        }
        .bind(device, &bvh_layout);
        // Geometry only, as the CPU's `SceneBvh::occluded`: the alpha test compiles away.
        let pipeline = compute_pipeline_with_constants(
            device,
            "surfel link rays",
            &[&ray_layout, &bvh_layout],
            &super::shaders::SURFEL_LINK_RAYS.create_module(device),
            "main",
            &[("ALPHA_TESTED", 0.0)],
        );
        let visible_bytes = (batch * words as usize * 4).max(4) as u64;
        let slot = |_| {
            let params = params_buffer(
                device,
                "link ray params",
                std::mem::size_of::<LinkRayParams>(),
            );
            let caches = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("link ray caches"),
                size: (batch * 16) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let visible = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("link ray bits"),
                size: visible_bytes,
                // COPY_DST for the clear before each batch.
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let readback = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("link ray bits readback"),
                size: visible_bytes,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            });
            let group = RayResources {
                params: &params,
                caches: &caches,
                surfels: &surfel_buffer,
                visible: &visible,
            }
            .bind(device, &ray_layout);
            Slot {
                params,
                caches,
                visible,
                readback,
                group,
            }
        };
        Ok(Self {
            ctx: ctx.clone(),
            pipeline,
            bvh_group,
            slots: [0, 1].map(slot),
            surfels,
            words,
            batch,
            epsilon: senders.ray_offset(),
        })
    }

    /// Caches per batch.
    pub fn batch(&self) -> usize {
        self.batch
    }

    /// Starts tracing from `positions` (at most [`Self::batch`]) in buffer slot `slot` (0 or
    /// 1; a slot is free again once its [`Pending`] was waited for).
    pub fn submit(&self, slot: usize, positions: &[Vec3]) -> Pending {
        assert!(
            positions.len() <= self.batch,
            "a batch of at most `batch` caches"
        );
        let s = &self.slots[slot];
        let queue = &self.ctx.queue;
        let params = LinkRayParams {
            surfels: self.surfels,
            caches: positions.len() as u32,
            words: self.words,
            epsilon: self.epsilon,
        };
        queue.write_buffer(&s.params, 0, bytemuck::bytes_of(&params));
        let caches: Vec<[f32; 4]> = positions.iter().map(|p| p.extend(1.0).to_array()).collect();
        queue.write_buffer(&s.caches, 0, bytemuck::cast_slice(&caches));
        let mut encoder = self
            .ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("surfel link rays"),
            });
        encoder.clear_buffer(&s.visible, 0, None);
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("surfel link rays"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &s.group, &[]);
            pass.set_bind_group(1, &self.bvh_group, &[]);
            pass.dispatch_workgroups(self.surfels.div_ceil(64), positions.len() as u32, 1);
        }
        encoder.copy_buffer_to_buffer(&s.visible, 0, &s.readback, 0, None);
        let submission = queue.submit([encoder.finish()]);
        Pending {
            map: PendingMap::new(&s.readback),
            submission,
            words: self.words as usize,
            caches: positions.len(),
        }
    }

    /// The bits of a submitted batch, once the GPU traced it.
    pub fn wait(&self, pending: Pending) -> Result<Visibility, GpuError> {
        self.ctx.device.poll(wgpu::PollType::Wait {
            submission_index: Some(pending.submission),
            timeout: None,
        })?;
        let bytes = pending.map.finish()?;
        let mut bits: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        bits.truncate(pending.caches * pending.words);
        Ok(Visibility {
            words: pending.words,
            bits,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::surfels::shaders::SURFEL_LINK_RAYS;
    use crate::gpu::shaders::layout_check::assert_struct;
    use std::mem::{offset_of, size_of};

    #[test]
    fn link_ray_params_match_wgsl() {
        assert_struct(
            &SURFEL_LINK_RAYS,
            "LinkRayParams",
            size_of::<LinkRayParams>(),
            &[
                ("surfels", offset_of!(LinkRayParams, surfels)),
                ("caches", offset_of!(LinkRayParams, caches)),
                ("words", offset_of!(LinkRayParams, words)),
                ("epsilon", offset_of!(LinkRayParams, epsilon)),
            ],
        );
    }
}
