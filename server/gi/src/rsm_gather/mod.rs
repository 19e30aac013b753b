//! `rsm_gather`: reflective shadow maps as Dachsbacher & Stamminger (2005) gather them, the
//! ancestor the seed methods improve on and the baseline of the comparison. Per frame and with
//! no precomputation: the RSM (the shared pass, every texel a pixel light with its position,
//! normal, flux and disk area), then every pixel sums the light of a fixed pattern of texels
//! around the one it projects to, without visibility ([`pattern`]: the pattern, its weights
//! and the CPU reference of the gather). The paper's screen-space interpolation from a coarse
//! image is the renderer's `indirect_downscale`.
//!
//! What it leaves out, and the seed methods add: occlusion between a pixel light and the pixel
//! (seed 003's clustered visibility, seed 004's proxy occlusion), texels beyond the gather
//! radius (LightSkin sums every texel; BRSM draws texels by their importance to the view).

pub mod bench;
pub mod params;
pub mod passes;
pub mod pattern;
pub mod shaders;
pub mod stages;
pub mod views;

use super::common::params::emitters;
use super::cost::{self, Cost, FrameShape, Knob};
use super::{
    DebugCapture, DebugData, FrameInputs, GiError, InvalidSetting, Method, MethodEntry,
    ProgressBuffer, SceneResources,
};
use crate::gpu::readback::{
    read_buffer, read_rgba_texture, read_rgba_u32_texture, stage_buffer, PendingMap,
    TextureReadback,
};
use crate::gpu::{timing::FrameStages, GpuContext, GpuError};
use crate::passes::rsm::{max_rsm_size, Rsm, RsmFace, RsmPass};
use crate::passes::ShaderPass;
use crate::passes::Target;
use lightcast_protocol::{GiMethod, GiParams, View};
use params::Settings;
use passes::{GatherFace, GatherParams, GatherResources, GATHER_GROUP};
use pattern::GatherSample;
use std::any::{Any, TypeId};
use std::sync::Arc;

/// The method's name.
pub const RSM_GATHER: GiMethod = GiMethod::new("rsm_gather");

/// A point light's six faces for each of the most lights a frame has, and the emitter face.
const MAX_FACES: usize = 6 * crate::passes::frame_uniforms::MAX_LIGHTS + 1;

/// The module with its pipeline's bind group (see [`ShaderPass`]).
const PASSES: &[ShaderPass] = &[ShaderPass::new(&shaders::GATHER, &[&passes::GATHER_GROUP])];

pub const ENTRY: MethodEntry = MethodEntry {
    tables: &[params::TABLE],
    type_id: TypeId::of::<RsmGather>,
    validate,
    check_table: |gi| Settings::of(gi).map(drop),
    create: |r| Ok(Box::new(RsmGather::new(r))),
    precompute: None,
    cost,
    knobs: &[
        Knob::lower(&params::GATHER_SAMPLES),
        Knob::lower(&crate::gi::common::params::RSM_SIZE),
    ],
    shaders: PASSES,
    stages: stages::ALL,
    limits: &[&crate::gi::common::limits::MAX_RSM_SIZE],
    downscales: true,
    samples_environment: false,
    follows_moved_nodes: super::follows_every_pose,
    bench: Some(&bench::SWEEP),
};

/// One frame's stages: the RSM and the gather (each pixel N texel fetches and pixel lights in
/// every light face). Weight in reference ns per pixel·sample·face, measured on the Cornell box
/// at 128×96 on lavapipe (`bench --gi rsm_gather`, wall clock per stage: 10 to 14 over 100 …
/// 1,600 samples with one face).
fn cost(gi: &GiParams, shape: &FrameShape, cost: &mut Cost) {
    cost::rsm(gi, shape, cost);
    let pixels = shape.reduced_pixels(gi);
    let Ok(gi) = Settings::of(gi) else {
        return;
    };
    cost.add(
        "gather (pixels × gather_samples × light faces)",
        pixels * f64::from(gi.gather_samples) * f64::from(shape.light_faces.max(1)),
        12.0,
    );
}

/// What the table's ranges cannot say: the RSM within the light's faces.
fn validate(gi: &GiParams, faces: u32) -> Result<(), InvalidSetting> {
    let g = Settings::of(gi)?;
    InvalidSetting::check_range("rsm_size", g.rsm_size, 16, max_rsm_size(faces))
}

/// Staged copies behind [`views::GatherView`].
struct GatherCapture {
    rsm_size: u32,
    faces: u32,
    flux: TextureReadback,
    probe: wgpu::Buffer,
    samples: Vec<GatherSample>,
    radius: f32,
}

impl DebugCapture for GatherCapture {
    fn read(
        self: Box<Self>,
        ctx: &GpuContext,
        submission: Option<&wgpu::SubmissionIndex>,
    ) -> Result<DebugData, GpuError> {
        let flux = self.flux.begin_read();
        let probe = PendingMap::new(&self.probe);
        ctx.wait_for(submission)?;
        let flux_area: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&flux.finish()?);
        let probe: [f32; 4] = bytemuck::pod_read_unaligned(&probe.finish()?[..16]);
        Ok(DebugData(Arc::new(views::GatherView {
            rsm_size: self.rsm_size,
            faces: self.faces,
            flux_area,
            probe: read_probe(probe),
            samples: self.samples,
            radius: self.radius,
        })))
    }
}

/// The probe pixel's face and texel coordinates, if it shows a surface.
fn read_probe(p: [f32; 4]) -> Option<(usize, glam::Vec2)> {
    (p[3] != 0.0).then(|| (p[0] as usize, glam::Vec2::new(p[1], p[2])))
}

/// A frame's RSM, pattern and probe as read back (blocking; for tests).
#[derive(Clone, Debug)]
pub struct GatherReadback {
    pub rsm_size: u32,
    pub faces: u32,
    pub rsm_position: Vec<[f32; 4]>,
    pub rsm_normal: Vec<[f32; 4]>,
    pub rsm_flux_area: Vec<[f32; 4]>,
    /// `GlossySender::decode` reads these.
    pub rsm_glossy: Vec<[u32; 4]>,
    /// Each face's view-projection.
    /// Each atlas face's light and view-projection.
    pub face_view_proj: Vec<(u32, glam::Mat4)>,
    pub samples: Vec<GatherSample>,
    pub probe: Option<(usize, glam::Vec2)>,
}

/// Per-scene state of `rsm_gather`.
pub struct RsmGather {
    ctx: GpuContext,
    rsm_pass: RsmPass,
    rsm: Option<Rsm>,
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    params: wgpu::Buffer,
    faces: wgpu::Buffer,
    /// The pattern of `samples`' length, rewritten when the count changes.
    samples: Vec<GatherSample>,
    sample_buffer: Option<wgpu::Buffer>,
    probe: wgpu::Buffer,
    /// The last frame's faces and r_max (texels), for the view and the tests.
    last: Option<(Vec<(u32, glam::Mat4)>, f32)>,
}

fn storage(device: &wgpu::Device, label: &str, bytes: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes,
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

impl RsmGather {
    pub fn new(r: &SceneResources) -> Self {
        let device = &r.ctx.device;
        let layout = GATHER_GROUP.layout(device);
        let module = shaders::GATHER.create_module(device);
        Self {
            ctx: r.ctx.clone(),
            rsm_pass: RsmPass::new(device, &r.lights, &r.material_layout),
            rsm: None,
            pipeline: crate::passes::compute_pipeline(
                device,
                GATHER_GROUP.label,
                &layout,
                &module,
                "gather",
            ),
            layout,
            params: crate::passes::params_buffer(
                device,
                "rsm gather params",
                size_of::<GatherParams>(),
            ),
            faces: storage(
                device,
                "rsm gather faces",
                (MAX_FACES * size_of::<GatherFace>()) as u64,
            ),
            samples: Vec::new(),
            sample_buffer: None,
            probe: storage(device, "rsm gather probe", 16),
            last: None,
        }
    }

    /// The last frame's RSM, pattern and probe (blocking readback; for tests), or `None`
    /// before the first frame.
    pub fn read_back(&self) -> Result<Option<GatherReadback>, GpuError> {
        let (Some(rsm), Some((faces, _))) = (&self.rsm, &self.last) else {
            return Ok(None);
        };
        let ctx = &self.ctx;
        let read = |t: &Target| read_rgba_texture(ctx, &t.texture);
        let probe: [f32; 4] = bytemuck::pod_read_unaligned(&read_buffer(ctx, &self.probe)?[..16]);
        Ok(Some(GatherReadback {
            rsm_size: rsm.size,
            faces: rsm.faces,
            rsm_position: read(&rsm.position)?,
            rsm_normal: read(&rsm.normal)?,
            rsm_flux_area: read(&rsm.flux_area)?,
            rsm_glossy: read_rgba_u32_texture(ctx, &rsm.glossy.texture)?,
            face_view_proj: faces.clone(),
            samples: self.samples.clone(),
            probe: read_probe(probe),
        }))
    }
}

impl Method for RsmGather {
    fn encode(
        &mut self,
        frame: &FrameInputs,
        stages: &mut FrameStages,
    ) -> Result<Option<ProgressBuffer>, GiError> {
        let r = frame.resources;
        let g = Settings::of(frame.settings)?;
        let faces = frame.light_faces;
        let device = &r.ctx.device;
        let queue = &r.ctx.queue;
        // Emissive surfaces as one more face, gathered whole (gather.wgsl).
        let emitter_face =
            self.rsm_pass
                .prepare_emitters(device, &r.scene, g.rsm_size, emitters(frame.settings));
        let face_count = faces.len() as u32 + u32::from(emitter_face);
        let rsm = Rsm::reuse_or_new(
            &mut self.rsm,
            device,
            g.rsm_size,
            face_count,
            frame.visibility_buffer,
        );
        let rsm_faces = RsmFace::all(faces, g.rsm_size, g.senders);
        self.rsm_pass.set_faces(queue, &rsm_faces);
        let view_proj: Vec<(u32, glam::Mat4)> = faces
            .iter()
            .map(|(light, f)| (*light, f.view_proj))
            .chain(emitter_face.then_some((pattern::EMITTER_FACE, glam::Mat4::IDENTITY)))
            .collect();
        let gather_faces: Vec<GatherFace> = view_proj
            .iter()
            .map(|(light, m)| GatherFace {
                view_proj: m.to_cols_array_2d(),
                light: *light,
                emitter_samples: if *light == pattern::EMITTER_FACE {
                    crate::passes::rsm::emitter_samples(g.rsm_size)
                } else {
                    0
                },
                ..GatherFace::default()
            })
            .collect();
        queue.write_buffer(&self.faces, 0, bytemuck::cast_slice(&gather_faces));
        if self.samples.len() != g.gather_samples as usize || self.sample_buffer.is_none() {
            self.samples = pattern::pattern(g.gather_samples);
            let buffer = storage(
                device,
                "rsm gather samples",
                (self.samples.len() * size_of::<GatherSample>()) as u64,
            );
            queue.write_buffer(&buffer, 0, bytemuck::cast_slice(&self.samples));
            self.sample_buffer = Some(buffer);
        }
        let radius = g.gather_radius * g.rsm_size as f32;
        let params = GatherParams {
            width: frame.width,
            height: frame.height,
            rsm_size: g.rsm_size,
            faces: face_count,
            sample_count: g.gather_samples,
            radius,
            probe_x: frame.width / 2,
            probe_y: frame.height / 2,
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        self.last = Some((view_proj, radius));
        let gb = frame.gbuffer;
        let samples = self
            .sample_buffer
            .as_ref()
            .expect("the pattern was written above");
        let group = GatherResources {
            params: &self.params,
            camera: &r.camera,
            g_position: &gb.position,
            g_normal_roughness: &gb.normal_roughness,
            g_base_metallic: &gb.base_metallic,
            g_emissive_specular: &gb.emissive_specular,
            rsm_position: &rsm.position,
            rsm_normal: &rsm.normal,
            rsm_flux_area: &rsm.flux_area,
            faces: &self.faces,
            samples,
            probe: &self.probe,
            indirect_out: frame.indirect,
            brdf_table: &r.scene_buffers.brdf_table,
            rsm_glossy: &rsm.glossy,
        }
        .bind(device, &self.layout);
        self.rsm_pass
            .encode_stage(stages, rsm, &r.scene_buffers, frame.shared)?;
        stages.stage(stages::RSM_GATHER, |e| {
            crate::passes::dispatch_2d(
                e,
                GATHER_GROUP.label,
                &self.pipeline,
                &group,
                frame.width,
                frame.height,
            )
        })?;
        Ok(None)
    }

    fn capture_debug(
        &self,
        view: View,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Option<Box<dyn DebugCapture>> {
        if view != views::GATHER_SAMPLES.name {
            return None;
        }
        let (rsm, (_, radius)) = (self.rsm.as_ref()?, self.last.as_ref()?);
        let flux = TextureReadback::new(device, "rsm gather flux", rsm.width(), rsm.height(), 16);
        flux.encode_copy(encoder, &rsm.flux_area.texture);
        Some(Box::new(GatherCapture {
            rsm_size: rsm.size,
            faces: rsm.faces,
            flux,
            probe: stage_buffer(device, encoder, &self.probe),
            samples: self.samples.clone(),
            radius: *radius,
        }))
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}
