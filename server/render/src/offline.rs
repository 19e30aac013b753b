//! The offline `render` command: one frame of a scene to an image file, no network.

use crate::debug_views::{self, View};
use crate::gi::common::params::EMITTERS;
use crate::gi::lightskin::caches::CacheSet;
use crate::gi::precompute::{self, BuildEnv, Built, Progress, SceneFacts, Store};
use crate::gi::reference::params::SPP;
use crate::gi::GiMethod;
use crate::gpu::{context::AdapterSummary, BackendChoice, GpuContext};
use crate::passes::exposure::Exposure;
use crate::renderer::{RenderError, RenderSettings, Renderer};
use crate::scene::environment_image::EnvironmentImage;
use crate::scene::{
    default_light::{default_camera, default_lights, emitter_stand_in, emitters_for},
    Scene,
};
use glam::Vec3;
use lightcast_protocol::{Camera, GiParams, LightKind};
use std::path::PathBuf;
use std::str::FromStr;
use std::sync::Arc;
use std::time::Instant;

/// The reference's samples per pixel of an offline render that names no `spp`: one image to
/// keep, not a frame of a stream (the table's default adds 4 a frame).
pub const OFFLINE_SPP: u32 = 256;

/// The default scene when none is named: the built-in Cornell box.
pub const DEFAULT_SCENE: &str = "procedural:cornell";

/// Three comma-separated numbers, e.g. `1.5,2,-3`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vec3Arg(pub [f32; 3]);

impl FromStr for Vec3Arg {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        lightcast_protocol::parse_vec3(s).map(Self)
    }
}

/// `auto` or a positive linear scale.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExposureArg(pub Exposure);

impl FromStr for ExposureArg {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.eq_ignore_ascii_case("auto") {
            return Ok(Self(Exposure::Auto));
        }
        match s.parse::<f32>() {
            Ok(v) if v.is_finite() && v > 0.0 => Ok(Self(Exposure::Manual(v))),
            _ => Err(format!("expected 'auto' or a positive number, got '{s}'")),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LightTypeArg {
    Directional,
    Spot,
    Point,
}

impl From<LightTypeArg> for LightKind {
    fn from(a: LightTypeArg) -> Self {
        match a {
            LightTypeArg::Directional => LightKind::Directional,
            LightTypeArg::Spot => LightKind::Spot,
            LightTypeArg::Point => LightKind::Point,
        }
    }
}

/// GI parameters by name and the precomputation store, shared by `render`, `bench` and
/// `bench-stream`.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct GiArgs {
    /// A GI parameter by its `render.gi` name, e.g. `--gi-param rsm_size=256` or
    /// `--gi-param visibility=vpl_shadows` (repeatable). The value is JSON (a number,
    /// `true`/`false`, `null`) or else a name. Every method's parameters, with their ranges and
    /// defaults, are in the README's table and `/v1/server`; those the method does not read are
    /// ignored.
    #[arg(long = "gi-param", value_name = "NAME=VALUE", value_parser = parse_gi_param)]
    pub gi_params: Vec<(String, serde_json::Value)>,
    /// Where precomputed light caches and surfel sets are kept (env LIGHTCAST_CACHE_DIR;
    /// default: the user's cache directory).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
}

/// `NAME=VALUE` of `--gi-param`: a parameter some method has, and a value of its type (its
/// range is checked when the frame's method reads it).
pub fn parse_gi_param(s: &str) -> Result<(String, serde_json::Value), String> {
    let (name, value) = s
        .split_once('=')
        .ok_or_else(|| format!("{s:?} is not NAME=VALUE"))?;
    let param = crate::gi::params::find(name).ok_or_else(|| {
        let names: Vec<&str> = crate::gi::params::all().iter().map(|p| p.name).collect();
        format!(
            "no GI parameter {name:?}; the parameters are {}",
            names.join(", ")
        )
    })?;
    let value = serde_json::from_str(value).unwrap_or_else(|_| value.into());
    param
        .check(&value, false, None)
        .map_err(|reason| format!("{name}: {reason}"))?;
    Ok((name.to_string(), value))
}

impl GiArgs {
    /// `method` with the named parameters.
    pub fn gi(&self, method: GiMethod) -> GiParams {
        let mut gi = GiParams::new(method);
        for (name, value) in &self.gi_params {
            gi.set(name, value.clone());
        }
        gi
    }

    /// Builds what frames of `gi` precompute per scene (loading it from the store where it is
    /// there, using `gpu` where the build can), logging progress and how long it took; `None`
    /// for methods without.
    pub fn precompute(
        &self,
        gi: &GiParams,
        scene: &Scene,
        gpu: Option<&GpuContext>,
        log: &mut dyn FnMut(&str),
    ) -> Result<Option<Built>, PrecomputeError> {
        let Some(entry) = precompute::entry_for(gi.method) else {
            return Ok(None);
        };
        let key = (entry.key)(gi, &SceneFacts::of(scene)).map_err(|e| PrecomputeError {
            what: entry.label,
            message: format!("--gi-param {}: {}", e.field, e.reason),
        })?;
        let store = Store::new(self.cache_dir.clone().unwrap_or_else(Store::default_dir));
        let started = Instant::now();
        let mut last_step = "";
        let mut progress = |p: Progress| {
            if p.step != last_step || p.done == p.total {
                log(&format!(
                    "{}: {} {}/{}",
                    entry.label, p.step, p.done, p.total
                ));
                last_step = p.step;
            }
        };
        let mut env = BuildEnv {
            store: &store,
            progress: &mut progress,
            cancelled: &|| false,
            gpu,
        };
        let built = (entry.build)(scene, &key, &mut env).map_err(|message| PrecomputeError {
            what: entry.label,
            message,
        })?;
        log(&format!(
            "{}: {}{key}, {} in {:.1} ms",
            entry.label,
            entry
                .budget
                .as_ref()
                .map(|b| format!("{} {}, ", built.units, b.unit))
                .unwrap_or_default(),
            if built.from_store {
                "loaded"
            } else {
                "computed"
            },
            started.elapsed().as_secs_f64() * 1e3
        ));
        Ok(Some(built))
    }

    /// The scene's light caches for the named parameters (see [`Self::precompute`]).
    pub fn load(
        &self,
        scene: &Scene,
        log: &mut dyn FnMut(&str),
    ) -> Result<Arc<CacheSet>, PrecomputeError> {
        let built = self.precompute(&self.gi(crate::gi::lightskin::LIGHTSKIN), scene, None, log)?;
        built
            .and_then(|b| b.data.downcast::<CacheSet>().ok())
            .ok_or_else(|| PrecomputeError {
                what: "light caches",
                message: "the light-cache precomputation made no light caches".into(),
            })
    }
}

/// A per-scene precomputation failed.
#[derive(Debug, thiserror::Error)]
#[error("{what}: {message}")]
pub struct PrecomputeError {
    pub what: &'static str,
    pub message: String,
}

/// Options of `lightcast-server render`.
#[derive(Clone, Debug, clap::Args)]
pub struct RenderArgs {
    /// Scene: a .gltf/.glb file, or `procedural:cornell` /
    /// `procedural:street?blocks=N&detail=D&seed=S&materials=M&cars=C` (see the README).
    /// Default: the built-in Cornell box.
    #[arg(long)]
    pub scene: Option<String>,
    /// Output width in pixels.
    #[arg(long, default_value_t = 960)]
    pub width: u32,
    /// Output height in pixels.
    #[arg(long, default_value_t = 540)]
    pub height: u32,
    /// Output image (PNG).
    #[arg(long, default_value = "lightcast.png")]
    pub out: PathBuf,
    /// Camera position X,Y,Z. Default: the file's first camera, else framing the scene bounds.
    #[arg(long, allow_hyphen_values = true)]
    pub camera_pos: Option<Vec3Arg>,
    /// Point the camera looks at, X,Y,Z.
    #[arg(long, allow_hyphen_values = true)]
    pub camera_target: Option<Vec3Arg>,
    /// Vertical field of view in degrees.
    #[arg(long, allow_negative_numbers = true)]
    pub fov: Option<f32>,
    /// Type of the first light. Default: the file's KHR_lights_punctual lights (every one is
    /// rendered; the `--light-*` flags change the first), else a light standing in for the
    /// scene's emissive surfaces, else a sun.
    #[arg(long, value_enum)]
    pub light_type: Option<LightTypeArg>,
    /// Light position X,Y,Z (spot and point).
    #[arg(long, allow_hyphen_values = true)]
    pub light_pos: Option<Vec3Arg>,
    /// Direction the light travels X,Y,Z (directional and spot).
    #[arg(long, allow_hyphen_values = true)]
    pub light_dir: Option<Vec3Arg>,
    /// Linear light colour R,G,B.
    #[arg(long)]
    pub light_color: Option<Vec3Arg>,
    /// Lux for directional lights, candela for spot and point lights.
    #[arg(long, allow_negative_numbers = true)]
    pub light_intensity: Option<f32>,
    /// Spot light inner cone angle in degrees (full intensity inside).
    #[arg(long, allow_negative_numbers = true)]
    pub light_inner_cone: Option<f32>,
    /// Spot light outer cone angle in degrees (zero outside).
    #[arg(long, allow_negative_numbers = true)]
    pub light_outer_cone: Option<f32>,
    /// No punctual light: the scene's emissive surfaces (`--gi-param emitters`, on by default
    /// then) and an --environment light it alone.
    #[arg(long, conflicts_with_all = ["light_type", "light_pos", "light_dir", "light_color", "light_intensity", "light_inner_cone", "light_outer_cone"])]
    pub no_lights: bool,
    #[command(flatten)]
    pub environment: EnvironmentArgs,
    /// `auto` (log-average luminance to middle grey) or a linear scale applied before tone mapping.
    #[arg(long, default_value = "auto", allow_negative_numbers = true)]
    pub exposure: ExposureArg,
    /// Shadow map side in texels (per cube face for point lights).
    #[arg(long, default_value_t = 2048)]
    pub shadow_map_size: u32,
    /// Indirect light: a registered GI method (an unknown one is refused with the list; the
    /// README's GI section describes each).
    #[arg(long, default_value = "brsm", value_parser = crate::gi::parse_method)]
    pub gi: GiMethod,
    #[command(flatten)]
    pub gi_args: GiArgs,
    /// Which image to write: `final` or a debug view the GI method draws (an unknown one is
    /// refused with the list; `/v1/server` describes each method's).
    #[arg(long, default_value = "final", value_parser = crate::gi::views::parse)]
    pub view: View,
    /// wgpu backend.
    #[arg(long, value_enum, env = "LIGHTCAST_BACKEND", default_value = "auto")]
    pub backend: BackendChoice,
    /// Print the report as JSON on stdout instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// `render.environment` on the command line (`render`, `bench`).
#[derive(clap::Args, Clone, Debug, Default)]
pub struct EnvironmentArgs {
    /// Light from every direction: `uniform` (the same radiance everywhere), `sky` (a clear
    /// daylight sky around the first directional light, its sun) or `image` (the
    /// equirectangular HDR file of --environment-image). Default: none.
    #[arg(long, value_enum)]
    pub environment: Option<lightcast_protocol::EnvironmentKind>,
    /// A Radiance `.hdr` or OpenEXR equirectangular image for `--environment image` (rows
    /// from the zenith down; the left edge faces −Z, the centre +Z, as in Mitsuba and PBRT).
    #[arg(long, requires = "environment")]
    pub environment_image: Option<PathBuf>,
    /// `uniform`: radiance scale; `sky`: its horizontal illuminance over the sun's
    /// intensity; `image`: a scale on its texels. Default 1 (`uniform`, `image`), 0.2 (`sky`).
    #[arg(long, requires = "environment", allow_negative_numbers = true)]
    pub environment_intensity: Option<f32>,
    /// Linear colour R,G,B of a uniform environment, tint of a sky.
    #[arg(long, requires = "environment")]
    pub environment_color: Option<Vec3Arg>,
    /// Sky turbidity, 2 (very clear) to 10 (hazy).
    #[arg(long, requires = "environment", default_value_t = lightcast_protocol::DEFAULT_TURBIDITY)]
    pub turbidity: f32,
    /// Directional lights the real-time methods split the environment into (median cut).
    #[arg(long, requires = "environment", default_value_t = lightcast_protocol::DEFAULT_ENVIRONMENT_DIRECTIONS)]
    pub environment_directions: u32,
}

impl EnvironmentArgs {
    /// The environment the flags describe, if any.
    pub fn environment(&self) -> Option<lightcast_protocol::Environment> {
        self.environment
            .map(|kind| lightcast_protocol::Environment {
                kind,
                color: self.environment_color.map_or([1.0; 3], |Vec3Arg(c)| c),
                intensity: self.environment_intensity,
                turbidity: self.turbidity,
                directions: self.environment_directions,
            })
    }

    /// Reads --environment-image into `scene` (at most [`MAX_ENVIRONMENT_IMAGE_BYTES`]
    /// decoded).
    pub fn attach_image(&self, scene: &mut Scene) -> Result<(), OfflineError> {
        let Some(path) = &self.environment_image else {
            return Ok(());
        };
        let failed = |error: String| OfflineError::EnvironmentImage {
            path: path.clone(),
            error,
        };
        let bytes = std::fs::read(path).map_err(|e| failed(e.to_string()))?;
        let name = path
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into());
        let image = EnvironmentImage::decode(&name, &bytes, MAX_ENVIRONMENT_IMAGE_BYTES)
            .map_err(|e| failed(e.to_string()))?;
        scene.environment_image = Some(std::sync::Arc::new(image));
        Ok(())
    }
}

/// Most bytes an --environment-image may take decoded: a 16k × 8k image, far above what the
/// kept map (1024×512) resolves.
pub const MAX_ENVIRONMENT_IMAGE_BYTES: u64 =
    16384 * 8192 * crate::scene::environment_image::DECODED_BYTES_PER_TEXEL;

/// What `render` reports after writing the image.
#[derive(Debug, serde::Serialize)]
pub struct RenderReport {
    pub out: PathBuf,
    pub view: View,
    /// The method and every parameter it read.
    pub gi: GiParams,
    pub adapter: String,
    pub scene: String,
    pub triangles: usize,
    pub width: u32,
    pub height: u32,
    pub camera: Camera,
    /// The first light (the one the `--light-*` flags change); none with --no-lights.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub light: Option<lightcast_protocol::Light>,
    /// Every light rendered.
    pub lights: Vec<lightcast_protocol::Light>,
    /// The environment, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub environment: Option<lightcast_protocol::Environment>,
    pub exposure_scale: f32,
    pub timing_source: crate::gpu::timing::TimingSource,
    /// See [`lightcast_protocol::RenderReport::timing_note`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub timing_note: Option<String>,
    pub stages: Vec<crate::gpu::timing::StageTiming>,
    pub gpu_total_ms: f64,
    pub load_ms: f64,
    pub setup_ms: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum OfflineError {
    // Messages are complete on their own (the inner error is not a `source`, so a printed
    // chain does not repeat it).
    #[error("scene '{scene}': {error}")]
    Scene {
        scene: String,
        error: crate::scene::OpenError,
    },
    #[error("--environment-image {}: {error}", path.display())]
    EnvironmentImage { path: PathBuf, error: String },
    #[error(transparent)]
    Precompute(#[from] PrecomputeError),
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
    #[error(transparent)]
    Render(#[from] crate::renderer::RenderError),
    #[error(
        "--view {view} is drawn by --gi {}, not by --gi {method}",
        or_gi(drawn_by)
    )]
    ViewNotDrawn {
        view: View,
        method: GiMethod,
        drawn_by: Vec<GiMethod>,
    },
    #[error("--view: {0}")]
    View(debug_views::ViewError),
    #[error("writing {path}: {error}")]
    Write {
        path: PathBuf,
        error: image::ImageError,
    },
}

fn or_gi(methods: &[GiMethod]) -> String {
    let names: Vec<&str> = methods.iter().map(GiMethod::name).collect();
    names.join(" or --gi ")
}

impl From<debug_views::ViewError> for OfflineError {
    /// The same refusals as the service's, in terms of the command-line flags.
    fn from(e: debug_views::ViewError) -> Self {
        match e {
            debug_views::ViewError::NotDrawn {
                view,
                method,
                drawn_by,
            } => Self::ViewNotDrawn {
                view,
                method,
                drawn_by,
            },
            e => Self::View(e),
        }
    }
}

/// Applies the command-line camera and light options on top of the scene's defaults.
pub fn settings_from_args(args: &RenderArgs, scene: &Scene) -> RenderSettings {
    let mut camera = default_camera(scene);
    if let Some(Vec3Arg(p)) = args.camera_pos {
        camera.position = p;
        if args.camera_target.is_none() {
            camera.target = scene.bounds.center().into();
        }
    }
    if let Some(Vec3Arg(t)) = args.camera_target {
        camera.target = t;
    }
    if let Some(fov) = args.fov {
        camera.fov_y_degrees = fov;
    }

    // Every light of the scene (none with --no-lights); the `--light-*` flags change the first.
    let mut lights = if args.no_lights {
        Vec::new()
    } else {
        default_lights(scene, crate::passes::frame_uniforms::MAX_LIGHTS)
    };
    if let Some(light) = lights.first_mut() {
        apply_light_flags(args, scene, light);
    }
    let mut gi = args.gi_args.gi(args.gi);
    if gi.get(SPP.name).is_none() {
        gi.set(SPP.name, OFFLINE_SPP);
    }
    let asked = gi.get(EMITTERS.name).and_then(serde_json::Value::as_bool);
    gi.set(
        EMITTERS.name,
        emitters_for(asked, emitter_stand_in(scene).as_ref(), &lights),
    );
    RenderSettings {
        width: args.width,
        height: args.height,
        camera,
        lights,
        environment: args.environment.environment(),
        exposure: args.exposure.0,
        shadow_map_size: args.shadow_map_size,
        capture_hdr: false,
        debug_view: View::FINAL,
        gi,
        history: None,
        still: false,
        yuv420: false,
        poses: Vec::new(),
        pick: None,
    }
}

/// The `--light-*` flags on `light`, the first of the frame's.
fn apply_light_flags(args: &RenderArgs, scene: &Scene, light: &mut lightcast_protocol::Light) {
    if let Some(kind) = args.light_type {
        let kind = LightKind::from(kind);
        if kind != light.kind && kind != LightKind::Directional && args.light_pos.is_none() {
            // A positional light switched on from the command line without a position: hang
            // it above the scene centre, aimed down, so the result is lit.
            let center = scene.bounds.center();
            light.position = (center + Vec3::Y * scene.bounds.radius() * 0.9).into();
            light.direction = [0.0, -1.0, 0.0];
        }
        if kind == LightKind::Spot && light.outer_cone <= 0.0 {
            light.inner_cone = 30f32.to_radians();
            light.outer_cone = 45f32.to_radians();
        }
        light.kind = kind;
    }
    if let Some(Vec3Arg(p)) = args.light_pos {
        light.position = p;
    }
    if let Some(Vec3Arg(d)) = args.light_dir {
        light.direction = d;
    }
    if let Some(Vec3Arg(c)) = args.light_color {
        light.color = c;
    }
    if let Some(i) = args.light_intensity {
        light.intensity = i;
    }
    if let Some(a) = args.light_inner_cone {
        light.inner_cone = a.to_radians();
    }
    if let Some(a) = args.light_outer_cone {
        light.outer_cone = a.to_radians();
    }
}

/// Loads the scene, renders one frame, writes the PNG and returns the report.
pub fn render(args: &RenderArgs, log: &mut dyn FnMut(&str)) -> Result<RenderReport, OfflineError> {
    let spec = args.scene.as_deref().unwrap_or(DEFAULT_SCENE);
    let started = Instant::now();
    let mut scene = Scene::open(spec).map_err(|error| OfflineError::Scene {
        scene: spec.to_string(),
        error,
    })?;
    args.environment.attach_image(&mut scene)?;
    let load_ms = started.elapsed().as_secs_f64() * 1e3;
    log(&format!(
        "scene {}: {} triangles, {} materials, {} textures ({load_ms:.1} ms)",
        scene.name,
        scene.triangle_count(),
        scene.materials.len(),
        scene.textures.len()
    ));

    // A view the method cannot show is refused before the adapter and the precomputation.
    debug_views::check(args.view, args.gi)?;
    let ctx = GpuContext::new(args.backend)?;
    let adapter = AdapterSummary(&ctx.info).to_string();
    let adapter_is_cpu = ctx.info.device_type == wgpu::DeviceType::Cpu;
    log(&format!("adapter: {adapter}"));
    let settings = settings_from_args(args, &scene);
    // The flags describe the first light.
    settings
        .validate(&ctx)
        .map_err(RenderError::for_one_light)?;
    let setup_start = Instant::now();
    let data = args
        .gi_args
        .precompute(&settings.gi, &scene, Some(&ctx), log)?
        .map(|b| b.data);
    let mut renderer = Renderer::new(ctx, scene);
    if let Some(data) = &data {
        renderer.set_scene_data(args.gi, data)?;
    }
    let setup_ms = setup_start.elapsed().as_secs_f64() * 1e3;
    let mut settings = settings;
    settings.capture_hdr = debug_views::reads_indirect(args.view);
    settings.debug_view = args.view;
    let frame = renderer.render(&settings)?;
    let exposure_scale = frame.exposure_scale;
    let timing_source = frame.timing_source;
    let stages = frame.timings.clone();
    let image = debug_views::compose(
        args.view,
        frame,
        &settings.camera,
        &renderer.scene().bounds,
        data.as_ref(),
    )?;
    write_png(&image, &args.out)?;
    let scene = renderer.scene();
    Ok(RenderReport {
        out: args.out.clone(),
        view: args.view,
        gi: crate::gi::params::resolved(&settings.gi),
        adapter,
        scene: scene.name.clone(),
        triangles: scene.triangle_count(),
        width: image.width,
        height: image.height,
        camera: settings.camera,
        light: settings.lights.first().cloned(),
        lights: settings.lights.clone(),
        environment: settings.environment.clone(),
        exposure_scale,
        timing_source,
        timing_note: timing_source.note(adapter_is_cpu),
        gpu_total_ms: stages.iter().map(|t| t.ms).sum(),
        stages,
        load_ms,
        setup_ms,
    })
}

pub fn write_png(image: &debug_views::Image, path: &std::path::Path) -> Result<(), OfflineError> {
    image::save_buffer(
        path,
        &image.rgba8,
        image.width,
        image.height,
        image::ExtendedColorType::Rgba8,
    )
    .map_err(|error| OfflineError::Write {
        path: path.to_path_buf(),
        error,
    })
}

impl RenderReport {
    /// The per-stage table printed after a render.
    pub fn table(&self) -> String {
        let source = match self.timing_source {
            crate::gpu::timing::TimingSource::GpuTimestamps => "GPU timestamps",
            crate::gpu::timing::TimingSource::CpuWallClock => {
                "CPU wall clock (adapter has no timestamp queries)"
            }
        };
        let mut s = format!("stage            ms   ({source})\n");
        for t in &self.stages {
            s += &format!("{:<14} {:>8.3}\n", t.stage, t.ms);
        }
        s += &format!("{:<14} {:>8.3}\n", "total", self.gpu_total_ms);
        if let Some(note) = &self.timing_note {
            s += &format!("note: {note}\n");
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vec3_arg_parses_and_rejects_precisely() {
        assert_eq!(
            "1, -2.5,3".parse::<Vec3Arg>(),
            Ok(Vec3Arg([1.0, -2.5, 3.0]))
        );
        assert!("1,2".parse::<Vec3Arg>().unwrap_err().contains("three"));
        assert!("1,x,3".parse::<Vec3Arg>().unwrap_err().contains("'x'"));
        assert!("1,inf,3".parse::<Vec3Arg>().is_err());
    }

    #[test]
    fn exposure_arg_accepts_auto_or_positive_scale() {
        assert_eq!(
            "auto".parse::<ExposureArg>(),
            Ok(ExposureArg(Exposure::Auto))
        );
        assert_eq!(
            "2.5".parse::<ExposureArg>(),
            Ok(ExposureArg(Exposure::Manual(2.5)))
        );
        assert!("0".parse::<ExposureArg>().is_err());
        assert!("-1".parse::<ExposureArg>().is_err());
    }
}
