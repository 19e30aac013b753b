//! Global illumination: the indirect light of a frame, computed by exactly one method.
//!
//! The renderer runs the shared stages (shadow map, G-buffer, direct light, exposure, tone
//! map, readback) and asks the frame's [`Method`] to fill the indirect buffer in between. A
//! method is one module with its WGSL in `shaders/<method>/`:
//!
//! - [`none`]: no indirect light.
//! - [`lightskin`]: LightSkin light caches fed by Bidirectional Reflective Shadow Maps (seed
//!   paper 004), the `lightskin` and `brsm` methods.
//! - [`reference`]: a progressive path tracer, the truth the others are measured against.
//! - [`clustered`]: VPLs from the RSM clustered into virtual area lights (seed paper 003).
//! - [`surfels`]: surfels, a flux hierarchy, precomputed SH links and SH caches with
//!   progressive multi-bounce (seed paper 001).
//!
//! Adding a method: a module implementing [`Method`], an entry in [`REGISTRY`] (whose
//! `describe` lists its parameters with their ranges: `/v1/server` publishes them, the service
//! enforces them and the viewer builds its controls from them; whose `precompute`, if the
//! method needs per-scene data, is built off the render loop with progress, see
//! [`precompute`]; whose `cost` estimates a frame from its parameters, see [`cost`]), a
//! [`GiMethod`] variant and its parameters in the protocol's `GiParams`.
//! The renderer, the service and the clients need no other change.

pub mod clustered;
pub mod common;
pub mod cost;
pub mod lightskin;
pub mod none;
pub mod precompute;
pub mod reference;
pub mod surfels;

use crate::gpu::{timing::FrameStages, GpuContext, GpuError};
use crate::passes::{gbuffer::GBuffer, scene_buffers::SceneBuffers, Target};
use crate::scene::Scene;
use lightcast_protocol::{Camera, ClusteredVisibility, GiMethodInfo, Light, Limits, View};
use std::any::{Any, TypeId};
use std::sync::Arc;

pub use lightcast_protocol::GiMethod;

/// Default α of [`GiSettings::defensive`]: the largest weight 1/(N·P) stays below 3.4·M/N
/// for M RSM texels and N VALs. Chosen by measurement (`bench --defensive`, lavapipe, RSM
/// 256², 8,192 VALs, 512 view samples, relative mean absolute difference to LightSkin): on the
/// procedural street α = 0 gave 48 %, 0.1 gave 22 %, 0.3 gave 8.8 %; on the Cornell box
/// 0.94 % and (α = 0.3) 0.58 %.
pub const DEFAULT_DEFENSIVE: f32 = 0.3;

/// Parameters of the GI methods.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct GiSettings {
    pub method: GiMethod,
    /// RSM side per light face, in texels.
    pub rsm_size: u32,
    /// N_VS: view samples for the importance estimate (BRSM).
    pub view_samples: u32,
    /// N_sVAL: VALs drawn from the importance distribution (BRSM).
    pub val_count: u32,
    /// Offset of the stratified VAL draws within their strata, in [0, 1).
    pub jitter: f32,
    /// Weight α of a uniform distribution mixed into the BRSM selection pdf (defensive
    /// importance sampling): bounds the weight of VALs the view samples barely see but
    /// caches do. 0 is the paper's plain importance sampling.
    pub defensive: f32,
    /// Give every RSM texel importance 1 (turns BRSM into plain stratified sampling; with one
    /// draw per texel it equals LightSkin).
    pub uniform_importance: bool,
    /// Dim proxy lights hidden behind other caches (the paper's double projection).
    pub occlusion: bool,
    /// Phong exponent k (eq. 3–4) for every material, in direct and indirect shading alike;
    /// `None` keeps the materials' own.
    pub glossy_exponent: Option<f32>,
    /// `reference`, `surfels`: reflections after the surface a pixel sees (1: single bounce).
    pub bounces: u32,
    /// `reference`, `surfels`: emissive surfaces light the scene as area lights.
    pub emitters: bool,
    /// `reference`: samples per pixel added per frame.
    pub spp: u32,
    /// `clustered`: N VPLs.
    pub vpl_count: u32,
    /// `clustered`: M VALs (k-means clusters).
    pub cluster_count: u32,
    /// `clustered`: k-means iterations per frame.
    pub kmeans_iterations: u32,
    /// `clustered`: w_x of the clustering distance (§5.1), per unit of the scene's extent.
    pub cluster_position_weight: f32,
    /// `clustered`: w_α of the clustering distance (§5.1), per radian.
    pub cluster_normal_weight: f32,
    /// `clustered`: interleaved-sampling block side.
    pub interleave: u32,
    /// `clustered`: the blur's distance threshold as a fraction of the scene's extent.
    pub blur_distance: f32,
    /// `clustered`: the blur's normal (cosine) threshold.
    pub blur_normal: f32,
    /// `clustered`: how VPL visibility is found.
    pub visibility: ClusteredVisibility,
    /// `clustered`: side of each paraboloid depth map in texels.
    pub paraboloid_size: u32,
    /// `clustered`: K, Fourier terms of the convolution soft shadow maps.
    pub fourier_terms: u32,
    /// `clustered`: the light the `val-shadow` view shows.
    pub shadow_light: u32,

    /// Indirect light at 1/n of the output's width and height (the renderer reduces the
    /// G-buffer and upsamples the method's result, see `passes::indirect_resolution`).
    pub indirect_downscale: u32,
}

impl From<&lightcast_protocol::GiParams> for GiSettings {
    /// A request's GI parameters (the light-cache ones are the scene's business, not the
    /// frame's).
    fn from(p: &lightcast_protocol::GiParams) -> Self {
        Self {
            method: p.method,
            rsm_size: p.rsm_size,
            view_samples: p.view_samples,
            val_count: p.val_count,
            jitter: 0.5,
            defensive: p.defensive,
            uniform_importance: false,
            occlusion: p.occlusion,
            glossy_exponent: p.glossy_exponent,
            bounces: p.bounces,
            // `null` decides by the render's light, which the scene resolves
            // (`default_light::emitters_for`); without a scene, on.
            emitters: p.emitters.unwrap_or(true),
            spp: p.spp,
            vpl_count: p.vpl_count,
            cluster_count: p.cluster_count,
            kmeans_iterations: p.kmeans_iterations,
            cluster_position_weight: p.cluster_position_weight,
            cluster_normal_weight: p.cluster_normal_weight,
            interleave: p.interleave,
            blur_distance: p.blur_distance,
            blur_normal: p.blur_normal,
            visibility: p.visibility,
            paraboloid_size: p.paraboloid_size,
            fourier_terms: p.fourier_terms,
            shadow_light: p.shadow_light,
            indirect_downscale: p.indirect_downscale,
        }
    }
}

impl Default for GiSettings {
    /// The protocol's defaults, which are the paper's evaluation settings: 512 view samples
    /// and 8,192 VALs; a 1024² RSM.
    fn default() -> Self {
        (&lightcast_protocol::GiParams::default()).into()
    }
}

impl GiSettings {
    /// No indirect light.
    pub fn off() -> Self {
        Self {
            method: GiMethod::None,
            ..Self::default()
        }
    }

    /// Whether a reference this frame is compared with lets emissive surfaces light the
    /// scene: only when the method lights from them too and `emitters` is on, so that both
    /// see the same light sources.
    pub fn reference_emitters(&self) -> bool {
        self.emitters && self.method.lights_from_emitters()
    }
}

/// A setting a method cannot use, naming its field (as the renderer's settings name it).
#[derive(Debug, thiserror::Error)]
#[error("invalid {field}: {reason}")]
pub struct InvalidSetting {
    pub field: &'static str,
    pub reason: String,
}

impl InvalidSetting {
    pub fn new(field: &'static str, reason: impl Into<String>) -> Self {
        Self {
            field,
            reason: reason.into(),
        }
    }

    /// `value` of `field` within `lo..=hi`.
    pub fn check_range(field: &'static str, value: u32, lo: u32, hi: u32) -> Result<(), Self> {
        if (lo..=hi).contains(&value) {
            Ok(())
        } else {
            Err(Self::new(field, format!("{value} is outside {lo}..={hi}")))
        }
    }
}

/// Why a method could not encode its frame.
#[derive(Debug, thiserror::Error)]
pub enum GiError {
    #[error(transparent)]
    Invalid(#[from] InvalidSetting),
    /// The method cannot use the scene, or needs per-scene data the caller has not supplied.
    #[error("{0}")]
    Scene(String),
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// Per-scene resources the renderer owns and shares with every method it creates.
pub struct SceneResources {
    pub ctx: GpuContext,
    pub scene: Arc<Scene>,
    pub scene_buffers: SceneBuffers,
    pub material_layout: wgpu::BindGroupLayout,
    /// `CameraUniform` (see `passes::frame_uniforms`), written every frame.
    pub camera: wgpu::Buffer,
    /// `LightUniform`, written every frame.
    pub light: wgpu::Buffer,
}

/// What a method reads of the frame being encoded, and the buffer it fills.
pub struct FrameInputs<'a> {
    pub resources: &'a SceneResources,
    pub width: u32,
    pub height: u32,
    pub camera: &'a Camera,
    pub light: &'a Light,
    pub settings: &'a GiSettings,
    pub gbuffer: &'a GBuffer,
    /// The frame's shadow map, rendered before the GI stages (`surfels` lights its surfels
    /// through it).
    pub shadow: &'a crate::passes::shadow_map::ShadowMap,
    /// Indirect radiance per pixel (RGBA16F storage texture); the method writes every pixel.
    pub indirect: &'a Target,
    /// Which image history a progressive method may continue: a session's id, or `None` to
    /// start afresh (one-shot renders, so that equal requests give equal pixels).
    pub history: Option<u64>,
    /// The frame is a session's still (see `RenderSettings::still`).
    pub still: bool,
    /// The debug view the frame is read back for: a method may compute what only that view
    /// shows (to hand it over in [`Method::capture_debug`]).
    pub debug_view: View,
}

/// One GI method's per-scene GPU state and per-frame passes.
pub trait Method: Any {
    /// Encodes the frame's GI stages into `stages`; they must write every pixel of
    /// `frame.indirect`. Returns the convergence of a progressive method.
    fn encode(
        &mut self,
        frame: &FrameInputs,
        stages: &mut FrameStages,
    ) -> Result<Option<ProgressBuffer>, GiError>;

    /// Encodes copies of what debug view `view` shows of this frame (after its stages), to
    /// be read with the frame on the readback side; `None` if the method has nothing for it.
    fn capture_debug(
        &self,
        view: View,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Option<Box<dyn DebugCapture>> {
        let _ = (view, device, encoder);
        None
    }

    /// Takes the scene's data its [`MethodEntry::precompute`] built; frames before it fail
    /// with [`GiError::Scene`].
    fn set_scene_data(&mut self, data: &precompute::SceneData) -> Result<(), GiError> {
        let _ = data;
        Err(GiError::Scene(
            "this GI method takes no precomputed scene data".into(),
        ))
    }

    /// The renderer dropped the targets of output sizes other than `live`: release anything
    /// made for them.
    fn retain_targets(&mut self, live: &[&GBuffer]) {
        let _ = live;
    }

    fn as_any_mut(&mut self) -> &mut dyn Any;

    fn as_any(&self) -> &dyn Any;
}

/// A progressive method's convergence sums for the frame, on the GPU: the renderer copies
/// `buffer` (one [`ProgressSums`]) with the frame's results and reads it without waiting.
pub struct ProgressBuffer {
    pub samples: u32,
    pub buffer: wgpu::Buffer,
}

/// Mirrors `ProgressSums` in `shaders/reference/resolve.wgsl`: sums over the pixels of the
/// variance of their mean luminance and of their mean luminance.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ProgressSums {
    pub variance_of_mean: f32,
    pub luminance: f32,
    pub pixels: f32,
    pub pad0: f32,
}

impl ProgressSums {
    /// Root-mean-square standard error of the pixels' luminance over their mean luminance.
    pub fn relative_standard_error(&self) -> f32 {
        if self.luminance > 0.0 && self.pixels > 0.0 {
            (self.variance_of_mean / self.pixels).sqrt() / (self.luminance / self.pixels)
        } else {
            0.0
        }
    }
}

/// A method's staged copies for a debug view, read once the frame's submission is done.
pub trait DebugCapture: Send {
    /// Maps the copies encoded into the frame's `submission` and decodes them, waiting for
    /// that submission only: frames submitted after it may still be on the GPU.
    fn read(
        self: Box<Self>,
        ctx: &GpuContext,
        submission: Option<&wgpu::SubmissionIndex>,
    ) -> Result<DebugData, GpuError>;
}

/// What a debug view shows of a frame, in the method's own types (`debug_views` knows them).
#[derive(Clone)]
pub struct DebugData(pub Arc<dyn Any + Send + Sync>);

impl std::fmt::Debug for DebugData {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("DebugData")
    }
}

/// One registered method family.
pub struct MethodEntry {
    /// The protocol's method names this implementation serves.
    pub methods: &'static [GiMethod],
    /// The Rust type of the implementation (for [`crate::renderer::Renderer::gi`]).
    pub type_id: fn() -> TypeId,
    /// Checks the settings a frame of one of `methods` uses. `faces` is the light's face
    /// count (6 for point lights).
    pub validate: fn(&GiSettings, faces: u32) -> Result<(), InvalidSetting>,
    /// Builds the per-scene state.
    pub create: fn(&SceneResources) -> Result<Box<dyn Method>, GiError>,
    /// Parameter descriptions and limits for `/v1/server`, one per name in `methods`.
    pub describe: fn(&Limits) -> Vec<GiMethodInfo>,
    /// The per-scene data frames of `methods` need before their first frame, if any.
    pub precompute: Option<&'static precompute::PrecomputeEntry>,
    /// Adds the estimated cost of the method's stages of one frame (the shared stages are
    /// [`cost::shared`]'s), from its parameters and the frame's shape.
    pub cost: fn(&lightcast_protocol::GiParams, &cost::FrameShape, &mut cost::Cost),
    /// The parameters that scale that cost, in the order a refusal suggests lowering them.
    pub knobs: &'static [cost::Knob],
    /// Whether the renderer may run the method at `indirect_downscale` (the methods that
    /// approximate; not `none`, which has nothing to compute, nor the reference, which is the
    /// full-resolution truth the others are compared with).
    pub downscales: bool,
}

/// Every method the renderer can run.
pub const REGISTRY: &[MethodEntry] = &[
    none::ENTRY,
    lightskin::ENTRY,
    reference::ENTRY,
    clustered::ENTRY,
    surfels::ENTRY,
];

/// The registry entry serving `method` and its index.
pub fn entry(method: GiMethod) -> (usize, &'static MethodEntry) {
    REGISTRY
        .iter()
        .enumerate()
        .find(|(_, e)| e.methods.contains(&method))
        .unwrap_or_else(|| panic!("GI method {method:?} is not registered in gi::REGISTRY"))
}

/// `render.gi.emitters` as `/v1/server` lists it for the methods that read it.
pub(crate) fn emitters_param(d: &lightcast_protocol::GiParams) -> lightcast_protocol::GiParamInfo {
    lightcast_protocol::GiParamInfo {
        name: "emitters".into(),
        kind: lightcast_protocol::GiParamKind::Boolean,
        default: d.emitters.into(),
        min: None,
        max: None,
        choices: Vec::new(),
        description: "Emissive surfaces light the scene as area lights besides the punctual \
                      light; null (the default): on unless the light is the scene's stand-in \
                      for them (its default light when it has no lights of its own), whose \
                      light would count twice"
            .into(),
    }
}

/// Descriptions of every registered method, in registry order, with the limits of a server
/// configured with `limits`. The methods whose entry [`MethodEntry::downscales`] also take the
/// renderer's `indirect_downscale`.
pub fn describe_all(limits: &Limits) -> Vec<GiMethodInfo> {
    let mut methods: Vec<GiMethodInfo> =
        REGISTRY.iter().flat_map(|e| (e.describe)(limits)).collect();
    for m in methods.iter_mut().filter(|m| entry(m.method).1.downscales) {
        m.parameters.push(lightcast_protocol::GiParamInfo {
            name: "indirect_downscale".into(),
            kind: lightcast_protocol::GiParamKind::Integer,
            default: lightcast_protocol::GiParams::default()
                .indirect_downscale
                .into(),
            min: Some(1.0),
            max: Some(crate::passes::indirect_resolution::MAX_DOWNSCALE.into()),
            choices: Vec::new(),
            description: "Indirect light at 1/n of the output's width and height (n is 1, 2 \
                          or 4), brought back with an edge-aware (joint bilateral) upsample; 1: \
                          full resolution"
                .into(),
        });
    }
    methods
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_protocol_default_alpha_is_the_measured_one() {
        assert_eq!(
            super::GiSettings::default().defensive,
            super::DEFAULT_DEFENSIVE
        );
    }
}
