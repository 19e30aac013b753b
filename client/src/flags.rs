//! Camera, light and GI flags shared by `render`, `stream` and `loadtest`; the same names as the
//! offline `lightcast-server render`.

use lightcast_protocol::{
    parse_vec3, Camera, ClusteredFlags, GiMethod, Light, LightKind, RenderParams, View,
};

/// What to render. Unset options keep the server's defaults (the scene's camera and light).
#[derive(Clone, Debug, clap::Args)]
pub struct RenderFlags {
    /// Scene id on the server (see `lightcast scenes list`).
    #[arg(long, default_value = "default")]
    pub scene: String,
    #[arg(long, default_value_t = 960)]
    pub width: u32,
    #[arg(long, default_value_t = 540)]
    pub height: u32,
    /// Camera position X,Y,Z (looks at --camera-target, else the scene's default target).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub camera_pos: Option<[f32; 3]>,
    /// Point the camera looks at, X,Y,Z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub camera_target: Option<[f32; 3]>,
    /// Vertical field of view in degrees.
    #[arg(long)]
    pub fov: Option<f32>,
    /// Light kind (replaces the scene's light; other light options fill in).
    #[arg(long, value_enum)]
    pub light_type: Option<LightKind>,
    /// Light position X,Y,Z (spot, point).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub light_pos: Option<[f32; 3]>,
    /// Direction the light travels X,Y,Z (directional, spot).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub light_dir: Option<[f32; 3]>,
    /// Linear light colour R,G,B.
    #[arg(long, value_parser = parse_vec3)]
    pub light_color: Option<[f32; 3]>,
    /// Lux (directional) or candela (spot, point).
    #[arg(long)]
    pub light_intensity: Option<f32>,
    /// Fixed linear exposure scale (default: automatic).
    #[arg(long)]
    pub exposure: Option<f32>,
    #[arg(long, default_value_t = 2048)]
    pub shadow_map_size: u32,
    /// Indirect light method.
    #[arg(long, value_enum, default_value = "brsm")]
    pub gi: GiMethod,
    #[arg(long, default_value_t = 1024)]
    pub rsm_size: u32,
    #[arg(long, default_value_t = 512)]
    pub view_samples: u32,
    /// N_sVAL: VALs selected per frame (BRSM).
    #[arg(long, default_value_t = 8192)]
    pub vals: u32,
    /// Uniform part α of BRSM's selection pdf.
    #[arg(long, default_value_t = 0.3)]
    pub defensive: f32,
    /// Do not dim proxy lights hidden behind other caches.
    #[arg(long)]
    pub no_occlusion: bool,
    /// Phong exponent k for every material; default: each material's own.
    #[arg(long)]
    pub glossy_exponent: Option<f32>,
    /// Light-cache distance d_eps (scene units); default: the scene's.
    #[arg(long)]
    pub cache_distance: Option<f32>,
    /// Light-cache angle theta_eps in degrees.
    #[arg(long)]
    pub cache_angle: Option<f32>,
    /// `--gi reference`: reflections after the visible surface (1: single bounce).
    #[arg(long, default_value_t = 1)]
    pub bounces: u32,
    /// `--gi reference`: samples per pixel per frame (a render takes exactly this many).
    #[arg(long, default_value_t = 4)]
    pub spp: u32,
    #[command(flatten)]
    pub clustered: ClusteredFlags,
    /// The final frame or a debug view.
    #[arg(long, value_enum, default_value = "final")]
    pub view: View,
}

impl RenderFlags {
    /// The request's `render` object; `scene_camera`/`scene_light` are the scene's defaults,
    /// needed only when a flag changes part of them.
    pub fn params(
        &self,
        scene_camera: Option<&Camera>,
        scene_light: Option<&Light>,
    ) -> RenderParams {
        let camera =
            if self.camera_pos.is_some() || self.camera_target.is_some() || self.fov.is_some() {
                scene_camera.map(|c| Camera {
                    position: self.camera_pos.unwrap_or(c.position),
                    target: self.camera_target.unwrap_or(c.target),
                    fov_y_degrees: self.fov.unwrap_or(c.fov_y_degrees),
                })
            } else {
                None
            };
        let light_changed = self.light_type.is_some()
            || self.light_pos.is_some()
            || self.light_dir.is_some()
            || self.light_color.is_some()
            || self.light_intensity.is_some();
        let light = if light_changed {
            scene_light.map(|l| Light {
                kind: self.light_type.unwrap_or(l.kind),
                position: self.light_pos.unwrap_or(l.position),
                direction: self.light_dir.unwrap_or(l.direction),
                color: self.light_color.unwrap_or(l.color),
                intensity: self.light_intensity.unwrap_or(l.intensity),
                ..l.clone()
            })
        } else {
            None
        };
        let mut gi = lightcast_protocol::GiParams {
            method: self.gi,
            rsm_size: self.rsm_size,
            view_samples: self.view_samples,
            val_count: self.vals,
            defensive: self.defensive,
            occlusion: !self.no_occlusion,
            glossy_exponent: self.glossy_exponent,
            cache_distance: self.cache_distance,
            cache_angle: self.cache_angle,
            bounces: self.bounces,
            spp: self.spp,
            ..Default::default()
        };
        self.clustered.apply(&mut gi);
        RenderParams {
            scene: self.scene.clone(),
            width: self.width,
            height: self.height,
            camera,
            light,
            exposure: self.exposure,
            shadow_map_size: self.shadow_map_size,
            gi,
            view: self.view,
        }
    }

    /// Whether the flags need the scene's default camera or light to fill in.
    pub fn needs_scene_defaults(&self) -> bool {
        self.camera_pos.is_some()
            || self.camera_target.is_some()
            || self.fov.is_some()
            || self.light_type.is_some()
            || self.light_pos.is_some()
            || self.light_dir.is_some()
            || self.light_color.is_some()
            || self.light_intensity.is_some()
    }
}
