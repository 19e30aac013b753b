//! The camera path of `bench-stream`: an orbit around the scene's target or a dolly towards it.

use super::*;

/// How the camera moves along the path (`--motion`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Motion {
    Orbit,
    Dolly,
}

/// The camera path: `base` (the scene's default camera) moved by `motion`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CameraMotion {
    pub motion: Motion,
    /// Degrees per second (`orbit`) or the share of the distance to the target per second
    /// (`dolly`).
    pub speed: f32,
    pub base: Camera,
}

impl CameraMotion {
    /// The camera `seconds` into the path.
    pub fn at(&self, seconds: f64) -> Camera {
        let amount = seconds * f64::from(self.speed);
        let base = &self.base;
        match self.motion {
            // As `lightcast`'s orbit: about the vertical axis through the target.
            Motion::Orbit => {
                let (s, c) = (amount.to_radians() as f32).sin_cos();
                let [px, py, pz] = base.position;
                let [tx, _, tz] = base.target;
                let (dx, dz) = (px - tx, pz - tz);
                Camera {
                    position: [tx + dx * c - dz * s, py, tz + dx * s + dz * c],
                    ..base.clone()
                }
            }
            Motion::Dolly => {
                let step = |p: [f32; 3]| {
                    [0, 1, 2].map(|k| p[k] + (base.target[k] - base.position[k]) * amount as f32)
                };
                Camera {
                    position: step(base.position),
                    target: step(base.target),
                    ..base.clone()
                }
            }
        }
    }

    /// The first `seconds` of the path as `lightcast stream --camera-path` reads it, a keyframe
    /// every 1/`fps` second (the client interpolates linearly between them).
    pub fn to_json(&self, seconds: f32, fps: f32) -> serde_json::Value {
        let count = (f64::from(seconds) * f64::from(fps)).ceil() as u32;
        let keyframes: Vec<serde_json::Value> = (0..=count)
            .map(|i| {
                let t = f64::from(i) / f64::from(fps);
                serde_json::json!({ "t": t, "camera": self.at(t) })
            })
            .collect();
        serde_json::json!({ "keyframes": keyframes })
    }
}

impl std::fmt::Display for CameraMotion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.motion {
            Motion::Orbit => write!(f, "orbits its target at {}°/s", self.speed),
            Motion::Dolly => write!(
                f,
                "dollies towards its target at {} % of the distance per second",
                self.speed * 100.0
            ),
        }
    }
}
