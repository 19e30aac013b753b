//! Environments: light from infinitely far away around the scene, as a radiance map over the
//! sphere of directions.
//!
//! - [`EnvironmentMap::new`] evaluates a [`lightcast_protocol::Environment`] into an
//!   equirectangular map: a uniform radiance, the analytic daylight sky of Preetham,
//!   Shirley & Smits (1999, "A Practical Analytic Model for Daylight", appendix A), or the
//!   scene's HDR image ([`crate::environment_image`]).
//! - [`EnvironmentMap::sampling`] is what the path-traced reference importance-samples it
//!   with: a texel chosen by its power (radiance luminance × solid angle), then a direction
//!   uniform in the texel's solid angle, so the density per solid angle is exact and
//!   piecewise constant ([`EnvironmentMap::pdf`]).
//! - [`EnvironmentMap::median_cut`] splits it into directional lights of about equal power
//!   (Debevec 2005, "A Median Cut Algorithm for Light Probe Sampling"), which the real-time
//!   methods light with like any punctual light (shadow map, RSM).
//!
//! Directions: +Y up (glTF). Texel `(i, j)` of a `width`×`height` map covers the polar angle
//! θ ∈ [π j/h, π (j+1)/h] from +Y and the azimuth φ ∈ [2π i/w, 2π (i+1)/w], with
//! d = (sin θ cos φ, cos θ, sin θ sin φ); `shaders/environment.wgsl` mirrors it.

use crate::environment_image::EnvironmentImage;
use glam::Vec3;
use lightcast_protocol::{Environment, EnvironmentKind, Light, LightKind};
use std::f32::consts::PI;

/// Side lengths of the maps analytic environments are evaluated into: 2.8° texels, finer
/// than the sky's features away from the sun (the sun itself is a directional light).
pub const ANALYTIC_WIDTH: u32 = 128;
pub const ANALYTIC_HEIGHT: u32 = 64;
/// Largest radiance scale (intensity × colour, × the sun's for a sky) accepted: the sky's
/// brightest texels are a few hundred times its horizontal illuminance, and the tables sum
/// 8,192 texels' power, all far within f32.
pub const MAX_RADIANCE_SCALE: f32 = 1e30;
/// The turbidities Preetham et al. fitted their model for.
pub const TURBIDITY_RANGE: std::ops::RangeInclusive<f32> = 2.0..=10.0;

/// A field of an [`Environment`] that cannot be used, and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid environment.{field}: {reason}")]
pub struct EnvironmentError {
    /// The field under `environment` (`intensity`, `kind` …).
    pub field: &'static str,
    pub reason: String,
}

fn invalid(field: &'static str, reason: impl Into<String>) -> EnvironmentError {
    EnvironmentError {
        field,
        reason: reason.into(),
    }
}

/// Linear-RGB radiance per direction, texels in rows from the zenith (+Y) down.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvironmentMap {
    pub width: u32,
    pub height: u32,
    pub radiance: Vec<[f32; 3]>,
}

/// Importance-sampling tables of an [`EnvironmentMap`] (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct EnvironmentSampling {
    /// Density per solid angle of each texel's directions (0 where it has no power).
    pub pdf: Vec<f32>,
    /// Inclusive cumulative distribution over rows (the last is 1).
    pub rows: Vec<f32>,
    /// Per row, the inclusive cumulative distribution over its texels (each row's last is 1;
    /// a row without power is uniform).
    pub columns: Vec<f32>,
}

/// Rec. 709 luminance of linear RGB.
pub fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// The light a sky takes its sun from: the first directional light.
pub fn sun(lights: &[Light]) -> Option<&Light> {
    lights.iter().find(|l| l.kind == LightKind::Directional)
}

/// What is wrong with `env` for a frame lit by `lights`, if anything, without evaluating it.
/// `directions` is the renderer's to check (it knows the light budget), the image of kind
/// `image` the scene's ([`check_image`]).
pub fn check(env: &Environment, lights: &[Light]) -> Result<(), EnvironmentError> {
    let intensity = env.intensity();
    if !(intensity.is_finite() && intensity >= 0.0) {
        return Err(invalid("intensity", "must be a finite number ≥ 0"));
    }
    if !env.color.iter().all(|c| c.is_finite() && *c >= 0.0) {
        return Err(invalid("color", "must be finite numbers ≥ 0"));
    }
    // The scale of the radiance the map will hold: far below f32's range, whose overflow would
    // reach the sampling tables (they sum every texel's power).
    let sun_scale = match (env.kind, sun(lights)) {
        (EnvironmentKind::Sky, Some(s)) => luminance(s.color) * s.intensity,
        _ => 1.0,
    };
    let peak = intensity * env.color.iter().fold(0.0f32, |m, &c| m.max(c)) * sun_scale;
    if !(peak.is_finite() && peak <= MAX_RADIANCE_SCALE) {
        return Err(invalid(
            "intensity",
            format!("the radiance scale {peak:e} is above {MAX_RADIANCE_SCALE:e}"),
        ));
    }
    if env.kind == EnvironmentKind::Sky {
        if !TURBIDITY_RANGE.contains(&env.turbidity) {
            return Err(invalid(
                "turbidity",
                format!(
                    "{} is outside {}..={}",
                    env.turbidity,
                    TURBIDITY_RANGE.start(),
                    TURBIDITY_RANGE.end()
                ),
            ));
        }
        if sun(lights).is_none() {
            return Err(invalid(
                "kind",
                "`sky` takes its sun from a directional light, and the frame has none",
            ));
        }
    }
    Ok(())
}

/// What is wrong with `env` for a scene whose environment image is `image`: kind `image`
/// needs one.
pub fn check_image(
    env: &Environment,
    image: Option<&EnvironmentImage>,
) -> Result<(), EnvironmentError> {
    if env.kind == EnvironmentKind::Image && image.is_none() {
        return Err(invalid(
            "kind",
            "`image` lights with the scene's environment image (a .hdr or .exr file uploaded \
             with the scene, or --environment-image), and this scene has none",
        ));
    }
    Ok(())
}

impl EnvironmentMap {
    /// Evaluates `env` for a frame lit by `lights` of a scene with environment image `image`
    /// (a sky takes its sun from the first directional light; see [`check`]).
    pub fn new(
        env: &Environment,
        lights: &[Light],
        image: Option<&EnvironmentImage>,
    ) -> Result<Self, EnvironmentError> {
        check(env, lights)?;
        check_image(env, image)?;
        let intensity = env.intensity();
        let (mut w, mut h) = (ANALYTIC_WIDTH, ANALYTIC_HEIGHT);
        let tint = Vec3::from(env.color);
        let radiance = match env.kind {
            EnvironmentKind::Uniform => vec![(tint * intensity).to_array(); (w * h) as usize],
            EnvironmentKind::Image => {
                let Some(image) = image else {
                    unreachable!("check found the image");
                };
                (w, h) = (image.width, image.height);
                let scale = tint * intensity;
                let peak = image.peak() * scale.max_element();
                if !(peak.is_finite() && peak <= MAX_RADIANCE_SCALE) {
                    return Err(invalid(
                        "intensity",
                        format!(
                            "the image's brightest texel times intensity × color is {peak:e}, \
                             above {MAX_RADIANCE_SCALE:e}"
                        ),
                    ));
                }
                image
                    .radiance
                    .iter()
                    .map(|&c| (Vec3::from(c) * scale).to_array())
                    .collect()
            }
            EnvironmentKind::Sky => {
                let Some(sun) = sun(lights) else {
                    unreachable!("check found the sun");
                };
                let to_sun = -Vec3::from(sun.direction).normalize_or_zero();
                let sky = Preetham::new(env.turbidity, to_sun);
                let mut texels: Vec<[f32; 3]> = (0..h)
                    .flat_map(|j| (0..w).map(move |i| (i, j)))
                    .map(|(i, j)| (sky.radiance(texel_centre(i, j, w, h)) * tint).to_array())
                    .collect();
                // Scale the model's luminance (kcd/m²) to the asked horizontal illuminance.
                let map = Self {
                    width: w,
                    height: h,
                    radiance: texels.clone(),
                };
                let target = intensity * luminance(sun.color) * sun.intensity;
                let horizontal = map.horizontal_illuminance();
                let scale = if horizontal > 0.0 {
                    target / horizontal
                } else {
                    0.0
                };
                for t in &mut texels {
                    *t = (Vec3::from(*t) * scale).to_array();
                }
                texels
            }
        };
        // Finite inputs can still overflow f32 (a huge intensity times a bright sun), and
        // the sampling tables sum every texel's power.
        let power: f32 = radiance.iter().map(|&c| luminance(c)).sum();
        if !power.is_finite() {
            return Err(invalid(
                "intensity",
                "too large: the environment's radiance overflows",
            ));
        }
        Ok(Self {
            width: w,
            height: h,
            radiance,
        })
    }

    fn texel(&self, i: u32, j: u32) -> [f32; 3] {
        self.radiance[(j * self.width + i) as usize]
    }

    /// Radiance arriving from direction `d` (unit), piecewise constant per texel.
    pub fn lookup(&self, d: Vec3) -> [f32; 3] {
        let (i, j) = texel_of(d, self.width, self.height);
        self.texel(i, j)
    }

    /// ∫ L(ω) cos⁺θ dω over the upper hemisphere, in luminance: the illuminance an open
    /// surface facing +Y receives.
    pub fn horizontal_illuminance(&self) -> f32 {
        let dphi = 2.0 * PI / self.width as f32;
        (0..self.height)
            .map(|j| {
                let (t0, t1) = row_angles(j, self.height);
                // ∫ cos θ sin θ dθ over the row, above the horizon only.
                let (a, b) = (t0.min(PI / 2.0), t1.min(PI / 2.0));
                let cosine = 0.5 * (b.sin().powi(2) - a.sin().powi(2));
                let row: f32 = (0..self.width).map(|i| luminance(self.texel(i, j))).sum();
                row * dphi * cosine
            })
            .sum()
    }

    /// Luminance power of each texel: luminance × solid angle.
    fn powers(&self) -> Vec<f32> {
        (0..self.height)
            .flat_map(|j| (0..self.width).map(move |i| (i, j)))
            .map(|(i, j)| {
                luminance(self.texel(i, j)) * texel_solid_angle(j, self.width, self.height)
            })
            .collect()
    }

    /// The importance-sampling tables (see [`EnvironmentSampling`]).
    pub fn sampling(&self) -> EnvironmentSampling {
        let (w, h) = (self.width as usize, self.height as usize);
        let power = self.powers();
        let total: f64 = power.iter().map(|&p| f64::from(p)).sum();
        let mut rows = Vec::with_capacity(h);
        let mut columns = Vec::with_capacity(w * h);
        let mut pdf = Vec::with_capacity(w * h);
        let mut running = 0.0f64;
        for j in 0..h {
            let row = &power[j * w..(j + 1) * w];
            let row_sum: f64 = row.iter().map(|&p| f64::from(p)).sum();
            let mut acc = 0.0f64;
            for &p in row {
                acc += if row_sum > 0.0 { f64::from(p) } else { 1.0 };
                columns.push((acc / if row_sum > 0.0 { row_sum } else { w as f64 }) as f32);
                let probability = if total > 0.0 {
                    f64::from(p) / total
                } else {
                    0.0
                };
                let omega = f64::from(texel_solid_angle(j as u32, self.width, self.height));
                pdf.push((probability / omega) as f32);
            }
            running += row_sum;
            rows.push(if total > 0.0 {
                (running / total) as f32
            } else {
                (j + 1) as f32 / h as f32
            });
        }
        // Exactly 1 at the ends, so a search for u < 1 always lands in the table.
        if let Some(last) = rows.last_mut() {
            *last = 1.0;
        }
        for j in 0..h {
            columns[j * w + w - 1] = 1.0;
        }
        EnvironmentSampling { pdf, rows, columns }
    }

    /// Density per solid angle with which [`EnvironmentSampling`] picks `d`.
    pub fn pdf(&self, sampling: &EnvironmentSampling, d: Vec3) -> f32 {
        let (i, j) = texel_of(d, self.width, self.height);
        sampling.pdf[(j * self.width + i) as usize]
    }

    /// A direction for two uniform numbers in [0, 1), with its density per solid angle: the
    /// CPU twin of `env_sample` in `shaders/environment.wgsl`.
    pub fn sample(&self, sampling: &EnvironmentSampling, u: [f32; 3]) -> (Vec3, f32) {
        let (w, h) = (self.width, self.height);
        let j = sampling
            .rows
            .partition_point(|&c| c <= u[0])
            .min(h as usize - 1) as u32;
        let row = &sampling.columns[(j * w) as usize..((j + 1) * w) as usize];
        let i = row.partition_point(|&c| c <= u[1]).min(w as usize - 1);
        // Uniform in solid angle within the texel: cos θ uniform between its row's edges, φ
        // between its column's, from where u[1] fell in the texel's share of the row.
        let below = if i > 0 { row[i - 1] } else { 0.0 };
        let share = row[i] - below;
        let along = if share > 0.0 {
            ((u[1] - below) / share).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let i = i as u32;
        let (t0, t1) = row_angles(j, h);
        let cos_theta = t0.cos() + (t1.cos() - t0.cos()) * u[2];
        let phi = 2.0 * PI * (i as f32 + along) / w as f32;
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let d = Vec3::new(sin_theta * phi.cos(), cos_theta, sin_theta * phi.sin());
        (d, sampling.pdf[(j * w + i) as usize])
    }

    /// At most `count` directional lights of about equal power whose sum approximates the
    /// map (median cut, Debevec 2005): the region with the most power is split across its
    /// longer angular side where its power is halved, until there are `count` regions (or
    /// none can be split). Each region becomes the directional light of its irradiance
    /// vector V = ∫ L(ω) ω dω (Arvo 1995): from V's direction, with illuminance |V|, so it
    /// gives every surface that sees the whole region exactly the region's irradiance
    /// (V · n); a surface whose horizon cuts the region gets an approximation. Regions without
    /// power give no light.
    pub fn median_cut(&self, count: usize) -> Vec<Light> {
        let power = self.powers();
        let (w, h) = (self.width, self.height);
        let region_power = |r: &Region| -> f32 {
            (r.j0..r.j1)
                .flat_map(|j| (r.i0..r.i1).map(move |i| (i, j)))
                .map(|(i, j)| power[(j * w + i) as usize])
                .sum()
        };
        let mut regions = vec![Region {
            i0: 0,
            i1: w,
            j0: 0,
            j1: h,
        }];
        while regions.len() < count {
            let Some(k) = regions
                .iter()
                .enumerate()
                .filter(|(_, r)| r.i1 - r.i0 > 1 || r.j1 - r.j0 > 1)
                .max_by(|a, b| region_power(a.1).total_cmp(&region_power(b.1)))
                .map(|(k, _)| k)
            else {
                break;
            };
            let r = regions.swap_remove(k);
            let (a, b) = r.split(&power, w, h);
            regions.push(a);
            regions.push(b);
        }
        regions
            .iter()
            .filter_map(|r| {
                // Irradiance vectors per channel: ∫ L_k ω dω, texel by texel.
                let mut v = [Vec3::ZERO; 3];
                for j in r.j0..r.j1 {
                    for i in r.i0..r.i1 {
                        let d = texel_vector(i, j, w, h);
                        let l = self.texel(i, j);
                        for k in 0..3 {
                            v[k] += d * l[k];
                        }
                    }
                }
                let direction = (0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2]).try_normalize()?;
                let rgb = [
                    v[0].dot(direction),
                    v[1].dot(direction),
                    v[2].dot(direction),
                ]
                .map(|c| c.max(0.0));
                let intensity = luminance(rgb);
                (intensity > 0.0).then(|| Light {
                    kind: LightKind::Directional,
                    position: [0.0; 3],
                    direction: (-direction).to_array(),
                    color: rgb.map(|c| c / intensity),
                    intensity,
                    inner_cone: 0.0,
                    outer_cone: std::f32::consts::FRAC_PI_4,
                })
            })
            .collect()
    }
}

/// A rectangle of texels `[i0, i1) × [j0, j1)`.
#[derive(Clone, Copy, Debug)]
struct Region {
    i0: u32,
    i1: u32,
    j0: u32,
    j1: u32,
}

impl Region {
    /// Halves across the longer angular side (φ extent × sin θ at the middle against θ
    /// extent) at the texel line where the power is closest to split in two.
    fn split(&self, power: &[f32], w: u32, h: u32) -> (Self, Self) {
        let theta_mid = PI * (self.j0 + self.j1) as f32 / (2 * h) as f32;
        let phi_extent = 2.0 * PI * (self.i1 - self.i0) as f32 / w as f32 * theta_mid.sin();
        let theta_extent = PI * (self.j1 - self.j0) as f32 / h as f32;
        let across_phi =
            self.j1 - self.j0 == 1 || (self.i1 - self.i0 > 1 && phi_extent >= theta_extent);
        let at = |i: u32, j: u32| power[(j * w + i) as usize];
        let lines: Vec<f32> = if across_phi {
            (self.i0..self.i1)
                .map(|i| (self.j0..self.j1).map(|j| at(i, j)).sum())
                .collect()
        } else {
            (self.j0..self.j1)
                .map(|j| (self.i0..self.i1).map(|i| at(i, j)).sum())
                .collect()
        };
        let total: f32 = lines.iter().sum();
        // The cut after line `k` (1 ≤ k < len) whose left part is closest to half.
        let mut acc = 0.0;
        let mut best = (f32::INFINITY, 1);
        for (k, l) in lines.iter().enumerate().take(lines.len() - 1) {
            acc += l;
            let off = (acc - 0.5 * total).abs();
            if off < best.0 {
                best = (off, k + 1);
            }
        }
        let cut = best.1 as u32;
        if across_phi {
            let m = self.i0 + cut;
            (Self { i1: m, ..*self }, Self { i0: m, ..*self })
        } else {
            let m = self.j0 + cut;
            (Self { j1: m, ..*self }, Self { j0: m, ..*self })
        }
    }
}

/// Polar angles of the top and bottom edge of row `j`.
fn row_angles(j: u32, h: u32) -> (f32, f32) {
    (PI * j as f32 / h as f32, PI * (j + 1) as f32 / h as f32)
}

/// Solid angle of a texel of row `j`: Δφ (cos θ₀ − cos θ₁), as 2 sin((θ₀+θ₁)/2)
/// sin((θ₁−θ₀)/2), which keeps f32's precision at the poles of a fine map (where the
/// difference of two cosines near 1 would lose it).
pub fn texel_solid_angle(j: u32, w: u32, h: u32) -> f32 {
    let (t0, t1) = row_angles(j, h);
    2.0 * PI / w as f32 * 2.0 * (0.5 * (t0 + t1)).sin() * (0.5 * (t1 - t0)).sin()
}

/// ∫ ω dω over texel `(i, j)`: its irradiance vector under a radiance of 1.
fn texel_vector(i: u32, j: u32, w: u32, h: u32) -> Vec3 {
    let (t0, t1) = row_angles(j, h);
    let (p0, p1) = (
        2.0 * PI * i as f32 / w as f32,
        2.0 * PI * (i + 1) as f32 / w as f32,
    );
    // ∫∫ (sin θ cos φ, cos θ, sin θ sin φ) sin θ dθ dφ.
    let sin2 = 0.5 * (t1 - t0) - 0.25 * ((2.0 * t1).sin() - (2.0 * t0).sin());
    let cos_sin = 0.5 * (t1.sin().powi(2) - t0.sin().powi(2));
    Vec3::new(
        sin2 * (p1.sin() - p0.sin()),
        cos_sin * (p1 - p0),
        sin2 * (p0.cos() - p1.cos()),
    )
}

/// Unit direction through the centre of texel `(i, j)`.
pub fn texel_centre(i: u32, j: u32, w: u32, h: u32) -> Vec3 {
    let theta = PI * (j as f32 + 0.5) / h as f32;
    let phi = 2.0 * PI * (i as f32 + 0.5) / w as f32;
    Vec3::new(
        theta.sin() * phi.cos(),
        theta.cos(),
        theta.sin() * phi.sin(),
    )
}

/// The texel direction `d` (unit) falls in.
pub fn texel_of(d: Vec3, w: u32, h: u32) -> (u32, u32) {
    let theta = d.y.clamp(-1.0, 1.0).acos();
    let phi = d.z.atan2(d.x).rem_euclid(2.0 * PI);
    let i = ((phi / (2.0 * PI) * w as f32) as u32).min(w - 1);
    let j = ((theta / PI * h as f32) as u32).min(h - 1);
    (i, j)
}

/// The Perez sky-luminance distribution F(θ, γ) = (1 + A e^{B / cos θ})(1 + C e^{D γ} +
/// E cos² γ) (Preetham et al. eq. 3), θ from the zenith, γ from the sun.
fn perez(c: [f32; 5], cos_theta: f32, gamma: f32) -> f32 {
    let [a, b, cc, d, e] = c;
    (1.0 + a * (b / cos_theta).exp()) * (1.0 + cc * (d * gamma).exp() + e * gamma.cos().powi(2))
}

/// Preetham et al.'s clear sky for one sun position and turbidity: luminance Y and
/// chromaticity x, y each a Perez distribution scaled to its zenith value (appendix A).
struct Preetham {
    to_sun: Vec3,
    coefficients: [[f32; 5]; 3],
    /// Zenith value over F(0, θs), per Y, x, y.
    scale: [f32; 3],
}

impl Preetham {
    fn new(turbidity: f32, to_sun: Vec3) -> Self {
        let t = turbidity;
        // A sun below the horizon is outside the model: it gets the sky of a sun on it.
        let to_sun = Vec3::new(to_sun.x, to_sun.y.max(0.0), to_sun.z)
            .try_normalize()
            .unwrap_or(Vec3::Y);
        let theta_s = to_sun.y.clamp(-1.0, 1.0).acos();
        let coefficients = [
            [
                0.1787 * t - 1.4630,
                -0.3554 * t + 0.4275,
                -0.0227 * t + 5.3251,
                0.1206 * t - 2.5771,
                -0.0670 * t + 0.3703,
            ],
            [
                -0.0193 * t - 0.2592,
                -0.0665 * t + 0.0008,
                -0.0004 * t + 0.2125,
                -0.0641 * t - 0.8989,
                -0.0033 * t + 0.0452,
            ],
            [
                -0.0167 * t - 0.2608,
                -0.0950 * t + 0.0092,
                -0.0079 * t + 0.2102,
                -0.0441 * t - 1.6537,
                -0.0109 * t + 0.0529,
            ],
        ];
        let chi = (4.0 / 9.0 - t / 120.0) * (PI - 2.0 * theta_s);
        let zenith_y = (4.0453 * t - 4.9710) * chi.tan() - 0.2155 * t + 2.4192;
        let (s, s2, s3) = (theta_s, theta_s * theta_s, theta_s * theta_s * theta_s);
        let zenith_x = t * t * (0.00166 * s3 - 0.00375 * s2 + 0.00209 * s)
            + t * (-0.02903 * s3 + 0.06377 * s2 - 0.03202 * s + 0.00394)
            + (0.11693 * s3 - 0.21196 * s2 + 0.06052 * s + 0.25886);
        let zenith_yc = t * t * (0.00275 * s3 - 0.00610 * s2 + 0.00317 * s)
            + t * (-0.04214 * s3 + 0.08970 * s2 - 0.04153 * s + 0.00516)
            + (0.15346 * s3 - 0.26756 * s2 + 0.06670 * s + 0.26688);
        let zenith = [zenith_y.max(0.0), zenith_x, zenith_yc];
        let scale = std::array::from_fn(|k| zenith[k] / perez(coefficients[k], 1.0, theta_s));
        Self {
            to_sun,
            coefficients,
            scale,
        }
    }

    /// Linear-RGB radiance towards unit direction `d` (up to the model's scale); black below
    /// the horizon.
    fn radiance(&self, d: Vec3) -> Vec3 {
        if d.y <= 0.0 {
            return Vec3::ZERO;
        }
        let gamma = d.dot(self.to_sun).clamp(-1.0, 1.0).acos();
        let [y, x, yc]: [f32; 3] = std::array::from_fn(|k| {
            self.scale[k] * perez(self.coefficients[k], d.y.max(1e-3), gamma)
        });
        if yc <= 0.0 {
            return Vec3::ZERO;
        }
        // xyY → XYZ → linear Rec. 709.
        let (cx, cz) = (x * y / yc, (1.0 - x - yc) * y / yc);
        Vec3::new(
            3.2406 * cx - 1.5372 * y - 0.4986 * cz,
            -0.9689 * cx + 1.8758 * y + 0.0415 * cz,
            0.0557 * cx - 0.2040 * y + 1.0570 * cz,
        )
        .max(Vec3::ZERO)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sun(direction: [f32; 3]) -> Light {
        Light {
            kind: LightKind::Directional,
            position: [0.0; 3],
            direction,
            color: [1.0, 1.0, 1.0],
            intensity: 5.0,
            inner_cone: 0.0,
            outer_cone: 0.5,
        }
    }

    fn uniform(intensity: f32) -> Environment {
        Environment {
            intensity: Some(intensity),
            ..Environment::default()
        }
    }

    #[test]
    fn solid_angles_cover_the_sphere_and_the_horizontal_illuminance_of_uniform_is_pi_l() {
        let (w, h) = (ANALYTIC_WIDTH, ANALYTIC_HEIGHT);
        let total: f32 = (0..h).map(|j| texel_solid_angle(j, w, h) * w as f32).sum();
        assert!((total - 4.0 * PI).abs() < 1e-3, "{total}");
        let map = EnvironmentMap::new(&uniform(2.0), &[], None).expect("uniform");
        // E = ∫ L cos θ dω over the hemisphere = π L.
        assert!((map.horizontal_illuminance() - 2.0 * PI).abs() < 1e-3);
    }

    #[test]
    fn texel_lookup_inverts_the_texel_centre() {
        let (w, h) = (16, 8);
        for j in 0..h {
            for i in 0..w {
                assert_eq!(texel_of(texel_centre(i, j, w, h), w, h), (i, j));
            }
        }
    }

    #[test]
    fn sampling_density_integrates_to_one_and_matches_the_sampled_texel() {
        let map = EnvironmentMap::new(
            &Environment {
                kind: EnvironmentKind::Sky,
                ..Environment::default()
            },
            &[sun([0.3, -0.5, 0.2])],
            None,
        )
        .expect("sky");
        let s = map.sampling();
        let (w, h) = (map.width, map.height);
        let integral: f32 = (0..h)
            .flat_map(|j| (0..w).map(move |i| (i, j)))
            .map(|(i, j)| s.pdf[(j * w + i) as usize] * texel_solid_angle(j, w, h))
            .sum();
        assert!((integral - 1.0).abs() < 1e-4, "{integral}");
        // Samples land where the density says, and their histogram follows the power: the
        // estimate E[L cos⁺/pdf] of the horizontal illuminance converges to the exact one.
        let mut state = 7u64;
        let mut rand = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let n = 200_000;
        let mut estimate = 0.0f64;
        // A sample on a texel's edge may round into its neighbour.
        let mut elsewhere = 0;
        for _ in 0..n {
            let (d, pdf) = map.sample(&s, [rand(), rand(), rand()]);
            assert!((d.length() - 1.0).abs() < 1e-4);
            assert!(pdf > 0.0, "a sample where the map has no power: {d}");
            elsewhere += usize::from(pdf != map.pdf(&s, d));
            estimate += f64::from(luminance(map.lookup(d)) * d.y.max(0.0) / pdf);
        }
        assert!(elsewhere < 20, "{elsewhere} samples outside their texel");
        let exact = f64::from(map.horizontal_illuminance());
        let estimate = estimate / f64::from(n);
        assert!(
            (estimate / exact - 1.0).abs() < 0.01,
            "{estimate} vs {exact}"
        );
    }

    #[test]
    fn sky_has_the_asked_horizontal_illuminance_and_brightens_towards_the_sun() {
        let light = sun([0.0, -1.0, -1.0]);
        let env = Environment {
            kind: EnvironmentKind::Sky,
            intensity: Some(0.25),
            ..Environment::default()
        };
        let map = EnvironmentMap::new(&env, std::slice::from_ref(&light), None).expect("sky");
        let e = map.horizontal_illuminance();
        assert!((e - 0.25 * 5.0).abs() < 1e-3, "{e}");
        let to_sun = Vec3::new(0.0, 1.0, 1.0).normalize();
        let near_sun = luminance(map.lookup((to_sun + Vec3::new(0.0, 0.0, 0.1)).normalize()));
        let away = luminance(map.lookup(Vec3::new(0.0, 0.7, -0.7).normalize()));
        assert!(near_sun > 2.0 * away, "{near_sun} vs {away}");
        // Blue: a clear sky away from the sun.
        let c = map.lookup(Vec3::new(0.0, 0.7, -0.7).normalize());
        assert!(c[2] > c[0], "{c:?}");
        assert_eq!(map.lookup(Vec3::new(0.2, -0.5, 0.1).normalize()), [0.0; 3]);
        // Without a directional light there is no sun to drive it.
        let point = Light {
            kind: LightKind::Point,
            ..light
        };
        assert_eq!(
            EnvironmentMap::new(&env, &[point], None).map_err(|e| e.field),
            Err("kind")
        );
        let blinding = Environment {
            intensity: Some(3e38),
            ..env.clone()
        };
        assert_eq!(
            EnvironmentMap::new(&blinding, &[sun([0.0, -1.0, 0.0])], None).map_err(|e| e.field),
            Err("intensity")
        );
        let hazy = Environment {
            turbidity: 12.0,
            ..env
        };
        assert_eq!(
            EnvironmentMap::new(&hazy, &[sun([0.0, -1.0, 0.0])], None).map_err(|e| e.field),
            Err("turbidity")
        );
    }

    #[test]
    fn median_cut_lights_surfaces_like_the_map() {
        for env in [
            uniform(1.0),
            Environment {
                kind: EnvironmentKind::Sky,
                ..Environment::default()
            },
        ] {
            let map = EnvironmentMap::new(&env, &[sun([0.4, -0.6, 0.3])], None).expect("map");
            let (w, h) = (map.width, map.height);
            // Irradiance (luminance) on a surface facing `n`, texel by texel.
            let exact = |n: Vec3| -> f32 {
                (0..h)
                    .flat_map(|j| (0..w).map(move |i| (i, j)))
                    .map(|(i, j)| {
                        luminance(map.texel(i, j))
                            * texel_solid_angle(j, w, h)
                            * texel_centre(i, j, w, h).dot(n).max(0.0)
                    })
                    .sum()
            };
            let normals = [
                Vec3::Y,
                Vec3::X,
                -Vec3::Z,
                Vec3::new(1.0, 1.0, 0.0).normalize(),
                Vec3::new(-0.3, 0.5, 0.8).normalize(),
            ];
            // Measured: the worst of these normals is 29 % (8 lights) and 10 % (15) too dark
            // under the uniform sphere, 13 % under the sky: a light whose region the
            // surface's horizon cuts counts whole or not at all.
            for (count, tolerance) in [(8, 0.30), (15, 0.13)] {
                let lights = map.median_cut(count);
                assert!(lights.len() == count, "{env:?}: {} lights", lights.len());
                let approx = |n: Vec3| -> f32 {
                    lights
                        .iter()
                        .map(|l| {
                            l.intensity
                                * luminance(l.color)
                                * (-Vec3::from(l.direction)).dot(n).max(0.0)
                        })
                        .sum()
                };
                for n in normals {
                    let (a, e) = (approx(n), exact(n));
                    assert!(
                        (a / e - 1.0).abs() < tolerance,
                        "{env:?}, {count} lights, n {n}: {a} vs {e}"
                    );
                }
            }
            // The regions' irradiance vectors: an upward surface sees the upper hemisphere
            // whole, so 8 lights give its irradiance almost exactly for the uniform sky,
            // whose regions do not straddle the horizon.
            if env.kind == EnvironmentKind::Uniform {
                let lights = map.median_cut(8);
                let up: f32 = lights
                    .iter()
                    .map(|l| l.intensity * (-l.direction[1]).max(0.0))
                    .sum();
                assert!((up / PI - 1.0).abs() < 1e-3, "{up}");
            }
        }
    }
}
