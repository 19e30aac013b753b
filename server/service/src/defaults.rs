//! What a request gets for the render fields it leaves out. On a GPU these are the protocol's
//! defaults (the paper's evaluation settings); on a CPU (software) adapter such as lavapipe
//! they would take seconds to tens of seconds a frame, so the server picks a smaller profile
//! there. Fields a request sets are always used: the defaults fill only what is missing, and a
//! merge patch's `null` restores them.

use super::error::{from_value, parse_json, ApiError};
use crate::gi::common::params::{INDIRECT_DOWNSCALE, RSM_SIZE};
use crate::gi::lightskin::params::{VAL_COUNT, VIEW_SAMPLES};
use lightcast_protocol::{DefaultsProfile, RenderDefaults, RenderParams};
use serde_json::Value;

/// `--defaults`: which profile, or `auto` to choose by the adapter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DefaultsChoice {
    /// `software` on a CPU adapter, `gpu` otherwise.
    Auto,
    Gpu,
    Software,
}

/// The render defaults of a profile: every GI parameter at its table's default, in the
/// software profile at its software default where the table gives one (measured on lavapipe
/// with 2 cores, `bench/first-minute.sh`, `bench/results/first-minute-lavapipe-*.md`: the
/// README's `POST /v1/render -d '{}'` in about 0.5 s instead of 3.2 s with the GPU's, and
/// about 2 GI frames a second in a viewer-sized stream instead of 0.25; each row says why its
/// value), and a 1024² shadow map.
fn render_defaults(software: bool) -> RenderParams {
    let mut render = RenderParams::default();
    render.gi.values = crate::gi::params::defaults(software);
    if software {
        render.shadow_map_size = 1024;
    }
    render
}

/// The share of the canvas a viewer streams at on a software adapter (a quarter of the
/// pixels); GPUs stream at full resolution.
const SOFTWARE_VIEWER_SCALE: f32 = 0.5;

/// The server's defaults and their JSON form, which requests are filled from.
#[derive(Clone, Debug)]
pub struct Defaults {
    pub info: RenderDefaults,
    render: Value,
}

impl Defaults {
    /// The defaults `choice` gives on an adapter named `adapter` (`is_cpu`: a software one).
    pub fn choose(choice: DefaultsChoice, adapter: &str, is_cpu: bool) -> Self {
        let (profile, reason) = match choice {
            DefaultsChoice::Auto if is_cpu => (
                DefaultsProfile::Software,
                format!("auto: the adapter is a CPU (software) one, {adapter}"),
            ),
            DefaultsChoice::Auto => (
                DefaultsProfile::Gpu,
                format!("auto: the adapter is a GPU, {adapter}"),
            ),
            DefaultsChoice::Gpu => (DefaultsProfile::Gpu, "--defaults gpu".into()),
            DefaultsChoice::Software => (DefaultsProfile::Software, "--defaults software".into()),
        };
        let (render, viewer_scale) = match profile {
            DefaultsProfile::Gpu => (render_defaults(false), 1.0),
            DefaultsProfile::Software => (render_defaults(true), SOFTWARE_VIEWER_SCALE),
        };
        Self {
            render: serde_json::to_value(&render).unwrap_or(Value::Null),
            info: RenderDefaults {
                profile,
                reason,
                render,
                viewer_scale,
            },
        }
    }

    /// One line for the start-up log.
    pub fn summary(&self) -> String {
        let r = &self.info.render;
        let g = &r.gi;
        let profile = match self.info.profile {
            DefaultsProfile::Gpu => "gpu",
            DefaultsProfile::Software => "software",
        };
        format!(
            "defaults: {profile} profile ({}): {}×{}, shadow map {}², {} with RSM {}², {} \
             view samples, {} VALs, indirect light at 1/{} resolution; requests that set a \
             field get what they set (--defaults gpu|software to choose)",
            self.info.reason,
            r.width,
            r.height,
            r.shadow_map_size,
            g.method,
            RSM_SIZE.u32(g),
            VIEW_SAMPLES.u32(g),
            VAL_COUNT.u32(g),
            INDIRECT_DOWNSCALE.u32(g),
        )
    }

    /// Fills the fields of `render` (a request's `render` object) that it leaves out; objects
    /// are filled field by field, so `{"gi": {"method": "lightskin"}}` keeps the other GI
    /// defaults. Anything but an object is refused: serde would fill the struct from an
    /// array by position.
    pub fn fill_render(&self, render: &mut Value) -> Result<(), ApiError> {
        if !render.is_object() {
            return Err(ApiError::field("render", "must be a JSON object"));
        }
        fill(render, &self.render);
        Ok(())
    }

    /// Parses a request body (a JSON object, or empty for `{}`) into `T`, whose `render`
    /// field is filled from the defaults first. Errors name the field as [`parse_json`]'s do.
    pub fn parse<T: serde::de::DeserializeOwned>(&self, bytes: &[u8]) -> Result<T, ApiError> {
        let bytes: &[u8] = if bytes.iter().all(u8::is_ascii_whitespace) {
            b"{}"
        } else {
            bytes
        };
        // Strict parsing of the body as sent names a bad field before any default is added.
        parse_json::<T>(bytes)?;
        let mut value: Value =
            serde_json::from_slice(bytes).map_err(|e| ApiError::internal(e.to_string()))?;
        if let Value::Object(map) = &mut value {
            self.fill_render(
                map.entry("render")
                    .or_insert(Value::Object(Default::default())),
            )?;
        }
        from_value(value)
    }
}

/// Inserts into `target` every field of `defaults` it lacks, recursing into objects both have.
fn fill(target: &mut Value, defaults: &Value) {
    let (Value::Object(target), Value::Object(defaults)) = (target, defaults) else {
        return;
    };
    for (key, default) in defaults {
        match target.get_mut(key) {
            Some(value) => fill(value, default),
            None => {
                target.insert(key.clone(), default.clone());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightcast_protocol::{RenderRequest, SessionParams};

    fn software() -> Defaults {
        Defaults::choose(DefaultsChoice::Auto, "llvmpipe", true)
    }

    #[test]
    fn auto_picks_the_software_profile_only_on_a_cpu_adapter() {
        let cpu = software();
        assert_eq!(cpu.info.profile, DefaultsProfile::Software);
        assert!(cpu.info.reason.contains("llvmpipe"), "{}", cpu.info.reason);
        let gpu = Defaults::choose(DefaultsChoice::Auto, "H100", false);
        assert_eq!(gpu.info.profile, DefaultsProfile::Gpu);
        assert_eq!(gpu.info.render, render_defaults(false));
        assert_eq!(gpu.info.viewer_scale, 1.0);
        let forced = Defaults::choose(DefaultsChoice::Gpu, "llvmpipe", true);
        assert_eq!(forced.info.render, render_defaults(false));
        let forced = Defaults::choose(DefaultsChoice::Software, "H100", false);
        assert_eq!(forced.info.profile, DefaultsProfile::Software);
        assert!(
            cpu.summary().contains("1/2 resolution"),
            "{}",
            cpu.summary()
        );
    }

    #[test]
    fn an_empty_request_gets_every_default_and_a_set_field_is_kept() {
        let d = software();
        let empty: RenderRequest = d.parse(b"").expect("valid");
        assert_eq!(empty.render, d.info.render);
        let set: RenderRequest = d
            .parse(
                br#"{"render": {"width": 320, "gi": {"method": "lightskin", "rsm_size": 1024}}}"#,
            )
            .expect("valid");
        assert_eq!(set.render.width, 320);
        assert_eq!(set.render.height, d.info.render.height);
        assert_eq!(set.render.gi.method, crate::gi::lightskin::LIGHTSKIN);
        let gi = &set.render.gi;
        assert_eq!(RSM_SIZE.u32(gi), 1024, "an explicit value wins");
        assert_eq!(VAL_COUNT.u32(gi), VAL_COUNT.u32(&d.info.render.gi));
        assert_eq!(INDIRECT_DOWNSCALE.u32(gi), 2);
        let session: SessionParams = d
            .parse(br#"{"fps_cap": 5, "render": {"gi": {"indirect_downscale": 1}}}"#)
            .expect("valid");
        assert_eq!(session.fps_cap, 5.0);
        assert_eq!(INDIRECT_DOWNSCALE.u32(&session.render.gi), 1);
        assert_eq!(RSM_SIZE.u32(&session.render.gi), 112);
    }

    /// Every method's frame at the software defaults fits a CPU adapter's frame limit on the
    /// default scene, at the viewer's size and at a newcomer's 320×240: none is refused
    /// before the user changes anything (issue 31: `lightskin` was, at 2.08 s).
    #[test]
    fn every_method_fits_a_cpu_adapters_frame_at_the_software_defaults() {
        use crate::service::cost::{AdapterSpeed, FrameCost};
        let mut limits = crate::service::config::tests::default_limits();
        limits.adapter_speed = AdapterSpeed::Auto.resolve(true);
        limits.max_frame_seconds = FrameCost::Auto.resolve(true);
        let store = tempfile::tempdir().expect("tempdir");
        let scenes = crate::service::scenes::SceneRegistry::new(
            crate::gi::precompute::Store::new(store.path()),
            &limits,
            None,
        );
        let entry = scenes
            .detached(crate::scene::procedural::cornell_box(), 0.0)
            .expect("the Cornell box");
        for method in crate::gi::methods() {
            for (width, height) in [(800, 450), (320, 240)] {
                let mut params = SessionParams {
                    render: render_defaults(true),
                    ..SessionParams::default()
                };
                params.render.width = width;
                params.render.height = height;
                params.render.gi.method = method;
                if let Err(e) =
                    crate::service::params::resolve_session(&params, &entry, &limits, 16_384)
                {
                    panic!("{method} at {width}×{height}: {}", e.body.message);
                }
            }
        }
    }

    #[test]
    fn bad_fields_are_named_as_sent() {
        let d = software();
        let e = d
            .parse::<RenderRequest>(br#"{"render": {"widht": 1}}"#)
            .expect_err("unknown field");
        assert_eq!(e.body.field.as_deref(), Some("render.widht"));
        // `render.gi`'s fields are the methods' tables' business: `params::resolve` refuses
        // a misspelt one (`render.gi.rsm_sise`, see `gi::params::check_request`).
        let e = d
            .parse::<RenderRequest>(br#"{"render": []}"#)
            .expect_err("not an object");
        assert_eq!(e.body.field.as_deref(), Some("render"));
        let e = d.parse::<RenderRequest>(b"[]").expect_err("not an object");
        assert_eq!(e.status, axum::http::StatusCode::BAD_REQUEST);
    }
}
