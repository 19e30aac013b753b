//! Camera, light and GI flags shared by `render`, `stream` and `loadtest`; the same names as the
//! offline `lightcast-server render`.

use lightcast_protocol::{
    parse_vec3, Camera, ClusteredFlags, GiMethod, GiParams, Light, LightKind, RenderParams, View,
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
    /// Any GI parameter by its name in `/v1/server`'s `gi_methods`, as NAME=VALUE (a JSON
    /// value: `surfel_count=65536`, `visibility=off`); repeatable, applied after the flags
    /// above. Every method's parameters are reachable this way, including methods added
    /// after this client.
    #[arg(long = "gi-param", value_name = "NAME=VALUE", value_parser = parse_gi_param)]
    pub gi_params: Vec<(String, serde_json::Value)>,
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
        // Each pair was checked against the GI parameters when it was parsed.
        if let Ok(set) = with_params(&gi, &self.gi_params) {
            gi = set;
        }
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

/// `gi` with the named fields replaced by the values.
fn with_params(gi: &GiParams, params: &[(String, serde_json::Value)]) -> Result<GiParams, String> {
    let mut value = serde_json::to_value(gi).map_err(|e| e.to_string())?;
    let known = value.as_object().map(|o| o.len()).unwrap_or(0);
    for (name, v) in params {
        value[name.as_str()] = v.clone();
    }
    if value.as_object().map_or(0, |o| o.len()) != known {
        let names: Vec<String> = serde_json::to_value(GiParams::default())
            .ok()
            .and_then(|v| v.as_object().map(|o| o.keys().cloned().collect()))
            .unwrap_or_default();
        return Err(format!("unknown GI parameter; known: {}", names.join(", ")));
    }
    serde_json::from_value(value).map_err(|e| e.to_string())
}

/// `NAME=VALUE` of `--gi-param`: VALUE is read as JSON, else taken as a string; the pair must
/// name a GI parameter and fit its type.
fn parse_gi_param(s: &str) -> Result<(String, serde_json::Value), String> {
    let (name, raw) = s
        .split_once('=')
        .ok_or_else(|| format!("'{s}' is not NAME=VALUE"))?;
    let value = serde_json::from_str(raw).unwrap_or_else(|_| serde_json::Value::String(raw.into()));
    let pair = (name.to_string(), value);
    with_params(&GiParams::default(), std::slice::from_ref(&pair))
        .map_err(|e| format!("{name}: {e}"))?;
    Ok(pair)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gi_params_by_name_are_checked_when_parsed_and_applied_over_the_flags() {
        assert_eq!(
            parse_gi_param("vpl_count=4096"),
            Ok(("vpl_count".into(), serde_json::json!(4096)))
        );
        assert_eq!(
            parse_gi_param("visibility=off"),
            Ok(("visibility".into(), serde_json::json!("off")))
        );
        assert!(parse_gi_param("cache_distance=null").is_ok());
        let unknown = parse_gi_param("vpls=4").expect_err("not a GI parameter");
        assert!(
            unknown.starts_with("vpls: unknown GI parameter; known: "),
            "{unknown}"
        );
        assert!(unknown.contains("vpl_count"), "{unknown}");
        assert!(parse_gi_param("vpl_count=many").is_err(), "wrong type");
        assert!(parse_gi_param("vpl_count").is_err(), "no value");
        let gi = with_params(
            &GiParams::default(),
            &[
                ("rsm_size".into(), serde_json::json!(64)),
                ("method".into(), serde_json::json!("clustered")),
            ],
        )
        .expect("valid");
        assert_eq!((gi.rsm_size, gi.method), (64, GiMethod::Clustered));
    }
}
