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
//! - [`rsm_gather`]: reflective shadow maps gathered per pixel (Dachsbacher & Stamminger
//!   2005), the ancestor of the seed methods.
//!
//! Adding a method: a module implementing [`Method`] that names itself in a `const`
//! [`GiMethod`], and an entry in [`REGISTRY`] whose `tables` hold its parameter table
//! ([`params`]: every row written once, from which the request checks, `/v1/server`, the
//! OpenAPI schema, `--gi-param`, the viewer's panel, the software defaults and the README's
//! table are derived), whose `shaders` list its WGSL modules with their bind groups (every
//! one is validated with naga by the `shader_tests` below), whose `precompute`, if the method needs
//! per-scene data, is built off the render loop with progress (see [`precompute`]), whose
//! `cost` estimates a frame from its parameters (see [`cost`]) and whose `stages` name its
//! stages with their frame-header indices (see [`stages`]) and whose `bench` declares what
//! `lightcast-server bench` sweeps (see [`bench`]). Its table lists its debug views with
//! their drawing code (`gi/<method>/views.rs`, see [`views`]).

// Paths as when the layers were modules of one crate: `crate::gi::…`, `crate::passes::…`.
use crate as gi;
use lightcast_passes::{gpu, passes};
use lightcast_scene as scene;

pub mod bench;
pub mod clustered;
pub mod common;
pub mod cost;
pub mod lightskin;
pub mod limits;
pub mod none;
pub mod params;
pub mod precompute;
pub mod reference;
pub mod rsm_gather;
pub mod stages;
pub mod surfels;
pub mod views;

use crate::gpu::{timing::FrameStages, GpuContext, GpuError};
use crate::passes::{gbuffer::GBuffer, scene_buffers::SceneBuffers, Target};
use crate::scene::Scene;
use lightcast_protocol::{Camera, GiMethodInfo, Light, Limits, View, ViewInfo};
use std::any::{Any, TypeId};
use std::sync::Arc;

pub use lightcast_protocol::{GiMethod, GiParams};

/// Whether a reference this frame is compared with lets emissive surfaces light the scene:
/// only when the method lights from them too and `emitters` is on, so that both see the same
/// light sources.
pub fn reference_emitters(gi: &GiParams) -> bool {
    common::params::emitters(gi) && lights_from_emitters(gi.method)
}

/// How a reference that models the light transport of frames of `gi` reflects direct light at
/// the surfaces that send it on (its `senders` parameter): [`params::Senders::Full`] for a
/// method that models it whole, where the full reference is the same.
pub fn reference_senders(gi: &GiParams) -> params::Senders {
    (table(gi.method).senders)(gi)
}

/// Whether `method` lights the scene from emissive surfaces (area lights), as
/// `render.gi.emitters` asks: the methods whose table has that parameter. The others light it
/// from the punctual light only, so a comparison measures them against a reference with
/// `emitters` off: the same light sources.
pub fn lights_from_emitters(method: GiMethod) -> bool {
    params::of(method)
        .iter()
        .any(|p| p.name == common::params::EMITTERS.name)
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
    /// `LightsUniform`: every light of the frame, written every frame.
    pub lights: wgpu::Buffer,
}

/// What a method reads of the frame being encoded, and the buffer it fills.
pub struct FrameInputs<'a> {
    pub resources: &'a SceneResources,
    pub width: u32,
    pub height: u32,
    pub camera: &'a Camera,
    /// Every light of the frame (at most `passes::frame_uniforms::MAX_LIGHTS`): its punctual
    /// lights, then, unless the method samples the environment itself, the environment's
    /// directional lights.
    pub lights: &'a [Light],
    /// The faces of every light in light order with its index in `lights`, as the shadow map
    /// renders them (`passes::frame_uniforms::lights_faces`: a directional light's fitted to
    /// the view where the method's `light_fit` says so): the RSM's faces.
    pub light_faces: &'a [(u32, crate::passes::frame_uniforms::LightFace)],
    /// The frame's environment, if any (see [`MethodEntry::samples_environment`]).
    pub environment: Option<&'a std::sync::Arc<crate::passes::environment::FrameEnvironment>>,
    pub settings: &'a GiParams,
    pub gbuffer: &'a GBuffer,
    /// The frame's shadow map, rendered before the GI stages (a method may light its own
    /// samples through it).
    pub shadow: &'a crate::passes::shadow_map::ShadowMap,
    /// Indirect radiance per pixel (RGBA16F storage texture); the method writes every pixel.
    pub indirect: &'a Target,
    /// Which image history a progressive method may continue: a session's id, or `None` to
    /// start afresh (one-shot renders, so that equal requests give equal pixels).
    pub history: Option<u64>,
    /// The frame is a session's still (see `RenderSettings::still`).
    pub still: bool,
    /// The movable nodes' poses, which the renderer's vertex buffer holds them in (a method
    /// with its own copy of the geometry, the reference's BVH, places it so).
    pub poses: &'a crate::scene::nodes::Poses,
    /// The frame's lights and poses as bytes: a pass that does not depend on the camera
    /// reuses its target where the target was made from the same (`passes::reuse`, as
    /// `RsmPass::encode_stage` does); `None`: reuse is off, every pass runs.
    pub shared: Option<&'a [u8]>,
    /// The debug view the frame is read back for: a method may compute what only that view
    /// shows (to hand it over in [`Method::capture_debug`]).
    pub debug_view: View,
    /// The frame's raster passes draw visibility buffers and resolve them (the G-buffer has;
    /// an RSM does likewise: `passes::rsm::Rsm::new`). Set only where the device has triangle
    /// ids and the scene's buffers fit a storage binding.
    pub visibility_buffer: bool,
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
    /// The protocol's method names this implementation serves, with their parameter tables.
    pub tables: &'static [params::MethodTable],
    /// The Rust type of the implementation (for [`crate::renderer::Renderer::gi`]).
    pub type_id: fn() -> TypeId,
    /// Checks what the parameter tables cannot say alone (one parameter against another, or
    /// against the light's face count `faces`, 6 for point lights) for a frame of one of the
    /// methods.
    pub validate: fn(&GiParams, faces: u32) -> Result<(), InvalidSetting>,
    /// Reads the parameters as the method's own struct: a table row the struct lacks, or a
    /// field the table lacks, fails (tested over the registry).
    pub check_table: fn(&GiParams) -> Result<(), InvalidSetting>,
    /// Builds the per-scene state.
    pub create: fn(&SceneResources) -> Result<Box<dyn Method>, GiError>,
    /// The per-scene data frames of the methods need before their first frame, if any.
    pub precompute: Option<&'static precompute::PrecomputeEntry>,
    /// Adds the estimated cost of the method's stages of one frame (the shared stages are
    /// [`cost::shared`]'s), from its parameters and the frame's shape.
    pub cost: fn(&GiParams, &cost::FrameShape, &mut cost::Cost),
    /// The parameters that scale that cost, in the order a refusal suggests lowering them.
    pub knobs: &'static [cost::Knob],
    /// The method's shader modules with their bind groups (`gi/<method>/shaders.rs`).
    pub shaders: &'static [crate::passes::ShaderPass],
    /// The method's own stages (`gi/<method>/stages.rs`; the shared ones are
    /// `passes::stages`'), with the indices frame headers carry (see [`stages`]).
    pub stages: &'static [crate::gpu::timing::Stage],
    /// The server limits of its parameters and budgets (`gi/<method>/limits.rs`, see
    /// [`limits`]), shared ones included.
    pub limits: &'static [&'static limits::GiLimit],
    /// Whether the renderer may run the method at `indirect_downscale` (the methods that
    /// approximate; not `none`, which has nothing to compute, nor the reference, which is the
    /// full-resolution truth the others are compared with).
    pub downscales: bool,
    /// Whether the method samples the frame's environment itself
    /// ([`FrameInputs::environment`]) and lights with the punctual lights alone (the
    /// reference); else the renderer appends the environment's directional lights
    /// (`passes::environment::FrameEnvironment::lights`) to its lights, and it lights with
    /// them as with any light.
    pub samples_environment: bool,
    /// Checks that the method, with these parameters, follows movable nodes a frame poses
    /// (`RenderSettings::poses`); every method does, each as its seed paper has it (see the
    /// README), except with parameters whose per-scene data only holds the rest pose
    /// (LightSkin's `cache_visibility` maps).
    pub follows_moved_nodes: fn(&GiParams) -> Result<(), InvalidSetting>,
    /// What `lightcast-server bench --gi <method>` measures (`gi/<method>/bench.rs`, see
    /// [`bench`]); `None`: the method has no evaluation.
    pub bench: Option<&'static bench::Sweep>,
}

/// [`MethodEntry::follows_moved_nodes`] of a method with nothing held at rest.
pub fn follows_every_pose(_: &GiParams) -> Result<(), InvalidSetting> {
    Ok(())
}

impl MethodEntry {
    /// Whether the entry serves `method`.
    pub fn serves(&self, method: GiMethod) -> bool {
        self.tables.iter().any(|t| t.method == method)
    }
}

/// Every method the renderer can run.
pub const REGISTRY: &[MethodEntry] = &[
    none::ENTRY,
    lightskin::ENTRY,
    reference::ENTRY,
    clustered::ENTRY,
    surfels::ENTRY,
    rsm_gather::ENTRY,
];

/// Every registered method, in registry order (the order `/v1/server` lists them).
pub fn methods() -> impl Iterator<Item = GiMethod> {
    REGISTRY
        .iter()
        .flat_map(|e| e.tables.iter().map(|t| t.method))
}

/// The registry entry serving `method` and its index, if it is registered.
pub fn find(method: GiMethod) -> Option<(usize, &'static MethodEntry)> {
    REGISTRY.iter().enumerate().find(|(_, e)| e.serves(method))
}

/// Whether `method` is registered; else why not, listing those that are (what a request
/// naming it is refused with).
pub fn check_method(method: GiMethod) -> Result<(), InvalidSetting> {
    if find(method).is_some() {
        return Ok(());
    }
    let known: Vec<String> = methods().map(|m| m.to_string()).collect();
    Err(InvalidSetting::new(
        "method",
        format!(
            "this server has no GI method {method}; its methods are {}",
            known.join(", ")
        ),
    ))
}

/// A registered method by name, for command-line flags (`--gi`).
pub fn parse_method(name: &str) -> Result<GiMethod, String> {
    let method = GiMethod::parse(name)?;
    check_method(method).map_err(|e| e.reason)?;
    Ok(method)
}

/// The registry entry serving `method` and its index. Requests are checked first
/// ([`check_method`]): an unregistered method here is a bug.
pub fn entry(method: GiMethod) -> (usize, &'static MethodEntry) {
    find(method).unwrap_or_else(|| panic!("GI method {method} is not registered in gi::REGISTRY"))
}

/// The parameter table of `method`.
pub fn table(method: GiMethod) -> &'static params::MethodTable {
    entry(method)
        .1
        .tables
        .iter()
        .find(|t| t.method == method)
        .unwrap_or_else(|| panic!("GI method {method:?} has no table"))
}

/// Descriptions of every registered method, in registry order, with the limits of a
/// server configured with `limits`: each method's parameters, then the frame's
/// ([`params::frame_params`]).
pub fn describe_all(limits: &Limits) -> Vec<GiMethodInfo> {
    methods()
        .map(|method| {
            let t = table(method);
            GiMethodInfo {
                method,
                summary: t.summary.into(),
                progressive: t.progressive,
                parameters: params::of(method).iter().map(|p| p.info(limits)).collect(),
                views: t
                    .views
                    .iter()
                    .map(|v| ViewInfo {
                        view: v.name,
                        summary: v.summary.into(),
                    })
                    .collect(),
            }
        })
        .collect()
}

/// Every shader module: the shared passes', the shared GI modules' (and the BVH test
/// harness's) and each registered method's, with their bind groups.
pub fn all_shaders() -> impl Iterator<Item = &'static crate::passes::ShaderPass> {
    crate::passes::SHADERS
        .iter()
        .chain(common::shaders::PASSES)
        .chain(REGISTRY.iter().flat_map(|e| e.shaders))
}

#[cfg(test)]
mod shader_tests {
    use super::all_shaders;
    use crate::gpu::shaders::layout_check;
    use std::collections::BTreeSet;

    /// The build script validated every module the registry lists (and only those): a
    /// declaration its scan of the `shaders.rs` files misses fails here.
    #[test]
    fn the_build_validated_every_module() {
        let validated: BTreeSet<&str> =
            include_str!(concat!(env!("OUT_DIR"), "/validated_shaders.txt"))
                .lines()
                .collect();
        let listed: BTreeSet<&str> = all_shaders().map(|p| p.source.name).collect();
        assert_eq!(validated, listed);
    }

    #[test]
    fn every_pass_module_validates_with_naga() {
        for pass in all_shaders() {
            let source = pass.source;
            let module = layout_check::parse(source);
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::PRIMITIVE_INDEX,
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{}: {}", source.name, e.emit_to_string(&source.source())));
        }
    }

    #[test]
    fn no_pass_binds_a_uniform_buffer() {
        // lavapipe recompiles, and leaks, a shader variant per dispatch for uniform values
        // that steer control flow; parameters are bound as storage (`passes::PARAMS_BINDING`).
        for pass in all_shaders() {
            let module = layout_check::parse(pass.source);
            let uniforms: Vec<_> = module
                .global_variables
                .iter()
                .filter(|(_, v)| v.space == naga::AddressSpace::Uniform)
                .map(|(_, v)| v.name.clone().unwrap_or_default())
                .collect();
            assert!(
                uniforms.is_empty(),
                "{}: var<uniform> {uniforms:?}; use var<storage, read>",
                pass.source.name
            );
        }
    }

    /// Each pipeline's bind groups, as its pass declares them, are what its WGSL declares; the
    /// only modules without them are the integration tests' harnesses.
    #[test]
    fn every_pass_binds_what_its_wgsl_declares() {
        let errors: Vec<String> = all_shaders()
            .filter_map(|p| Some((p.source, p.groups?)))
            .flat_map(|(source, groups)| {
                crate::passes::bind::wgsl_mismatches(source, groups)
                    .into_iter()
                    .map(|e| format!("{}: {e}", source.name))
            })
            .collect();
        assert!(errors.is_empty(), "{}", errors.join("\n"));
        let unchecked: Vec<&str> = all_shaders()
            .filter(|p| p.groups.is_none())
            .map(|p| p.source.name)
            .collect();
        let harnesses = [
            &super::common::shaders::BVH_TEST,
            &super::common::shaders::BRDF_TEST,
        ];
        assert_eq!(unchecked, harnesses.map(|s| s.name));
        let names: Vec<&str> = all_shaders().map(|p| p.source.name).collect();
        let unique: BTreeSet<&str> = names.iter().copied().collect();
        assert_eq!(
            unique.len(),
            names.len(),
            "a module listed twice: {names:?}"
        );
    }

    #[test]
    fn every_file_in_shaders_dir_belongs_to_a_pass() {
        let root = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shaders"));
        // shaders/ and one level of method folders (shaders/<method>/).
        let mut on_disk = BTreeSet::new();
        let mut dirs = vec![root.to_path_buf()];
        while let Some(dir) = dirs.pop() {
            for entry in std::fs::read_dir(&dir).expect("shaders/ exists") {
                let path = entry.expect("dir entry").path();
                if path.is_dir() {
                    dirs.push(path);
                } else if path.extension().is_some_and(|e| e == "wgsl") {
                    let relative = path.strip_prefix(root).expect("under shaders/");
                    on_disk.insert(relative.to_string_lossy().into_owned());
                }
            }
        }
        let used: BTreeSet<String> = all_shaders()
            .flat_map(|p| p.source.files.iter().map(|(n, _)| n.to_string()))
            .collect();
        assert_eq!(
            on_disk, used,
            "every WGSL file must be part of a validated pass"
        );
    }
}
