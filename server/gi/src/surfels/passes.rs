//! The surfels' per-frame GPU passes (`shaders/surfels/`), compared with [`super::cpu`]:
//!
//! 1. `surfel_light`: every surfel's radiosity from the frame's light and shadow map, its
//!    emission and, on multi-bounce frames, the previous bounce's caches;
//! 2. `surfel_pull`: flux pulled up the hierarchy, one dispatch per level;
//! 3. `surfel_cache_light`: every cache's SH radiance over its links (eq. 4);
//! 4. `surfel_shade`: per-pixel diffuse and glossy indirect light from the interpolated caches
//!    (eq. 5–8).
//!
//! [`SurfelBuffers`] holds a scene's surfel set on the GPU.

use super::{cpu, sh, SurfelSet};
use crate::gpu::shaders;
use crate::passes::bind::{self, bind_group, BindKind};
use crate::passes::{
    gbuffer::GBuffer, params_buffer, shadow_map::ShadowMap, ParamSlots, Target, INDIRECT_FORMAT,
};
use crate::scene::nodes::{can_move, owners, posed_worlds, Poses};
use crate::scene::Scene;
use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3};
use wgpu::util::DeviceExt;

/// Most SH bands the GPU passes handle (16 coefficients per cache).
pub const MAX_GPU_BANDS: u32 = 4;

/// Mirrors `SurfelGpu` in `shaders/surfels/surfel_light.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct SurfelGpu {
    pub position: [f32; 3],
    pub pad0: f32,
    pub normal: [f32; 3],
    pub pad1: f32,
    /// Diffuse albedo ρ of the surface under the surfel.
    pub albedo: [f32; 3],
    pub pad2: f32,
    /// Emitted radiosity π·L_e.
    pub emitted: [f32; 3],
    pub pad3: f32,
}

/// Mirrors `GridUniform` in `shaders/surfels/caches.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GridUniform {
    pub origin: [f32; 3],
    pub spacing: f32,
    pub dims: [u32; 3],
    pub coefficients: u32,
}

/// Mirrors `LightParams` in `shaders/surfels/surfel_light.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct LightParams {
    pub surfel_count: u32,
    pub feedback: u32,
    pub offset: f32,
    /// 1: add the surfels' emission (`render.gi.emitters`).
    pub emitters: u32,
}

/// Mirrors `PullLevel` in `shaders/surfels/pull.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct PullLevel {
    pub first: u32,
    pub count: u32,
    pub leaves: u32,
    pub pad0: u32,
}

/// Mirrors `CacheLightParams` in `shaders/surfels/cache_light.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct CacheLightParams {
    pub caches: u32,
    pub per_cache: u32,
    pub coefficients: u32,
    pub pad0: u32,
}

bind_group! {
    /// Group 0 of `shaders/surfels/surfel_light.wgsl`.
    pub struct LightResources as LIGHT_GROUP("surfel light", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        lights: bind::PARAMS,
        shadow_map: BindKind::Texture {
            sample_type: wgpu::TextureSampleType::Depth,
            dimension: wgpu::TextureViewDimension::D2Array,
        },
        shadow_sampler: BindKind::Sampler(wgpu::SamplerBindingType::Comparison),
        surfels: bind::STORAGE,
        grid: bind::PARAMS,
        cache_usable: bind::STORAGE,
        cache_light: bind::STORAGE,
        flux: bind::STORAGE_RW,
        moved: bind::STORAGE,
    }
}

bind_group! {
    /// Group 0 of `shaders/surfels/pull.wgsl`.
    pub struct PullResources as PULL_GROUP("surfel pull", wgpu::ShaderStages::COMPUTE) {
        level: bind::param_slot::<PullLevel>(),
        children: bind::STORAGE,
        by_level: bind::STORAGE,
        flux: bind::STORAGE_RW,
    }
}

bind_group! {
    /// Group 0 of `shaders/surfels/cache_light.wgsl`.
    pub struct CacheLightResources as CACHE_LIGHT_GROUP("surfel cache light", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        link_nodes: bind::STORAGE,
        link_coeffs: bind::STORAGE,
        flux: bind::STORAGE,
        cache_light: bind::STORAGE_RW,
    }
}

bind_group! {
    /// Group 0 of `shaders/surfels/shade.wgsl`.
    pub struct ShadeResources as SHADE_GROUP("surfel shade", wgpu::ShaderStages::COMPUTE) {
        camera: bind::PARAMS,
        g_position: bind::TEXTURE,
        g_normal_roughness: bind::TEXTURE,
        g_base_metallic: bind::TEXTURE,
        g_emissive_specular: bind::TEXTURE,
        grid: bind::PARAMS,
        cache_usable: bind::STORAGE,
        cache_light: bind::STORAGE,
        indirect_out: bind::storage_texture(INDIRECT_FORMAT),
        brdf_table: bind::STORAGE,
    }
}

bind_group! {
    /// Group 0 of `shaders/surfels/cache_sh_view.wgsl` (debug view `cache-sh`).
    pub struct ShViewResources as SH_VIEW_GROUP("surfel cache sh view", wgpu::ShaderStages::COMPUTE) {
        g_position: bind::TEXTURE,
        g_normal_roughness: bind::TEXTURE,
        grid: bind::PARAMS,
        cache_usable: bind::STORAGE,
        cache_light: bind::STORAGE,
        view_out: bind::STORAGE_RW,
    }
}

/// Diffuse albedo and emitted radiosity of the surface under every surfel: the diffuse lobe's
/// albedo of the material's BRDF with its base colour times its texture at the surfel's uv,
/// averaged over cosine-weighted directions (`Brdf::mean_lobes`: a surfel's light goes every
/// way).
pub fn surfel_materials(scene: &Scene, set: &SurfelSet) -> Vec<(Vec3, Vec3)> {
    set.surfels
        .iter()
        .map(|s| {
            let Some(m) = scene.materials.get(s.material as usize) else {
                return (Vec3::ZERO, Vec3::ZERO);
            };
            let texture = m
                .base_color_texture
                .and_then(|t| scene.textures.get(t))
                .map_or(Vec3::ONE, |t| texel_linear(t, s.uv));
            let albedo = m.brdf_with(texture).mean_lobes().diffuse;
            (albedo, Vec3::from(m.emissive) * std::f32::consts::PI)
        })
        .collect()
}

/// The sRGB texel nearest to `uv` (repeat wrapping) as linear RGB. Nearest rather than the
/// raster passes' bilinear filter: a surfel stands for a patch far larger than a texel.
fn texel_linear(t: &crate::scene::Texture, uv: Vec2) -> Vec3 {
    if t.width == 0 || t.height == 0 {
        return Vec3::ONE;
    }
    let wrap = |c: f32, n: u32| ((c.rem_euclid(1.0) * n as f32) as u32).min(n - 1);
    let (x, y) = (wrap(uv.x, t.width), wrap(uv.y, t.height));
    let i = 4 * (y as usize * t.width as usize + x as usize);
    let linear = |c: u8| {
        let c = f32::from(c) / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    match t.rgba8.get(i..i + 3) {
        Some(p) => Vec3::new(linear(p[0]), linear(p[1]), linear(p[2])),
        None => Vec3::ONE,
    }
}

/// A scene's surfel set on the GPU, with the flux and cache-light buffers its frames fill.
pub struct SurfelBuffers {
    pub surfel_count: u32,
    pub node_count: u32,
    pub cache_count: u32,
    pub per_cache: u32,
    pub coefficients: u32,
    /// Half a cache spacing: where a surfel reads the caches (off its own surface).
    pub offset: f32,
    /// (first, count) of every level of internal nodes, leaves first.
    pub levels: Vec<(u32, u32)>,
    surfels: wgpu::Buffer,
    grid: wgpu::Buffer,
    cache_usable: wgpu::Buffer,
    children: wgpu::Buffer,
    by_level: wgpu::Buffer,
    link_nodes: wgpu::Buffer,
    link_coeffs: wgpu::Buffer,
    /// Radiosity of every leaf, then the pulled flux of every internal node.
    pub flux: wgpu::Buffer,
    /// Per surfel: the position in `Scene::nodes` of the node that moves it (`u32::MAX`:
    /// static), and 1 where the frame's poses moved it (`moved`, for `surfel_light`), for
    /// `poses`.
    surfel_nodes: Vec<u32>,
    moved: wgpu::Buffer,
    poses: Poses,
}

/// Why a surfel set cannot go to the GPU.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum UploadError {
    #[error("the surfels' GPU passes take at most {MAX_GPU_BANDS} SH bands, the set has {0}")]
    Bands(u32),
    #[error("the {what} take {bytes} bytes, more than the GPU binds at once ({limit} bytes); use fewer links or SH bands, or a larger cache spacing")]
    TooLarge {
        what: &'static str,
        bytes: u64,
        limit: u64,
    },
}

/// Bytes of the links' SH coefficients of a set with `caches` caches, `links` links each and
/// `bands` SH bands: the largest buffer the surfels bind.
pub fn link_coefficient_bytes(caches: u64, links: u32, bands: u32) -> u64 {
    caches * u64::from(links) * sh::coefficient_count(bands) as u64 * 4
}

impl SurfelBuffers {
    pub fn new(device: &wgpu::Device, scene: &Scene, set: &SurfelSet) -> Result<Self, UploadError> {
        if set.links.bands > MAX_GPU_BANDS {
            return Err(UploadError::Bands(set.links.bands));
        }
        let limits = device.limits();
        let limit = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let bytes = link_coefficient_bytes(
            set.grid.count() as u64,
            set.links.per_cache,
            set.links.bands,
        );
        if bytes > limit {
            return Err(UploadError::TooLarge {
                what: "links' SH coefficients",
                bytes,
                limit,
            });
        }
        let storage = |label: &str, contents: &[u8]| {
            // wgpu refuses empty bindings; a 16-byte zero buffer stands in for an empty list.
            let contents = if contents.is_empty() {
                &[0u8; 16][..]
            } else {
                contents
            };
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            })
        };
        let materials = surfel_materials(scene, set);
        let surfels: Vec<SurfelGpu> = set
            .surfels
            .iter()
            .zip(&materials)
            .map(|(s, (albedo, emitted))| SurfelGpu {
                position: s.position.to_array(),
                pad0: 0.0,
                normal: s.normal.to_array(),
                pad1: 0.0,
                albedo: albedo.to_array(),
                pad2: 0.0,
                emitted: emitted.to_array(),
                pad3: 0.0,
            })
            .collect();
        let coefficients = sh::coefficient_count(set.links.bands) as u32;
        let grid = GridUniform {
            origin: set.grid.origin.to_array(),
            spacing: set.grid.spacing,
            dims: set.grid.dims.to_array(),
            coefficients,
        };
        let usable: Vec<u32> = (0..set.grid.count())
            .map(|c| u32::from(cpu::usable(set, c)))
            .collect();
        let tree = &set.tree;
        let levels: Vec<(u32, u32)> = tree
            .level_offsets
            .windows(2)
            .map(|w| (w[0], w[1] - w[0]))
            .filter(|&(_, count)| count > 0)
            .collect();
        let surfel_count = set.surfels.len() as u32;
        let node_count = surfel_count + tree.children.len() as u32;
        let cache_count = set.grid.count() as u32;
        let flux = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("surfel flux"),
            size: u64::from(node_count.max(1)) * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let grid_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("surfel grid"),
            contents: bytemuck::bytes_of(&grid),
            usage: crate::passes::PARAMS_USAGE,
        });
        Ok(Self {
            surfel_count,
            node_count,
            cache_count,
            per_cache: set.links.per_cache,
            coefficients,
            offset: 0.5 * set.grid.spacing,
            levels,
            surfels: storage("surfels", bytemuck::cast_slice(&surfels)),
            grid: grid_buffer,
            cache_usable: storage("surfel cache usable", bytemuck::cast_slice(&usable)),
            children: storage("surfel tree children", bytemuck::cast_slice(&tree.children)),
            by_level: storage("surfel tree levels", bytemuck::cast_slice(&tree.by_level)),
            link_nodes: storage("surfel link nodes", bytemuck::cast_slice(&set.links.nodes)),
            link_coeffs: storage(
                "surfel link coefficients",
                bytemuck::cast_slice(&set.links.coeffs),
            ),
            flux,
            moved: storage("surfels moved", &vec![0u8; 4 * surfels.len().max(1)]),
            surfel_nodes: surfel_nodes(scene, set),
            poses: Poses::new(),
        })
    }

    /// Marks the surfels on nodes `poses` moves from where they were sampled (see `moved`):
    /// `posed_worlds` keeps an unmoved node's rest world bit for bit, so equality tells.
    pub fn set_poses(&mut self, queue: &wgpu::Queue, scene: &Scene, poses: &Poses) {
        if *poses == self.poses {
            return;
        }
        let worlds = posed_worlds(&scene.nodes, poses);
        let moved: Vec<u32> = self
            .surfel_nodes
            .iter()
            .map(|&n| {
                u32::from(
                    scene
                        .nodes
                        .get(n as usize)
                        .is_some_and(|node| worlds[n as usize] != node.rest_world),
                )
            })
            .collect();
        if !moved.is_empty() {
            queue.write_buffer(&self.moved, 0, bytemuck::cast_slice(&moved));
        }
        self.poses = poses.clone();
    }

    /// A buffer for one cache lighting: `coefficients` RGB(A) values per cache.
    pub fn cache_light_buffer(&self, device: &wgpu::Device) -> wgpu::Buffer {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("surfel cache light"),
            size: (u64::from(self.cache_count) * u64::from(self.coefficients) * 16).max(16),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    }
}

/// What [`SurfelPasses::encode_light`] reads.
pub struct Bounce<'a> {
    /// The frame's `LightsUniform`.
    pub lights: &'a wgpu::Buffer,
    pub shadow: &'a ShadowMap,
    /// The cache lighting of the previous bounce (`None`: the first bounce).
    pub previous: Option<&'a wgpu::Buffer>,
    /// Whether emissive surfels add their emission (area lights).
    pub emitters: bool,
}

/// The four pipelines and their per-frame parameters.
pub struct SurfelPasses {
    light: wgpu::ComputePipeline,
    light_layout: wgpu::BindGroupLayout,
    pull: wgpu::ComputePipeline,
    pull_layout: wgpu::BindGroupLayout,
    cache: wgpu::ComputePipeline,
    cache_layout: wgpu::BindGroupLayout,
    shade: wgpu::ComputePipeline,
    shade_layout: wgpu::BindGroupLayout,
    sh_view: wgpu::ComputePipeline,
    sh_view_layout: wgpu::BindGroupLayout,
    shadow_sampler: wgpu::Sampler,
    /// By `feedback + 2·emitters`.
    light_params: [wgpu::Buffer; 4],
    /// Bound in place of the previous bounce's caches on a first bounce (not read there).
    no_caches: wgpu::Buffer,
    cache_params: wgpu::Buffer,
    pull_levels: Option<ParamSlots>,
}

impl SurfelPasses {
    pub fn new(device: &wgpu::Device) -> Self {
        let pipeline = |source: &shaders::ShaderSource, layout: &wgpu::BindGroupLayout| {
            let module = source.create_module(device);
            crate::passes::compute_pipeline(device, source.name, layout, &module, "main")
        };
        let light_layout = LIGHT_GROUP.layout(device);
        let pull_layout = PULL_GROUP.layout(device);
        let cache_layout = CACHE_LIGHT_GROUP.layout(device);
        let shade_layout = SHADE_GROUP.layout(device);
        let sh_view_layout = SH_VIEW_GROUP.layout(device);
        let params = |label| params_buffer(device, label, 16);
        Self {
            light: pipeline(&super::shaders::SURFEL_LIGHT, &light_layout),
            pull: pipeline(&super::shaders::SURFEL_PULL, &pull_layout),
            cache: pipeline(&super::shaders::SURFEL_CACHE_LIGHT, &cache_layout),
            shade: pipeline(&super::shaders::SURFEL_SHADE, &shade_layout),
            sh_view: pipeline(&super::shaders::SURFEL_CACHE_SH_VIEW, &sh_view_layout),
            light_layout,
            pull_layout,
            cache_layout,
            shade_layout,
            sh_view_layout,
            shadow_sampler: device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("surfel shadow comparison"),
                mag_filter: wgpu::FilterMode::Linear,
                min_filter: wgpu::FilterMode::Linear,
                compare: Some(wgpu::CompareFunction::LessEqual),
                ..Default::default()
            }),
            light_params: std::array::from_fn(|_| params("surfel light params")),
            no_caches: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("surfel no caches"),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            }),
            cache_params: params("surfel cache light params"),
            pull_levels: None,
        }
    }

    /// Writes the parameters of `buffers`' passes; call before encoding with them.
    pub fn prepare(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, buffers: &SurfelBuffers) {
        for (slot, params) in (0u32..).zip(&self.light_params) {
            let p = LightParams {
                surfel_count: buffers.surfel_count,
                feedback: slot % 2,
                offset: buffers.offset,
                emitters: slot / 2,
            };
            queue.write_buffer(params, 0, bytemuck::bytes_of(&p));
        }
        let c = CacheLightParams {
            caches: buffers.cache_count,
            per_cache: buffers.per_cache,
            coefficients: buffers.coefficients,
            pad0: 0,
        };
        queue.write_buffer(&self.cache_params, 0, bytemuck::bytes_of(&c));
        let levels = buffers.levels.len() as u32;
        if self.pull_levels.as_ref().is_none_or(|s| s.slots() < levels) {
            self.pull_levels = Some(ParamSlots::new::<PullLevel>(
                device,
                "surfel pull levels",
                levels,
            ));
        }
        if let Some(slots) = &self.pull_levels {
            let values: Vec<PullLevel> = buffers
                .levels
                .iter()
                .map(|&(first, count)| PullLevel {
                    first,
                    count,
                    leaves: buffers.surfel_count,
                    pad0: 0,
                })
                .collect();
            slots.write(queue, &values);
        }
    }

    /// Every surfel's radiosity, with the previous bounce's caches when there is one.
    pub fn encode_light(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        buffers: &SurfelBuffers,
        bounce: &Bounce,
    ) {
        let slot = usize::from(bounce.previous.is_some()) + 2 * usize::from(bounce.emitters);
        let group = LightResources {
            params: &self.light_params[slot],
            lights: bounce.lights,
            shadow_map: &bounce.shadow.array_view,
            shadow_sampler: &self.shadow_sampler,
            surfels: &buffers.surfels,
            grid: &buffers.grid,
            cache_usable: &buffers.cache_usable,
            cache_light: bounce.previous.unwrap_or(&self.no_caches),
            flux: &buffers.flux,
            moved: &buffers.moved,
        }
        .bind(device, &self.light_layout);
        let mut pass = crate::passes::begin_compute(encoder, "surfel light");
        pass.set_pipeline(&self.light);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(buffers.surfel_count.div_ceil(64), 1, 1);
    }

    /// Flux up the hierarchy (one dispatch per level).
    pub fn encode_pull(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        buffers: &SurfelBuffers,
    ) {
        let Some(slots) = &self.pull_levels else {
            return;
        };
        let group = PullResources {
            level: slots,
            children: &buffers.children,
            by_level: &buffers.by_level,
            flux: &buffers.flux,
        }
        .bind(device, &self.pull_layout);
        let mut pass = crate::passes::begin_compute(encoder, "surfel pull");
        pass.set_pipeline(&self.pull);
        for (i, &(_, count)) in buffers.levels.iter().enumerate() {
            pass.set_bind_group(0, &group, &[ParamSlots::offset(i as u32)]);
            pass.dispatch_workgroups(count.div_ceil(64), 1, 1);
        }
    }

    /// Eq. 4 into `target` (a [`SurfelBuffers::cache_light_buffer`]).
    pub fn encode_cache_light(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        buffers: &SurfelBuffers,
        target: &wgpu::Buffer,
    ) {
        let group = CacheLightResources {
            params: &self.cache_params,
            link_nodes: &buffers.link_nodes,
            link_coeffs: &buffers.link_coeffs,
            flux: &buffers.flux,
            cache_light: target,
        }
        .bind(device, &self.cache_layout);
        let mut pass = crate::passes::begin_compute(encoder, "surfel cache light");
        pass.set_pipeline(&self.cache);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(
            (buffers.cache_count * buffers.coefficients).div_ceil(64),
            1,
            1,
        );
    }

    /// Per-pixel indirect light from the cache lighting `source` into `indirect`.
    #[allow(clippy::too_many_arguments)]
    pub fn encode_shade(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        camera: &wgpu::Buffer,
        gbuffer: &GBuffer,
        buffers: &SurfelBuffers,
        source: &wgpu::Buffer,
        indirect: &Target,
        size: (u32, u32),
        brdf_table: &wgpu::Buffer,
    ) {
        let group = ShadeResources {
            camera,
            g_position: &gbuffer.position,
            g_normal_roughness: &gbuffer.normal_roughness,
            g_base_metallic: &gbuffer.base_metallic,
            g_emissive_specular: &gbuffer.emissive_specular,
            grid: &buffers.grid,
            cache_usable: &buffers.cache_usable,
            cache_light: source,
            indirect_out: indirect,
            brdf_table,
        }
        .bind(device, &self.shade_layout);
        crate::passes::dispatch_2d(encoder, "surfel shade", &self.shade, &group, size.0, size.1);
    }

    /// Debug view `cache-sh`: the caches' SH radiance of `source` along every pixel's normal
    /// into `out` (a [`sh_view_buffer`] of the G-buffer's size).
    pub fn encode_sh_view(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        gbuffer: &GBuffer,
        buffers: &SurfelBuffers,
        source: &wgpu::Buffer,
        out: &wgpu::Buffer,
    ) {
        let size = gbuffer.position.texture.size();
        let group = ShViewResources {
            g_position: &gbuffer.position,
            g_normal_roughness: &gbuffer.normal_roughness,
            grid: &buffers.grid,
            cache_usable: &buffers.cache_usable,
            cache_light: source,
            view_out: out,
        }
        .bind(device, &self.sh_view_layout);
        crate::passes::dispatch_2d(
            encoder,
            "surfel cache sh view",
            &self.sh_view,
            &group,
            size.width,
            size.height,
        );
    }
}

/// A buffer for [`SurfelPasses::encode_sh_view`]: one RGBA f32 value per pixel.
pub fn sh_view_buffer(device: &wgpu::Device, width: u32, height: u32) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("surfel cache sh view"),
        size: u64::from(width) * u64::from(height) * 16,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

/// Per surfel, the position in `Scene::nodes` of the innermost node of its triangle when that
/// node can move (`u32::MAX`: static geometry).
fn surfel_nodes(scene: &Scene, set: &SurfelSet) -> Vec<u32> {
    let moves = can_move(&scene.nodes);
    let owner = owners(&scene.nodes, scene.vertices.len() as u32);
    set.surfels
        .iter()
        .map(|s| {
            let vertex = scene.indices[3 * s.triangle as usize] as usize;
            match owner.get(vertex) {
                Some(&n) if moves.get(n as usize).copied().unwrap_or(false) => n,
                _ => u32::MAX,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::surfels::shaders::{SURFEL_CACHE_LIGHT, SURFEL_LIGHT, SURFEL_PULL};
    use crate::gpu::shaders::layout_check::assert_struct;
    use std::mem::{offset_of, size_of};

    #[test]
    fn surfel_structs_match_wgsl() {
        assert_struct(
            &SURFEL_LIGHT,
            "SurfelGpu",
            size_of::<SurfelGpu>(),
            &[
                ("position", offset_of!(SurfelGpu, position)),
                ("pad0", offset_of!(SurfelGpu, pad0)),
                ("normal", offset_of!(SurfelGpu, normal)),
                ("pad1", offset_of!(SurfelGpu, pad1)),
                ("albedo", offset_of!(SurfelGpu, albedo)),
                ("pad2", offset_of!(SurfelGpu, pad2)),
                ("emitted", offset_of!(SurfelGpu, emitted)),
                ("pad3", offset_of!(SurfelGpu, pad3)),
            ],
        );
        assert_struct(
            &SURFEL_LIGHT,
            "GridUniform",
            size_of::<GridUniform>(),
            &[
                ("origin", offset_of!(GridUniform, origin)),
                ("spacing", offset_of!(GridUniform, spacing)),
                ("dims", offset_of!(GridUniform, dims)),
                ("coefficients", offset_of!(GridUniform, coefficients)),
            ],
        );
        assert_struct(
            &SURFEL_LIGHT,
            "LightParams",
            size_of::<LightParams>(),
            &[
                ("surfel_count", offset_of!(LightParams, surfel_count)),
                ("feedback", offset_of!(LightParams, feedback)),
                ("offset", offset_of!(LightParams, offset)),
                ("emitters", offset_of!(LightParams, emitters)),
            ],
        );
        assert_struct(
            &SURFEL_PULL,
            "PullLevel",
            size_of::<PullLevel>(),
            &[
                ("first", offset_of!(PullLevel, first)),
                ("count", offset_of!(PullLevel, count)),
                ("leaves", offset_of!(PullLevel, leaves)),
                ("pad0", offset_of!(PullLevel, pad0)),
            ],
        );
        assert_struct(
            &SURFEL_CACHE_LIGHT,
            "CacheLightParams",
            size_of::<CacheLightParams>(),
            &[
                ("caches", offset_of!(CacheLightParams, caches)),
                ("per_cache", offset_of!(CacheLightParams, per_cache)),
                ("coefficients", offset_of!(CacheLightParams, coefficients)),
                ("pad0", offset_of!(CacheLightParams, pad0)),
            ],
        );
    }
}
