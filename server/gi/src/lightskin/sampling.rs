//! Per-frame VAL sampling of the BRSM method: RSM → importance (eq. 10–11) → cumulative
//! sums → selection of N_sVAL VALs with their weights (eq. 13–15). Owns the passes and the
//! buffers between them.

use super::Settings;
use super::{
    cumulative_sums::CumulativeSumsPass,
    importance::{ImportanceParams, ImportancePass, ViewSample},
    val_select::{SelectionBuffers, Val, ValSelectPass},
};
use crate::gpu::readback::{stage_buffer, PendingMap, TextureReadback};
use crate::gpu::{GpuContext, GpuError};
use crate::passes::{
    frame_uniforms::LightFace,
    gbuffer::GBuffer,
    rsm::{Rsm, RsmFace, RsmPass},
    scene_buffers::SceneBuffers,
};
use crate::scene::Scene;

/// What one set of sampling buffers is for. The G-buffer itself, not just its size, is part of
/// it: the importance stage's bind group reads that G-buffer, and targets of a size evicted
/// and created again are new textures.
#[derive(Clone, PartialEq, Eq)]
struct Key {
    rsm_size: u32,
    faces: u32,
    /// The RSM is resolved from a visibility buffer.
    visibility: bool,
    view_samples: u32,
    val_count: u32,
    gbuffer: wgpu::Texture,
}

/// Sets of sampling buffers kept at once, most recently used first, so that sessions of
/// different sizes or GI parameters served in turn do not rebuild them every frame.
const MAX_SETS: usize = 4;

/// Buffers and bind groups for one [`Key`].
struct Resources {
    key: Key,
    rsm: Rsm,
    /// This frame's view samples, gathered from its G-buffer.
    samples: wgpu::Buffer,
    /// The view samples importance is estimated from: this frame's, or those of every session
    /// sharing the frame's VALs (`shared`), copied in.
    pooled: wgpu::Buffer,
    importance: wgpu::Buffer,
    column_sums: wgpu::Buffer,
    row_sums: wgpu::Buffer,
    vals: wgpu::Buffer,
    /// The importance pass bound to `samples` (the gather writes them).
    gather_group: wgpu::BindGroup,
    /// The importance pass bound to `pooled` (the estimate reads them).
    importance_group: wgpu::BindGroup,
    sums_group: wgpu::BindGroup,
    select_group: wgpu::BindGroup,
}

pub struct ValSampling {
    rsm_pass: RsmPass,
    importance_pass: ImportancePass,
    sums_pass: CumulativeSumsPass,
    select_pass: ValSelectPass,
    /// Most recently used first; the first is the current frame's.
    resources: Vec<Resources>,
    /// RSM rows of each importance dispatch, chosen by the last `prepare`.
    importance_bands: Vec<std::ops::Range<u32>>,
}

/// Everything the sampling stages produced, read back for tests and debug views.
#[derive(Clone, Debug)]
pub struct SamplingReadback {
    pub rsm_width: u32,
    pub rsm_height: u32,
    /// RGBA per texel: world position, w = 1 where a VAL exists.
    pub rsm_position: Vec<[f32; 4]>,
    /// RGBA per texel: VAL normal (xyz).
    pub rsm_normal: Vec<[f32; 4]>,
    /// RGBA per texel: reflected flux (rgb) and disk area (a).
    pub rsm_flux_area: Vec<[f32; 4]>,
    /// Per texel: the glossy lobe it sends on (`GlossySender::decode`).
    pub rsm_glossy: Vec<[u32; 4]>,
    pub view_samples: Vec<ViewSample>,
    pub importance: Vec<f32>,
    pub column_sums: Vec<f32>,
    pub row_sums: Vec<f32>,
    pub vals: Vec<Val>,
}

fn storage(device: &wgpu::Device, label: &str, bytes: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// View samples to copy into the ones importance is estimated from: `count` of them from
/// sample `first` of `buffer` on.
pub struct SampleRange<'a> {
    pub buffer: &'a wgpu::Buffer,
    pub first: u32,
    pub count: u32,
}

const SAMPLE_BYTES: u64 = std::mem::size_of::<ViewSample>() as u64;

impl ValSampling {
    pub fn new(
        device: &wgpu::Device,
        light: &wgpu::Buffer,
        material_layout: &wgpu::BindGroupLayout,
    ) -> Self {
        Self {
            rsm_pass: RsmPass::new(device, light, material_layout),
            importance_pass: ImportancePass::new(device),
            sums_pass: CumulativeSumsPass::new(device),
            select_pass: ValSelectPass::new(device),
            resources: Vec::new(),
            importance_bands: Vec::new(),
        }
    }

    /// Makes the buffers for this frame's G-buffer and parameters current (reusing a kept set)
    /// and writes the uniforms.
    /// `emitters`: the scene's emissive surfaces light the frame too, as VALs of one more
    /// RSM face (`passes::rsm::EmitterFace`), sampled and selected like any other texel.
    /// `visibility`: the RSM is drawn as a visibility buffer (`FrameInputs::visibility_buffer`).
    pub fn prepare(
        &mut self,
        ctx: &GpuContext,
        gbuffer: &GBuffer,
        faces: &[(u32, LightFace)],
        (scene, emitters): (&Scene, bool),
        settings: &Settings,
        visibility: bool,
    ) {
        let emitter_face =
            self.rsm_pass
                .prepare_emitters(&ctx.device, scene, settings.rsm_size, emitters);
        let key = Key {
            rsm_size: settings.rsm_size,
            faces: faces.len() as u32 + u32::from(emitter_face),
            visibility,
            view_samples: settings.view_samples,
            val_count: settings.val_count,
            gbuffer: gbuffer.position.texture.clone(),
        };
        match self.resources.iter().position(|r| r.key == key) {
            Some(i) => {
                let hit = self.resources.remove(i);
                self.resources.insert(0, hit);
            }
            None => {
                // Release the least recently used set before allocating the new one.
                self.resources.truncate(MAX_SETS - 1);
                let created = self.create_resources(ctx, gbuffer, key, settings);
                self.resources.insert(0, created);
            }
        }
        let res = &self.resources[0];
        let queue = &ctx.queue;
        // Every light's faces lie in one atlas and eq. 10–11's importance is estimated over all
        // of it, so the VAL budget is split between the lights by their share of the summed
        // importance: light k draws N·ΣI_k/ΣI VALs in expectation (1/(N·P) keeps each unbiased).
        let rsm_faces = RsmFace::all(faces, settings.rsm_size, settings.senders);
        self.rsm_pass.set_faces(queue, &rsm_faces);
        let bands = self
            .importance_pass
            .prepare(queue, &importance_params(&res.rsm, settings));
        self.sums_pass
            .prepare(queue, res.rsm.width(), res.rsm.height());
        self.select_pass.prepare(
            queue,
            &res.rsm,
            settings.val_count,
            settings.jitter,
            settings.defensive,
        );
        self.importance_bands = bands;
    }

    /// Drops the sets made for G-buffers other than `live` (the renderer's current targets),
    /// so evicted targets do not stay alive through them.
    pub fn retain_gbuffers<'a>(&mut self, live: impl Iterator<Item = &'a GBuffer> + Clone) {
        self.resources
            .retain(|r| live.clone().any(|g| g.position.texture == r.key.gbuffer));
    }

    fn create_resources(
        &self,
        ctx: &GpuContext,
        gbuffer: &GBuffer,
        key: Key,
        settings: &Settings,
    ) -> Resources {
        let device = &ctx.device;
        let rsm = Rsm::new(device, settings.rsm_size, key.faces, key.visibility);
        let texels = u64::from(rsm.texels());
        let samples = storage(
            device,
            "view samples",
            u64::from(settings.view_samples) * SAMPLE_BYTES,
        );
        let pooled = storage(
            device,
            "pooled view samples",
            u64::from(settings.view_samples) * SAMPLE_BYTES,
        );
        let importance = storage(device, "importance", texels * 4);
        let column_sums = storage(device, "column sums", texels * 4);
        let row_sums = storage(device, "row sums", u64::from(rsm.width()) * 4);
        let vals = storage(
            device,
            "selected vals",
            u64::from(settings.val_count) * std::mem::size_of::<Val>() as u64,
        );
        let gather_group = self
            .importance_pass
            .bind(device, gbuffer, &rsm, &samples, &importance);
        let importance_group =
            self.importance_pass
                .bind(device, gbuffer, &rsm, &pooled, &importance);
        let sums_group = self
            .sums_pass
            .bind(device, &importance, &column_sums, &row_sums);
        let select_group = self.select_pass.bind(
            device,
            &rsm,
            &SelectionBuffers {
                importance: &importance,
                column_sums: &column_sums,
                row_sums: &row_sums,
                vals: &vals,
            },
        );
        Resources {
            key,
            rsm,
            samples,
            pooled,
            importance,
            column_sums,
            row_sums,
            vals,
            gather_group,
            importance_group,
            sums_group,
            select_group,
        }
    }

    fn res(&self) -> &Resources {
        self.resources
            .first()
            .expect("ValSampling::prepare must run before encoding")
    }

    pub fn rsm(&self) -> &Rsm {
        &self.res().rsm
    }

    /// The selected VALs of the last prepared frame.
    pub fn vals(&self) -> &wgpu::Buffer {
        &self.res().vals
    }

    /// The `rsm` stage (reused where the RSM holds this frame's already, see
    /// `RsmPass::encode_stage`).
    pub fn encode_rsm(
        &self,
        stages: &mut crate::gpu::timing::FrameStages,
        scene: &SceneBuffers,
        shared: Option<&[u8]>,
    ) -> Result<(), crate::gpu::GpuError> {
        self.rsm_pass
            .encode_stage(stages, &self.res().rsm, scene, shared)
    }

    /// This frame's view samples (after [`Self::encode_gather`]).
    pub fn samples(&self) -> &wgpu::Buffer {
        &self.res().samples
    }

    /// Gathers this frame's N_VS view samples from its G-buffer.
    pub fn encode_gather(&self, encoder: &mut wgpu::CommandEncoder, settings: &Settings) {
        self.importance_pass.encode_gather(
            encoder,
            &self.res().gather_group,
            settings.view_samples,
        );
    }

    /// Eq. 10–11's importance from the view samples of `sources`, copied in order (N_VS in
    /// all; `None`: this frame's own).
    pub fn encode_importance(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        settings: &Settings,
        sources: Option<&[SampleRange]>,
    ) {
        let res = self.res();
        let own = [SampleRange {
            buffer: &res.samples,
            first: 0,
            count: settings.view_samples,
        }];
        let mut at = 0;
        for s in sources.unwrap_or(&own) {
            let count = s.count.min(settings.view_samples - at);
            encoder.copy_buffer_to_buffer(
                s.buffer,
                u64::from(s.first) * SAMPLE_BYTES,
                &res.pooled,
                u64::from(at) * SAMPLE_BYTES,
                Some(u64::from(count) * SAMPLE_BYTES),
            );
            at += count;
        }
        self.importance_pass.encode_estimate(
            encoder,
            &res.importance_group,
            &importance_params(&res.rsm, settings),
            &self.importance_bands,
        );
    }

    pub fn encode_cumulative_sums(&self, encoder: &mut wgpu::CommandEncoder) {
        let res = self.res();
        self.sums_pass
            .encode(encoder, &res.sums_group, res.rsm.width());
    }

    pub fn encode_selection(&self, encoder: &mut wgpu::CommandEncoder, settings: &Settings) {
        self.select_pass
            .encode(encoder, &self.res().select_group, settings.val_count);
    }

    /// Reads back every intermediate result (blocking; for tests and debug views).
    /// Encodes copies of every sampling buffer of the last prepared frame into staging
    /// buffers, to be read once the encoder's submission is done (see [`SamplingCapture`]).
    pub fn capture(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
    ) -> SamplingCapture {
        let res = self.res();
        let rsm = &res.rsm;
        // RGBA textures of 32-bit (16 bytes per texel) or 16-bit (8 bytes) channels.
        let readback = |encoder: &mut wgpu::CommandEncoder, t: &wgpu::Texture, bytes: u32| {
            let readback =
                TextureReadback::new(device, "rsm readback", rsm.width(), rsm.height(), bytes);
            readback.encode_copy(encoder, t);
            readback
        };
        let texture = |encoder: &mut wgpu::CommandEncoder, t: &wgpu::Texture, bytes: u32| {
            (readback(encoder, t, bytes), bytes)
        };
        SamplingCapture {
            rsm_width: rsm.width(),
            rsm_height: rsm.height(),
            view_samples: res.key.view_samples,
            val_count: res.key.val_count,
            rsm: [
                texture(encoder, &rsm.position.texture, 16),
                texture(encoder, &rsm.normal.texture, 8),
                texture(encoder, &rsm.flux_area.texture, 16),
            ],
            rsm_glossy: readback(encoder, &rsm.glossy.texture, 16),
            buffers: [
                &res.pooled,
                &res.importance,
                &res.column_sums,
                &res.row_sums,
                &res.vals,
            ]
            .map(|b| stage_buffer(device, encoder, b)),
        }
    }

    /// The sampling stages' results of the last frame (blocking readback).
    pub fn read_back(&self, ctx: &GpuContext) -> Result<SamplingReadback, GpuError> {
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        let capture = self.capture(&ctx.device, &mut encoder);
        let submission = ctx.queue.submit([encoder.finish()]);
        capture.read(ctx, Some(&submission))
    }
}

/// Staged copies of the sampling buffers of one frame.
pub struct SamplingCapture {
    rsm_width: u32,
    rsm_height: u32,
    view_samples: u32,
    val_count: u32,
    /// RSM position, normal and flux/area, with their bytes per texel.
    rsm: [(TextureReadback, u32); 3],
    rsm_glossy: TextureReadback,
    /// View samples, importance, column sums, row sums, VALs.
    buffers: [wgpu::Buffer; 5],
}

impl SamplingCapture {
    /// Maps the copies encoded into `submission` (waiting for it if the GPU has not finished
    /// it) and decodes them.
    pub fn read(
        self,
        ctx: &GpuContext,
        submission: Option<&wgpu::SubmissionIndex>,
    ) -> Result<SamplingReadback, GpuError> {
        let rsm = self.rsm.map(|(r, bytes)| (r.begin_read(), bytes));
        let glossy = self.rsm_glossy.begin_read();
        let maps = self.buffers.each_ref().map(PendingMap::new);
        ctx.wait_for(submission)?;
        let texels = (self.rsm_width * self.rsm_height) as usize;
        let mut decoded = Vec::with_capacity(3);
        for (rows, bytes_per_texel) in rsm {
            let bytes = rows.finish()?;
            decoded.push(crate::gpu::readback::rgba_f32(&bytes, bytes_per_texel));
        }
        let [samples, importance, column_sums, row_sums, vals] = maps;
        let floats = |map: PendingMap, n: usize| -> Result<Vec<f32>, GpuError> {
            let mut v: Vec<f32> = bytemuck::pod_collect_to_vec(&map.finish()?);
            v.truncate(n);
            Ok(v)
        };
        let mut view_samples: Vec<ViewSample> = bytemuck::pod_collect_to_vec(&samples.finish()?);
        view_samples.truncate(self.view_samples as usize);
        let importance = floats(importance, texels)?;
        let column_sums = floats(column_sums, texels)?;
        let row_sums = floats(row_sums, self.rsm_width as usize)?;
        let mut vals: Vec<Val> = bytemuck::pod_collect_to_vec(&vals.finish()?);
        vals.truncate(self.val_count as usize);
        let [rsm_position, rsm_normal, rsm_flux_area]: [Vec<[f32; 4]>; 3] = decoded
            .try_into()
            .map_err(|_| GpuError::Map("three RSM textures were staged".into()))?;
        Ok(SamplingReadback {
            rsm_width: self.rsm_width,
            rsm_height: self.rsm_height,
            rsm_position,
            rsm_normal,
            rsm_flux_area,
            rsm_glossy: bytemuck::pod_collect_to_vec(&glossy.finish()?),
            view_samples,
            importance,
            column_sums,
            row_sums,
            vals,
        })
    }
}

fn importance_params(rsm: &Rsm, settings: &Settings) -> ImportanceParams {
    ImportanceParams {
        rsm_width: rsm.width(),
        rsm_height: rsm.height(),
        sample_count: settings.view_samples,
        uniform_importance: u32::from(settings.uniform_importance),
        first_row: 0,
        pad0: 0,
        pad1: 0,
        pad2: 0,
    }
}
