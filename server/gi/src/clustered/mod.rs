//! `clustered`: instant radiosity with clustered visibility (seed paper 003, Dong et al.,
//! "Real-time Indirect Illumination with Clustered Visibility"). Per frame and with no
//! precomputation: the RSM, N VPLs fetched from it at Halton positions, k-means of the VPLs
//! into M virtual area lights restarted from the same seeds every frame (§5), and every pixel
//! lit by all N VPLs through interleaved sampling and a geometry-aware blur (§6).
//!
//! Visibility (`visibility`): `cssm`, the paper's, renders one paraboloid depth map per VAL
//! and turns it into convolution soft shadow maps (§4.1–4.2), whose fractional V_C(i)(x)
//! every VPL of the VAL shares; `vpl_shadows` renders a map per VPL and tests it hard (exact
//! from-point visibility up to the map's resolution, Figure 10's instant-radiosity baseline);
//! `off` lets every VPL see every point (Figure 10's "without visibility"). The maps draw
//! alpha-masked materials as opaque. [`passes`] holds the GPU passes; [`cpu`] is the CPU
//! reference of their equations.

pub mod bench;
pub mod cpu;
pub mod cpu_visibility;
pub mod params;
pub mod passes;
pub mod shaders;
pub mod stages;
pub mod views;

use super::common::params::emitters;
use super::cost::{self, Cheaper, Cost, FrameShape, Knob};
use super::{
    DebugCapture, DebugData, FrameInputs, GiError, InvalidSetting, Method, MethodEntry,
    ProgressBuffer, SceneResources,
};
use crate::gpu::readback::{
    read_buffer, read_rgba_texture, read_rgba_u32_texture, stage_buffer, PendingMap,
    TextureReadback,
};
use crate::gpu::{timing::FrameStages, GpuContext, GpuError};
use crate::passes::ShaderPass;
use crate::passes::{
    gbuffer::GBuffer,
    rsm::{max_rsm_size, GlossySender, Rsm, RsmFace, RsmPass},
    Target,
};
use lightcast_protocol::{GiParams, View};
use params::Settings;
pub use params::Visibility;

/// The method's name.
pub const CLUSTERED: lightcast_protocol::GiMethod = lightcast_protocol::GiMethod::new("clustered");
use passes::{
    AtlasLayout, BlurResources, ClusterBuffers, ClusteredParams, ClusteringPass, ImagePass,
    IndirectResources, Val, VisibilityPass, VisibilityTargets, Vpl, BLUR_GROUP, INDIRECT_GROUP,
};
use std::any::{Any, TypeId};
use std::sync::Arc;

/// Most bytes of paraboloid maps and CSSM basis a frame may hold: 30 VALs at 256² take
/// 75 MiB, 256 VALs fit at 128², 1,024 hard-shadow VPLs at 256².
pub const MAX_VISIBILITY_BYTES: u64 = 256 << 20;

/// Every module with its pipeline's bind groups (see [`ShaderPass`]).
const PASSES: &[ShaderPass] = &[
    ShaderPass::new(&shaders::CLUSTERING, &[&passes::CLUSTERING_GROUP]),
    ShaderPass::new(&shaders::CLUSTERED_INDIRECT, &[&passes::INDIRECT_GROUP]),
    ShaderPass::new(&shaders::PARABOLOID_MAPS, &[&passes::MAPS_GROUP]),
    ShaderPass::new(&shaders::CSSM_BASIS, &[&passes::BASIS_GROUP]),
    ShaderPass::new(&shaders::CSSM_MIPS, &[&passes::MIPS_GROUP]),
    ShaderPass::new(&shaders::GEOMETRY_BLUR, &[&passes::BLUR_GROUP]),
];

pub const ENTRY: MethodEntry = MethodEntry {
    tables: &[params::TABLE],
    type_id: TypeId::of::<Clustered>,
    validate,
    check_table: |gi| Settings::of(gi).map(drop),
    create: |r| Ok(Box::new(Clustered::new(r))),
    precompute: None,
    cost,
    knobs: &[
        Knob::lower(&params::VPL_COUNT),
        Knob {
            param: &params::INTERLEAVE,
            cheaper: Cheaper::Higher,
            choices: &[],
        },
        Knob::lower(&params::PARABOLOID_SIZE),
        Knob::lower(&params::CLUSTER_COUNT),
        Knob::lower(&params::KMEANS_ITERATIONS),
    ],
    shaders: PASSES,
    stages: stages::ALL,
    limits: &[&crate::gi::common::limits::MAX_RSM_SIZE],
    downscales: true,
    samples_environment: false,
    follows_moved_nodes: super::follows_every_pose,
    bench: Some(&bench::SWEEP),
};

/// One frame's stages: the RSM and VPLs, k-means (§5.1: every pass compares N VPLs with M
/// clusters), the paraboloid maps (§4.1: one per VAL, or per VPL for `vpl_shadows`, each
/// drawing every triangle), interleaved shading (each pixel N/B² VPLs) and the blur (B²
/// taps). Weights in reference ns per item, measured on the Cornell box at 64×48: 140 per
/// pixel·VPL with CSSM (90 with hard VPL shadows, 50 without visibility), 10 per VPL·VAL per
/// k-means pass, 1 µs per map·triangle plus 0.65 µs per CSSM map texel (0.33 without the
/// Fourier basis), 30 per blur tap.
fn cost(gi: &GiParams, shape: &FrameShape, cost: &mut Cost) {
    cost::rsm(gi, shape, cost);
    let pixels = shape.reduced_pixels(gi);
    let Ok(gi) = Settings::of(gi) else {
        return;
    };
    let (n, m) = (f64::from(gi.vpl_count), f64::from(gi.cluster_count));
    let block = f64::from(gi.interleave.max(1)).powi(2);
    let texels = f64::from(gi.paraboloid_size).powi(2);
    let (shade_ns, maps, texel_ns) = match gi.visibility {
        Visibility::Cssm => (140.0, m, 650.0),
        Visibility::VplShadows => (90.0, n, 330.0),
        Visibility::Off => (50.0, 0.0, 0.0),
    };
    cost.add(
        "VPL shading (pixels × vpl_count / interleave²)",
        pixels * n / block,
        shade_ns,
    );
    if gi.visibility != Visibility::VplShadows {
        cost.add(
            "k-means (vpl_count × cluster_count × (2 × kmeans_iterations + 2))",
            n * m * f64::from(2 * gi.kmeans_iterations + 2),
            10.0,
        );
    }
    cost.add(
        "paraboloid maps (maps × triangles)",
        maps * shape.triangles as f64,
        cost::NS_PER_TRIANGLE,
    );
    cost.add(
        "paraboloid maps (maps × paraboloid_size²)",
        maps * texels,
        texel_ns,
    );
    cost.add("blur (pixels × interleave²)", pixels * block, 30.0);
}

/// What the table's ranges cannot say: the RSM within the light's faces, the weights not
/// both zero, the maps a power of two within their memory, the shown light one that exists.
fn validate(gi: &GiParams, faces: u32) -> Result<(), InvalidSetting> {
    let g = Settings::of(gi)?;
    let range = InvalidSetting::check_range;
    range("rsm_size", g.rsm_size, 16, max_rsm_size(faces))?;
    if g.cluster_position_weight + g.cluster_normal_weight <= 0.0 {
        return Err(InvalidSetting::new(
            "cluster_position_weight",
            "cluster_position_weight and cluster_normal_weight are both 0: every distance \
             would be 0",
        ));
    }
    if !g.paraboloid_size.is_power_of_two() {
        return Err(InvalidSetting::new(
            "paraboloid_size",
            format!(
                "{} is not a power of two (the maps' mip chains halve it down to 1)",
                g.paraboloid_size
            ),
        ));
    }
    let lights = match g.visibility {
        Visibility::VplShadows => g.vpl_count,
        _ => g.cluster_count,
    };
    range("shadow_light", g.shadow_light, 0, lights - 1)?;
    let atlas = AtlasLayout::of(
        g.visibility,
        g.paraboloid_size,
        g.vpl_count,
        g.cluster_count,
    );
    let count = match g.visibility {
        Visibility::VplShadows => format!("{} VPLs", g.vpl_count),
        _ => format!("{} VALs", g.cluster_count),
    };
    let side = atlas.tallest_side();
    if !atlas.fits() {
        return Err(InvalidSetting::new(
            "paraboloid_size",
            format!(
                "{count} with {} {s}×{s} paraboloid maps need {} MiB and an atlas {side} texels \
                 high; the limits are {} MiB and {}: lower paraboloid_size or the count",
                g.visibility.name(),
                atlas.bytes().div_ceil(1 << 20),
                MAX_VISIBILITY_BYTES >> 20,
                passes::MAX_ATLAS_SIDE,
                s = g.paraboloid_size,
            ),
        ));
    }
    Ok(())
}

/// What the `clusters` and `vpls` debug views show of a frame: every VPL's RSM texel,
/// surface point, normal, flux and VAL.
#[derive(Clone, Debug, PartialEq)]
pub struct ClusterView {
    pub rsm_width: u32,
    pub rsm_height: u32,
    /// Row-major RSM texel of each VPL.
    pub texels: Vec<u32>,
    /// C: each VPL's VAL, `None` for unlit VPLs. With `vpl_shadows` every lit VPL is its own
    /// light: C(i) = i.
    pub mapping: Vec<Option<u32>>,
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub flux: Vec<[f32; 3]>,
}

/// One pixel of the `val-shadow` view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightShadowTexel {
    /// No geometry.
    Empty,
    /// The light and the surface face away from each other: no light either way.
    FacingAway,
    /// The light's visibility at the surface, 0 (shadow) to 1.
    Visibility(f32),
}

/// What the `val-shadow` view shows: one light's visibility per pixel, row-major at the
/// method's resolution.
#[derive(Clone, Debug, PartialEq)]
pub struct LightShadowView {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<LightShadowTexel>,
}

/// Staged copies behind [`ClusterView`] and [`LightShadowView`].
enum ClusteredCapture {
    Clusters {
        rsm_width: u32,
        rsm_height: u32,
        vpls: wgpu::Buffer,
        /// `None`: every lit VPL is its own light (`vpl_shadows`).
        mapping: Option<wgpu::Buffer>,
    },
    LightShadow {
        width: u32,
        height: u32,
        readback: TextureReadback,
    },
}

impl DebugCapture for ClusteredCapture {
    fn read(
        self: Box<Self>,
        ctx: &GpuContext,
        submission: Option<&wgpu::SubmissionIndex>,
    ) -> Result<DebugData, GpuError> {
        match *self {
            Self::Clusters {
                rsm_width,
                rsm_height,
                vpls,
                mapping,
            } => {
                let vpls = PendingMap::new(&vpls);
                let mapping = mapping.as_ref().map(PendingMap::new);
                ctx.wait_for(submission)?;
                let vpls: Vec<Vpl> = bytemuck::pod_collect_to_vec(&vpls.finish()?);
                let mapping: Vec<Option<u32>> = match mapping {
                    Some(m) => bytemuck::pod_collect_to_vec::<u8, u32>(&m.finish()?)
                        .into_iter()
                        .map(|c| (c != passes::NO_VAL).then_some(c))
                        .collect(),
                    None => (0..)
                        .zip(&vpls)
                        .map(|(i, v)| (v.lit != 0).then_some(i))
                        .collect(),
                };
                Ok(DebugData(Arc::new(ClusterView {
                    rsm_width,
                    rsm_height,
                    texels: vpls.iter().map(|v| v.texel).collect(),
                    mapping,
                    positions: vpls.iter().map(|v| v.position).collect(),
                    normals: vpls.iter().map(|v| v.normal).collect(),
                    flux: vpls.iter().map(|v| v.flux).collect(),
                })))
            }
            Self::LightShadow {
                width,
                height,
                readback,
            } => {
                let pending = readback.begin_read();
                ctx.wait_for(submission)?;
                let texels: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&pending.finish()?);
                Ok(DebugData(Arc::new(LightShadowView {
                    width,
                    height,
                    texels: texels
                        .iter()
                        .map(|t| match t[3] {
                            0.0 => LightShadowTexel::Empty,
                            1.0 => LightShadowTexel::Visibility(t[0]),
                            _ => LightShadowTexel::FacingAway,
                        })
                        .collect(),
                })))
            }
        }
    }
}

/// The interleaved-shading texture of one output size, with the G-buffer it was made for.
struct Interleaved {
    gbuffer: wgpu::Texture,
    target: Target,
}

/// Interleaved textures kept at once (one per output size in use).
const MAX_INTERLEAVED: usize = 4;

/// The RSM, the cluster buffers and the interleaved textures, made for the frames' sizes
/// and parameters.
#[derive(Default)]
struct FrameTargets {
    rsm: Option<Rsm>,
    buffers: Option<ClusterBuffers>,
    visibility: Option<VisibilityTargets>,
    /// Most recently used first.
    interleaved: Vec<Interleaved>,
}

/// What [`FrameTargets::prepare`] hands a frame.
struct Prepared<'a> {
    rsm: &'a Rsm,
    buffers: &'a ClusterBuffers,
    visibility: &'a VisibilityTargets,
    interleaved: &'a Target,
}

impl FrameTargets {
    /// The RSM, cluster buffers, visibility maps and interleaved texture of this frame, made
    /// or reused.
    fn prepare(
        &mut self,
        device: &wgpu::Device,
        visibility_pass: &VisibilityPass,
        frame: &FrameInputs,
        g: &Settings,
        faces: u32,
    ) -> Prepared<'_> {
        let rsm = Rsm::reuse_or_new(
            &mut self.rsm,
            device,
            g.rsm_size,
            faces,
            frame.visibility_buffer,
        );
        if !self
            .buffers
            .as_ref()
            .is_some_and(|b| b.vpl_count == g.vpl_count && b.cluster_count == g.cluster_count)
        {
            self.buffers = None;
        }
        let buffers = self
            .buffers
            .get_or_insert_with(|| ClusterBuffers::new(device, g.vpl_count, g.cluster_count));
        let atlas = AtlasLayout::of(
            g.visibility,
            g.paraboloid_size,
            g.vpl_count,
            g.cluster_count,
        );
        if !self.visibility.as_ref().is_some_and(|v| v.layout == atlas) {
            self.visibility = None;
        }
        let visibility = self
            .visibility
            .get_or_insert_with(|| VisibilityTargets::new(device, visibility_pass, atlas));
        let gbuffer = &frame.gbuffer.position.texture;
        match self.interleaved.iter().position(|i| &i.gbuffer == gbuffer) {
            Some(i) => {
                let hit = self.interleaved.remove(i);
                self.interleaved.insert(0, hit);
            }
            None => {
                self.interleaved.truncate(MAX_INTERLEAVED - 1);
                self.interleaved.insert(
                    0,
                    Interleaved {
                        gbuffer: gbuffer.clone(),
                        target: passes::interleaved_target(device, frame.width, frame.height),
                    },
                );
            }
        }
        Prepared {
            rsm,
            buffers,
            visibility,
            interleaved: &self.interleaved[0].target,
        }
    }
}

/// Per-scene state of `clustered`.
pub struct Clustered {
    ctx: GpuContext,
    rsm_pass: RsmPass,
    params: wgpu::Buffer,
    clustering: ClusteringPass,
    visibility: VisibilityPass,
    indirect: ImagePass,
    /// The `val-shadow` view's pass.
    light_shadow: ImagePass,
    blur: ImagePass,
    targets: FrameTargets,
    /// The scene's extent (bounding-box diagonal): the unit of Δx and of the blur distance.
    extent: f32,
    /// Whether the last frame ran (the buffers hold its results).
    encoded: bool,
    /// The last frame's visibility.
    visibility_mode: Visibility,
    /// VALs the next frame's k-means starts from instead of the seeds (once).
    next_start: Option<Vec<Val>>,
}

/// Everything a frame's clustering produced, read back for tests.
#[derive(Clone, Debug)]
pub struct ClusteredReadback {
    pub rsm_width: u32,
    pub rsm_height: u32,
    pub rsm_position: Vec<[f32; 4]>,
    pub rsm_normal: Vec<[f32; 4]>,
    pub rsm_flux_area: Vec<[f32; 4]>,
    /// `GlossySender::decode` reads these.
    pub rsm_glossy: Vec<[u32; 4]>,
    pub vpls: Vec<Vpl>,
    /// Each VPL's glossy lobe.
    pub vpl_glossy: Vec<GlossySender>,
    /// The VALs.
    pub vals: Vec<Val>,
    /// C: the VAL of every VPL ([`passes::NO_VAL`] for unlit ones).
    pub mapping: Vec<u32>,
    /// The interleaved shading before the blur (RGBA).
    pub interleaved: Vec<[f32; 4]>,
    /// Where the paraboloid maps lie, and their depths (distance over the extent, 1 where
    /// nothing was hit), row-major over the atlas.
    pub atlas: AtlasLayout,
    pub maps: Vec<f32>,
    /// The scene's extent the distances were scaled by.
    pub extent: f32,
}

impl Clustered {
    pub fn new(r: &SceneResources) -> Self {
        let device = &r.ctx.device;
        Self {
            ctx: r.ctx.clone(),
            rsm_pass: RsmPass::new(device, &r.lights, &r.material_layout),
            params: crate::passes::params_buffer(
                device,
                "clustered params",
                size_of::<ClusteredParams>(),
            ),
            clustering: ClusteringPass::new(device),
            visibility: VisibilityPass::new(device),
            indirect: ImagePass::new(
                device,
                &INDIRECT_GROUP,
                &shaders::CLUSTERED_INDIRECT,
                "shade",
            ),
            light_shadow: ImagePass::new(
                device,
                &INDIRECT_GROUP,
                &shaders::CLUSTERED_INDIRECT,
                "light_shadow",
            ),
            blur: ImagePass::new(device, &BLUR_GROUP, &shaders::GEOMETRY_BLUR, "blur"),
            targets: FrameTargets::default(),
            extent: (r.scene.bounds.radius() * 2.0).max(f32::MIN_POSITIVE),
            encoded: false,
            visibility_mode: Visibility::default(),
            next_start: None,
        }
    }

    /// Starts the next frame's k-means from `vals` (a previous frame's VALs, as
    /// [`Self::read_back`] gives them) instead of the seeds: the reuse of last frame's clusters
    /// that §5.2 argues against, so that tests and benchmarks can compare it with the restart.
    /// Ignored unless the next frame has as many VALs.
    pub fn start_next_frame_from(&mut self, vals: Vec<Val>) {
        self.next_start = Some(vals);
    }

    /// The last frame's RSM, VPLs, VALs, mapping and interleaved shading (blocking readback;
    /// for tests), or `None` before the first frame.
    pub fn read_back(&self) -> Result<Option<ClusteredReadback>, GpuError> {
        let t = &self.targets;
        let (Some(rsm), Some(buffers), Some(visibility), Some(interleaved), true) = (
            &t.rsm,
            &t.buffers,
            &t.visibility,
            t.interleaved.first(),
            self.encoded,
        ) else {
            return Ok(None);
        };
        let ctx = &self.ctx;
        let read_raw = |t: &wgpu::Texture, bytes: u32| -> Result<Vec<u8>, GpuError> {
            let size = t.size();
            let readback =
                TextureReadback::new(&ctx.device, "clustered", size.width, size.height, bytes);
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
            readback.encode_copy(&mut encoder, t);
            ctx.queue.submit([encoder.finish()]);
            readback.read(ctx)
        };
        let read_texture = |t: &wgpu::Texture| read_rgba_texture(ctx, t);
        Ok(Some(ClusteredReadback {
            rsm_width: rsm.width(),
            rsm_height: rsm.height(),
            rsm_position: read_texture(&rsm.position.texture)?,
            rsm_normal: read_texture(&rsm.normal.texture)?,
            rsm_flux_area: read_texture(&rsm.flux_area.texture)?,
            rsm_glossy: read_rgba_u32_texture(ctx, &rsm.glossy.texture)?,
            vpls: bytemuck::pod_collect_to_vec(&read_buffer(ctx, &buffers.vpls)?),
            vpl_glossy: bytemuck::pod_collect_to_vec(&read_buffer(ctx, &buffers.vpl_glossy)?),
            vals: bytemuck::pod_collect_to_vec(&read_buffer(ctx, &buffers.vals)?),
            mapping: bytemuck::pod_collect_to_vec(&read_buffer(ctx, &buffers.mapping)?),
            interleaved: read_texture(&interleaved.target.texture)?,
            atlas: visibility.layout,
            maps: bytemuck::pod_collect_to_vec(&read_raw(&visibility.depth.texture, 4)?),
            extent: self.extent,
        }))
    }
}

impl Method for Clustered {
    fn encode(
        &mut self,
        frame: &FrameInputs,
        stages: &mut FrameStages,
    ) -> Result<Option<ProgressBuffer>, GiError> {
        let r = frame.resources;
        let g = &Settings::of(frame.settings)?;
        let faces = frame.light_faces;
        let device = &r.ctx.device;
        // Emissive surfaces send VPLs from one more face, clustered with the lights' VPLs.
        let emitter_face =
            self.rsm_pass
                .prepare_emitters(device, &r.scene, g.rsm_size, emitters(frame.settings));
        let Prepared {
            rsm,
            buffers,
            visibility,
            interleaved,
        } = self.targets.prepare(
            device,
            &self.visibility,
            frame,
            g,
            faces.len() as u32 + u32::from(emitter_face),
        );
        let queue = &r.ctx.queue;
        let rsm_faces = RsmFace::all(faces, g.rsm_size, g.senders);
        self.rsm_pass.set_faces(queue, &rsm_faces);
        let atlas = visibility.layout;
        let params = ClusteredParams {
            rsm_width: rsm.width(),
            rsm_height: rsm.height(),
            vpl_count: g.vpl_count,
            cluster_count: g.cluster_count,
            position_weight: g.cluster_position_weight / self.extent,
            normal_weight: g.cluster_normal_weight,
            interleave: g.interleave,
            width: frame.width,
            height: frame.height,
            blur_distance: g.blur_distance * self.extent,
            blur_normal: g.blur_normal,
            visibility: passes::visibility_code(g.visibility),
            map_size: atlas.map_size,
            atlas_columns: atlas.columns,
            atlas_rows: atlas.rows,
            fourier_terms: g.fourier_terms,
            extent: self.extent,
            shadow_light: g.shadow_light,
            keep_centres: 0,
            pad2: 0,
        };
        let start = self
            .next_start
            .take()
            .filter(|v| v.len() == g.cluster_count as usize);
        let params = match &start {
            Some(vals) => {
                queue.write_buffer(&buffers.vals, 0, bytemuck::cast_slice(vals));
                ClusteredParams {
                    keep_centres: 1,
                    ..params
                }
            }
            None => params,
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let clustering_group = self.clustering.bind(device, &self.params, rsm, buffers);
        // The maps' lights: the VALs, or every VPL for the hard-shadow baseline.
        let centres = match g.visibility {
            Visibility::VplShadows => &buffers.vpls,
            Visibility::Off | Visibility::Cssm => &buffers.vals,
        };
        let gb = frame.gbuffer;
        let indirect_resources = IndirectResources {
            params: &self.params,
            camera: &r.camera,
            g_position: &gb.position,
            g_normal_roughness: &gb.normal_roughness,
            g_base_metallic: &gb.base_metallic,
            g_emissive_specular: &gb.emissive_specular,
            vpls: &buffers.vpls,
            interleaved_out: interleaved,
            centres,
            mapping: &buffers.mapping,
            depth_atlas: &visibility.depth.view,
            basis: &visibility.basis_view,
            basis_sampler: &visibility.sampler,
            brdf_table: &r.scene_buffers.brdf_table,
            vpl_glossy: &buffers.vpl_glossy,
        };
        let indirect_group = indirect_resources.bind(device, &self.indirect.layout);
        let blur_group = BlurResources {
            params: &self.params,
            g_position: &gb.position,
            g_normal_roughness: &gb.normal_roughness,
            interleaved,
            indirect_out: frame.indirect,
        }
        .bind(device, &self.blur.layout);
        self.encoded = true;
        self.visibility_mode = g.visibility;
        self.rsm_pass
            .encode_stage(stages, rsm, &r.scene_buffers, frame.shared)?;
        stages.stage(stages::VPL_GENERATION, |e| {
            self.clustering
                .encode_vpls(e, &clustering_group, g.vpl_count)
        })?;
        // Per-VPL shadows need no VALs: the baseline's cost leaves clustering out.
        if g.visibility != Visibility::VplShadows {
            stages.stage(stages::CLUSTERING, |e| {
                self.clustering.encode_clustering(
                    e,
                    &clustering_group,
                    buffers,
                    g.kmeans_iterations,
                )
            })?;
        }
        if g.visibility != Visibility::Off {
            stages.stage(stages::PARABOLOID_MAPS, |e| {
                self.visibility.encode_maps(
                    device,
                    e,
                    &self.params,
                    centres,
                    &r.scene_buffers,
                    visibility,
                )
            })?;
        }
        if g.visibility == Visibility::Cssm {
            stages.stage(stages::CSSM_BASIS, |e| {
                self.visibility.encode_basis(e, visibility)
            })?;
        }
        stages.stage(stages::CLUSTERED_INDIRECT, |e| {
            self.indirect
                .encode(e, &indirect_group, frame.width, frame.height)
        })?;
        // The view's pass runs after the blur has read the interleaved texture it overwrites.
        let shadow_group = (frame.debug_view == views::VAL_SHADOW.name)
            .then(|| indirect_resources.bind(device, &self.light_shadow.layout));
        stages.stage(stages::GEOMETRY_BLUR, |e| {
            self.blur.encode(e, &blur_group, frame.width, frame.height);
            if let Some(group) = &shadow_group {
                self.light_shadow
                    .encode(e, group, frame.width, frame.height);
            }
        })?;
        Ok(None)
    }

    fn capture_debug(
        &self,
        view: View,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Option<Box<dyn DebugCapture>> {
        let t = &self.targets;
        let capture = match view {
            v if v == views::CLUSTERS.name || v == views::VPLS.name => {
                let (rsm, buffers) = (t.rsm.as_ref()?, t.buffers.as_ref()?);
                // The per-VPL baseline skips the clustering: its mapping is stale.
                let own_lights = self.visibility_mode == Visibility::VplShadows;
                ClusteredCapture::Clusters {
                    rsm_width: rsm.width(),
                    rsm_height: rsm.height(),
                    vpls: stage_buffer(device, encoder, &buffers.vpls),
                    mapping: (!own_lights).then(|| stage_buffer(device, encoder, &buffers.mapping)),
                }
            }
            v if v == views::VAL_SHADOW.name => {
                let target = &t.interleaved.first()?.target.texture;
                let size = target.size();
                let readback =
                    TextureReadback::new(device, "light shadow", size.width, size.height, 16);
                readback.encode_copy(encoder, target);
                ClusteredCapture::LightShadow {
                    width: size.width,
                    height: size.height,
                    readback,
                }
            }
            _ => return None,
        };
        Some(Box::new(capture))
    }

    fn retain_targets(&mut self, live: &[&GBuffer]) {
        self.targets
            .interleaved
            .retain(|i| live.iter().any(|g| g.position.texture == i.gbuffer));
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}
