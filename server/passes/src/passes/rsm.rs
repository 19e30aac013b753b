//! Reflective shadow map (`shaders/rsm_texel.wgsl`): VAL position, normal, flux and disk area
//! per texel and the glossy lobe it sends on ([`GlossySender`]), the faces of every light of
//! the frame side by side in one atlas, and, when emissive surfaces light the frame, one face
//! more holding samples of the emitters ([`EmitterFace`]), so that every RSM-based method
//! lights from them as from any texel.
//!
//! With triangle ids the atlas can be rasterised as a visibility buffer (issue 36), the
//! triangle id and the base colour (`shaders/rsm_visibility.wgsl`, 12 bytes a texel), which a
//! compute pass resolves into the targets (`shaders/rsm_resolve.wgsl`, stage `rsm_resolve`);
//! otherwise the raster writes every target (`shaders/rsm.wgsl`, 56 bytes a texel). The
//! methods read the same targets either way.

use super::bind::{self, bind_group};
use super::frame_uniforms::{face_index, LightFace};
use super::scene_buffers::SceneBuffers;
use super::{ParamSlots, Target};
use crate::gpu::readback::padded_bytes_per_row;
use crate::gpu::shaders;
use crate::gpu::{timing::FrameStages, GpuError};
use crate::scene::{emitters, Scene};
use bytemuck::{Pod, Zeroable};
use lightcast_protocol::Senders;

pub const POSITION_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
pub const NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
/// Flux of a small texel far from a dim light can be far below f16's normal range.
pub const FLUX_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
/// [`GlossySender::encode`]: three f32 and a packed direction and exponent.
pub const GLOSSY_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Uint;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// A point light's six faces for each of the most lights a frame has.
const MAX_FACES: u32 = 6 * super::frame_uniforms::MAX_LIGHTS as u32;
/// Largest RSM side per light face.
pub const MAX_RSM_SIZE: u32 = 4096;
/// Most RSM texels over all faces (each costs ~66 bytes across the sampling stages, 60 in
/// the RSM's targets and depth, and 12 more with a visibility buffer: 78).
pub const MAX_RSM_TEXELS: u64 = 4096 * 4096;
/// Widest atlas: the texture width every Vulkan adapter we run on allows (lavapipe and
/// desktop GPUs: 16,384 or more).
pub const MAX_ATLAS_WIDTH: u32 = 16384;

/// Largest RSM side per face for `faces` faces of all the frame's lights together (6 per
/// point light): the texel budget and the atlas width shared between them.
pub fn max_rsm_size(faces: u32) -> u32 {
    let faces = faces.max(1);
    MAX_RSM_SIZE
        .min(((MAX_RSM_TEXELS / u64::from(faces)) as f64).sqrt() as u32)
        .min(MAX_ATLAS_WIDTH / faces)
}

/// Mirrors `RsmFace` in `shaders/rsm_texel.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct RsmFace {
    pub view_proj: [[f32; 4]; 4],
    pub axis: [f32; 3],
    pub texel_area: f32,
    pub perspective: u32,
    /// The face's light in the frame's `LightsUniform`.
    pub light: u32,
    /// The face's index among its light's (a cube face, a directional light's cascade).
    pub index: u32,
    /// 1: texels send on their glossy part (`senders: full`).
    pub glossy: u32,
}

impl RsmFace {
    /// Eq. 1 for an RSM of `size`² texels per face: the disk area is `texel_area · z²` for
    /// perspective faces (w_near·h_near / z_near² is the squared frustum side at unit depth)
    /// and `texel_area` itself for an orthographic face. `light` is the face's light's index,
    /// `index` the face's among its light's; with `senders` full texels send on their glossy
    /// part.
    pub fn new(face: &LightFace, size: u32, light: u32, index: u32, senders: Senders) -> Self {
        let texel_side = face.extent / size as f32;
        Self {
            view_proj: face.view_proj.to_cols_array_2d(),
            axis: face.axis.into(),
            texel_area: texel_side * texel_side,
            perspective: u32::from(face.perspective),
            light,
            index,
            glossy: u32::from(senders == Senders::Full),
        }
    }

    /// The RSM faces of every light's `faces` (as `frame_uniforms::lights_faces` lists them).
    pub fn all(faces: &[(u32, LightFace)], size: u32, senders: Senders) -> Vec<Self> {
        faces
            .iter()
            .enumerate()
            .map(|(i, (light, f))| Self::new(f, size, *light, face_index(faces, i), senders))
            .collect()
    }
}

/// Mirrors `GlossySender` in `shaders/rsm_glossy.wgsl`: the glossy lobe an RSM texel sends on,
/// ρ_g·Φ_in·(k+2)/2π·max(r·ω, 0)^k (see there), as the VALs and VPLs made from texels carry it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GlossySender {
    /// ρ_g·Φ_in: the Phong lobe's colour times the flux the texel receives.
    pub weight: [f32; 3],
    /// Phong exponent k.
    pub exponent: f32,
    /// Unit mirror direction of the light the texel receives.
    pub mirror: [f32; 3],
    pub pad0: f32,
}

/// Bits of the octahedral mirror direction's coordinates and of log2 k in an RSM texel
/// (`GLOSSY_*` in `shaders/rsm_glossy.wgsl`).
const GLOSSY_OCT_BITS: u32 = 11;
const GLOSSY_EXPONENT_BITS: u32 = 10;
const GLOSSY_MAX_LOG2_EXPONENT: f32 = 12.0;

impl GlossySender {
    /// `decode_glossy`: the sender of a [`GLOSSY_FORMAT`] texel as read back.
    pub fn decode(texel: [u32; 4]) -> Self {
        let unit = |q: u32, bits: u32| (q & ((1 << bits) - 1)) as f32 / ((1 << bits) - 1) as f32;
        let w = texel[3];
        let oct = glam::Vec2::new(
            unit(w, GLOSSY_OCT_BITS),
            unit(w >> GLOSSY_OCT_BITS, GLOSSY_OCT_BITS),
        ) * 2.0
            - glam::Vec2::ONE;
        let log2_k = unit(w >> (2 * GLOSSY_OCT_BITS), GLOSSY_EXPONENT_BITS);
        Self {
            weight: [0, 1, 2].map(|i| f32::from_bits(texel[i])),
            exponent: (log2_k * GLOSSY_MAX_LOG2_EXPONENT).exp2(),
            mirror: crate::scene::octahedral::decode(oct).into(),
            pad0: 0.0,
        }
    }

    /// `sent_flux`: the flux a light of diffuse flux `flux` sends towards unit `toward` (in
    /// the units of a diffuse flux: its intensity is this times cosθ/π), its lobe widened by
    /// `spread` ([`Self::spread`]).
    pub fn sent_flux(&self, flux: glam::Vec3, toward: glam::Vec3, spread: f32) -> glam::Vec3 {
        let c = glam::Vec3::from(self.mirror).dot(toward);
        if c <= 0.0 {
            return flux;
        }
        let k = self.exponent / (1.0 + self.exponent * spread);
        flux + glam::Vec3::from(self.weight) * (0.5 * (k + 2.0) * c.powf(k))
    }

    /// `glossy_spread`: the variance a light standing for texels over `area` adds to its
    /// lobe seen from squared distance `d2`, A/(4π d²).
    pub fn spread(area: f32, d2: f32) -> f32 {
        area / (4.0 * std::f32::consts::PI * d2)
    }

    /// This sender with its weight times `s` (a VPL standing for `s` texels).
    pub fn scaled(self, s: f32) -> Self {
        Self {
            weight: self.weight.map(|w| w * s),
            ..self
        }
    }
}

/// The visibility buffer's id format (scene-wide triangle ids, as the G-buffer's).
pub const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
/// The visibility buffer's base colour (half floats: within 2^-11 of the material's, which the
/// fat raster lights at f32), with the facing in alpha (1 front, 0.5 back, 0 empty).
pub const BASE_FACING_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// The RSM atlas: `faces` squares of `size`² side by side.
pub struct Rsm {
    pub size: u32,
    pub faces: u32,
    pub position: Target,
    pub normal: Target,
    pub flux_area: Target,
    pub glossy: Target,
    depth: Target,
    /// The visibility buffer's triangle id and base colour with facing, where the atlas is
    /// resolved from one.
    visibility: Option<[Target; 2]>,
    /// What its faces were last drawn from ([`RsmPass::encode_stage`]).
    made: super::reuse::MadeFrom,
}

impl Rsm {
    /// `faces` faces (one at least, left empty where a frame has no light and no emitters:
    /// a texture needs a texel); with `visibility` rasterised as a visibility buffer and
    /// resolved (which needs triangle ids: `Features::PRIMITIVE_INDEX`).
    pub fn new(device: &wgpu::Device, size: u32, faces: u32, visibility: bool) -> Self {
        let faces = faces.max(1);
        let (w, h) = (size * faces, size);
        let drawn = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        let usage = drawn
            | wgpu::TextureUsages::COPY_SRC
            | wgpu::TextureUsages::COPY_DST
            | if visibility {
                wgpu::TextureUsages::STORAGE_BINDING
            } else {
                wgpu::TextureUsages::empty()
            };
        Self {
            size,
            faces,
            position: Target::new(device, "rsm position", w, h, POSITION_FORMAT, usage),
            normal: Target::new(device, "rsm normal", w, h, NORMAL_FORMAT, usage),
            flux_area: Target::new(device, "rsm flux", w, h, FLUX_FORMAT, usage),
            glossy: Target::new(device, "rsm glossy", w, h, GLOSSY_FORMAT, usage),
            depth: Target::new(
                device,
                "rsm depth",
                w,
                h,
                DEPTH_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
            ),
            visibility: visibility.then(|| {
                [
                    Target::new(device, "rsm triangle id", w, h, ID_FORMAT, drawn),
                    Target::new(device, "rsm base colour", w, h, BASE_FACING_FORMAT, drawn),
                ]
            }),
            made: Default::default(),
        }
    }

    /// The RSM in `slot` if it has `size`, `faces` and `visibility`, else a new one there (the
    /// old one released before the new one is allocated).
    pub fn reuse_or_new<'a>(
        slot: &'a mut Option<Rsm>,
        device: &wgpu::Device,
        size: u32,
        faces: u32,
        visibility: bool,
    ) -> &'a Rsm {
        if !slot.as_ref().is_some_and(|r| {
            r.size == size && r.faces == faces.max(1) && r.visibility() == visibility
        }) {
            *slot = None;
        }
        slot.get_or_insert_with(|| Self::new(device, size, faces, visibility))
    }

    /// Whether the atlas is resolved from a visibility buffer.
    pub fn visibility(&self) -> bool {
        self.visibility.is_some()
    }

    pub fn width(&self) -> u32 {
        self.size * self.faces
    }

    pub fn height(&self) -> u32 {
        self.size
    }

    pub fn texels(&self) -> u32 {
        self.width() * self.height()
    }
}

bind_group! {
    /// Group 0 of `shaders/rsm_vertex.wgsl` (group 1 is
    /// [`super::scene_buffers::MATERIAL_GROUP`]).
    pub struct Resources as GROUP("rsm", wgpu::ShaderStages::VERTEX_FRAGMENT) {
        face: bind::param_slot::<RsmFace>(),
        lights: bind::PARAMS,
    }
}

bind_group! {
    /// Group 0 of `shaders/rsm_resolve.wgsl`.
    pub struct ResolveResources as RESOLVE_GROUP("rsm resolve", wgpu::ShaderStages::COMPUTE) {
        faces: bind::STORAGE,
        lights: bind::PARAMS,
        vis_id: bind::UINT_TEXTURE,
        vis_base: bind::TEXTURE,
        indices: bind::STORAGE,
        vertices: bind::STORAGE,
        materials: bind::STORAGE,
        out_position: bind::storage_texture(POSITION_FORMAT),
        out_normal: bind::storage_texture(NORMAL_FORMAT),
        out_flux_area: bind::storage_texture(FLUX_FORMAT),
        out_glossy: bind::storage_texture(GLOSSY_FORMAT),
        brdf_table: bind::STORAGE,
    }
}

/// The visibility buffer's raster and resolve.
struct Visibility {
    raster: wgpu::RenderPipeline,
    resolve: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

pub struct RsmPass {
    /// Rasterises every target.
    pipeline: wgpu::RenderPipeline,
    pipeline_layout: wgpu::PipelineLayout,
    /// The device has triangle ids, which the visibility buffer needs.
    triangle_ids: bool,
    /// Made for the first RSM drawn as a visibility buffer (a CPU adapter, which keeps the
    /// fat targets by default, never compiles them).
    visibility: std::sync::OnceLock<Visibility>,
    faces: ParamSlots,
    /// The faces again as one array, for the resolve.
    face_array: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    lights: wgpu::Buffer,
    /// The emitter face of the last size asked for, by that size (kept while the size stays;
    /// `None` inside where the scene has no emitters), and whether the frame being prepared
    /// has it as the atlas's last face.
    emitters: Option<(u32, Option<EmitterFace>)>,
    emitter_face: bool,
    /// Faces drawn from the lights ([`Self::set_faces`]); the emitter face follows them.
    light_faces: u32,
    /// Those faces as written, part of what an RSM is made from.
    face_bytes: Vec<u8>,
}

/// Most emitter samples an emitter face holds: 256² points stand for the emitters finer than
/// any real-time method resolves them, and keep the face's copy buffers small (2.6 MB) at
/// every RSM size.
pub const MAX_EMITTER_SAMPLES: u32 = 256 * 256;

/// The emitter samples a face of `size`² holds: all its texels, at most
/// [`MAX_EMITTER_SAMPLES`]; they fill its first texels in rows, the rest stay empty.
pub fn emitter_samples(size: u32) -> u32 {
    (size * size).min(MAX_EMITTER_SAMPLES)
}

/// Emissive surfaces as VALs: [`emitter_samples`] samples of the scene's emitters
/// ([`crate::scene::emitters::sample`]), in the texel layout of an RSM face, copied into the
/// atlas's last face after the lights' faces are drawn. A texel holds a sample's position
/// (w = 1), normal and flux with its disk area: what `shaders/rsm_texel.wgsl` makes of a
/// surface a light reflects from, here the light the emitter sends itself. Emitters are
/// Lambertian: the face's glossy texels stay zero as the raster's clear (or the resolve, which
/// clears texels the raster left empty) left them (no glossy lobe).
pub struct EmitterFace {
    pub size: u32,
    /// Rows of the face the samples fill (the copy's height).
    rows: u32,
    position: wgpu::Buffer,
    normal: wgpu::Buffer,
    flux_area: wgpu::Buffer,
}

impl EmitterFace {
    /// The scene's emitters as a face of `size`²; `None` when it has none.
    pub fn new(device: &wgpu::Device, scene: &Scene, size: u32) -> Option<Self> {
        let samples = emitters::sample(scene, emitter_samples(size) as usize);
        if samples.is_empty() {
            return None;
        }
        let filled_rows = (samples.len() as u32).div_ceil(size);
        let rows = |bytes_per_texel: u32, texel: &dyn Fn(&emitters::EmitterSample) -> Vec<u8>| {
            let stride = padded_bytes_per_row(size, bytes_per_texel) as usize;
            let mut data = vec![0u8; stride * filled_rows as usize];
            for (k, s) in samples.iter().enumerate() {
                let (x, y) = (k % size as usize, k / size as usize);
                let at = y * stride + x * bytes_per_texel as usize;
                data[at..at + bytes_per_texel as usize].copy_from_slice(&texel(s));
            }
            data
        };
        let buffer = |label, contents: Vec<u8>| {
            wgpu::util::DeviceExt::create_buffer_init(
                device,
                &wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: &contents,
                    usage: wgpu::BufferUsages::COPY_SRC,
                },
            )
        };
        let f32s = |v: [f32; 4]| bytemuck::cast_slice(&v).to_vec();
        Some(Self {
            size,
            rows: filled_rows,
            position: buffer(
                "rsm emitter positions",
                rows(16, &|s| f32s(s.position.extend(1.0).to_array())),
            ),
            normal: buffer(
                "rsm emitter normals",
                rows(8, &|s| {
                    let n = s.normal.extend(0.0).to_array().map(half::f16::from_f32);
                    bytemuck::cast_slice(&n).to_vec()
                }),
            ),
            flux_area: buffer(
                "rsm emitter flux",
                rows(16, &|s| f32s(s.flux.extend(s.area).to_array())),
            ),
        })
    }

    /// Copies the samples into face `face` of `rsm`.
    fn encode(&self, encoder: &mut wgpu::CommandEncoder, rsm: &Rsm, face: u32) {
        for (buffer, target, bytes_per_texel) in [
            (&self.position, &rsm.position, 16),
            (&self.normal, &rsm.normal, 8),
            (&self.flux_area, &rsm.flux_area, 16),
        ] {
            encoder.copy_buffer_to_texture(
                wgpu::TexelCopyBufferInfo {
                    buffer,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(padded_bytes_per_row(self.size, bytes_per_texel)),
                        rows_per_image: Some(self.rows),
                    },
                },
                wgpu::TexelCopyTextureInfo {
                    texture: &target.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: face * rsm.size,
                        y: 0,
                        z: 0,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::Extent3d {
                    width: self.size,
                    height: self.rows,
                    depth_or_array_layers: 1,
                },
            );
        }
    }
}

impl RsmPass {
    pub fn new(
        device: &wgpu::Device,
        lights: &wgpu::Buffer,
        material_layout: &wgpu::BindGroupLayout,
    ) -> Self {
        let layout = GROUP.layout(device);
        let faces = ParamSlots::new::<RsmFace>(device, "rsm faces", MAX_FACES);
        let bind_group = Resources {
            face: &faces,
            lights,
        }
        .bind(device, &layout);
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("rsm"),
            bind_group_layouts: &[Some(&layout), Some(material_layout)],
            immediate_size: 0,
        });
        Self {
            pipeline: raster_pipeline(
                device,
                &pipeline_layout,
                &shaders::RSM,
                &[POSITION_FORMAT, NORMAL_FORMAT, FLUX_FORMAT, GLOSSY_FORMAT],
            ),
            pipeline_layout,
            triangle_ids: device.features().contains(wgpu::Features::PRIMITIVE_INDEX),
            visibility: std::sync::OnceLock::new(),
            faces,
            face_array: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("rsm resolve faces"),
                size: u64::from(MAX_FACES) * std::mem::size_of::<RsmFace>() as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            bind_group,
            lights: lights.clone(),
            emitters: None,
            emitter_face: false,
            light_faces: 0,
            face_bytes: Vec::new(),
        }
    }

    /// The lights' faces of the next frame, drawn in this order at the atlas's start.
    pub fn set_faces(&mut self, queue: &wgpu::Queue, faces: &[RsmFace]) {
        self.faces.write(queue, faces);
        let drawn = &faces[..faces.len().min(MAX_FACES as usize)];
        queue.write_buffer(&self.face_array, 0, bytemuck::cast_slice(drawn));
        self.light_faces = faces.len() as u32;
        self.face_bytes = bytemuck::cast_slice(faces).to_vec();
    }

    /// Whether the next frame's RSM of `size`² faces ends with the emitter face: when `on`
    /// (`render.gi.emitters`) and `scene` has emitters. Builds the face on first use of a size.
    pub fn prepare_emitters(
        &mut self,
        device: &wgpu::Device,
        scene: &Scene,
        size: u32,
        on: bool,
    ) -> bool {
        if on && self.emitters.as_ref().is_none_or(|(s, _)| *s != size) {
            self.emitters = Some((size, EmitterFace::new(device, scene, size)));
        }
        self.emitter_face = on && matches!(self.emitters, Some((_, Some(_))));
        self.emitter_face
    }

    /// The `rsm` stage of a frame, which draws the lights' faces of `rsm` (as a visibility
    /// buffer where `rsm` has one, resolved in stage `rsm_resolve`) and copies the emitter face
    /// in after them if [`Self::prepare_emitters`] said so; or nothing where `rsm` already
    /// holds what this frame's faces make from `shared` (the frame's lights and poses as bytes;
    /// `None`: reuse off), the stages then reported as reused ([`super::reuse`]).
    pub fn encode_stage(
        &self,
        stages: &mut FrameStages,
        rsm: &Rsm,
        scene: &SceneBuffers,
        shared: Option<&[u8]>,
    ) -> Result<(), GpuError> {
        let inputs = shared.map(|s| {
            [
                s,
                &self.face_bytes,
                &[u8::from(self.emitter_face)],
                &rsm.size.to_le_bytes(),
            ]
            .concat()
        });
        let thin = rsm.visibility.as_ref().filter(|_| self.triangle_ids);
        if rsm.made.holds(inputs.as_deref()) {
            stages.reused(super::stages::RSM);
            if thin.is_some() {
                stages.reused(super::stages::RSM_RESOLVE);
            }
            return Ok(());
        }
        let made = match thin {
            None => stages.stage(super::stages::RSM, |e| {
                let targets = [
                    &rsm.position.view,
                    &rsm.normal.view,
                    &rsm.flux_area.view,
                    &rsm.glossy.view,
                ];
                self.draw(e, rsm, scene, &self.pipeline, &targets);
                self.copy_emitters(e, rsm);
            }),
            Some(ids_and_base) => {
                let device = stages.device();
                let v = self
                    .visibility
                    .get_or_init(|| Visibility::new(device, &self.pipeline_layout));
                let [id, base] = ids_and_base;
                stages
                    .stage(super::stages::RSM, |e| {
                        self.draw(e, rsm, scene, &v.raster, &[&id.view, &base.view])
                    })
                    .and_then(|()| {
                        stages.stage(super::stages::RSM_RESOLVE, |e| {
                            self.encode_resolve(device, e, v, (rsm, ids_and_base), scene);
                            self.copy_emitters(e, rsm);
                        })
                    })
            }
        };
        made.inspect_err(|_| rsm.made.forget())
    }

    /// Rasterises the lights' faces of `rsm` into `targets` with `pipeline` (every target, or
    /// the visibility buffer).
    fn draw(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        rsm: &Rsm,
        scene: &SceneBuffers,
        pipeline: &wgpu::RenderPipeline,
        targets: &[&wgpu::TextureView],
    ) {
        let mut pass =
            super::scene_buffers::begin_material_pass(encoder, "rsm", targets, &rsm.depth.view);
        pass.set_pipeline(pipeline);
        for face in 0..self.light_faces.min(rsm.faces) {
            let size = rsm.size as f32;
            pass.set_viewport(face as f32 * size, 0.0, size, size, 0.0, 1.0);
            pass.set_bind_group(0, &self.bind_group, &[ParamSlots::offset(face)]);
            scene.draw_with_materials(&mut pass, &scene.shadow_casting);
        }
    }

    /// Fills `rsm`'s targets from its visibility buffer, the triangle ids and base colours
    /// `[id, base]` (empty texels cleared).
    fn encode_resolve(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        v: &Visibility,
        (rsm, [id, base]): (&Rsm, &[Target; 2]),
        scene: &SceneBuffers,
    ) {
        let group = ResolveResources {
            faces: &self.face_array,
            lights: &self.lights,
            vis_id: id,
            vis_base: base,
            indices: &scene.indices,
            vertices: &scene.vertices,
            materials: &scene.material_table,
            out_position: &rsm.position,
            out_normal: &rsm.normal,
            out_flux_area: &rsm.flux_area,
            out_glossy: &rsm.glossy,
            brdf_table: &scene.brdf_table,
        }
        .bind(device, &v.layout);
        let mut pass = super::begin_compute(encoder, "rsm resolve");
        pass.set_pipeline(&v.resolve);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(
            rsm.width().div_ceil(super::TILE),
            rsm.height().div_ceil(super::TILE),
            1,
        );
    }

    /// If [`Self::prepare_emitters`] said so, copies the emitter face in after the lights'
    /// faces.
    fn copy_emitters(&self, encoder: &mut wgpu::CommandEncoder, rsm: &Rsm) {
        if let (true, Some((_, Some(emitters)))) = (self.emitter_face, &self.emitters) {
            emitters.encode(encoder, rsm, self.light_faces.min(rsm.faces));
        }
    }
}

impl Visibility {
    fn new(device: &wgpu::Device, pipeline_layout: &wgpu::PipelineLayout) -> Self {
        let layout = RESOLVE_GROUP.layout(device);
        Self {
            raster: raster_pipeline(
                device,
                pipeline_layout,
                &shaders::RSM_VISIBILITY,
                &[ID_FORMAT, BASE_FACING_FORMAT],
            ),
            resolve: super::compute_pipeline(
                device,
                "rsm resolve",
                &layout,
                &shaders::RSM_RESOLVE.create_module(device),
                "resolve",
            ),
            layout,
        }
    }
}

/// An RSM raster of `source` into `formats`.
fn raster_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    source: &shaders::ShaderSource,
    formats: &[wgpu::TextureFormat],
) -> wgpu::RenderPipeline {
    super::scene_buffers::material_pipeline(
        device,
        source.name,
        layout,
        &source.create_module(device),
        formats,
        DEPTH_FORMAT,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shaders::{layout_check::assert_struct, RSM};
    use std::mem::{offset_of, size_of};

    #[test]
    fn rsm_face_matches_wgsl() {
        assert_struct(
            &RSM,
            "RsmFace",
            size_of::<RsmFace>(),
            &[
                ("view_proj", offset_of!(RsmFace, view_proj)),
                ("axis", offset_of!(RsmFace, axis)),
                ("texel_area", offset_of!(RsmFace, texel_area)),
                ("perspective", offset_of!(RsmFace, perspective)),
                ("light", offset_of!(RsmFace, light)),
                ("index", offset_of!(RsmFace, index)),
                ("glossy", offset_of!(RsmFace, glossy)),
            ],
        );
    }

    #[test]
    fn glossy_sender_matches_wgsl() {
        assert_struct(
            &RSM,
            "GlossySender",
            size_of::<GlossySender>(),
            &[
                ("weight", offset_of!(GlossySender, weight)),
                ("exponent", offset_of!(GlossySender, exponent)),
                ("mirror", offset_of!(GlossySender, mirror)),
                ("pad0", offset_of!(GlossySender, pad0)),
            ],
        );
    }
}
