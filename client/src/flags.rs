//! Camera, light and GI flags shared by `render`, `stream` and `loadtest`; the same names as the
//! offline `lightcast-server render`.

use lightcast_protocol::{parse_vec3, Camera, EnvironmentKind, GiMethod, Light, LightKind, View};

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
    /// No punctual light (`render.lights: []`): the scene's emissive surfaces and an
    /// --environment light it alone.
    #[arg(long, conflicts_with_all = ["light_type", "light_pos", "light_dir", "light_color", "light_intensity"])]
    pub no_lights: bool,
    /// Light from every direction (`render.environment`): `uniform`, `sky` (a daylight sky
    /// around the first directional light) or `image` (the `.hdr`/`.exr` uploaded with the
    /// scene: `scenes upload --environment-image`). Default: none.
    #[arg(long, value_enum)]
    pub environment: Option<EnvironmentKind>,
    /// The environment's scale: `uniform` radiance, a sky's horizontal illuminance over the
    /// sun's intensity, or a scale on an image's texels (server defaults 1, 0.2 and 1).
    #[arg(long, requires = "environment")]
    pub environment_intensity: Option<f32>,
    /// Linear colour R,G,B of a uniform environment, tint of a sky.
    #[arg(long, requires = "environment", value_parser = parse_vec3)]
    pub environment_color: Option<[f32; 3]>,
    /// Sky turbidity, 2 (very clear) to 10 (hazy); server default 3.
    #[arg(long, requires = "environment")]
    pub turbidity: Option<f32>,
    /// Directional lights the real-time methods split the environment into; server
    /// default 8.
    #[arg(long, requires = "environment")]
    pub environment_directions: Option<u32>,
    /// Fixed linear exposure scale (default: automatic).
    #[arg(long)]
    pub exposure: Option<f32>,
    /// Shadow map side in texels (server default 2048 on a GPU).
    #[arg(long)]
    pub shadow_map_size: Option<u32>,
    /// Indirect light method, one of the server's (`/v1/server`'s `gi_methods` lists
    /// them; server default brsm).
    #[arg(long, value_parser = GiMethod::parse)]
    pub gi: Option<GiMethod>,
    /// A GI parameter by its name in `/v1/server`'s `gi_methods` (the README's table lists
    /// every method's), as NAME=VALUE: `rsm_size=256`, `surfel_count=65536`,
    /// `visibility=off`, `emitters=false`. VALUE is JSON (a number, true/false, null), else a
    /// name; repeatable. The server checks each against the method's table and names the
    /// field it refuses (`render.gi.NAME`), so methods added after this client work too.
    #[arg(long = "gi-param", value_name = "NAME=VALUE", value_parser = parse_gi_param)]
    pub gi_params: Vec<(String, serde_json::Value)>,
    /// `final` or a debug view the GI method draws (default final; `GET /v1/server` lists
    /// each method's views, and the server refuses one its method does not draw).
    #[arg(long)]
    pub view: Option<View>,
    /// Move a movable node (`render.nodes`; `lightcast scenes show` lists them) to a
    /// translation relative to its parent, as ID=X,Y,Z; repeatable.
    #[arg(long = "node", value_name = "ID=X,Y,Z", value_parser = parse_node, allow_hyphen_values = true)]
    pub nodes: Vec<(u32, [f32; 3])>,
    /// One of the scene's glTF animations (`render.animation`; `lightcast scenes show` lists
    /// them), as NAME or NAME@SECONDS (from 0 s without one): `render` poses it at that time,
    /// `stream` and `loadtest` play it in the session from there, looping. A name that holds
    /// `@` needs the @SECONDS.
    #[arg(long, value_name = "NAME[@SECONDS]", value_parser = parse_animation)]
    pub animation: Option<(String, f32)>,
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
        for (name, value) in &self.gi_params {
            gi.insert(name.clone(), value.clone());
        }
        let mut render = serde_json::Map::new();
        put(&mut render, "scene", Some(&self.scene));
        put(&mut render, "width", self.width);
        put(&mut render, "height", self.height);
        put(&mut render, "camera", camera);
        put(&mut render, "light", light);
        if self.no_lights {
            render.insert("lights".into(), serde_json::json!([]));
        }
        if let Some(kind) = self.environment {
            let mut environment = serde_json::Map::new();
            put(&mut environment, "kind", Some(kind));
            put(&mut environment, "intensity", self.environment_intensity);
            put(&mut environment, "color", self.environment_color);
            put(&mut environment, "turbidity", self.turbidity);
            put(&mut environment, "directions", self.environment_directions);
            render.insert("environment".into(), environment.into());
        }
        put(&mut render, "exposure", self.exposure);
        put(&mut render, "shadow_map_size", self.shadow_map_size);
        put(&mut render, "view", self.view);
        if !gi.is_empty() {
            render.insert("gi".into(), gi.into());
        }
        if !self.nodes.is_empty() {
            let nodes: Vec<serde_json::Value> = self
                .nodes
                .iter()
                .map(|(node, t)| serde_json::json!({"node": node, "translation": t}))
                .collect();
            render.insert("nodes".into(), nodes.into());
        }
        if let Some((name, time)) = &self.animation {
            render.insert(
                "animation".into(),
                serde_json::json!({"name": name, "time": time}),
            );
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

/// `ID=X,Y,Z` of `--node`.
fn parse_node(s: &str) -> Result<(u32, [f32; 3]), String> {
    let (id, at) = s
        .split_once('=')
        .ok_or_else(|| format!("'{s}' is not ID=X,Y,Z"))?;
    let id = id
        .trim()
        .parse()
        .map_err(|_| format!("'{id}' is not a node id (a whole number)"))?;
    Ok((id, parse_vec3(at)?))
}

/// `NAME[@SECONDS]` of `--animation`: a name alone is at 0 s; the name may hold `@` (the
/// last one splits, so such a name needs the @SECONDS).
fn parse_animation(s: &str) -> Result<(String, f32), String> {
    let (name, time) = match s.rsplit_once('@') {
        Some((name, time)) => {
            let time: f32 = time
                .trim()
                .parse()
                .ok()
                .filter(|t: &f32| t.is_finite())
                .ok_or_else(|| format!("'{time}' is not a number of seconds"))?;
            (name, time)
        }
        None => (s, 0.0),
    };
    if name.is_empty() {
        return Err(format!("'{s}': name one of the scene's animations"));
    }
    Ok((name.to_string(), time))
}

/// `NAME=VALUE` of `--gi-param`: VALUE is read as JSON, else taken as a string. The server
/// checks the name and value against the methods' tables (this client knows none of them).
fn parse_gi_param(s: &str) -> Result<(String, serde_json::Value), String> {
    let (name, raw) = s
        .split_once('=')
        .ok_or_else(|| format!("'{s}' is not NAME=VALUE"))?;
    if name.is_empty() || name == "method" {
        return Err(format!("'{s}': name a GI parameter (the method is --gi's)"));
    }
    let value = serde_json::from_str(raw).unwrap_or_else(|_| serde_json::Value::String(raw.into()));
    Ok((name.to_string(), value))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(clap::Parser)]
    struct Wrapper {
        #[command(flatten)]
        flags: RenderFlags,
    }

    #[test]
    fn environment_flags_give_only_the_fields_they_name() {
        use clap::Parser;
        let w = Wrapper::parse_from(["t", "--environment", "sky", "--turbidity", "4"]);
        assert_eq!(
            w.flags.params(None, None)["environment"],
            serde_json::json!({"kind": "sky", "turbidity": 4.0})
        );
        let w = Wrapper::parse_from(["t"]);
        assert!(w.flags.params(None, None).get("environment").is_none());
        assert!(Wrapper::try_parse_from(["t", "--turbidity", "4"]).is_err());
    }

    #[test]
    fn no_lights_asks_for_an_empty_light_list_and_excludes_light_flags() {
        use clap::Parser;
        let w = Wrapper::parse_from(["t", "--no-lights"]);
        assert_eq!(w.flags.params(None, None)["lights"], serde_json::json!([]));
        assert!(Wrapper::parse_from(["t"])
            .flags
            .params(None, None)
            .get("lights")
            .is_none());
        assert!(Wrapper::try_parse_from(["t", "--no-lights", "--light-intensity", "2"]).is_err());
    }

    #[test]
    fn nodes_and_animation_flags_pose_the_render() {
        use clap::Parser;
        let w = Wrapper::parse_from([
            "t",
            "--node",
            "1=-0.25,0,0.5",
            "--node",
            "2=0.375,0,-0.125",
            "--animation",
            "walk@cycle@1.5",
        ]);
        let render = w.flags.params(None, None);
        assert_eq!(
            render["nodes"],
            serde_json::json!([
                {"node": 1, "translation": [-0.25, 0.0, 0.5]},
                {"node": 2, "translation": [0.375, 0.0, -0.125]},
            ])
        );
        assert_eq!(
            render["animation"],
            serde_json::json!({"name": "walk@cycle", "time": 1.5})
        );
        assert!(parse_node("x=1,2,3").is_err());
        assert!(parse_node("1=1,2").is_err());
        assert_eq!(parse_animation("walk"), Ok(("walk".into(), 0.0)));
        assert_eq!(parse_animation("walk@0.25"), Ok(("walk".into(), 0.25)));
        assert!(parse_animation("walk@").is_err());
        assert!(
            parse_animation("walk@cycle").is_err(),
            "a name with @ needs @SECONDS"
        );
        assert!(parse_animation("walk@inf").is_err());
        assert!(parse_animation("@2").is_err());
        assert!(parse_animation("").is_err());
    }

    #[test]
    fn gi_params_are_name_value_pairs_with_json_values() {
        assert_eq!(
            parse_gi_param("vpl_count=4096"),
            Ok(("vpl_count".into(), serde_json::json!(4096)))
        );
        assert_eq!(
            parse_gi_param("visibility=off"),
            Ok(("visibility".into(), serde_json::json!("off")))
        );
        assert_eq!(
            parse_gi_param("cache_distance=null"),
            Ok(("cache_distance".into(), serde_json::Value::Null))
        );
        assert!(parse_gi_param("vpl_count").is_err(), "no value");
        assert!(parse_gi_param("=4").is_err(), "no name");
        assert!(parse_gi_param("method=brsm").is_err(), "--gi's");
    }
}
