//! `reference`: a progressive path tracer on the GPU, the truth the GI methods are measured
//! against (issue 10).
//!
//! Compute shaders only (no ray-tracing hardware, so it runs on lavapipe): a BVH built per scene
//! on the CPU ([`bvh`], shared with other methods' visibility rays) is traversed in WGSL (`shaders/bvh.wgsl`, `shaders/reference/`). For every pixel it
//! estimates the indirect radiance leaving the surface point the pixel centre sees towards the
//! camera — the quantity the other methods write into their indirect buffer — with the same
//! BRDF (glTF's metallic-roughness model, `scene::brdf`), punctual lights and emitters, but
//! with exact visibility. `bounces` = 1 is the single-bounce light seed 004 approximates.
//!
//! Materials are the raster passes' (`shaders/material_model.wgsl` is shared): at every hit the
//! base colour factor times the base-colour texture at the hit's interpolated uv (filtered like
//! the raster sampler: bilinear, repeat, sRGB decoded) gives the BRDF's base colour. All
//! texels of the scene lie in one storage buffer ([`PackedTextures`]), so its size is bounded by
//! the device's storage binding size ([`check_device`]). Where an alpha mask cuts a surface away
//! (glTF `MASK`, the texels the G-buffer and the RSM discard) the traversal skips the hit, so
//! camera, bounce and shadow rays pass through; `BLEND` is opaque, as in the raster passes. Only
//! triangles of masked materials are tested (a flag in the BVH), and in scenes without masks
//! the test is compiled away (on lavapipe it would otherwise double the cost of a sample). The
//! shadow map cuts masked texels away too, so direct light passes the same holes.
//!
//! Samples accumulate while the camera, lights, size and settings stay the same; each sample
//! is one dispatch (short enough for lavapipe's silent dispatch limit at small sizes). Random
//! numbers are a hash of pixel, sample index and seed, so the same request gives the same
//! pixels on the same adapter. Each image history (a session; see [`FrameInputs::history`])
//! keeps its own accumulation, so sessions on one scene do not restart each other; one-shot
//! renders start afresh. As a frame's method it adds `spp` samples, then [`resolve`] writes
//! the mean into the indirect buffer with the convergence sums the frame header reports.

pub mod limits;
pub mod params;
pub mod resolve;
pub mod shaders;
pub mod stages;

use super::common::bvh;
use super::common::params::{emitters, roughness_override, BOUNCES};
use super::cost::{Cost, FrameShape, Knob};
pub use super::params::Senders;
use super::precompute::{
    BudgetPool, Built, PrecomputeEntry, PrecomputeKey, Progress, SceneData, UnitBudget,
};
use super::{FrameInputs, GiError, InvalidSetting, Method, MethodEntry, ProgressBuffer};
use crate::gpu::{readback::read_buffer, timing::FrameStages, GpuContext, GpuError};
use crate::passes::bind::{self, bind_group};
use crate::passes::environment::{EnvironmentBuffer, FrameEnvironment};
use crate::passes::frame_uniforms::{camera_view_proj, LightsUniform};
use crate::passes::scene_buffers::MaterialGpu;
use crate::passes::tonemap::luminance;
use crate::passes::ShaderPass;
use crate::passes::{self, ParamSlots};
use crate::scene::nodes::{posed_worlds, Node, Poses};
use crate::scene::{brdf::Brdf, Material, Scene, Texture};
use bytemuck::{Pod, Zeroable};
use lightcast_protocol::{Camera, GiMethod, GiParams, Light};
use std::any::{Any, TypeId};
use std::sync::Arc;
use wgpu::util::DeviceExt;

use crate::gi::common::limits::BOUNCES_CAP;

/// The method's name.
pub const REFERENCE: GiMethod = GiMethod::new("reference");
/// Samples per pixel one frame or [`PathTracer::accumulate`] call adds at most (one dispatch
/// each).
pub const MAX_SAMPLES_PER_CALL: u32 = 1024;
/// Image histories (sessions, chunked one-shots) whose accumulations a scene's tracer keeps
/// at once: a chunked one-shot of the reference compared with both references holds three
/// (its own and its two comparisons'), so two of them fit beside a session.
const MAX_HISTORIES: usize = 6;
/// Rays one dispatch traces at most (a band of rows of one sample): about 0.6 s on lavapipe
/// with 2 cores, well below the ~2.8 s after which it silently cuts a dispatch short.
pub const BAND_RAYS: u64 = 1 << 19;
/// The history of [`PathTracer::accumulate`]'s callers (bench, tests).
const DIRECT_HISTORY: u64 = u64::MAX;

/// Every module with its pipeline's bind groups (see [`ShaderPass`]).
const PASSES: &[ShaderPass] = &[
    ShaderPass::new(&shaders::REFERENCE_PATH_TRACE, &[&PASS_GROUP, &SCENE_GROUP]),
    ShaderPass::new(&shaders::REFERENCE_RESOLVE, &[&resolve::GROUP]),
];

pub const ENTRY: MethodEntry = MethodEntry {
    tables: &[params::TABLE],
    type_id: TypeId::of::<Reference>,
    validate: |gi, _| params::Settings::of(gi).map(drop),
    check_table: |gi| params::Settings::of(gi).map(drop),
    create: |r| Ok(Box::new(Reference::new(r)?)),
    precompute: Some(&PRECOMPUTE),
    cost,
    knobs: &[
        Knob::lower(&params::SPP),
        Knob::lower(&crate::gi::common::params::BOUNCES),
    ],
    shaders: PASSES,
    stages: stages::ALL,
    limits: limits::LIMITS,
    downscales: false,
    samples_environment: true,
    follows_moved_nodes: super::follows_every_pose,
    bench: None,
};

/// One frame's paths: every pixel traces `spp` paths of a camera ray and, per bounce, a
/// bounce ray and a shadow ray per light. A ray costs about 120 reference ns per level of the BVH
/// (1.2 µs on the 1,090-triangle Cornell box, measured at 32² with 16 … 256 spp and 2 … 16
/// bounces); paths that leave the scene early make the real cost lower, never higher.
fn cost(gi: &GiParams, shape: &FrameShape, cost: &mut Cost) {
    let (spp, bounces) = (params::SPP.u32(gi), BOUNCES.u32(gi));
    // An environment adds a shadow ray per vertex, the first included.
    let sky = u32::from(shape.environment.is_some());
    let rays =
        shape.pixels() * f64::from(spp) * f64::from(1 + sky + (1 + shape.lights + sky) * bounces);
    let depth = (shape.triangles.max(2) as f64).log2().max(10.0);
    cost.add(
        "path tracing (pixels × spp × (1 + sky + (1 + lights + sky) × bounces) rays)",
        rays,
        120.0 * depth,
    );
}

/// The scene's BVH, built on the service's precompute worker so that a large scene's build
/// (about 2 s for 1.2 M triangles) stalls no session. Not kept in the store: reading a
/// stored BVH would cost about what building it does. It holds a copy of every triangle
/// (about 110 bytes each with the nodes) for as long as the scene is held, so it counts the
/// scene's triangles against the total triangle budget a second time.
pub static PRECOMPUTE: PrecomputeEntry = PrecomputeEntry {
    kind: BVH,
    label: "BVH",
    key: |_, _| Ok(bvh_key()),
    budget: Some(UnitBudget {
        pool: BudgetPool::Triangles,
        unit: "triangles",
        field: "method",
        advice: |_, _, _| "delete a scene, or use a GI method other than the reference".into(),
    }),
    estimate: |_, facts| facts.triangles,
    cost: |_, facts, cost| {
        cost.add(
            "BVH build (triangles)",
            facts.triangles as f64,
            bvh::BUILD_NS_PER_TRIANGLE,
        )
    },
    knobs: &[],
    build: |scene, _, env| {
        let total = scene.triangle_count() as u64;
        (env.progress)(Progress {
            step: "bvh",
            done: 0,
            total,
        });
        let bvh = bvh::SceneBvh::build(scene).map_err(|e| e.to_string())?;
        (env.progress)(Progress {
            step: "bvh",
            done: total,
            total,
        });
        Ok(Built {
            data: Arc::new(bvh),
            units: total,
            from_store: false,
        })
    },
    // Built in a second or two from the scene; not worth a file.
    extension: None,
};

/// Kind of the reference's precomputation.
pub const BVH: &str = "bvh";

/// The key of the scene's BVH (one per scene: it has no parameters).
pub fn bvh_key() -> PrecomputeKey {
    PrecomputeKey {
        kind: BVH,
        params: Vec::new(),
    }
}

fn check_counts(bounces: u32, spp: u32) -> Result<(), InvalidSetting> {
    if !(1..=BOUNCES_CAP).contains(&bounces) {
        return Err(InvalidSetting::new(
            "bounces",
            format!("{bounces} is outside 1..={BOUNCES_CAP}"),
        ));
    }
    if !(1..=MAX_SAMPLES_PER_CALL).contains(&spp) {
        return Err(InvalidSetting::new(
            "spp",
            format!("{spp} is outside 1..={MAX_SAMPLES_PER_CALL}"),
        ));
    }
    Ok(())
}

/// Mirrors `TraceParams` in `shaders/reference/path_trace.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct TraceParams {
    pub inv_view_proj: [[f32; 4]; 4],
    pub camera_position: [f32; 3],
    pub width: u32,
    pub height: u32,
    pub sample_index: u32,
    pub bounces: u32,
    pub seed: u32,
    pub ray_epsilon: f32,
    /// Roughness for every material (the `glossy_exponent` override); 0 keeps their own.
    pub roughness: f32,
    /// 1: a path adds the emission of the surfaces it reaches (`render.gi.emitters`).
    pub emitters: u32,
    /// First row of this dispatch's band of the image.
    pub row_offset: u32,
    /// 1: light straight from a light leaves the surface it reaches by the diffuse lobe alone
    /// ([`Senders::Diffuse`]).
    pub diffuse_senders: u32,
    pub pad: [u32; 3],
}

/// Mirrors `SurfaceGpu` in `shaders/reference/surfaces.wgsl`: a material as the reference
/// shades it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct SurfaceGpu {
    /// The material's factors, as the raster passes read them.
    pub material: MaterialGpu,
    /// The base-colour texture's first texel in [`PackedTextures::texels`] and its size.
    pub texture_offset: u32,
    pub texture_width: u32,
    pub texture_height: u32,
    pub pad0: u32,
}

impl SurfaceGpu {
    /// The material with its base-colour texture (if any) among `textures`; the shader splits
    /// the textured base colour per hit, as the G-buffer does per pixel.
    pub fn from_material(m: &Material, textures: &PackedTextures) -> Self {
        let texture = textures.span(m.base_color_texture);
        Self {
            material: MaterialGpu::from(m),
            texture_offset: texture.offset,
            texture_width: texture.width,
            texture_height: texture.height,
            ..Self::zeroed()
        }
    }

    /// An untextured, opaque surface with this BRDF (tests light a Lambertian,
    /// [`Brdf::lambertian`], to compare with closed forms).
    pub fn new(brdf: &Brdf, emissive: [f32; 3]) -> Self {
        Self {
            material: MaterialGpu::from(&Material {
                base_color: brdf.base.extend(1.0).to_array(),
                metallic: brdf.metallic,
                roughness: brdf.roughness,
                specular: brdf.specular,
                emissive,
                ..Material::default()
            }),
            texture_offset: WHITE.offset,
            texture_width: WHITE.width,
            texture_height: WHITE.height,
            pad0: 0,
        }
    }
}

/// Where one texture's texels lie in [`PackedTextures::texels`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureSpan {
    pub offset: u32,
    pub width: u32,
    pub height: u32,
}

/// The surfaces of the scene's own materials, with their textures among `textures`.
fn material_surfaces(scene: &Scene, textures: &PackedTextures) -> Vec<SurfaceGpu> {
    scene
        .materials
        .iter()
        .map(|m| SurfaceGpu::from_material(m, textures))
        .collect()
}

/// The white texel untextured materials sample, as the raster passes bind a 1×1 white texture.
const WHITE: TextureSpan = TextureSpan {
    offset: 0,
    width: 1,
    height: 1,
};

/// Every base-colour texture of a scene in one buffer, as `shaders/reference/surfaces.wgsl`
/// samples them by hand (a compute shader cannot index a varying number of textures portably).
#[derive(Clone, Debug, PartialEq)]
pub struct PackedTextures {
    /// The [`WHITE`] texel, then each texture's texels, rows top to bottom: RGBA8 in sRGB with
    /// red in the low byte (`unpack4x8unorm`).
    pub texels: Vec<u32>,
    /// Where each of the scene's textures starts, by index.
    pub spans: Vec<TextureSpan>,
}

impl PackedTextures {
    /// Packs `textures` in order after the white texel.
    pub fn pack(textures: &[Texture]) -> Self {
        let mut texels = vec![u32::from_le_bytes([255; 4])];
        let spans = textures
            .iter()
            .map(|t| {
                let span = TextureSpan {
                    // `check_device` bounds the whole buffer to u32 indices.
                    offset: texels.len() as u32,
                    width: t.width,
                    height: t.height,
                };
                texels.extend(
                    t.rgba8
                        .chunks_exact(4)
                        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])),
                );
                span
            })
            .collect();
        Self { texels, spans }
    }

    /// The span of texture `index`, white for untextured materials (as the raster passes bind
    /// it for them).
    pub fn span(&self, index: Option<usize>) -> TextureSpan {
        index
            .and_then(|i| self.spans.get(i))
            .copied()
            .unwrap_or(WHITE)
    }
}

/// Bytes [`PackedTextures::pack`] makes of `textures` (the white texel included), computed
/// before packing so that a scene too large for the device is refused without the copy.
pub fn packed_texture_bytes(textures: &[Texture]) -> u64 {
    4 + textures.iter().map(|t| t.rgba8.len() as u64).sum::<u64>()
}

/// Storage buffers the path-tracing shader binds: params, lights, accumulation and
/// environment (group 0), the BVH's nodes, triangles, top-level nodes and instances,
/// vertices, indices, surfaces, texels and the BRDF table (group 1).
const STORAGE_BUFFERS: u32 = 13;

/// Refuses a device that cannot bind the tracer's buffers: the packed textures
/// (`texture_bytes`, from [`packed_texture_bytes`]) must fit one storage binding and be
/// addressable by the shader's u32 texel indices.
pub fn check_device(limits: &wgpu::Limits, texture_bytes: u64) -> Result<(), ReferenceError> {
    if limits.max_storage_buffers_per_shader_stage < STORAGE_BUFFERS {
        return Err(ReferenceError::TooFewStorageBuffers {
            needed: STORAGE_BUFFERS,
            limit: limits.max_storage_buffers_per_shader_stage,
        });
    }
    let limit = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size)
        .min(u64::from(u32::MAX));
    if texture_bytes > limit {
        return Err(ReferenceError::TexturesTooLarge {
            bytes: texture_bytes,
            limit,
        });
    }
    Ok(())
}

/// What the reference renders.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceSettings {
    /// Reflections after the surface a pixel sees (1: single-bounce indirect light).
    pub bounces: u32,
    /// Seed of the random streams.
    pub seed: u32,
    /// Roughness for every material (`None`: their own), as in the other methods.
    pub roughness: Option<f32>,
    /// Whether emissive surfaces light the scene (area lights) besides the punctual light.
    pub emitters: bool,
    /// How the light a surface receives straight from a light leaves it.
    pub senders: Senders,
}

impl Default for ReferenceSettings {
    fn default() -> Self {
        Self {
            bounces: 1,
            seed: 0,
            roughness: None,
            emitters: true,
            senders: Senders::Full,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ReferenceError {
    #[error(transparent)]
    Bvh(#[from] bvh::BvhError),
    #[error("invalid {field}: {reason}")]
    InvalidSetting { field: &'static str, reason: String },
    #[error(
        "the scene's base-colour textures take {bytes} bytes packed for the reference, more \
         than the {limit} bytes this GPU binds as one storage buffer"
    )]
    TexturesTooLarge { bytes: u64, limit: u64 },
    #[error("the reference binds {needed} storage buffers per shader; this GPU allows {limit}")]
    TooFewStorageBuffers { needed: u32, limit: u32 },
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

impl From<ReferenceError> for GiError {
    fn from(e: ReferenceError) -> Self {
        match e {
            ReferenceError::Bvh(_)
            | ReferenceError::TexturesTooLarge { .. }
            | ReferenceError::TooFewStorageBuffers { .. } => GiError::Scene(e.to_string()),
            ReferenceError::InvalidSetting { field, reason } => {
                GiError::Invalid(InvalidSetting { field, reason })
            }
            ReferenceError::Gpu(g) => GiError::Gpu(g),
        }
    }
}

/// The converged-so-far indirect light of every pixel.
#[derive(Clone, Debug)]
pub struct ReferenceImage {
    pub width: u32,
    pub height: u32,
    /// Samples per pixel accumulated.
    pub samples: u32,
    /// Mean indirect radiance per pixel (linear RGB), rows top to bottom; zero where the pixel
    /// sees no geometry.
    pub indirect: Vec<[f32; 3]>,
    /// Convergence estimate: the root-mean-square standard error of the pixels' luminance over
    /// their mean luminance (0 when every sample agreed).
    pub relative_standard_error: f32,
}

/// What the accumulated samples were rendered with; a change restarts accumulation.
#[derive(Clone, Debug, PartialEq)]
struct AccumKey {
    history: Option<u64>,
    width: u32,
    height: u32,
    camera: Camera,
    lights: Vec<Light>,
    environment: Option<Arc<FrameEnvironment>>,
    settings: ReferenceSettings,
    /// The movable nodes' poses the BVH's top level placed them in.
    poses: Poses,
}

/// Per-scene GPU state of the reference path tracer.
pub struct PathTracer {
    ctx: GpuContext,
    pipeline: wgpu::ComputePipeline,
    pass_layout: wgpu::BindGroupLayout,
    scene_group: wgpu::BindGroup,
    /// The BVH's bottom levels, and the top level's buffers (rewritten when poses change)
    /// with the poses they hold.
    levels: Vec<bvh::Level>,
    top_nodes: wgpu::Buffer,
    instances: wgpu::Buffer,
    poses: Poses,
    params: ParamSlots,
    lights: wgpu::Buffer,
    environment: EnvironmentBuffer,
    bounds: crate::scene::Aabb,
    /// Accumulations of the most recently used histories, most recent first.
    accumulations: Vec<Accumulation>,
    resolve: resolve::ResolvePass,
    /// Rays per dispatch at most ([`BAND_RAYS`]).
    band_rays: u64,
}

/// Per-pixel sums of radiance (rgb) and squared luminance (w) for one key.
struct Accumulation {
    key: AccumKey,
    buffer: wgpu::Buffer,
    samples: u32,
}

bind_group! {
    /// Group 0 of `shaders/reference/path_trace.wgsl`.
    pub struct PassResources as PASS_GROUP("reference", wgpu::ShaderStages::COMPUTE) {
        params: bind::param_slot::<TraceParams>(),
        lights: bind::PARAMS,
        accum: bind::STORAGE_RW,
        environment: bind::STORAGE,
    }
}

bind_group! {
    /// Group 1 of `shaders/reference/path_trace.wgsl`: the BVH (`bvh.wgsl`) and the scene data
    /// shading reads (`surfaces.wgsl`).
    pub struct SceneResources as SCENE_GROUP("reference scene", wgpu::ShaderStages::COMPUTE) {
        bvh_nodes: bind::STORAGE,
        bvh_triangles: bind::STORAGE,
        tlas_nodes: bind::STORAGE,
        bvh_instances: bind::STORAGE,
        vertices: bind::STORAGE,
        indices: bind::STORAGE,
        surfaces: bind::STORAGE,
        texels: bind::STORAGE,
        brdf_table: bind::STORAGE,
    }
}

fn storage_init(device: &wgpu::Device, label: &str, contents: &[u8]) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage: wgpu::BufferUsages::STORAGE,
    })
}

/// The top level's buffers, sized for the most nodes and instances `levels` can need (a
/// binary tree over them), at rest.
fn top_buffers(device: &wgpu::Device, bvh: &bvh::SceneBvh) -> (wgpu::Buffer, wgpu::Buffer) {
    let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
    let padded = |label, bytes: &[u8], capacity: usize| {
        let mut contents = bytes.to_vec();
        contents.resize(capacity.max(bytes.len()).max(16), 0);
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: &contents,
            usage,
        })
    };
    let levels = bvh.levels.len().max(1);
    (
        padded(
            "tlas nodes",
            bytemuck::cast_slice(&bvh.top.nodes),
            (2 * levels) * std::mem::size_of::<bvh::BvhNode>(),
        ),
        padded(
            "bvh instances",
            bytemuck::cast_slice(&bvh.top.instances),
            levels * std::mem::size_of::<bvh::BvhInstance>(),
        ),
    )
}

/// The scene's BVH, vertices (`vertices`: the renderer's, which it poses, or else a copy at
/// rest), indices, surfaces and texels on the GPU, bound as group 1.
#[allow(clippy::too_many_arguments)]
fn scene_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    scene: &Scene,
    bvh: &bvh::SceneBvh,
    top: (&wgpu::Buffer, &wgpu::Buffer),
    vertices: Option<&wgpu::Buffer>,
    surfaces: &[SurfaceGpu],
    texels: &[u32],
) -> wgpu::BindGroup {
    let own_vertices;
    SceneResources {
        bvh_nodes: &storage_init(device, "bvh nodes", bytemuck::cast_slice(&bvh.nodes)),
        bvh_triangles: &storage_init(
            device,
            "bvh triangles",
            bytemuck::cast_slice(&bvh.triangles),
        ),
        tlas_nodes: top.0,
        bvh_instances: top.1,
        vertices: match vertices {
            Some(v) => v,
            None => {
                own_vertices =
                    storage_init(device, "vertices", bytemuck::cast_slice(&scene.vertices));
                &own_vertices
            }
        },
        indices: &storage_init(device, "indices", bytemuck::cast_slice(&scene.indices)),
        surfaces: &storage_init(device, "surfaces", bytemuck::cast_slice(surfaces)),
        texels: &storage_init(device, "texels", bytemuck::cast_slice(texels)),
        brdf_table: &passes::scene_buffers::brdf_table(device),
    }
    .bind(device, layout)
}

impl PathTracer {
    /// A tracer for `scene` with its materials and textures.
    pub fn new(ctx: GpuContext, scene: &Scene) -> Result<Self, ReferenceError> {
        Self::with_surfaces(ctx, scene, |textures| material_surfaces(scene, textures))
    }

    /// A tracer for `scene` whose material `i` reflects and emits as the `i`th surface
    /// `surfaces` makes of the scene's packed textures.
    pub fn with_surfaces(
        ctx: GpuContext,
        scene: &Scene,
        surfaces: impl FnOnce(&PackedTextures) -> Vec<SurfaceGpu>,
    ) -> Result<Self, ReferenceError> {
        check_device(&ctx.device.limits(), packed_texture_bytes(&scene.textures))?;
        let bvh = bvh::SceneBvh::build(scene)?;
        Self::with_bvh(ctx, scene, &bvh, None, surfaces)
    }

    /// [`Self::with_surfaces`] with the scene's BVH built already; shading reads `vertices`
    /// (the renderer's, which holds moved nodes where they are) or a copy of the scene's.
    pub fn with_bvh(
        ctx: GpuContext,
        scene: &Scene,
        bvh: &bvh::SceneBvh,
        vertices: Option<&wgpu::Buffer>,
        surfaces: impl FnOnce(&PackedTextures) -> Vec<SurfaceGpu>,
    ) -> Result<Self, ReferenceError> {
        check_device(&ctx.device.limits(), packed_texture_bytes(&scene.textures))?;
        let textures = PackedTextures::pack(&scene.textures);
        let surfaces = surfaces(&textures);
        let device = &ctx.device;
        let scene_layout = SCENE_GROUP.layout(device);
        let (top_nodes, instances) = top_buffers(device, bvh);
        let scene_group = scene_group(
            device,
            &scene_layout,
            scene,
            bvh,
            (&top_nodes, &instances),
            vertices,
            &surfaces,
            &textures.texels,
        );
        let params =
            ParamSlots::new::<TraceParams>(device, "reference params", MAX_SAMPLES_PER_CALL);
        let pass_layout = PASS_GROUP.layout(device);
        let alpha_tested = bvh.triangles.iter().any(|t| t.alpha_tested != 0);
        let pipeline = passes::compute_pipeline_with_constants(
            device,
            "reference path trace",
            &[&pass_layout, &scene_layout],
            &shaders::REFERENCE_PATH_TRACE.create_module(device),
            "main",
            &[("ALPHA_TESTED", f64::from(u8::from(alpha_tested)))],
        );
        let lights = passes::params_buffer(
            device,
            "reference lights",
            std::mem::size_of::<LightsUniform>(),
        );
        Ok(Self {
            environment: EnvironmentBuffer::new(device),
            pipeline,
            pass_layout,
            scene_group,
            levels: bvh.levels.clone(),
            top_nodes,
            instances,
            poses: Poses::new(),
            params,
            lights,
            bounds: scene.bounds,
            accumulations: Vec::new(),
            resolve: resolve::ResolvePass::new(device),
            band_rays: BAND_RAYS,
            ctx,
        })
    }

    /// The same tracer with bands of at most `rays` rays per dispatch (tests show the bands
    /// add up to the whole image).
    pub fn with_band_rays(mut self, rays: u64) -> Self {
        self.band_rays = rays.max(1);
        self
    }

    /// Places the BVH's movable levels by `poses` (of the scene's `nodes`): the top level is
    /// rebuilt and written where they changed; the bottom levels stay.
    pub fn set_poses(&mut self, nodes: &[Node], poses: &Poses) {
        if *poses == self.poses {
            return;
        }
        let worlds = posed_worlds(nodes, poses);
        let top = bvh::top_level(&self.levels, nodes, &worlds);
        let queue = &self.ctx.queue;
        queue.write_buffer(&self.top_nodes, 0, bytemuck::cast_slice(&top.nodes));
        queue.write_buffer(&self.instances, 0, bytemuck::cast_slice(&top.instances));
        self.poses = poses.clone();
    }

    /// Samples per pixel accumulated by [`Self::accumulate`] for its last key.
    pub fn samples(&self) -> u32 {
        self.direct().map_or(0, |a| a.samples)
    }

    fn direct(&self) -> Option<&Accumulation> {
        self.accumulations
            .iter()
            .find(|a| a.key.history == Some(DIRECT_HISTORY))
    }

    /// Makes the accumulation of `key` the first, restarting it (zeroed sums) when the key
    /// is new or has no history to continue; clears are encoded into `encoder`.
    fn ensure_accumulation(&mut self, encoder: &mut wgpu::CommandEncoder, key: AccumKey) {
        let found = self.accumulations.iter().position(|a| a.key == key);
        if let (Some(i), Some(_)) = (found, key.history) {
            let hit = self.accumulations.remove(i);
            self.accumulations.insert(0, hit);
            return;
        }
        // A history that moved on (new camera, light, …) gives its buffer to the new key.
        let same_history = self
            .accumulations
            .iter()
            .position(|a| a.key.history == key.history);
        let bytes = u64::from(key.width) * u64::from(key.height) * 16;
        // Else, with every slot taken, the least recently used history gives its buffer up
        // (sessions beyond the limit then restart each other rather than allocate per frame).
        let reused = same_history
            .map(|i| self.accumulations.remove(i))
            .filter(|a| a.buffer.size() == bytes)
            .or_else(|| {
                (self.accumulations.len() >= MAX_HISTORIES)
                    .then(|| self.accumulations.pop())
                    .flatten()
                    .filter(|a| a.buffer.size() == bytes)
            });
        let buffer = match reused {
            Some(a) => {
                encoder.clear_buffer(&a.buffer, 0, None);
                a.buffer
            }
            None => {
                self.accumulations.truncate(MAX_HISTORIES - 1);
                self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("reference accumulation"),
                    size: bytes,
                    usage: wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::COPY_SRC
                        | wgpu::BufferUsages::COPY_DST,
                    // wgpu zero-initialises it: the sums start at 0.
                    mapped_at_creation: false,
                })
            }
        };
        self.accumulations.insert(
            0,
            Accumulation {
                key,
                buffer,
                samples: 0,
            },
        );
    }

    /// Adds `samples` samples per pixel (at most [`MAX_SAMPLES_PER_CALL`]) lit by `lights`
    /// and `environment`, restarting the accumulation if anything changed since the last
    /// call, and waits for them.
    #[allow(clippy::too_many_arguments)]
    pub fn accumulate(
        &mut self,
        width: u32,
        height: u32,
        camera: &Camera,
        lights: &[Light],
        environment: Option<&Arc<FrameEnvironment>>,
        settings: &ReferenceSettings,
        samples: u32,
    ) -> Result<(), ReferenceError> {
        check_counts(settings.bounces, samples).map_err(|e| ReferenceError::InvalidSetting {
            field: e.field,
            reason: e.reason,
        })?;
        let mut encoder = self
            .ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("reference"),
            });
        let key = AccumKey {
            history: Some(DIRECT_HISTORY),
            width,
            height,
            camera: camera.clone(),
            lights: lights.to_vec(),
            environment: environment.cloned(),
            settings: *settings,
            poses: self.poses.clone(),
        };
        self.ensure_accumulation(&mut encoder, key);
        self.encode_samples(&mut encoder, samples);
        self.ctx.queue.submit([encoder.finish()]);
        self.ctx.wait_idle()?;
        Ok(())
    }

    /// Encodes `samples` more samples into the first accumulation.
    fn encode_samples(&mut self, encoder: &mut wgpu::CommandEncoder, samples: u32) {
        let device = &self.ctx.device;
        let Some(Accumulation {
            key:
                AccumKey {
                    width,
                    height,
                    camera,
                    lights,
                    environment,
                    settings,
                    ..
                },
            buffer: accum,
            samples: done,
        }) = self.accumulations.first_mut()
        else {
            return;
        };
        let (width, height) = (*width, *height);
        let view_proj = camera_view_proj(camera, width as f32 / height as f32, &self.bounds);
        let scale = self
            .bounds
            .radius()
            .max(self.bounds.center().abs().max_element());
        let base = TraceParams {
            inv_view_proj: view_proj.inverse().to_cols_array_2d(),
            camera_position: camera.position,
            width,
            height,
            sample_index: 0,
            bounces: settings.bounces,
            seed: settings.seed,
            // Far above f32 rounding at the scene's coordinates, far below its features.
            ray_epsilon: 1e-4 * scale,
            roughness: settings.roughness.unwrap_or(0.0),
            emitters: u32::from(settings.emitters),
            row_offset: 0,
            diffuse_senders: u32::from(settings.senders == Senders::Diffuse),
            pad: [0; 3],
        };
        // Each sample in bands of rows of at most `band_rays` rays (a camera ray, then a bounce
        // ray and a shadow ray per light per bounce), as many as the parameter slots hold.
        let sky = u32::from(environment.is_some());
        let rays_per_ray_bounce = 1 + lights.len() as u32 + sky;
        let rays_per_row =
            u64::from(width) * u64::from(1 + sky + rays_per_ray_bounce * settings.bounces);
        let wanted = u64::from(height)
            .div_ceil((self.band_rays / rays_per_row).max(1))
            .max(1);
        let bands = wanted.min(u64::from(MAX_SAMPLES_PER_CALL / samples.max(1)).max(1)) as u32;
        let rows = height.div_ceil(bands).next_multiple_of(passes::TILE);
        let bands = height.div_ceil(rows);
        let first = *done;
        let slots: Vec<TraceParams> = (0..samples)
            .flat_map(|i| {
                (0..bands).map(move |b| TraceParams {
                    sample_index: first + i,
                    row_offset: b * rows,
                    ..base
                })
            })
            .collect();
        self.params.write(&self.ctx.queue, &slots);
        let lights_uniform = LightsUniform::new(lights, &self.bounds, 16);
        self.ctx
            .queue
            .write_buffer(&self.lights, 0, bytemuck::bytes_of(&lights_uniform));
        self.environment
            .set(device, &self.ctx.queue, environment.as_deref());
        let group = PassResources {
            params: &self.params,
            lights: &self.lights,
            accum,
            environment: &self.environment.buffer,
        }
        .bind(device, &self.pass_layout);
        let mut pass = passes::begin_compute(encoder, "reference path trace");
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(1, &self.scene_group, &[]);
        // One dispatch per band of each sample, each reading its own parameter slot.
        for (slot, params) in slots.iter().enumerate() {
            pass.set_bind_group(0, &group, &[ParamSlots::offset(slot as u32)]);
            let band = rows.min(height - params.row_offset);
            pass.dispatch_workgroups(width.div_ceil(passes::TILE), band.div_ceil(passes::TILE), 1);
        }
        drop(pass);
        *done += samples;
    }

    /// The image [`Self::accumulate`] accumulated (blocking readback).
    pub fn read(&self) -> Result<Option<ReferenceImage>, ReferenceError> {
        let Some(a) = self.direct() else {
            return Ok(None);
        };
        let sums: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&read_buffer(&self.ctx, &a.buffer)?);
        Ok(Some(resolve(a.key.width, a.key.height, a.samples, &sums)))
    }
}

impl PathTracer {
    /// Adds the frame's samples to its history's accumulation and resolves the mean into
    /// the frame's indirect buffer.
    fn encode_frame(
        &mut self,
        frame: &FrameInputs,
        stages: &mut FrameStages,
    ) -> Result<Option<ProgressBuffer>, GiError> {
        let gi = frame.settings;
        let g = params::Settings::of(gi)?;
        check_counts(g.bounces, g.spp)?;
        self.set_poses(&frame.resources.scene.nodes, frame.poses);
        let key = AccumKey {
            history: frame.history,
            width: frame.width,
            height: frame.height,
            camera: frame.camera.clone(),
            lights: frame.lights.to_vec(),
            environment: frame.environment.cloned(),
            settings: ReferenceSettings {
                bounces: g.bounces,
                seed: 0,
                roughness: roughness_override(gi),
                emitters: emitters(gi),
                senders: g.senders,
            },
            poses: frame.poses.clone(),
        };
        stages.stage(stages::PATH_TRACE, |e| {
            self.ensure_accumulation(e, key);
            self.encode_samples(e, g.spp);
        })?;
        let Some(accumulation) = self.accumulations.first() else {
            unreachable!("the accumulation was just ensured");
        };
        let samples = accumulation.samples;
        let group = self.resolve.prepare(
            &self.ctx.device,
            &self.ctx.queue,
            &accumulation.buffer,
            samples,
            frame.gbuffer,
            frame.indirect,
        );
        stages.stage(stages::REFERENCE_RESOLVE, |e| {
            self.resolve.encode(e, &group, frame.width, frame.height)
        })?;
        Ok(Some(ProgressBuffer {
            samples,
            buffer: self.resolve.progress.clone(),
        }))
    }
}

/// The `reference` method of a scene: its [`PathTracer`] once the scene's BVH ([`PRECOMPUTE`])
/// is there.
pub struct Reference {
    ctx: GpuContext,
    scene: Arc<Scene>,
    /// The renderer's vertex buffer, which holds moved nodes where a frame poses them: what
    /// the tracer shades hits with.
    vertices: wgpu::Buffer,
    tracer: Option<PathTracer>,
}

impl Reference {
    /// Refuses a device that cannot bind the tracer's buffers before any BVH is built.
    fn new(r: &super::SceneResources) -> Result<Self, ReferenceError> {
        check_device(
            &r.ctx.device.limits(),
            packed_texture_bytes(&r.scene.textures),
        )?;
        Ok(Self {
            ctx: r.ctx.clone(),
            scene: Arc::clone(&r.scene),
            vertices: r.scene_buffers.vertices.clone(),
            tracer: None,
        })
    }
}

impl Method for Reference {
    fn encode(
        &mut self,
        frame: &FrameInputs,
        stages: &mut FrameStages,
    ) -> Result<Option<ProgressBuffer>, GiError> {
        let tracer = self.tracer.as_mut().ok_or_else(|| {
            GiError::Scene("the reference needs the scene's BVH; set its scene data first".into())
        })?;
        tracer.encode_frame(frame, stages)
    }

    fn set_scene_data(&mut self, data: &SceneData) -> Result<(), GiError> {
        let bvh = data
            .downcast_ref::<bvh::SceneBvh>()
            .ok_or_else(|| GiError::Scene("the reference's scene data must be a BVH".into()))?;
        self.tracer = Some(PathTracer::with_bvh(
            self.ctx.clone(),
            &self.scene,
            bvh,
            Some(&self.vertices),
            |textures| material_surfaces(&self.scene, textures),
        )?);
        Ok(())
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// Means and the convergence estimate from per-pixel sums of radiance and squared luminance.
fn resolve(width: u32, height: u32, samples: u32, sums: &[[f32; 4]]) -> ReferenceImage {
    let n = f64::from(samples.max(1));
    let mut variance_of_mean = 0.0;
    let mut mean_luminance = 0.0;
    let indirect = sums
        .iter()
        .map(|s| {
            let mean = [s[0] / n as f32, s[1] / n as f32, s[2] / n as f32];
            let y = f64::from(luminance(mean));
            if samples > 1 {
                let var = ((f64::from(s[3]) / n - y * y) * n / (n - 1.0)).max(0.0);
                variance_of_mean += var / n;
            }
            mean_luminance += y;
            mean
        })
        .collect();
    let pixels = sums.len().max(1) as f64;
    let relative_standard_error = if mean_luminance > 0.0 {
        ((variance_of_mean / pixels).sqrt() / (mean_luminance / pixels)) as f32
    } else {
        0.0
    };
    ReferenceImage {
        width,
        height,
        samples,
        indirect,
        relative_standard_error,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::reference::shaders::REFERENCE_PATH_TRACE;
    use crate::gpu::shaders::layout_check::assert_struct;
    use std::mem::{offset_of, size_of};

    #[test]
    fn trace_structs_match_wgsl() {
        assert_struct(
            &REFERENCE_PATH_TRACE,
            "TraceParams",
            size_of::<TraceParams>(),
            &[
                ("inv_view_proj", offset_of!(TraceParams, inv_view_proj)),
                ("camera_position", offset_of!(TraceParams, camera_position)),
                ("width", offset_of!(TraceParams, width)),
                ("height", offset_of!(TraceParams, height)),
                ("sample_index", offset_of!(TraceParams, sample_index)),
                ("bounces", offset_of!(TraceParams, bounces)),
                ("seed", offset_of!(TraceParams, seed)),
                ("ray_epsilon", offset_of!(TraceParams, ray_epsilon)),
                ("roughness", offset_of!(TraceParams, roughness)),
                ("emitters", offset_of!(TraceParams, emitters)),
                ("row_offset", offset_of!(TraceParams, row_offset)),
                ("diffuse_senders", offset_of!(TraceParams, diffuse_senders)),
            ],
        );
        assert_struct(
            &REFERENCE_PATH_TRACE,
            "SurfaceGpu",
            size_of::<SurfaceGpu>(),
            &[
                ("material", offset_of!(SurfaceGpu, material)),
                ("texture_offset", offset_of!(SurfaceGpu, texture_offset)),
                ("texture_width", offset_of!(SurfaceGpu, texture_width)),
                ("texture_height", offset_of!(SurfaceGpu, texture_height)),
                ("pad0", offset_of!(SurfaceGpu, pad0)),
            ],
        );
        // The nested material is the raster passes' struct from the shared file; its own
        // members are checked against the G-buffer's module in `passes::scene_buffers`.
        assert_struct(
            &REFERENCE_PATH_TRACE,
            "MaterialGpu",
            size_of::<MaterialGpu>(),
            &[
                ("base_color", offset_of!(MaterialGpu, base_color)),
                ("emissive", offset_of!(MaterialGpu, emissive)),
                ("metallic", offset_of!(MaterialGpu, metallic)),
                ("roughness", offset_of!(MaterialGpu, roughness)),
                ("alpha_cutoff", offset_of!(MaterialGpu, alpha_cutoff)),
                ("specular", offset_of!(MaterialGpu, specular)),
                ("pad0", offset_of!(MaterialGpu, pad0)),
            ],
        );
    }

    fn texture(width: u32, height: u32) -> Texture {
        Texture {
            name: "t".into(),
            width,
            height,
            rgba8: (0..width * height * 4).map(|i| i as u8).collect(),
        }
    }

    #[test]
    fn textures_pack_after_the_white_texel_with_red_in_the_low_byte() {
        let textures = [texture(2, 1), texture(1, 3)];
        let packed = PackedTextures::pack(&textures);
        assert_eq!(
            packed.texels.len() as u64 * 4,
            packed_texture_bytes(&textures)
        );
        assert_eq!(packed.texels[0], u32::MAX, "white, opaque");
        assert_eq!(packed.texels[1], u32::from_le_bytes([0, 1, 2, 3]));
        assert_eq!(
            packed.spans,
            vec![
                TextureSpan {
                    offset: 1,
                    width: 2,
                    height: 1
                },
                TextureSpan {
                    offset: 3,
                    width: 1,
                    height: 3
                },
            ]
        );
        assert_eq!(packed.texels[3], u32::from_le_bytes([0, 1, 2, 3]));
        assert_eq!(packed.span(None), WHITE);
        assert_eq!(packed.span(Some(1)), packed.spans[1]);
        let textured = Material {
            base_color_texture: Some(1),
            alpha_cutoff: Some(0.5),
            ..Material::default()
        };
        let surface = SurfaceGpu::from_material(&textured, &packed);
        assert_eq!(
            (
                surface.texture_offset,
                surface.texture_width,
                surface.texture_height
            ),
            (3, 1, 3)
        );
        assert_eq!(surface.material.alpha_cutoff, 0.5);
    }

    #[test]
    fn textures_larger_than_a_storage_binding_are_refused_with_their_sizes() {
        let textures = [texture(8, 8)];
        let bytes = packed_texture_bytes(&textures);
        assert_eq!(bytes, 4 + 8 * 8 * 4);
        // wgpu's default limits are WebGPU's, with one storage buffer too few for the tracer.
        let device = |binding_size| wgpu::Limits {
            max_storage_buffers_per_shader_stage: STORAGE_BUFFERS,
            max_storage_buffer_binding_size: binding_size,
            ..wgpu::Limits::default()
        };
        check_device(&device(bytes), bytes).expect("exactly at the limit");
        let err = check_device(&device(bytes - 4), bytes).expect_err("over the limit");
        assert!(
            matches!(err, ReferenceError::TexturesTooLarge { bytes: b, limit } if b == bytes && limit == bytes - 4),
            "{err:?}"
        );
        let message = err.to_string();
        assert!(
            message.contains("260 bytes") && message.contains("256 bytes"),
            "{message}"
        );
        assert!(matches!(
            check_device(&wgpu::Limits::default(), bytes),
            Err(ReferenceError::TooFewStorageBuffers { .. })
        ));
    }
}
