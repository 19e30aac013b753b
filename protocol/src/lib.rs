//! Types that cross the wire between lightcast clients and the server.
//!
//! Everything here is plain data (serde), versioned with the crate, and free of GPU or async
//! dependencies so that thin clients can depend on it cheaply. Vectors are `[f32; 3]` in the
//! scene's world space (glTF convention: right-handed, +Y up, metres).

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

pub mod api;
pub mod frame;
mod names;
pub mod stream;

pub use api::*;
pub use frame::{FrameHeader, FrameHeaderError};
pub use names::{GiMethod, View};
pub use stream::{ClientMessage, ServerEvent};

/// Parses three comma-separated finite numbers, e.g. `1.5,2,-3` (command-line vectors of the
/// server and the client).
pub fn parse_vec3(s: &str) -> Result<[f32; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [x, y, z] = parts.as_slice() else {
        return Err(format!(
            "expected three comma-separated numbers X,Y,Z, got '{s}'"
        ));
    };
    let parse = |p: &str| {
        p.parse::<f32>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("'{p}' is not a finite number"))
    };
    Ok([parse(x)?, parse(y)?, parse(z)?])
}

/// Version of the HTTP/WebSocket API; the paths carry it as `/v{API_VERSION}/…`.
pub const API_VERSION: u32 = 1;

/// Which kind of punctual light (the three kinds of glTF's `KHR_lights_punctual`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum LightKind {
    /// Parallel rays along `direction` (a sun). `intensity` is illuminance in lux.
    Directional,
    /// A cone from `position` along `direction`. `intensity` is luminous intensity in candela.
    Spot,
    /// Emits from `position` in all directions. `intensity` is luminous intensity in candela.
    Point,
}

/// One punctual light.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Light {
    pub kind: LightKind,
    /// Position (spot and point lights; ignored for directional).
    pub position: [f32; 3],
    /// Direction the light travels (directional and spot; ignored for point). Need not be unit.
    pub direction: [f32; 3],
    /// Linear RGB colour.
    pub color: [f32; 3],
    /// Lux for directional lights, candela for spot and point lights.
    pub intensity: f32,
    /// Spot light: angle in radians from the axis where the falloff starts.
    pub inner_cone: f32,
    /// Spot light: angle in radians from the axis where the light reaches zero.
    pub outer_cone: f32,
}

/// What an [`Environment`] is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum EnvironmentKind {
    /// The same radiance from every direction of the sphere: `color` × `intensity`.
    #[default]
    Uniform,
    /// A clear daylight sky (Preetham, Shirley & Smits 1999) around the frame's first
    /// directional light, its sun, with `turbidity`; black below the horizon. `intensity` is
    /// the illuminance the sky alone gives an open horizontal surface, as a multiple of the
    /// sun's `intensity`.
    Sky,
    /// The equirectangular HDR image (Radiance `.hdr` or OpenEXR) uploaded with the scene,
    /// times `color` × `intensity` (default 1): rows from the zenith (+Y) down; the image's
    /// left edge faces −Z, a quarter across +X, its centre +Z (Mitsuba's and PBRT's
    /// convention).
    Image,
}

/// Light from infinitely far away in every direction: a sky around the scene. It lights
/// surfaces, shows where no geometry covers a pixel, and bounces like any other light.
/// The path-traced `reference` samples it exactly (importance sampling with multiple
/// importance sampling); the real-time methods split it into `directions` directional lights
/// of equal power (median cut), each lighting with its own shadow map (and RSM), so their
/// sky light is shadowed from that many directions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(default)]
pub struct Environment {
    pub kind: EnvironmentKind,
    /// Linear RGB colour (`uniform`: the radiance's colour; `sky`, `image`: a tint).
    pub color: [f32; 3],
    /// `uniform`: radiance scale, in the lights' units per steradian. `sky`: the sky's
    /// horizontal illuminance over the sun's `intensity`. `image`: a scale on the image's
    /// texels. `null`: 1 for `uniform` and `image`, 0.2 for `sky` (a clear day's sky gives a
    /// horizontal surface about a fifth of the sun's illuminance).
    pub intensity: Option<f32>,
    /// `sky`: atmospheric turbidity, 2 (very clear) to 10 (hazy).
    pub turbidity: f32,
    /// Directional lights the real-time methods approximate the environment with, 1 to 15
    /// (with the punctual lights at most the server's light limit, 16).
    pub directions: u32,
}

/// The default sky turbidity: a clear day.
pub const DEFAULT_TURBIDITY: f32 = 3.0;
/// The default number of directions a real-time method splits an environment into.
pub const DEFAULT_ENVIRONMENT_DIRECTIONS: u32 = 8;

impl Default for Environment {
    fn default() -> Self {
        Self {
            kind: EnvironmentKind::Uniform,
            color: [1.0, 1.0, 1.0],
            intensity: None,
            turbidity: DEFAULT_TURBIDITY,
            directions: DEFAULT_ENVIRONMENT_DIRECTIONS,
        }
    }
}

impl Environment {
    /// `intensity`, or its default for the kind.
    pub fn intensity(&self) -> f32 {
        self.intensity.unwrap_or(match self.kind {
            EnvironmentKind::Uniform | EnvironmentKind::Image => 1.0,
            EnvironmentKind::Sky => 0.2,
        })
    }
}

/// A pinhole camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Camera {
    pub position: [f32; 3],
    pub target: [f32; 3],
    /// Vertical field of view in degrees.
    pub fov_y_degrees: f32,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_round_trips_through_json_with_lowercase_kind() {
        let light = Light {
            kind: LightKind::Spot,
            position: [0.0, 2.0, 0.0],
            direction: [0.0, -1.0, 0.0],
            color: [1.0, 0.9, 0.8],
            intensity: 40.0,
            inner_cone: 0.5,
            outer_cone: 0.8,
        };
        let json = serde_json::to_string(&light).expect("serialise");
        assert!(json.contains("\"kind\":\"spot\""), "{json}");
        let back: Light = serde_json::from_str(&json).expect("parse");
        assert_eq!(back, light);
    }

    #[test]
    fn parses_vectors_and_refuses_garbage() {
        assert_eq!(parse_vec3("1, -2.5,3"), Ok([1.0, -2.5, 3.0]));
        assert!(parse_vec3("1,2").is_err());
        assert!(parse_vec3("1,2,inf").is_err());
    }

    /// Answers of a newer server with fields this build does not know still parse (the server
    /// is the one that refuses unknown fields in requests).
    #[test]
    fn answers_with_newer_fields_still_parse() {
        let camera: Camera = serde_json::from_str(
            r#"{"position":[0,0,1],"target":[0,0,0],"fov_y_degrees":45,"zoom":2}"#,
        )
        .expect("unknown fields are tolerated");
        assert_eq!(camera.fov_y_degrees, 45.0);
        let params: SessionParams =
            serde_json::from_str(r#"{"render":{"gi":{"method":"none","future_knob":1}}}"#)
                .expect("nested unknown fields are tolerated");
        assert_eq!(params.render.gi.method, GiMethod::new("none"));
    }

    /// A method is any well-formed name on the wire (the server knows which it has); names
    /// that could not be one are refused as they are read.
    #[test]
    fn gi_methods_are_names_read_and_written_as_strings() {
        let m: GiMethod = serde_json::from_str(r#""rsm_gather""#).expect("a name");
        assert_eq!(
            (m.name(), m.to_string()),
            ("rsm_gather", "rsm_gather".into())
        );
        assert_eq!(serde_json::to_string(&m).expect("json"), r#""rsm_gather""#);
        assert_eq!(m, GiMethod::new("rsm_gather"));
        for bad in [
            r#""""#,
            r#""BRSM""#,
            r#""a-b""#,
            r#""0123456789012345678901234567890123""#,
            "3",
        ] {
            assert!(serde_json::from_str::<GiMethod>(bad).is_err(), "{bad}");
        }
        assert_eq!(GiMethod::default().name(), "brsm");
    }

    #[test]
    fn interactive_size_scales_to_even_sides_within_bounds() {
        let scaled = |scale: f32, w: u32, h: u32| {
            Encoding {
                interactive_scale: scale,
                ..Encoding::default()
            }
            .interactive_size(w, h)
        };
        // Off by default: the full size.
        assert_eq!(
            Encoding::default().interactive_size(1920, 1080),
            (1920, 1080)
        );
        assert_eq!(scaled(0.5, 1920, 1080), (960, 540));
        // 1280 × 0.75 = 960, 718 × 0.75 = 538.5: rounded down to even.
        assert_eq!(scaled(0.75, 1280, 718), (960, 538));
        assert_eq!(scaled(0.25, 998, 566), (248, 140));
        // Never below 16 pixels, never above the full side (a 10-pixel side stays 10).
        assert_eq!(scaled(0.25, 40, 10), (16, 10));
        // Odd full sides (JPEG allows them) come out even when scaled.
        let (w, h) = scaled(0.5, 1001, 333);
        assert_eq!((w % 2, h % 2), (0, 0));
    }

    #[test]
    fn an_automatic_bitrate_follows_the_pixel_rate_within_the_range() {
        let auto = Encoding::default();
        assert_eq!(auto.bitrate_kbps, None, "automatic by default");
        // 0.05 bit × 1920 × 1080 × 30 / 1000 = 3110.4.
        assert_eq!(auto.bitrate_kbps_for(1920, 1080, 30.0), 3110);
        assert_eq!(auto.bitrate_kbps_for(1280, 720, 30.0), 1382);
        // Twice the frames, twice the bits; a quarter of the pixels, a quarter.
        assert_eq!(auto.bitrate_kbps_for(1920, 1080, 60.0), 6221);
        assert_eq!(auto.bitrate_kbps_for(960, 540, 30.0), 778);
        // Held to the range a client may set.
        assert_eq!(auto.bitrate_kbps_for(64, 48, 1.0), MIN_BITRATE_KBPS);
        assert_eq!(auto.bitrate_kbps_for(3840, 2160, 1000.0), MAX_BITRATE_KBPS);
        let fixed = Encoding {
            bitrate_kbps: Some(8000),
            ..Encoding::default()
        };
        assert_eq!(
            fixed.bitrate_kbps_for(64, 48, 1.0),
            8000,
            "a set bitrate is kept"
        );
    }
}
