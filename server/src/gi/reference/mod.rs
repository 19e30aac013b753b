//! `reference`: a progressive path tracer on the GPU, the truth the GI methods are measured
//! against (issue 10).
//!
//! Compute shaders only (no ray-tracing hardware, so it runs on lavapipe): a BVH built per scene
//! on the CPU ([`bvh`]) is traversed in WGSL (`shaders/reference/`). For every pixel it
//! estimates the indirect radiance leaving the surface point the pixel centre sees towards the
//! camera — the quantity the other methods write into their indirect buffer — with the same
//! BRDF (diffuse + normalised Phong lobe, eq. 3–4 of seed 004), punctual light and emitters, but
//! with exact visibility. `bounces` = 1 is the single-bounce light seed 004 approximates.
//!
//! Samples accumulate while the camera, light, size and settings stay the same; each sample
//! is one dispatch (short enough for lavapipe's silent dispatch limit at small sizes). Random
//! numbers are a hash of pixel, sample index and seed, so the same request gives the same
//! pixels on the same adapter.
//!
//! Not yet modelled: base-colour textures (materials use their factors) and alpha masks.

pub mod bvh;

use crate::gpu::{readback::read_buffer, shaders, GpuContext, GpuError};
use crate::passes::frame_uniforms::{camera_view_proj, LightUniform};
use crate::passes::{self, ParamSlots};
use crate::scene::{material, Material, Scene};
use bytemuck::{Pod, Zeroable};
use lightcast_protocol::{Camera, Light};
use wgpu::util::DeviceExt;

/// Most bounces a path may take.
pub const MAX_BOUNCES: u32 = 16;
/// Samples per pixel one [`PathTracer::accumulate`] call encodes at most (one dispatch each).
pub const MAX_SAMPLES_PER_CALL: u32 = 256;

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
    pub glossy_exponent: f32,
    pub pad0: u32,
    pub pad1: u32,
}

/// Mirrors `SurfaceGpu` in `shaders/reference/path_trace.wgsl`: a material's BRDF split.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct SurfaceGpu {
    pub diffuse: [f32; 3],
    pub exponent: f32,
    pub glossy: [f32; 3],
    pub pad0: f32,
    pub emissive: [f32; 3],
    pub pad1: f32,
}

impl SurfaceGpu {
    /// The material's untextured diffuse/glossy split and emission (see [`material::split`]).
    pub fn from_material(m: &Material) -> Self {
        let s = m.diffuse_glossy();
        Self::new(s, m.emissive)
    }

    pub fn new(split: material::DiffuseGlossy, emissive: [f32; 3]) -> Self {
        Self {
            diffuse: split.diffuse.to_array(),
            exponent: split.exponent,
            glossy: split.glossy.to_array(),
            emissive,
            ..Self::default()
        }
    }
}

/// What the reference renders.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceSettings {
    /// Reflections after the surface a pixel sees (1: single-bounce indirect light).
    pub bounces: u32,
    /// Seed of the random streams.
    pub seed: u32,
    /// Phong exponent for every material (`None`: their own), as in the other methods.
    pub glossy_exponent: Option<f32>,
}

impl Default for ReferenceSettings {
    fn default() -> Self {
        Self {
            bounces: 1,
            seed: 0,
            glossy_exponent: None,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ReferenceError {
    #[error(transparent)]
    Bvh(#[from] bvh::BvhError),
    #[error("invalid {field}: {reason}")]
    InvalidSetting { field: &'static str, reason: String },
    #[error(transparent)]
    Gpu(#[from] GpuError),
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
    width: u32,
    height: u32,
    camera: Camera,
    light: Light,
    settings: ReferenceSettings,
}

/// Per-scene GPU state of the reference path tracer.
pub struct PathTracer {
    ctx: GpuContext,
    pipeline: wgpu::ComputePipeline,
    pass_layout: wgpu::BindGroupLayout,
    scene_group: wgpu::BindGroup,
    params: ParamSlots,
    light: wgpu::Buffer,
    bounds: crate::scene::Aabb,
    accum: Option<(AccumKey, wgpu::Buffer, u32)>,
}

/// Layout of group 1: the BVH and the scene data shading reads (`bvh.wgsl`, `path_trace.wgsl`).
fn scene_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("reference scene"),
        entries: &(0..5)
            .map(|b| passes::storage_entry(b, true))
            .collect::<Vec<_>>(),
    })
}

fn storage_init(device: &wgpu::Device, label: &str, contents: &[u8]) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage: wgpu::BufferUsages::STORAGE,
    })
}

/// The scene's BVH, vertices, indices and surfaces on the GPU, bound as group 1.
fn scene_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    scene: &Scene,
    bvh: &bvh::SceneBvh,
    surfaces: &[SurfaceGpu],
) -> wgpu::BindGroup {
    let buffers = [
        storage_init(device, "bvh nodes", bytemuck::cast_slice(&bvh.nodes)),
        storage_init(
            device,
            "bvh triangles",
            bytemuck::cast_slice(&bvh.triangles),
        ),
        storage_init(device, "vertices", bytemuck::cast_slice(&scene.vertices)),
        storage_init(device, "indices", bytemuck::cast_slice(&scene.indices)),
        storage_init(device, "surfaces", bytemuck::cast_slice(surfaces)),
    ];
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("reference scene"),
        layout,
        entries: &buffers
            .iter()
            .enumerate()
            .map(|(i, b)| passes::buffer_binding(i as u32, b))
            .collect::<Vec<_>>(),
    })
}

impl PathTracer {
    /// A tracer for `scene` with its materials' untextured BRDF.
    pub fn new(ctx: GpuContext, scene: &Scene) -> Result<Self, ReferenceError> {
        let surfaces: Vec<SurfaceGpu> = scene
            .materials
            .iter()
            .map(SurfaceGpu::from_material)
            .collect();
        Self::with_surfaces(ctx, scene, &surfaces)
    }

    /// A tracer for `scene` whose material `i` reflects and emits as `surfaces[i]`.
    pub fn with_surfaces(
        ctx: GpuContext,
        scene: &Scene,
        surfaces: &[SurfaceGpu],
    ) -> Result<Self, ReferenceError> {
        let bvh = bvh::SceneBvh::build(scene)?;
        let device = &ctx.device;
        let scene_layout = scene_layout(device);
        let scene_group = scene_group(device, &scene_layout, scene, &bvh, surfaces);
        let params = ParamSlots::new(
            device,
            "reference params",
            std::mem::size_of::<TraceParams>() as u64,
            MAX_SAMPLES_PER_CALL,
        );
        let pass_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("reference"),
            entries: &[
                params.layout_entry(0),
                passes::params_entry(1),
                passes::storage_entry(2, false),
            ],
        });
        let pipeline = passes::compute_pipeline_with_groups(
            device,
            "reference path trace",
            &[&pass_layout, &scene_layout],
            &shaders::REFERENCE_PATH_TRACE.create_module(device),
            "main",
        );
        let light = passes::params_buffer(
            device,
            "reference light",
            std::mem::size_of::<LightUniform>(),
        );
        Ok(Self {
            pipeline,
            pass_layout,
            scene_group,
            params,
            light,
            bounds: scene.bounds,
            accum: None,
            ctx,
        })
    }

    /// Samples per pixel accumulated for the current camera, light, size and settings.
    pub fn samples(&self) -> u32 {
        self.accum.as_ref().map_or(0, |(_, _, n)| *n)
    }

    /// Adds `samples` samples per pixel (at most [`MAX_SAMPLES_PER_CALL`]), restarting the
    /// accumulation if anything changed since the last call, and waits for them.
    pub fn accumulate(
        &mut self,
        width: u32,
        height: u32,
        camera: &Camera,
        light: &Light,
        settings: &ReferenceSettings,
        samples: u32,
    ) -> Result<(), ReferenceError> {
        if !(1..=MAX_BOUNCES).contains(&settings.bounces) {
            return Err(ReferenceError::InvalidSetting {
                field: "bounces",
                reason: format!("{} is outside 1..={MAX_BOUNCES}", settings.bounces),
            });
        }
        if !(1..=MAX_SAMPLES_PER_CALL).contains(&samples) {
            return Err(ReferenceError::InvalidSetting {
                field: "spp",
                reason: format!("{samples} is outside 1..={MAX_SAMPLES_PER_CALL}"),
            });
        }
        let key = AccumKey {
            width,
            height,
            camera: camera.clone(),
            light: light.clone(),
            settings: *settings,
        };
        let device = &self.ctx.device;
        if self.accum.as_ref().is_none_or(|(k, _, _)| *k != key) {
            let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("reference accumulation"),
                size: u64::from(width) * u64::from(height) * 16,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                // wgpu zero-initialises it: the sums start at 0.
                mapped_at_creation: false,
            });
            self.accum = Some((key, buffer, 0));
        }
        let Some((_, accum, done)) = self.accum.as_mut() else {
            unreachable!("accumulation was just ensured");
        };
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
            glossy_exponent: settings.glossy_exponent.unwrap_or(0.0),
            pad0: 0,
            pad1: 0,
        };
        let slots: Vec<TraceParams> = (0..samples)
            .map(|i| TraceParams {
                sample_index: *done + i,
                ..base
            })
            .collect();
        self.params.write(&self.ctx.queue, &slots);
        let light_uniform = LightUniform::new(light, &self.bounds, 16);
        self.ctx
            .queue
            .write_buffer(&self.light, 0, bytemuck::bytes_of(&light_uniform));
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("reference"),
            layout: &self.pass_layout,
            entries: &[
                self.params.binding(0),
                passes::buffer_binding(1, &self.light),
                passes::buffer_binding(2, accum),
            ],
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("reference"),
        });
        {
            let mut pass = passes::begin_compute(&mut encoder, "reference path trace");
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(1, &self.scene_group, &[]);
            // One dispatch per sample, each reading its own parameter slot.
            for i in 0..samples {
                pass.set_bind_group(0, &group, &[ParamSlots::offset(i)]);
                pass.dispatch_workgroups(
                    width.div_ceil(passes::TILE),
                    height.div_ceil(passes::TILE),
                    1,
                );
            }
        }
        self.ctx.queue.submit([encoder.finish()]);
        self.ctx.wait_idle()?;
        *done += samples;
        Ok(())
    }

    /// The accumulated image (blocking readback).
    pub fn read(&self) -> Result<Option<ReferenceImage>, ReferenceError> {
        let Some((key, accum, samples)) = self.accum.as_ref() else {
            return Ok(None);
        };
        let sums: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&read_buffer(&self.ctx, accum)?);
        Ok(Some(resolve(key.width, key.height, *samples, &sums)))
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

/// Rec. 709 luminance, as `luminance` in `path_trace.wgsl`.
pub fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}
