//! What a request gets for the render fields it leaves out. On a GPU these are the protocol's
//! defaults (the paper's evaluation settings); on a CPU (software) adapter such as lavapipe
//! they would take seconds to tens of seconds a frame, so the server picks a smaller profile
//! there. Fields a request sets are always used: the defaults fill only what is missing, and a
//! merge patch's `null` restores them.

use super::error::{from_value, parse_json, ApiError};
use lightcast_protocol::{DefaultsProfile, GiParams, RenderDefaults, RenderParams};
use serde_json::Value;

/// `--defaults`: which profile, or `auto` to choose by the adapter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DefaultsChoice {
    /// `software` on a CPU adapter, `gpu` otherwise.
    Auto,
    Gpu,
    Software,
}

/// The software profile's render defaults, measured on lavapipe with 2 cores
/// (`bench/first-minute.sh`, `bench/results/first-minute-lavapipe-*.md`): the README's
/// `POST /v1/render -d '{}'` in 0.54 s instead of 3.2 s with the protocol's defaults, and
/// about 2 GI frames a second in a viewer-sized stream instead of 0.25. `surfels` gets a
/// quarter of the surfels and half the links: its precomputation on the Cornell box takes
/// 34 s instead of about 2 minutes on 2 cores (once per parameter set: it is stored).
fn software_render() -> RenderParams {
    let gpu = RenderParams::default();
    RenderParams {
        shadow_map_size: 1024,
        gi: GiParams {
            rsm_size: SOFTWARE_RSM_SIZE,
            view_samples: 32,
            val_count: 512,
            indirect_downscale: 2,
            surfel_count: 8192,
            surfel_links: 64,
            // A session's `reference` frame at the viewer's software size (800×450) is ~1.3 s
            // per sample here: one sample per frame keeps it within the 2 s frame limit
            // (4 were refused, and switching the viewer to `reference` failed). One-shots
            // that name no `spp` take what their budget buys (`cost::one_shot_spp`).
            spp: 1,
            interleave: SOFTWARE_INTERLEAVE,
            // `clustered`'s 30 paraboloid maps at 256² take ~0.7 s a frame on lavapipe; at
            // 64² the GI stages of a 128×96 frame take ~90 ms (`bench --gi clustered`).
            paraboloid_size: 64,
            ..gpu.gi
        },
        ..gpu
    }
}

/// The software profile's RSM side. 128² put `lightskin`'s frame on the Cornell box (every
/// texel a VAL lighting every cache) at 2.08 s estimated, over a CPU adapter's 2 s frame limit,
/// so a newcomer's one-shot of it was refused (issue 31); 112² is 1.7 s, and BRSM's frames at
/// the defaults take the same time within noise (1.0–1.2 s for `curl -d '{}'` here).
pub const SOFTWARE_RSM_SIZE: u32 = 112;

/// `clustered`'s interleave block side in the software profile, whose indirect light is at
/// half resolution: 4×4 blocks there cover the 8×8 pixels of the paper's blocks at full
/// resolution (seed 003 §6: 8×8 with 1,024 VPLs). With 8×8 blocks at half resolution (16×16
/// pixels, 16 VPLs per class) the blur left the blocks visible (issue 31); 4×4 costs ~65 ms
/// more at 320×240 on lavapipe (345 → 410 ms a frame).
pub const SOFTWARE_INTERLEAVE: u32 = 4;

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
            DefaultsProfile::Gpu => (RenderParams::default(), 1.0),
            DefaultsProfile::Software => (software_render(), SOFTWARE_VIEWER_SCALE),
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
            g.rsm_size,
            g.view_samples,
            g.val_count,
            g.indirect_downscale,
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
    use lightcast_protocol::{GiMethod, RenderRequest, SessionParams};

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
        assert_eq!(gpu.info.render, RenderParams::default());
        assert_eq!(gpu.info.viewer_scale, 1.0);
        let forced = Defaults::choose(DefaultsChoice::Gpu, "llvmpipe", true);
        assert_eq!(forced.info.render, RenderParams::default());
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
        assert_eq!(set.render.gi.method, GiMethod::Lightskin);
        assert_eq!(set.render.gi.rsm_size, 1024, "an explicit value wins");
        assert_eq!(set.render.gi.val_count, d.info.render.gi.val_count);
        assert_eq!(set.render.gi.indirect_downscale, 2);
        let session: SessionParams = d
            .parse(br#"{"fps_cap": 5, "render": {"gi": {"indirect_downscale": 1}}}"#)
            .expect("valid");
        assert_eq!(session.fps_cap, 5.0);
        assert_eq!(session.render.gi.indirect_downscale, 1);
        assert_eq!(session.render.gi.rsm_size, SOFTWARE_RSM_SIZE);
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
        for &method in GiMethod::ALL {
            for (width, height) in [(800, 450), (320, 240)] {
                let mut params = SessionParams {
                    render: software_render(),
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
            .parse::<RenderRequest>(br#"{"render": {"gi": {"rsm_sise": 1}}}"#)
            .expect_err("unknown field");
        assert_eq!(e.body.field.as_deref(), Some("render.gi.rsm_sise"));
        let e = d
            .parse::<RenderRequest>(br#"{"render": []}"#)
            .expect_err("not an object");
        assert_eq!(e.body.field.as_deref(), Some("render"));
        let e = d.parse::<RenderRequest>(b"[]").expect_err("not an object");
        assert_eq!(e.status, axum::http::StatusCode::BAD_REQUEST);
    }
}
