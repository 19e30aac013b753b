//! `clustered`: instant radiosity with clustered visibility (seed paper 003, Dong et al.,
//! "Real-time Indirect Illumination with Clustered Visibility"). Per frame and with no
//! precomputation: the RSM, N VPLs fetched from it at Halton positions, k-means of the VPLs
//! into M virtual area lights restarted from the same seeds every frame (§5), and every pixel
//! lit by all N VPLs through interleaved sampling and a geometry-aware blur (§6).
//!
//! Visibility is `off` so far: every VPL sees every point, the paper's "without visibility"
//! baseline of Figure 10. The VALs (position, normal, area) and the mapping C are what the
//! soft-shadow visibility of §4.1–4.2 will read. [`passes`] holds the GPU passes; [`cpu`] is
//! the CPU reference of their equations.

pub mod cpu;
pub mod passes;

use super::{
    DebugCapture, DebugData, FrameInputs, GiError, GiSettings, InvalidSetting, Method, MethodEntry,
    ProgressBuffer, SceneResources,
};
use crate::gpu::readback::{read_buffer, stage_buffer, PendingMap, TextureReadback};
use crate::gpu::{timing::FrameStages, GpuContext, GpuError};
use crate::passes::{
    frame_uniforms::light_faces,
    gbuffer::GBuffer,
    rsm::{max_rsm_size, Rsm, RsmFace, RsmPass},
    Target,
};
use lightcast_protocol::{
    ClusteredVisibility, GiMethod, GiMethodInfo, GiParamInfo, GiParamKind, Limits, Stage, View,
};
use passes::{
    BlurResources, ClusterBuffers, ClusteredParams, ClusteringPass, ImagePass, IndirectResources,
    Val, Vpl, BLUR_GROUP, INDIRECT_GROUP,
};
use std::any::{Any, TypeId};
use std::sync::Arc;

/// Fewest VPLs (the lower bound: at least four per pixel with 8×8 interleaving).
pub const MIN_VPL_COUNT: u32 = 256;
/// Most VPLs: 3 MiB of VPLs and mapping, and N/B² VPLs per pixel.
pub const MAX_VPL_COUNT: u32 = 65_536;
/// Most VALs: each will own a paraboloid depth map and its Fourier basis textures.
pub const MAX_CLUSTER_COUNT: u32 = 256;
/// Most k-means iterations per frame (each costs O(N·M)).
pub const MAX_KMEANS_ITERATIONS: u32 = 64;
/// Largest interleaving block side (the blur reads B² pixels per pixel).
pub const MAX_INTERLEAVE: u32 = 16;

pub const ENTRY: MethodEntry = MethodEntry {
    methods: &[GiMethod::Clustered],
    type_id: TypeId::of::<Clustered>,
    validate,
    create: |r| Ok(Box::new(Clustered::new(r))),
    describe,
    precompute: None,
    downscales: true,
};

fn validate(g: &GiSettings, faces: u32) -> Result<(), InvalidSetting> {
    let range = InvalidSetting::check_range;
    let unit = |field, v: f32, lo: f32| {
        if (lo..=1.0).contains(&v) {
            Ok(())
        } else {
            Err(InvalidSetting::new(
                field,
                format!("{v} is outside [{lo}, 1]"),
            ))
        }
    };
    range("rsm_size", g.rsm_size, 16, max_rsm_size(faces))?;
    range("vpl_count", g.vpl_count, MIN_VPL_COUNT, MAX_VPL_COUNT)?;
    range("cluster_count", g.cluster_count, 1, MAX_CLUSTER_COUNT)?;
    range(
        "kmeans_iterations",
        g.kmeans_iterations,
        0,
        MAX_KMEANS_ITERATIONS,
    )?;
    range("interleave", g.interleave, 1, MAX_INTERLEAVE)?;
    unit("cluster_position_weight", g.cluster_position_weight, 0.0)?;
    unit("cluster_normal_weight", g.cluster_normal_weight, 0.0)?;
    if g.cluster_position_weight + g.cluster_normal_weight <= 0.0 {
        return Err(InvalidSetting::new(
            "cluster_position_weight",
            "cluster_position_weight and cluster_normal_weight are both 0: every distance \
             would be 0",
        ));
    }
    unit("blur_distance", g.blur_distance, 0.0)?;
    unit("blur_normal", g.blur_normal, -1.0)?;
    Ok(())
}

fn describe(limits: &Limits) -> Vec<GiMethodInfo> {
    let d = lightcast_protocol::GiParams::default();
    let param =
        |name: &str, kind, default: serde_json::Value, range: (f64, f64), text: &str| GiParamInfo {
            name: name.into(),
            kind,
            default,
            min: Some(range.0),
            max: Some(range.1),
            choices: Vec::new(),
            description: text.into(),
        };
    let int = GiParamKind::Integer;
    let num = GiParamKind::Number;
    vec![GiMethodInfo {
        method: GiMethod::Clustered,
        summary: "Clustered visibility (seed 003, §4-6): N VPLs from the RSM, k-means into M \
                  virtual area lights, interleaved shading and a geometry-aware blur; \
                  visibility off so far (the paper's baseline without visibility)"
            .into(),
        progressive: false,
        parameters: vec![
            param(
                "rsm_size",
                int,
                d.rsm_size.into(),
                (16.0, limits.max_rsm_size.into()),
                "RSM side per light face in texels; the VPLs are fetched from it",
            ),
            param(
                "vpl_count",
                int,
                d.vpl_count.into(),
                (MIN_VPL_COUNT.into(), MAX_VPL_COUNT.into()),
                "N: virtual point lights fetched from the RSM at Halton positions (§6)",
            ),
            param(
                "cluster_count",
                int,
                d.cluster_count.into(),
                (1.0, MAX_CLUSTER_COUNT.into()),
                "M: virtual area lights, k-means clusters of the VPLs (§5)",
            ),
            param(
                "kmeans_iterations",
                int,
                d.kmeans_iterations.into(),
                (0.0, MAX_KMEANS_ITERATIONS.into()),
                "k-means iterations per frame, restarted every frame from the same seeds, VPL k \
                 for cluster k (§5.2)",
            ),
            param(
                "cluster_position_weight",
                num,
                f64::from(d.cluster_position_weight).into(),
                (0.0, 1.0),
                "w_x of the clustering distance (§5.1), per scene extent (bounding-box \
                 diagonal)",
            ),
            param(
                "cluster_normal_weight",
                num,
                f64::from(d.cluster_normal_weight).into(),
                (0.0, 1.0),
                "w_alpha of the clustering distance (§5.1), per radian between normals",
            ),
            param(
                "interleave",
                int,
                d.interleave.into(),
                (1.0, MAX_INTERLEAVE.into()),
                "Interleaved-sampling block side B: each pixel shades N/B^2 VPLs (§6)",
            ),
            param(
                "blur_distance",
                num,
                f64::from(d.blur_distance).into(),
                (0.0, 1.0),
                "Geometry-aware blur: largest distance between blurred surface points, as a \
                 fraction of the scene extent (§6: 10 %)",
            ),
            param(
                "blur_normal",
                num,
                f64::from(d.blur_normal).into(),
                (-1.0, 1.0),
                "Geometry-aware blur: smallest cosine between blurred normals (§6: 0.8)",
            ),
            GiParamInfo {
                name: "visibility".into(),
                kind: GiParamKind::Choice,
                default: d.visibility.name().into(),
                min: None,
                max: None,
                choices: ClusteredVisibility::ALL
                    .iter()
                    .map(|v| v.name().to_string())
                    .collect(),
                description: "VPL visibility: off (every VPL sees every point, the paper's \
                              baseline without visibility)"
                    .into(),
            },
        ],
    }]
}

/// What the `clusters` debug view shows of a frame: the RSM texel of every VPL and its VAL.
#[derive(Clone, Debug, PartialEq)]
pub struct ClusterView {
    pub rsm_width: u32,
    pub rsm_height: u32,
    /// Row-major RSM texel of each VPL.
    pub texels: Vec<u32>,
    /// C: each VPL's VAL, `None` for unlit VPLs.
    pub mapping: Vec<Option<u32>>,
}

/// Staged copies of the VPLs and the mapping for [`ClusterView`].
struct ClusterCapture {
    rsm_width: u32,
    rsm_height: u32,
    vpls: wgpu::Buffer,
    mapping: wgpu::Buffer,
}

impl DebugCapture for ClusterCapture {
    fn read(
        self: Box<Self>,
        ctx: &GpuContext,
        submission: Option<&wgpu::SubmissionIndex>,
    ) -> Result<DebugData, GpuError> {
        let (vpls, mapping) = (PendingMap::new(&self.vpls), PendingMap::new(&self.mapping));
        ctx.wait_for(submission)?;
        let vpls: Vec<Vpl> = bytemuck::pod_collect_to_vec(&vpls.finish()?);
        let mapping: Vec<u32> = bytemuck::pod_collect_to_vec(&mapping.finish()?);
        Ok(DebugData(Arc::new(ClusterView {
            rsm_width: self.rsm_width,
            rsm_height: self.rsm_height,
            texels: vpls.iter().map(|v| v.texel).collect(),
            mapping: mapping
                .iter()
                .map(|&c| (c != passes::NO_VAL).then_some(c))
                .collect(),
        })))
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
    /// Most recently used first.
    interleaved: Vec<Interleaved>,
}

impl FrameTargets {
    /// The RSM, cluster buffers and interleaved texture of this frame, made or reused.
    fn prepare(
        &mut self,
        device: &wgpu::Device,
        frame: &FrameInputs,
        faces: u32,
    ) -> (&Rsm, &ClusterBuffers, &Target) {
        let g = frame.settings;
        if !self
            .rsm
            .as_ref()
            .is_some_and(|r| r.size == g.rsm_size && r.faces == faces)
        {
            // Release the old RSM before allocating the new one.
            self.rsm = None;
        }
        let rsm = self
            .rsm
            .get_or_insert_with(|| Rsm::new(device, g.rsm_size, faces));
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
        (rsm, buffers, &self.interleaved[0].target)
    }
}

/// Per-scene state of `clustered`.
pub struct Clustered {
    ctx: GpuContext,
    rsm_pass: RsmPass,
    params: wgpu::Buffer,
    clustering: ClusteringPass,
    indirect: ImagePass,
    blur: ImagePass,
    targets: FrameTargets,
    /// The scene's extent (bounding-box diagonal): the unit of Δx and of the blur distance.
    extent: f32,
    /// Whether the last frame ran (the buffers hold its results).
    encoded: bool,
}

/// Everything a frame's clustering produced, read back for tests.
#[derive(Clone, Debug)]
pub struct ClusteredReadback {
    pub rsm_width: u32,
    pub rsm_height: u32,
    pub rsm_position: Vec<[f32; 4]>,
    pub rsm_normal: Vec<[f32; 4]>,
    pub rsm_flux_area: Vec<[f32; 4]>,
    pub vpls: Vec<Vpl>,
    /// The VALs.
    pub vals: Vec<Val>,
    /// C: the VAL of every VPL ([`passes::NO_VAL`] for unlit ones).
    pub mapping: Vec<u32>,
    /// The interleaved shading before the blur (RGBA).
    pub interleaved: Vec<[f32; 4]>,
    /// The scene's extent the distances were scaled by.
    pub extent: f32,
}

impl Clustered {
    pub fn new(r: &SceneResources) -> Self {
        let device = &r.ctx.device;
        Self {
            ctx: r.ctx.clone(),
            rsm_pass: RsmPass::new(device, &r.light, &r.material_layout),
            params: crate::passes::params_buffer(
                device,
                "clustered params",
                size_of::<ClusteredParams>(),
            ),
            clustering: ClusteringPass::new(device),
            indirect: ImagePass::new(
                device,
                &INDIRECT_GROUP,
                &crate::gpu::shaders::CLUSTERED_INDIRECT,
                "shade",
            ),
            blur: ImagePass::new(
                device,
                &BLUR_GROUP,
                &crate::gpu::shaders::GEOMETRY_BLUR,
                "blur",
            ),
            targets: FrameTargets::default(),
            extent: (r.scene.bounds.radius() * 2.0).max(f32::MIN_POSITIVE),
            encoded: false,
        }
    }

    /// The last frame's RSM, VPLs, VALs, mapping and interleaved shading (blocking readback;
    /// for tests), or `None` before the first frame.
    pub fn read_back(&self) -> Result<Option<ClusteredReadback>, GpuError> {
        let t = &self.targets;
        let (Some(rsm), Some(buffers), Some(interleaved), true) =
            (&t.rsm, &t.buffers, t.interleaved.first(), self.encoded)
        else {
            return Ok(None);
        };
        let ctx = &self.ctx;
        let read_texture = |t: &wgpu::Texture, bytes: u32| -> Result<Vec<[f32; 4]>, GpuError> {
            let size = t.size();
            let readback =
                TextureReadback::new(&ctx.device, "clustered", size.width, size.height, bytes);
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
            readback.encode_copy(&mut encoder, t);
            ctx.queue.submit([encoder.finish()]);
            let raw = readback.read(ctx)?;
            Ok(if bytes == 8 {
                bytemuck::pod_collect_to_vec::<u8, half::f16>(&raw)
                    .chunks_exact(4)
                    .map(|c| [c[0].to_f32(), c[1].to_f32(), c[2].to_f32(), c[3].to_f32()])
                    .collect()
            } else {
                bytemuck::pod_collect_to_vec(&raw)
            })
        };
        Ok(Some(ClusteredReadback {
            rsm_width: rsm.width(),
            rsm_height: rsm.height(),
            rsm_position: read_texture(&rsm.position.texture, 16)?,
            rsm_normal: read_texture(&rsm.normal.texture, 8)?,
            rsm_flux_area: read_texture(&rsm.flux_area.texture, 16)?,
            vpls: bytemuck::pod_collect_to_vec(&read_buffer(ctx, &buffers.vpls)?),
            vals: bytemuck::pod_collect_to_vec(&read_buffer(ctx, &buffers.vals)?),
            mapping: bytemuck::pod_collect_to_vec(&read_buffer(ctx, &buffers.mapping)?),
            interleaved: read_texture(&interleaved.target.texture, 16)?,
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
        let g = frame.settings;
        let faces = light_faces(frame.light, &r.scene.bounds);
        let device = &r.ctx.device;
        let (rsm, buffers, interleaved) = self.targets.prepare(device, frame, faces.len() as u32);
        let queue = &r.ctx.queue;
        let rsm_faces: Vec<RsmFace> = faces.iter().map(|f| RsmFace::new(f, g.rsm_size)).collect();
        self.rsm_pass.set_faces(queue, &rsm_faces);
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
            pad0: 0,
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let clustering_group = self.clustering.bind(device, &self.params, rsm, buffers);
        let gb = frame.gbuffer;
        let indirect_group = IndirectResources {
            params: &self.params,
            camera: &r.camera,
            g_position: &gb.position,
            g_normal_exponent: &gb.normal_exponent,
            g_diffuse: &gb.diffuse,
            g_glossy: &gb.glossy,
            vpls: &buffers.vpls,
            interleaved_out: interleaved,
        }
        .bind(device, &self.indirect.layout);
        let blur_group = BlurResources {
            params: &self.params,
            g_position: &gb.position,
            g_normal_exponent: &gb.normal_exponent,
            interleaved,
            indirect_out: frame.indirect,
        }
        .bind(device, &self.blur.layout);
        self.encoded = true;
        stages.stage(Stage::Rsm, |e| {
            self.rsm_pass.encode(e, rsm, &r.scene_buffers)
        })?;
        stages.stage(Stage::VplGeneration, |e| {
            self.clustering
                .encode_vpls(e, &clustering_group, g.vpl_count)
        })?;
        stages.stage(Stage::Clustering, |e| {
            self.clustering
                .encode_clustering(e, &clustering_group, buffers, g.kmeans_iterations)
        })?;
        stages.stage(Stage::ClusteredIndirect, |e| {
            self.indirect
                .encode(e, &indirect_group, frame.width, frame.height)
        })?;
        stages.stage(Stage::GeometryBlur, |e| {
            self.blur.encode(e, &blur_group, frame.width, frame.height)
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
        let (View::Clusters, Some(rsm), Some(buffers)) = (view, &t.rsm, &t.buffers) else {
            return None;
        };
        Some(Box::new(ClusterCapture {
            rsm_width: rsm.width(),
            rsm_height: rsm.height(),
            vpls: stage_buffer(device, encoder, &buffers.vpls),
            mapping: stage_buffer(device, encoder, &buffers.mapping),
        }))
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
