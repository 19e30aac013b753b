//! Camera, light and GI flags shared by `render`, `stream` and `loadtest`; the same names as the
//! offline `lightcast-server render`.

use lightcast_protocol::{
    parse_vec3, Camera, ClusteredFlags, GiMethod, GiParams, Light, LightKind, View,
};

/// What to render. Unset options are left out of the request, so the server's defaults apply
/// (`lightcast-server` on a CPU adapter picks smaller GI settings than on a GPU; `/v1/server`
/// lists them under `defaults`), and the scene's camera and light.
#[derive(Clone, Debug, clap::Args)]
pub struct RenderFlags {
    /// Scene id on the server (see `lightcast scenes list`).
    #[arg(long, default_value = "default")]
    pub scene: String,
    /// Output width in pixels (server default 960).
    #[arg(long)]
    pub width: Option<u32>,
    /// Output height in pixels (server default 540).
    #[arg(long)]
    pub height: Option<u32>,
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
    /// Shadow map side in texels (server default 2048 on a GPU).
    #[arg(long)]
    pub shadow_map_size: Option<u32>,
    /// Indirect light method (server default brsm).
    #[arg(long, value_enum)]
    pub gi: Option<GiMethod>,
    /// RSM side per light face (server default 1024 on a GPU).
    #[arg(long)]
    pub rsm_size: Option<u32>,
    /// N_VS: view samples of the BRSM importance (server default 512 on a GPU).
    #[arg(long)]
    pub view_samples: Option<u32>,
    /// N_sVAL: VALs selected per frame (BRSM; server default 8192 on a GPU).
    #[arg(long)]
    pub vals: Option<u32>,
    /// Uniform part α of BRSM's selection pdf (server default 0.3).
    #[arg(long)]
    pub defensive: Option<f32>,
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
    /// `--gi reference`: reflections after the visible surface (1: single bounce; the default).
    #[arg(long)]
    pub bounces: Option<u32>,
    /// `--gi reference` and `surfels`: emissive surfaces do not light the scene (where the
    /// light stands in for them, as a scene's default light without lights of its own does).
    #[arg(long)]
    pub no_emitters: bool,
    /// `--gi reference`: samples per pixel per frame (a render takes exactly this many;
    /// server default 4).
    #[arg(long)]
    pub spp: Option<u32>,
    /// Indirect light at 1/N of the output's width and height (1, 2 or 4; server default 1 on
    /// a GPU, 2 on a CPU adapter).
    #[arg(long)]
    pub indirect_downscale: Option<u32>,
    #[command(flatten)]
    pub clustered: ClusteredFlags,
    /// Any GI parameter by its name in `/v1/server`'s `gi_methods`, as NAME=VALUE (a JSON
    /// value: `surfel_count=65536`, `visibility=off`); repeatable, applied after the flags
    /// above. Every method's parameters are reachable this way, including methods added
    /// after this client.
    #[arg(long = "gi-param", value_name = "NAME=VALUE", value_parser = parse_gi_param)]
    pub gi_params: Vec<(String, serde_json::Value)>,
    /// The final frame or a debug view (default final).
    #[arg(long, value_enum)]
    pub view: Option<View>,
}

/// Inserts `value` under `key` when it is given.
fn put<T: serde::Serialize>(
    map: &mut serde_json::Map<String, serde_json::Value>,
    key: &str,
    value: Option<T>,
) {
    if let Some(v) = value.and_then(|v| serde_json::to_value(v).ok()) {
        map.insert(key.to_string(), v);
    }
}

impl RenderFlags {
    /// The request's `render` object with the fields the flags give, and no others;
    /// `scene_camera`/`scene_light` are the scene's defaults, needed only when a flag changes
    /// part of them.
    pub fn params(
        &self,
        scene_camera: Option<&Camera>,
        scene_light: Option<&Light>,
    ) -> serde_json::Value {
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
        let mut gi = serde_json::Map::new();
        put(&mut gi, "method", self.gi);
        put(&mut gi, "rsm_size", self.rsm_size);
        put(&mut gi, "view_samples", self.view_samples);
        put(&mut gi, "val_count", self.vals);
        put(&mut gi, "defensive", self.defensive);
        put(&mut gi, "occlusion", self.no_occlusion.then_some(false));
        put(&mut gi, "glossy_exponent", self.glossy_exponent);
        put(&mut gi, "cache_distance", self.cache_distance);
        put(&mut gi, "cache_angle", self.cache_angle);
        put(&mut gi, "bounces", self.bounces);
        put(&mut gi, "emitters", self.no_emitters.then_some(false));
        put(&mut gi, "spp", self.spp);
        put(&mut gi, "indirect_downscale", self.indirect_downscale);
        for (name, value) in self.clustered.given() {
            gi.insert(name.to_string(), value);
        }
        for (name, value) in &self.gi_params {
            gi.insert(name.clone(), value.clone());
        }
        let mut render = serde_json::Map::new();
        put(&mut render, "scene", Some(&self.scene));
        put(&mut render, "width", self.width);
        put(&mut render, "height", self.height);
        put(&mut render, "camera", camera);
        put(&mut render, "light", light);
        put(&mut render, "exposure", self.exposure);
        put(&mut render, "shadow_map_size", self.shadow_map_size);
        put(&mut render, "view", self.view);
        if !gi.is_empty() {
            render.insert("gi".into(), gi.into());
        }
        render.into()
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
