//! The frame: runs the shared passes in order for one scene, asks the frame's GI method
//! (`crate::gi`) for the indirect light in between, and reads the image back.
//!
//! No async runtime is involved; the offline `render` command and tests drive it directly.

use crate::gi::common::params::{indirect_downscale, roughness_override};
use crate::gi::{
    self, DebugCapture, DebugData, FrameInputs, GiError, Method, ProgressBuffer, ProgressSums,
    SceneResources,
};
use crate::gpu::{
    readback::{PendingMap, PendingRows, TextureReadback},
    timing::{timestamp_staging, FrameTimer, PendingTimings, StageTiming, TimingSource},
    GpuContext, GpuError,
};
use crate::passes::environment::{EnvironmentBuffer, FrameEnvironment};
use crate::passes::{
    direct_light::{DirectLightInputs, DirectLightPass, HDR_FORMAT},
    exposure::{Exposure, ExposureBindings, ExposurePass, ExposureResult},
    frame_uniforms::{
        face_count, lights_faces, CameraUniform, Coverage, LightsUniform, MAX_LIGHTS,
    },
    gbuffer::{GBuffer, GBufferPass},
    indirect_resolution::{FullTargets, IndirectResolutionPass, ReducedTargets, MAX_DOWNSCALE},
    scene_buffers::{SceneBuffers, MATERIAL_GROUP},
    shadow_map::{ShadowMap, ShadowMapPass},
    tonemap::{TonemapPass, LDR_FORMAT},
    yuv420::{Yuv420, Yuv420Layout, Yuv420Pass, Yuv420Target},
    Target, INDIRECT_FORMAT,
};
use crate::scene::environment as env;
use crate::scene::nodes::{deltas, owners, posed_vertices, posed_worlds, Poses};
use crate::scene::{Scene, Vertex};
use glam::Vec3;
use lightcast_protocol::{Camera, Environment, GiParams, Light, LightKind, View};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use wgpu::util::DeviceExt;

/// Largest shadow map side accepted (further limited by the adapter).
pub const MAX_SHADOW_MAP_SIZE: u32 = 8192;
/// Most shadow-map texels over all faces (a point light's six faces share this budget): 256 MiB
/// of depth.
pub const MAX_SHADOW_TEXELS: u64 = 8192 * 8192;
/// Most output pixels: the frame's targets take about 92 bytes per pixel (5.7 GiB at this size;
/// 6 of them the video planes and their read-back copies).
pub const MAX_OUTPUT_PIXELS: u64 = 8192 * 8192;

/// Output sizes whose targets a renderer keeps at once.
const MAX_SIZES: usize = 4;
/// Shadow maps a renderer keeps at once: sessions with different shadow-map sizes or light
/// kinds take turns without rebuilding them, while the largest (6 × 8192² depth texels,
/// 1.6 GB) are not kept many times over.
const MAX_SHADOW_MAPS: usize = 2;

/// What one frame should show.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub camera: Camera,
    /// The punctual lights, 1 to [`MAX_LIGHTS`].
    pub lights: Vec<Light>,
    /// Light from every direction (a sky), if any; its directions count against
    /// [`MAX_LIGHTS`] with the punctual lights.
    pub environment: Option<Environment>,
    pub exposure: Exposure,
    /// Side of the (square) shadow map per light face.
    pub shadow_map_size: u32,
    /// Also read back the linear HDR radiance (before exposure).
    pub capture_hdr: bool,
    /// Also read back what this debug view shows (see [`Frame::debug`]); `Final`: nothing.
    pub debug_view: View,
    /// Indirect light: method and parameters.
    pub gi: GiParams,
    /// The image history a progressive GI method may continue (a session's id); `None`
    /// starts afresh, so equal settings give equal pixels.
    pub history: Option<u64>,
    /// A session's still: a GI method that converges by steps shows its converged result
    /// when it can reach it within this frame (every bounce at once).
    pub still: bool,
    /// Read the output back as Y'CbCr 4:2:0 for a video encoder ([`Frame::yuv420`]) instead
    /// of RGBA8: 1.5 instead of 4 bytes per pixel cross the bus, and the CPU skips the colour
    /// conversion.
    pub yuv420: bool,
    /// Movable nodes away from their own pose (`scene::nodes::resolve_poses`); every pass sees
    /// them moved.
    pub poses: crate::scene::nodes::Poses,
    /// Also read back what the G-buffer holds at this texel (x, y from the top left):
    /// [`Frame::pick`], what a viewer's click picks.
    pub pick: Option<[u32; 2]>,
}

/// A rendered frame.
#[derive(Clone, Debug)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// sRGB RGBA8, rows top to bottom; empty when [`RenderSettings::yuv420`] asked for
    /// [`Frame::yuv420`] instead.
    pub rgba8: Vec<u8>,
    /// The output as Y'CbCr 4:2:0, when [`RenderSettings::yuv420`] was set.
    pub yuv420: Option<Yuv420>,
    /// Linear HDR radiance, RGBA, when [`RenderSettings::capture_hdr`] was set. Alpha 0 marks
    /// pixels no geometry covers.
    pub hdr: Option<Vec<[f32; 4]>>,
    /// Linear indirect radiance alone (RGBA), when [`RenderSettings::capture_hdr`] was set.
    pub indirect: Option<Vec<[f32; 4]>>,
    pub timings: Vec<StageTiming>,
    pub timing_source: TimingSource,
    /// The exposure scale applied before the tone curve.
    pub exposure_scale: f32,
    /// CPU time spent waiting for the read-back buffers to be mapped.
    pub readback_ms: f64,
    /// How far a progressive GI method (`reference`) has converged.
    pub progress: Option<FrameProgress>,
    /// The GI method's data for [`RenderSettings::debug_view`], when it has any.
    pub debug: Option<DebugData>,
    /// What [`RenderSettings::pick`] asked for.
    pub pick: Option<Picked>,
}

/// What the G-buffer holds at a picked texel ([`RenderSettings::pick`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Picked {
    pub texel: [u32; 2],
    /// The surface seen there; `None` where no geometry covers the texel.
    pub surface: Option<PickedSurface>,
}

/// A surface a texel shows, found from the G-buffer's id.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PickedSurface {
    /// World position (as posed in the frame).
    pub position: [f32; 3],
    /// A vertex of the triangle seen (an index into the scene's vertices).
    pub vertex: u32,
    /// The innermost node holding it and the movable node dragging it moves (ids; see
    /// [`crate::scene::nodes::picked`]).
    pub node: Option<u32>,
    pub movable: Option<u32>,
}

impl PickedSurface {
    /// Reads the G-buffer's `id` (a triangle, or a provoking vertex without primitive
    /// indices) and `position` texels back into the scene's terms.
    fn from_texels(scene: &Scene, triangle_ids: bool, id: u32, position: [f32; 4]) -> Option<Self> {
        // w = 0 is the G-buffer's clear value: background.
        if position[3] == 0.0 {
            return None;
        }
        let vertex = if triangle_ids {
            *scene.indices.get(id as usize * 3)?
        } else {
            id
        };
        let ids = crate::scene::nodes::picked(&scene.nodes, vertex);
        let id_of = |i: usize| scene.nodes[i].id;
        Some(Self {
            position: [position[0], position[1], position[2]],
            vertex,
            node: ids.map(|(inner, _)| id_of(inner)),
            movable: ids.and_then(|(_, mover)| mover.map(id_of)),
        })
    }
}

/// Convergence of a progressive method's image.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct FrameProgress {
    /// Samples per pixel accumulated, this frame's included.
    pub samples: u32,
    /// Root-mean-square standard error of the pixels' luminance over their mean luminance.
    pub relative_standard_error: f32,
}

impl Frame {
    pub fn total_ms(&self) -> f64 {
        self.timings.iter().map(|t| t.ms).sum()
    }
}

/// A setting the renderer cannot use, naming the field.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("invalid {field}: {reason}")]
    InvalidSetting { field: String, reason: String },
    #[error(transparent)]
    Gi(GiError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

impl From<GiError> for RenderError {
    fn from(e: GiError) -> Self {
        match e {
            GiError::Invalid(i) => invalid(i.field, i.reason),
            GiError::Gpu(g) => Self::Gpu(g),
            other => Self::Gi(other),
        }
    }
}

impl RenderError {
    /// The error as a caller that gave one light (`light`, not `lights`) names its fields:
    /// `light.direction` for `lights[0].direction`.
    pub fn for_one_light(self) -> Self {
        match self {
            Self::InvalidSetting { field, reason } if field.starts_with("lights[0].") => {
                Self::InvalidSetting {
                    field: field.replacen("lights[0].", "light.", 1),
                    reason,
                }
            }
            other => other,
        }
    }
}

fn invalid(field: impl Into<String>, reason: impl Into<String>) -> RenderError {
    RenderError::InvalidSetting {
        field: field.into(),
        reason: reason.into(),
    }
}

fn check_finite(field: impl Into<String>, values: &[f32]) -> Result<(), RenderError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(invalid(field, "must be finite numbers"))
    }
}

/// What is wrong with one light, if anything: the field (`position`, `direction`, `color`,
/// `intensity`, `cone`) and why.
fn check_light(l: &Light) -> Result<(), (&'static str, String)> {
    let finite = |field, values: &[f32]| {
        if values.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err((field, "must be finite numbers".to_string()))
        }
    };
    finite("position", &l.position)?;
    finite("direction", &l.direction)?;
    finite("color", &l.color)?;
    if Vec3::from(l.direction).length() < 1e-6 {
        return Err(("direction", "must not be zero".into()));
    }
    if l.color.iter().any(|&c| c < 0.0) {
        return Err(("color", "must not be negative".into()));
    }
    if !(l.intensity.is_finite() && l.intensity >= 0.0) {
        return Err(("intensity", "must be a finite number ≥ 0".into()));
    }
    if !(l.inner_cone.is_finite() && l.outer_cone.is_finite())
        || l.inner_cone < 0.0
        || l.outer_cone > std::f32::consts::FRAC_PI_2
        || l.inner_cone > l.outer_cone
    {
        return Err(("cone", "need 0 ≤ inner ≤ outer ≤ 90 degrees".into()));
    }
    Ok(())
}

impl RenderSettings {
    /// Rejects settings that would produce garbage or exceed the adapter.
    pub fn validate(&self, ctx: &GpuContext) -> Result<(), RenderError> {
        self.validate_for(ctx.device.limits().max_texture_dimension_2d)
    }

    /// The light faces the method renders (an RSM face each in the RSM-based methods): the
    /// punctual lights' and, unless the method samples the environment itself, its
    /// directions'.
    fn method_faces(&self) -> u32 {
        let coverage = self.coverage();
        face_count(&self.lights, coverage)
            + if gi::entry(self.gi.method).1.samples_environment {
                0
            } else {
                self.environment_directions() * coverage.faces(LightKind::Directional)
            }
    }

    /// What the frame's directional lights cover, as its method's `light_fit` says.
    pub fn coverage(&self) -> Coverage<'_> {
        match crate::gi::common::params::light_fit(&self.gi) {
            crate::gi::common::params::LightFit::View => Coverage::View {
                camera: &self.camera,
                aspect: self.width as f32 / self.height.max(1) as f32,
            },
            crate::gi::common::params::LightFit::Scene => Coverage::Scene,
        }
    }

    /// [`Self::validate`] for an adapter whose textures may be `max` texels wide.
    pub fn validate_for(&self, max: u32) -> Result<(), RenderError> {
        for (field, v) in [("width", self.width), ("height", self.height)] {
            if v == 0 || v > max {
                return Err(invalid(field, format!("{v} is outside 1..={max}")));
            }
        }
        let pixels = u64::from(self.width) * u64::from(self.height);
        if pixels > MAX_OUTPUT_PIXELS {
            return Err(invalid(
                "width",
                format!(
                    "{}×{} is {pixels} pixels; at most {MAX_OUTPUT_PIXELS} are allowed",
                    self.width, self.height
                ),
            ));
        }
        if let Some([x, y]) = self.pick {
            if x >= self.width || y >= self.height {
                return Err(invalid(
                    "pick",
                    format!(
                        "texel ({x}, {y}) is outside the {}×{} frame",
                        self.width, self.height
                    ),
                ));
            }
        }
        // None is a frame lit by emissive surfaces or an environment alone.
        if self.lights.len() > MAX_LIGHTS {
            return Err(invalid(
                "lights",
                format!(
                    "{} lights; at most {MAX_LIGHTS} are allowed",
                    self.lights.len()
                ),
            ));
        }
        if let Some(e) = &self.environment {
            let room = MAX_LIGHTS - self.lights.len();
            if !(1..=room).contains(&(e.directions as usize)) {
                return Err(invalid(
                    "environment.directions",
                    format!(
                        "{} is outside 1..={room}: with {} punctual lights, at most {MAX_LIGHTS} \
                         lights in all",
                        e.directions,
                        self.lights.len()
                    ),
                ));
            }
        }
        // Every light's faces share the shadow-map budget.
        let coverage = self.coverage();
        let directions = self.environment_directions() * coverage.faces(LightKind::Directional);
        let faces = u64::from((face_count(&self.lights, coverage) + directions).max(1));
        let max_by_budget = ((MAX_SHADOW_TEXELS / faces) as f64).sqrt() as u32;
        let max_shadow = max.min(MAX_SHADOW_MAP_SIZE).min(max_by_budget);
        if !(16..=max_shadow).contains(&self.shadow_map_size) {
            return Err(invalid(
                "shadow_map_size",
                format!("{} is outside 16..={max_shadow}", self.shadow_map_size),
            ));
        }
        let c = &self.camera;
        check_finite("camera.position", &c.position)?;
        check_finite("camera.target", &c.target)?;
        if Vec3::from(c.position).distance(Vec3::from(c.target)) < 1e-6 {
            return Err(invalid("camera.target", "must differ from camera.position"));
        }
        if !(c.fov_y_degrees > 0.5 && c.fov_y_degrees < 179.5) {
            return Err(invalid(
                "camera.fov_y_degrees",
                format!("{} is outside (0.5, 179.5)", c.fov_y_degrees),
            ));
        }
        for (i, l) in self.lights.iter().enumerate() {
            check_light(l)
                .map_err(|(field, reason)| invalid(format!("lights[{i}].{field}"), reason))?;
        }
        if let Some(e) = &self.environment {
            env::check(e, &self.lights)
                .map_err(|e| invalid(format!("environment.{}", e.field), e.reason))?;
        }
        // Powers of two: a reduced pixel covers whole output pixels at every size the API
        // allows in steps of 2 (H.264's even sizes), and the documented choices are 1, 2, 4.
        gi::check_method(self.gi.method).map_err(|e| invalid(e.field, e.reason))?;
        for p in gi::params::of(self.gi.method) {
            p.check(&p.value(&self.gi), true, None)
                .map_err(|reason| invalid(p.name, reason))?;
        }
        let downscale = indirect_downscale(&self.gi);
        if !(downscale.is_power_of_two() && downscale <= MAX_DOWNSCALE) {
            return Err(invalid(
                "indirect_downscale",
                format!("{downscale} is not one of 1, 2 or 4"),
            ));
        }
        let entry = gi::entry(self.gi.method).1;
        (entry.validate)(&self.gi, self.method_faces()).map_err(|e| invalid(e.field, e.reason))?;
        if let Exposure::Manual(s) = self.exposure {
            if !(s.is_finite() && s > 0.0) {
                return Err(invalid(
                    "exposure",
                    format!("{s} must be a positive number"),
                ));
            }
        }
        Ok(())
    }

    /// The environment's directional lights (0 without one).
    fn environment_directions(&self) -> u32 {
        self.environment.as_ref().map_or(0, |e| e.directions)
    }
}

/// Targets that depend on the output size.
struct SizedTargets {
    width: u32,
    height: u32,
    gbuffer: GBuffer,
    hdr: Target,
    ldr: Target,
    indirect: Target,
    /// `indirect` plus the light of the environment's directional lights, as the direct
    /// pass writes it: what a frame reports as its indirect light.
    indirect_out: Target,
    /// Staging buffers of the frames in flight (see [`PendingFrame`]).
    readbacks: Vec<ReadbackSet>,
    exposure: ExposureBindings,
    tonemap: wgpu::BindGroup,
    /// The output's Y'CbCr planes (video frames).
    yuv420: Yuv420Target,
    /// The reduced G-buffer and indirect target of the last downscale factor used (see
    /// [`crate::passes::indirect_resolution`]).
    reduced: Option<ReducedTargets>,
}

impl SizedTargets {
    /// The G-buffers GI methods may have bound: the full one and the reduced one.
    fn gbuffers(&self) -> impl Iterator<Item = &GBuffer> {
        std::iter::once(&self.gbuffer).chain(self.reduced.as_ref().map(|r| &r.gbuffer))
    }
}

/// Frames of one size that may be in flight at once (submitted, not yet read back).
pub const READBACK_RING: usize = 3;

/// Whether the G-buffer and the RSM are rasterised as visibility buffers and resolved
/// (`gbuffer_resolve`, `rsm_resolve`: `on`, needs triangle ids and a scene whose buffers fit a
/// storage binding) or every target rasterised (`off`); `auto`: on except on a CPU adapter
/// (measured slower there: `bench/results/lavapipe-visibility-buffer.md`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum VisibilityBuffer {
    #[default]
    Auto,
    On,
    Off,
}

/// [`VisibilityBuffer::On`] where the adapter or scene cannot.
#[derive(Clone, Copy, Debug, thiserror::Error)]
#[error(
    "--visibility-buffer on: this adapter has no triangle ids (PRIMITIVE_INDEX), or the \
     scene's vertex or index buffer exceeds its storage binding size"
)]
pub struct NoVisibilityBuffer;

/// Where one frame's results are copied for reading back.
struct ReadbackSet {
    ldr: TextureReadback,
    /// The Y'CbCr planes of a video frame.
    yuv420: wgpu::Buffer,
    hdr: TextureReadback,
    indirect: TextureReadback,
    exposure: wgpu::Buffer,
    timestamps: wgpu::Buffer,
    /// The GI method's [`ProgressSums`], when it is progressive.
    progress: wgpu::Buffer,
    /// A picked texel's G-buffer id (offset 0) and position (offset [`PICK_POSITION`]).
    pick: wgpu::Buffer,
    /// Held by the [`PendingFrame`] using the set.
    busy: Arc<AtomicBool>,
}

impl ReadbackSet {
    fn new(device: &wgpu::Device, width: u32, height: u32) -> Self {
        Self {
            ldr: TextureReadback::new(device, "ldr readback", width, height, 4),
            yuv420: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("yuv420 readback"),
                size: Yuv420Layout::new(width, height).bytes() as u64,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }),
            hdr: TextureReadback::new(device, "hdr readback", width, height, 8),
            indirect: TextureReadback::new(device, "indirect readback", width, height, 8),
            exposure: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("exposure readback"),
                size: std::mem::size_of::<ExposureResult>() as u64,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }),
            timestamps: timestamp_staging(device),
            progress: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("gi progress readback"),
                size: std::mem::size_of::<ProgressSums>() as u64,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }),
            pick: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pick readback"),
                size: PICK_POSITION + 16,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }),
            busy: Arc::new(AtomicBool::new(false)),
        }
    }
}

/// Where a picked texel's position lies in [`ReadbackSet::pick`], after the id: a
/// texture-to-buffer copy starts at a multiple of its texel size (16 bytes here); 256 keeps
/// the two copies apart whatever the formats.
const PICK_POSITION: u64 = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as u64;

/// Marks a readback set free again when the frame using it is done (or abandoned).
struct SetLease(Arc<AtomicBool>);

impl Drop for SetLease {
    fn drop(&mut self) {
        self.0.store(false, Ordering::Release);
    }
}

/// A submitted frame whose results are on their way to staging buffers. [`PendingFrame::wait`]
/// blocks until they are readable; it may run on another thread while the renderer encodes
/// the next frame.
pub struct PendingFrame {
    ctx: GpuContext,
    width: u32,
    height: u32,
    /// RGBA8, or the Y'CbCr planes of a video frame.
    output: Output,
    hdr: Option<(TextureReadback, TextureReadback)>,
    exposure: wgpu::Buffer,
    /// Samples accumulated and the staging buffer of the [`ProgressSums`].
    progress: Option<(u32, wgpu::Buffer)>,
    /// The GI method's staged copies for the debug view.
    debug: Option<Box<dyn DebugCapture>>,
    pick: Option<PendingPick>,
    timings: PendingTimings,
    timing_source: TimingSource,
    submission: Option<wgpu::SubmissionIndex>,
    _lease: SetLease,
}

/// A picked texel's staging buffer and what turns its id into the scene's terms.
struct PendingPick {
    texel: [u32; 2],
    buffer: wgpu::Buffer,
    scene: Arc<Scene>,
    triangle_ids: bool,
}

impl PendingPick {
    fn read(self, map: PendingMap) -> Result<Picked, GpuError> {
        let bytes = map.finish()?;
        let id: u32 = bytemuck::pod_read_unaligned(&bytes[..4]);
        let at = PICK_POSITION as usize;
        let position: [f32; 4] = bytemuck::pod_read_unaligned(&bytes[at..at + 16]);
        Ok(Picked {
            texel: self.texel,
            surface: PickedSurface::from_texels(&self.scene, self.triangle_ids, id, position),
        })
    }
}

/// Where a frame's output is read back from.
enum Output {
    Rgba8(TextureReadback),
    Yuv420(Yuv420Layout, wgpu::Buffer),
}

/// An [`Output`] being mapped.
enum Reading {
    Rgba8(PendingRows),
    Yuv420(Yuv420Layout, PendingMap),
}

impl PendingFrame {
    /// Waits for the GPU to finish the frame and reads it back.
    /// Waits until the frame's GPU work has finished, reading nothing back (a chunk of a
    /// longer render whose results stay on the GPU).
    pub fn wait_submitted(self) -> Result<(), GpuError> {
        self.ctx.wait_for(self.submission.as_ref())
    }

    pub fn wait(self) -> Result<Frame, GpuError> {
        let started = std::time::Instant::now();
        let output = match &self.output {
            Output::Rgba8(ldr) => Reading::Rgba8(ldr.begin_read()),
            Output::Yuv420(layout, buffer) => Reading::Yuv420(*layout, PendingMap::new(buffer)),
        };
        let hdr = self
            .hdr
            .as_ref()
            .map(|(hdr, indirect)| (hdr.begin_read(), indirect.begin_read()));
        let exposure = PendingMap::new(&self.exposure);
        let progress = self
            .progress
            .as_ref()
            .map(|(samples, buffer)| (*samples, PendingMap::new(buffer)));
        let pick = self.pick.as_ref().map(|p| PendingMap::new(&p.buffer));
        let timings = self.timings.begin();
        self.ctx.wait_for(self.submission.as_ref())?;
        let (rgba8, yuv420) = match output {
            Reading::Rgba8(ldr) => (ldr.finish()?, None),
            Reading::Yuv420(layout, map) => (
                Vec::new(),
                Some(Yuv420 {
                    layout,
                    data: map.finish()?,
                }),
            ),
        };
        let (hdr, indirect) = match hdr {
            Some((h, i)) => (
                Some(rgba16f_to_f32(&h.finish()?)),
                Some(rgba16f_to_f32(&i.finish()?)),
            ),
            None => (None, None),
        };
        let exposure: ExposureResult = bytemuck::pod_read_unaligned(&exposure.finish()?);
        let progress = match progress {
            Some((samples, map)) => {
                let sums: ProgressSums = bytemuck::pod_read_unaligned(&map.finish()?);
                Some(FrameProgress {
                    samples,
                    relative_standard_error: sums.relative_standard_error(),
                })
            }
            None => None,
        };
        let debug = match self.debug {
            Some(capture) => Some(capture.read(&self.ctx, self.submission.as_ref())?),
            None => None,
        };
        let pick = match (self.pick, pick) {
            (Some(p), Some(map)) => Some(p.read(map)?),
            _ => None,
        };
        Ok(Frame {
            width: self.width,
            height: self.height,
            rgba8,
            yuv420,
            hdr,
            indirect,
            timings: timings.finish()?,
            timing_source: self.timing_source,
            exposure_scale: exposure.scale,
            readback_ms: started.elapsed().as_secs_f64() * 1e3,
            progress,
            debug,
            pick,
        })
    }
}

/// Renders one scene; keeps GPU resources between frames.
pub struct Renderer {
    /// The context, scene, its buffers and the camera and light parameters every pass and
    /// GI method reads.
    shared: SceneResources,
    timer: FrameTimer,
    gbuffer_pass: GBufferPass,
    shadow_pass: ShadowMapPass,
    direct_pass: DirectLightPass,
    exposure_pass: ExposurePass,
    tonemap_pass: TonemapPass,
    yuv420_pass: Yuv420Pass,
    resolution_pass: IndirectResolutionPass,
    /// Targets of the most recently used output sizes, most recent first (sessions of
    /// different sizes share one renderer).
    sized: Vec<SizedTargets>,
    /// Shadow maps of the most recently used size and face count, most recent first.
    shadow_maps: Vec<ShadowMap>,
    /// The GI methods used so far, by index in [`gi::REGISTRY`] (created on first use).
    methods: Vec<Option<Box<dyn Method>>>,
    /// The last environment evaluated, with what it was evaluated for (see
    /// [`Self::environment`]).
    environment: Option<(EnvironmentKey, Arc<FrameEnvironment>)>,
    /// The packed environment the direct-light pass reads.
    environment_buffer: EnvironmentBuffer,
    /// The scene has emissive triangles (`scene::emitters::has_emitters`).
    has_emitters: bool,
    /// The poses the vertex buffer holds its movable nodes in, and each vertex's innermost
    /// node (`scene::nodes::owners`, worked out on the first pose).
    poses: Poses,
    owners: Option<Vec<u32>>,
    /// Passes that do not depend on the camera reuse their targets while the lights and
    /// poses stay the same (`passes::reuse`); off: every pass runs every frame.
    reuse: bool,
    /// Part of what those targets are made from: bumped after a frame whose encoding failed
    /// part-way (its passes were recorded as made but never submitted), so nothing made
    /// before it is reused.
    reuse_epoch: u64,
    /// A frame is being encoded (set until [`Self::submit`] returns it).
    encoding: bool,
    /// The G-buffer and the RSM are rasterised as visibility buffers and resolved by compute
    /// passes where the device has triangle ids (`passes::gbuffer`, `passes::rsm`); off:
    /// rasterised whole. On by default except on CPU adapters, where the resolves cost more
    /// than the raster output they save (lavapipe, Cornell box at 1280×720: G-buffer raster
    /// 15.7 → 6.8 ms, resolve 23.7 ms; RSM at 1024² raster 34.7 → 13.4 ms, resolve 47.2 ms;
    /// bench/results/lavapipe-visibility-buffer.md).
    visibility_buffer: bool,
}

/// What an environment's evaluation depends on: its parameters and, for a sky, its sun.
#[derive(Clone, Debug, PartialEq)]
struct EnvironmentKey {
    environment: Environment,
    sun: Option<Light>,
}

impl Renderer {
    pub fn new(ctx: GpuContext, scene: impl Into<Arc<Scene>>) -> Self {
        let scene = scene.into();
        let device = &ctx.device;
        let uniform = |label, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: crate::passes::PARAMS_USAGE,
            })
        };
        let camera_buffer = uniform(
            "camera",
            bytemuck::bytes_of(&bytemuck::Zeroable::zeroed() as &CameraUniform),
        );
        let lights_buffer = uniform(
            "lights",
            bytemuck::bytes_of(&bytemuck::Zeroable::zeroed() as &LightsUniform),
        );
        let material_layout = MATERIAL_GROUP.layout(device);
        Self {
            has_emitters: crate::scene::emitters::has_emitters(&scene),
            timer: FrameTimer::new(&ctx),
            gbuffer_pass: GBufferPass::new(
                device,
                &camera_buffer,
                &material_layout,
                ctx.primitive_index,
                resolve_fits(device, &scene),
            ),
            shadow_pass: ShadowMapPass::new(device, &material_layout),
            direct_pass: DirectLightPass::new(device),
            exposure_pass: ExposurePass::new(device),
            tonemap_pass: TonemapPass::new(device),
            yuv420_pass: Yuv420Pass::new(device),
            resolution_pass: IndirectResolutionPass::new(device),
            sized: Vec::new(),
            shadow_maps: Vec::new(),
            methods: gi::REGISTRY.iter().map(|_| None).collect(),
            environment: None,
            environment_buffer: EnvironmentBuffer::new(device),
            poses: Poses::new(),
            owners: None,
            reuse: true,
            reuse_epoch: 0,
            encoding: false,
            visibility_buffer: ctx.info.device_type != wgpu::DeviceType::Cpu,
            shared: SceneResources {
                scene_buffers: SceneBuffers::new(device, &ctx.queue, &scene, &material_layout),
                camera: camera_buffer,
                lights: lights_buffer,
                material_layout,
                scene,
                ctx,
            },
        }
    }

    pub fn context(&self) -> &GpuContext {
        &self.shared.ctx
    }

    /// Rewrites the vertices of the nodes whose world transform `poses` changes from what the
    /// vertex buffer holds: the subtrees of the outermost such nodes, each one write (queued
    /// before the next submission, so frames in flight keep what they were encoded with).
    fn apply_poses(&mut self, poses: &Poses) {
        if *poses == self.poses {
            return;
        }
        let scene = &self.shared.scene;
        let owners = self
            .owners
            .get_or_insert_with(|| owners(&scene.nodes, scene.vertices.len() as u32));
        let before = posed_worlds(&scene.nodes, &self.poses);
        let after = posed_worlds(&scene.nodes, poses);
        let deltas = deltas(&scene.nodes, &after);
        let mut written_to = 0;
        for (i, node) in scene.nodes.iter().enumerate() {
            // A changed node's descendants lie in its range, written with it.
            if before[i] == after[i] || node.vertices.start < written_to {
                continue;
            }
            let moved = posed_vertices(&scene.vertices, owners, &deltas, node.vertices.clone());
            let offset = u64::from(node.vertices.start) * std::mem::size_of::<Vertex>() as u64;
            self.shared.ctx.queue.write_buffer(
                &self.shared.scene_buffers.vertices,
                offset,
                bytemuck::cast_slice(&moved),
            );
            written_to = node.vertices.end;
        }
        self.poses = poses.clone();
    }

    pub fn scene(&self) -> &Scene {
        &self.shared.scene
    }

    /// Turns reuse of the camera-independent passes' targets on or off (on by default; off
    /// measures what it saves): the images are the same either way, bit for bit.
    pub fn set_reuse(&mut self, on: bool) {
        self.reuse = on;
    }

    /// Turns the visibility-buffer G-buffer and RSM on or off (by default on except on CPU
    /// adapters; they need triangle ids; off rasterises every target): the images agree within
    /// `gpu_visibility_buffer.rs`'s tolerances.
    pub fn set_visibility_buffer(&mut self, on: bool) {
        if on != self.visibility_buffer {
            // The G-buffers are made for one or the other: made again at the next frame (the
            // methods' RSMs are remade when a frame asks for the other kind).
            self.visibility_buffer = on;
            self.sized.clear();
            for method in self.methods.iter_mut().flatten() {
                method.retain_targets(&[]);
            }
        }
    }

    /// Applies an operator's or a benchmark's choice: `auto` leaves the default, `on` fails
    /// where the device or scene cannot ([`Self::visibility_buffer`] stays false).
    pub fn choose_visibility_buffer(
        &mut self,
        choice: VisibilityBuffer,
    ) -> Result<(), NoVisibilityBuffer> {
        match choice {
            VisibilityBuffer::Auto => {}
            VisibilityBuffer::On => {
                self.set_visibility_buffer(true);
                if !self.visibility_buffer() {
                    return Err(NoVisibilityBuffer);
                }
            }
            VisibilityBuffer::Off => self.set_visibility_buffer(false),
        }
        Ok(())
    }

    /// Whether frames resolve the G-buffer and the RSM from visibility buffers: asked for, and
    /// the device and scene allow it (triangle ids; vertex and index buffers within a storage
    /// binding).
    pub fn visibility_buffer(&self) -> bool {
        self.visibility_buffer && self.gbuffer_pass.has_visibility_buffer()
    }

    /// Whether indirect light blends the light caches of each triangle's three vertices
    /// (primitive indices available) rather than using the provoking vertex's.
    pub fn triangle_ids(&self) -> bool {
        self.shared.ctx.primitive_index
    }

    pub fn timing_source(&self) -> TimingSource {
        self.timer.source()
    }

    /// The scene's instance of the registered method at `index` in [`gi::REGISTRY`], created
    /// on first use.
    fn method_at(&mut self, index: usize) -> Result<&mut Box<dyn Method>, RenderError> {
        let slot = &mut self.methods[index];
        if slot.is_none() {
            *slot = Some((gi::REGISTRY[index].create)(&self.shared)?);
        }
        Ok(slot.as_mut().expect("the method was just created"))
    }

    /// Hands `method` the scene data its precomputation built (see [`gi::precompute`]).
    pub fn set_scene_data(
        &mut self,
        method: gi::GiMethod,
        data: &gi::precompute::SceneData,
    ) -> Result<(), RenderError> {
        self.method_at(gi::entry(method).0)?.set_scene_data(data)?;
        Ok(())
    }

    /// The scene's instance of GI method type `M` (e.g. to read its state in tests), created
    /// on first use.
    pub fn gi<M: Method>(&mut self) -> Result<&mut M, RenderError> {
        let index = gi::REGISTRY
            .iter()
            .position(|e| (e.type_id)() == std::any::TypeId::of::<M>())
            .unwrap_or_else(|| panic!("{} is not in gi::REGISTRY", std::any::type_name::<M>()));
        let method = self.method_at(index)?;
        Ok(method
            .as_any_mut()
            .downcast_mut()
            .expect("the registry entry creates its own type"))
    }

    /// The scene's instance of GI method type `M`, if a frame or [`Self::gi`] created it.
    pub fn gi_if_created<M: Method>(&self) -> Option<&M> {
        self.methods
            .iter()
            .flatten()
            .find_map(|m| m.as_any().downcast_ref())
    }

    /// Makes the targets of `width`×`height` the first of [`Self::sized`].
    fn ensure_targets(&mut self, width: u32, height: u32) -> Result<(), GpuError> {
        let thin = self.visibility_buffer();
        if let Some(i) = self
            .sized
            .iter()
            .position(|s| s.width == width && s.height == height)
        {
            let hit = self.sized.remove(i);
            self.sized.insert(0, hit);
            return Ok(());
        }
        // Release the least recently used targets first so a new size does not need them all
        // in memory at once.
        self.sized.truncate(MAX_SIZES - 1);
        let live: Vec<&GBuffer> = self.sized.iter().flat_map(SizedTargets::gbuffers).collect();
        for method in self.methods.iter_mut().flatten() {
            method.retain_targets(&live);
        }
        let device = &self.shared.ctx.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let hdr = Target::new(
            device,
            "hdr",
            width,
            height,
            HDR_FORMAT,
            wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        let ldr = Target::new(
            device,
            "ldr",
            width,
            height,
            LDR_FORMAT,
            wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        let yuv420 = self
            .yuv420_pass
            .target(device, &self.shared.ctx.queue, &ldr, width, height);
        let indirect = Target::new(
            device,
            "indirect",
            width,
            height,
            INDIRECT_FORMAT,
            wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_SRC,
        );
        let indirect_out = Target::new(
            device,
            "indirect out",
            width,
            height,
            INDIRECT_FORMAT,
            wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
        );
        let exposure = self.exposure_pass.bind(device, &hdr, width, height);
        let tonemap = self
            .tonemap_pass
            .bind(device, &hdr, &self.exposure_pass.result, &ldr);
        let sized = SizedTargets {
            width,
            height,
            gbuffer: GBuffer::new(device, width, height, thin),
            readbacks: (0..READBACK_RING)
                .map(|_| ReadbackSet::new(device, width, height))
                .collect(),
            indirect,
            indirect_out,
            hdr,
            ldr,
            exposure,
            tonemap,
            yuv420,
            reduced: None,
        };
        check_allocation(scope, format!("{width}×{height} frame targets"))?;
        self.sized.insert(0, sized);
        Ok(())
    }

    /// Gives the first of [`Self::sized`] reduced targets at 1/`factor` of its size, or
    /// none for `factor` 1.
    fn ensure_reduced(&mut self, factor: u32) -> Result<(), GpuError> {
        let Some(sized) = self.sized.first_mut() else {
            return Ok(());
        };
        if sized.reduced.as_ref().map(|r| r.factor) == Some(factor) {
            return Ok(());
        }
        let released = sized.reduced.take();
        if released.is_some() {
            let live: Vec<&GBuffer> = self.sized.iter().flat_map(SizedTargets::gbuffers).collect();
            for method in self.methods.iter_mut().flatten() {
                method.retain_targets(&live);
            }
        }
        if factor == 1 {
            return Ok(());
        }
        let device = &self.shared.ctx.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let sized = &mut self.sized[0];
        let reduced = self.resolution_pass.targets(
            device,
            &FullTargets {
                camera: &self.shared.camera,
                gbuffer: &sized.gbuffer,
                indirect: &sized.indirect,
                width: sized.width,
                height: sized.height,
            },
            factor,
        );
        check_allocation(scope, format!("1/{factor} resolution indirect targets"))?;
        sized.reduced = Some(reduced);
        Ok(())
    }

    /// Makes the shadow map of `size`² × `faces` the first of [`Self::shadow_maps`].
    fn ensure_shadow_map(&mut self, size: u32, faces: u32) -> Result<(), GpuError> {
        let found = self
            .shadow_maps
            .iter()
            .position(|m| m.size == size && m.faces() == faces);
        if let Some(i) = found {
            let hit = self.shadow_maps.remove(i);
            self.shadow_maps.insert(0, hit);
            return Ok(());
        }
        self.shadow_maps.truncate(MAX_SHADOW_MAPS - 1);
        let scope = self
            .shared
            .ctx
            .device
            .push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let map = ShadowMap::new(&self.shared.ctx.device, size, faces);
        check_allocation(scope, format!("{faces}×{size}² shadow map"))?;
        self.shadow_maps.insert(0, map);
        Ok(())
    }

    /// The frame's environment evaluated (see [`FrameEnvironment`]), re-evaluated only when
    /// it or its sun changed.
    fn environment(
        &mut self,
        settings: &RenderSettings,
    ) -> Result<Option<Arc<FrameEnvironment>>, RenderError> {
        let Some(environment) = &settings.environment else {
            return Ok(None);
        };
        let key = EnvironmentKey {
            environment: environment.clone(),
            sun: (environment.kind == lightcast_protocol::EnvironmentKind::Sky)
                .then(|| env::sun(&settings.lights).cloned())
                .flatten(),
        };
        if let Some((k, evaluated)) = &self.environment {
            if *k == key {
                return Ok(Some(Arc::clone(evaluated)));
            }
        }
        let evaluated = Arc::new(
            FrameEnvironment::new(
                environment,
                &settings.lights,
                self.shared.scene.environment_image.as_deref(),
            )
            .map_err(|e| invalid(format!("environment.{}", e.field), e.reason))?,
        );
        self.environment = Some((key, Arc::clone(&evaluated)));
        Ok(Some(evaluated))
    }

    /// Renders one frame and reads it back (blocking).
    pub fn render(&mut self, settings: &RenderSettings) -> Result<Frame, RenderError> {
        Ok(self.submit(settings)?.wait()?)
    }

    /// Encodes and submits one frame without waiting for it. Up to [`READBACK_RING`] frames
    /// of one size may be pending; beyond that this waits for the oldest to be read.
    pub fn submit(&mut self, settings: &RenderSettings) -> Result<PendingFrame, RenderError> {
        if std::mem::take(&mut self.encoding) {
            self.reuse_epoch += 1;
        }
        settings.validate(&self.shared.ctx)?;
        // Emissive surfaces are one RSM face more in the methods that light from them
        // (`passes::rsm::EmitterFace`), where the scene has any.
        if self.has_emitters
            && gi::common::params::emitters(&settings.gi)
            && gi::lights_from_emitters(settings.gi.method)
        {
            (gi::entry(settings.gi.method).1.validate)(&settings.gi, settings.method_faces() + 1)
                .map_err(|e| invalid(e.field, e.reason))?;
        }
        let (width, height) = (settings.width, settings.height);
        let environment = self.environment(settings)?;
        let (method_index, entry) = gi::entry(settings.gi.method);
        if !settings.poses.is_empty() {
            (entry.follows_moved_nodes)(&settings.gi).map_err(|e| invalid(e.field, e.reason))?;
        }
        self.apply_poses(&settings.poses);
        // A method that does not sample the environment lights with its directions too.
        let mut lights = settings.lights.clone();
        if let (Some(e), false) = (&environment, entry.samples_environment) {
            lights.extend(e.lights.iter().cloned());
        }
        self.ensure_targets(width, height)?;
        // A frame without punctual lights keeps one face: a texture array has a layer at least.
        let coverage = settings.coverage();
        self.ensure_shadow_map(
            settings.shadow_map_size,
            face_count(&lights, coverage).max(1),
        )?;
        self.environment_buffer.set(
            &self.shared.ctx.device,
            &self.shared.ctx.queue,
            environment.as_deref(),
        );
        let downscale = indirect_downscale(&settings.gi);
        self.ensure_reduced(downscale)?;
        // Created before the targets are borrowed below.
        self.method_at(method_index)?;
        let (Some(sized), Some(shadow_map)) = (self.sized.first(), self.shadow_maps.first()) else {
            unreachable!("targets were just ensured");
        };

        let bounds = &self.shared.scene.bounds;
        let camera = CameraUniform::new(
            &settings.camera,
            width as f32 / height as f32,
            bounds,
            roughness_override(&settings.gi),
        );
        let light_faces = lights_faces(&lights, bounds, coverage);
        let lights_uniform = LightsUniform::with_punctual(
            &lights,
            settings.lights.len(),
            &light_faces,
            settings.shadow_map_size,
        );
        let queue = &self.shared.ctx.queue;
        queue.write_buffer(&self.shared.camera, 0, bytemuck::bytes_of(&camera));
        queue.write_buffer(&self.shared.lights, 0, bytemuck::bytes_of(&lights_uniform));
        self.shadow_pass
            .set_faces(queue, &lights_uniform.layer_view_proj());
        self.exposure_pass
            .prepare(queue, &sized.exposure, settings.exposure);
        let direct_bind_group = self.direct_pass.bind(
            &self.shared.ctx.device,
            &DirectLightInputs {
                camera: &self.shared.camera,
                lights: &self.shared.lights,
                gbuffer: &sized.gbuffer,
                shadow: shadow_map,
                indirect: &sized.indirect,
                environment: &self.environment_buffer.buffer,
                brdf_table: &self.shared.scene_buffers.brdf_table,
                hdr: &sized.hdr,
                indirect_out: &sized.indirect_out,
            },
        );

        // What the passes that do not depend on the camera are made from: the lights uniform
        // (their faces' matrices included) and the poses the vertex buffer holds.
        let shared: Option<Vec<u8>> = self.reuse.then(|| {
            [
                &self.reuse_epoch.to_le_bytes(),
                bytemuck::bytes_of(&lights_uniform),
                &crate::passes::reuse::pose_bytes(&settings.poses),
            ]
            .concat()
        });
        self.encoding = true;
        let set = free_set(&self.shared.ctx, &sized.readbacks)?;
        let lease = SetLease(Arc::clone(&set.busy));
        let thin = self.visibility_buffer();
        let mut stages = self.timer.begin(&self.shared.ctx);
        if shadow_map.made.holds(shared.as_deref()) {
            stages.reused(crate::passes::stages::SHADOW_MAP);
        } else {
            stages
                .stage(crate::passes::stages::SHADOW_MAP, |e| {
                    self.shadow_pass
                        .encode(e, shadow_map, &self.shared.scene_buffers)
                })
                .inspect_err(|_| shadow_map.made.forget())?;
        }
        let mut resolve = false;
        stages.stage(crate::passes::stages::GBUFFER, |e| {
            resolve = self
                .gbuffer_pass
                .encode(e, &sized.gbuffer, &self.shared.scene_buffers, thin);
        })?;
        if resolve {
            stages.stage(crate::passes::stages::GBUFFER_RESOLVE, |e| {
                self.gbuffer_pass.encode_resolve(
                    &self.shared.ctx.device,
                    e,
                    &sized.gbuffer,
                    &self.shared.scene_buffers,
                )
            })?;
        }
        // A downscaled frame's GI method sees only the reduced G-buffer and target.
        let reduced = sized.reduced.as_ref().filter(|_| downscale > 1);
        if let Some(r) = reduced {
            self.resolution_pass
                .prepare(queue, r, settings.camera.fov_y_degrees, height);
            stages.stage(crate::passes::stages::GBUFFER_REDUCE, |e| {
                self.resolution_pass.encode_reduce(e, r)
            })?;
        }
        let frame = FrameInputs {
            resources: &self.shared,
            width: reduced.map_or(width, |r| r.width),
            height: reduced.map_or(height, |r| r.height),
            camera: &settings.camera,
            lights: &lights,
            light_faces: &light_faces,
            environment: environment.as_ref(),
            settings: &settings.gi,
            gbuffer: reduced.map_or(&sized.gbuffer, |r| &r.gbuffer),
            shadow: shadow_map,
            indirect: reduced.map_or(&sized.indirect, |r| &r.indirect),
            history: settings.history,
            still: settings.still,
            poses: &settings.poses,
            shared: shared.as_deref(),
            debug_view: settings.debug_view,
            visibility_buffer: thin,
        };
        let Some(method) = self.methods[method_index].as_mut() else {
            unreachable!("the method was just created");
        };
        let progress: Option<ProgressBuffer> = method.encode(&frame, &mut stages)?;
        if let Some(r) = reduced {
            stages.stage(crate::passes::stages::INDIRECT_UPSAMPLE, |e| {
                self.resolution_pass.encode_upsample(e, r, width, height)
            })?;
        }
        stages.stage(crate::passes::stages::DIRECT_LIGHT, |e| {
            self.direct_pass
                .encode(e, &direct_bind_group, width, height)
        })?;
        if settings.exposure == Exposure::Auto {
            stages.stage(crate::passes::stages::EXPOSURE, |e| {
                self.exposure_pass
                    .encode(e, &sized.exposure, settings.exposure)
            })?;
        }
        stages.stage(crate::passes::stages::TONEMAP, |e| {
            self.tonemap_pass.encode(e, &sized.tonemap, width, height)
        })?;
        if settings.yuv420 {
            stages.stage(crate::passes::stages::YUV420, |e| {
                self.yuv420_pass.encode(e, &sized.yuv420);
            })?;
        }
        let mut debug = None;
        stages.stage(crate::passes::stages::READBACK_COPY, |e| {
            debug = method.capture_debug(settings.debug_view, &self.shared.ctx.device, e);
            if settings.yuv420 {
                e.copy_buffer_to_buffer(&sized.yuv420.planes, 0, &set.yuv420, 0, None);
            } else {
                set.ldr.encode_copy(e, &sized.ldr.texture);
            }
            if settings.capture_hdr {
                set.hdr.encode_copy(e, &sized.hdr.texture);
                set.indirect.encode_copy(e, &sized.indirect_out.texture);
            }
            e.copy_buffer_to_buffer(&self.exposure_pass.result, 0, &set.exposure, 0, None);
            if let Some(p) = &progress {
                e.copy_buffer_to_buffer(&p.buffer, 0, &set.progress, 0, None);
            }
            if let Some(texel) = settings.pick {
                encode_pick_copy(e, &sized.gbuffer, texel, &set.pick);
            }
        })?;
        let (timings, submission) = stages.submit_frame(&set.timestamps);
        self.encoding = false;
        Ok(PendingFrame {
            ctx: self.shared.ctx.clone(),
            width,
            height,
            output: if settings.yuv420 {
                Output::Yuv420(sized.yuv420.layout, set.yuv420.clone())
            } else {
                Output::Rgba8(set.ldr.clone())
            },
            hdr: settings
                .capture_hdr
                .then(|| (set.hdr.clone(), set.indirect.clone())),
            exposure: set.exposure.clone(),
            progress: progress.map(|p| (p.samples, set.progress.clone())),
            debug,
            pick: settings.pick.map(|texel| PendingPick {
                texel,
                buffer: set.pick.clone(),
                scene: Arc::clone(&self.shared.scene),
                triangle_ids: self.triangle_ids(),
            }),
            timings,
            timing_source: self.timer.source(),
            submission,
            _lease: lease,
        })
    }
}

/// Copies the G-buffer's id and position at `texel` into `staging` ([`ReadbackSet::pick`]).
fn encode_pick_copy(
    encoder: &mut wgpu::CommandEncoder,
    gbuffer: &GBuffer,
    texel: [u32; 2],
    staging: &wgpu::Buffer,
) {
    for (target, offset) in [(&gbuffer.id, 0), (&gbuffer.position, PICK_POSITION)] {
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &target.texture,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: texel[0],
                    y: texel[1],
                    z: 0,
                },
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: staging,
                layout: wgpu::TexelCopyBufferLayout {
                    offset,
                    bytes_per_row: None,
                    rows_per_image: None,
                },
            },
            wgpu::Extent3d {
                width: 1,
                height: 1,
                depth_or_array_layers: 1,
            },
        );
    }
}

/// A readback set no pending frame holds, marked busy. Waits (polling the device) while all
/// are held by frames other threads are still reading.
fn free_set<'a>(ctx: &GpuContext, sets: &'a [ReadbackSet]) -> Result<&'a ReadbackSet, GpuError> {
    let started = std::time::Instant::now();
    loop {
        if let Some(set) = sets.iter().find(|s| {
            s.busy
                .compare_exchange(false, true, Ordering::AcqRel, Ordering::Acquire)
                .is_ok()
        }) {
            return Ok(set);
        }
        if started.elapsed() > std::time::Duration::from_secs(30) {
            return Err(GpuError::Map(
                "every readback buffer is held by a frame nobody reads".into(),
            ));
        }
        ctx.device.poll(wgpu::PollType::Poll)?;
        std::thread::sleep(std::time::Duration::from_micros(200));
    }
}

/// Turns an out-of-memory error captured while allocating `what` into a [`GpuError`].
fn check_allocation(scope: wgpu::ErrorScopeGuard, what: String) -> Result<(), GpuError> {
    match pollster::block_on(scope.pop()) {
        None => Ok(()),
        Some(e) => Err(GpuError::OutOfMemory {
            what,
            message: e.to_string(),
        }),
    }
}

/// RGBA16F texels as f32.
fn rgba16f_to_f32(bytes: &[u8]) -> Vec<[f32; 4]> {
    let halves: Vec<half::f16> = bytemuck::pod_collect_to_vec(bytes);
    halves
        .chunks_exact(4)
        .map(|c| [c[0].to_f32(), c[1].to_f32(), c[2].to_f32(), c[3].to_f32()])
        .collect()
}

/// Whether the visibility buffers' resolves can bind `scene`'s vertex and index buffers whole
/// (a scene beyond the device's storage binding size keeps the rasterised G-buffer and RSM).
fn resolve_fits(device: &wgpu::Device, scene: &Scene) -> bool {
    let max = device.limits().max_storage_buffer_binding_size;
    let bytes = |n: usize, each: usize| (n as u64).saturating_mul(each as u64);
    bytes(scene.vertices.len(), std::mem::size_of::<Vertex>()) <= max
        && bytes(scene.indices.len(), 4) <= max
}
