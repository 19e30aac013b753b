//! Equirectangular HDR images as environments (`render.environment.kind` `image`): a Radiance
//! `.hdr` or OpenEXR file uploaded with the scene, decoded by the `image` crate and resampled
//! once into the [`super::environment::EnvironmentMap`] layout.
//!
//! The image's convention is Mitsuba's and PBRT's: rows from the zenith (+Y) down, column
//! `u ∈ [0, 1)` from the left at d = (sin 2πu sin θ, cos θ, −cos 2πu sin θ), so the left
//! edge faces −Z, a quarter across faces +X and the centre faces +Z. Our maps start φ at +X,
//! a quarter turn on: texel column φ/2π takes the image at u = φ/2π + ¼.
//!
//! Large images are reduced to at most [`MAX_WIDTH`]×[`MAX_HEIGHT`] by averaging the source
//! texels each target texel covers, weighted by covered azimuth × covered cos θ span (their
//! solid angle), so the map's power ∫ L dω is the image's, a small bright sun included.

use std::f64::consts::PI;
use std::io::Cursor;

/// Largest map an image is kept as: 0.35° texels, finer than a real-time method's lights
/// resolve, and 6 MiB of radiance (plus ~4 MiB of sampling tables on the GPU).
pub const MAX_WIDTH: u32 = 1024;
pub const MAX_HEIGHT: u32 = 512;
/// Bytes decoding takes per source texel (RGBA f32, what an EXR decodes to at most).
pub const DECODED_BYTES_PER_TEXEL: u64 = 16;

/// The image format of an environment image named `name`, by its extension (`.hdr`, `.exr`,
/// any case).
fn format_of(name: &str) -> Option<image::ImageFormat> {
    match name.rsplit_once('.')?.1.to_ascii_lowercase().as_str() {
        "hdr" => Some(image::ImageFormat::Hdr),
        "exr" => Some(image::ImageFormat::OpenExr),
        _ => None,
    }
}

/// Whether `name` is an environment image by its extension (`.hdr`, `.exr`).
pub fn is_environment_image(name: &str) -> bool {
    format_of(name).is_some()
}

#[derive(Debug, thiserror::Error)]
pub enum EnvironmentImageError {
    #[error("not a .hdr or .exr file name")]
    Extension,
    #[error("cannot read the image: {0}")]
    Decode(String),
    #[error(
        "{width}×{height} texels take {bytes} bytes to decode, above the {limit} bytes left \
         for this scene's textures"
    )]
    Budget {
        width: u32,
        height: u32,
        bytes: u64,
        limit: u64,
    },
    #[error("the image has no texels")]
    Empty,
    #[error("texel ({x}, {y}) is not a finite radiance ≥ 0 ({value})")]
    Texel { x: u32, y: u32, value: f32 },
}

/// An environment image, resampled into the map layout of
/// [`super::environment::EnvironmentMap`].
#[derive(Clone, Debug, PartialEq)]
pub struct EnvironmentImage {
    /// The uploaded file's name.
    pub name: String,
    /// The file's size in texels.
    pub source_width: u32,
    pub source_height: u32,
    pub width: u32,
    pub height: u32,
    /// Linear RGB, rows from +Y down, columns from φ = 0 (+X).
    pub radiance: Vec<[f32; 3]>,
}

impl EnvironmentImage {
    /// Decodes `bytes` (format by `name`'s extension), refusing before decoding an image
    /// whose decoded texels would take more than `max_bytes`.
    pub fn decode(name: &str, bytes: &[u8], max_bytes: u64) -> Result<Self, EnvironmentImageError> {
        let format = format_of(name).ok_or(EnvironmentImageError::Extension)?;
        let decode_error = |e: image::ImageError| EnvironmentImageError::Decode(e.to_string());
        let reader = || image::ImageReader::with_format(Cursor::new(bytes), format);
        let (width, height) = reader().into_dimensions().map_err(decode_error)?;
        if width == 0 || height == 0 {
            return Err(EnvironmentImageError::Empty);
        }
        let decoded = u64::from(width) * u64::from(height) * DECODED_BYTES_PER_TEXEL;
        if decoded > max_bytes {
            return Err(EnvironmentImageError::Budget {
                width,
                height,
                bytes: decoded,
                limit: max_bytes,
            });
        }
        let mut limited = reader();
        let mut limits = image::Limits::default();
        // The header's size was checked above; this bounds what the decoder allocates besides.
        limits.max_alloc = Some(max_bytes);
        limited.limits(limits);
        let rgb = limited.decode().map_err(decode_error)?.into_rgb32f();
        let texels: Vec<[f32; 3]> = rgb.pixels().map(|p| p.0).collect();
        Self::from_texels(name, width, height, &texels)
    }

    /// An image of `width`×`height` texels (rows from the top, the convention in the module
    /// doc) in our map layout, reduced to at most [`MAX_WIDTH`]×[`MAX_HEIGHT`].
    pub fn from_texels(
        name: &str,
        width: u32,
        height: u32,
        texels: &[[f32; 3]],
    ) -> Result<Self, EnvironmentImageError> {
        if width == 0 || height == 0 || texels.len() != (width as usize) * (height as usize) {
            return Err(EnvironmentImageError::Empty);
        }
        if let Some(k) = texels
            .iter()
            .position(|t| !t.iter().all(|c| c.is_finite() && *c >= 0.0))
        {
            let t = texels[k];
            return Err(EnvironmentImageError::Texel {
                x: (k % width as usize) as u32,
                y: (k / width as usize) as u32,
                value: t
                    .into_iter()
                    .find(|c| !(c.is_finite() && *c >= 0.0))
                    .unwrap_or(0.0),
            });
        }
        let (w, h) = (width.min(MAX_WIDTH), height.min(MAX_HEIGHT));
        // Columns: our texel i covers u ∈ [i/w + ¼, (i+1)/w + ¼) of the image, wrapping.
        let columns = overlaps(width, w, |i| {
            let a = f64::from(i) / f64::from(w) + 0.25;
            (a, a + 1.0 / f64::from(w))
        });
        // Rows: the same θ ranges, weighted by the cos θ span each covers.
        let rows = row_weights(height, h);
        let mut across = vec![[0.0f64; 3]; (height * w) as usize];
        for y in 0..height as usize {
            let source = &texels[y * width as usize..(y + 1) * width as usize];
            for (i, cover) in columns.iter().enumerate() {
                let mut sum = [0.0f64; 3];
                for &(x, weight) in cover {
                    for c in 0..3 {
                        sum[c] += weight * f64::from(source[x as usize][c]);
                    }
                }
                across[y * w as usize + i] = sum;
            }
        }
        let mut radiance = Vec::with_capacity((w * h) as usize);
        for cover in &rows {
            let total: f64 = cover.iter().map(|&(_, weight)| weight).sum();
            for i in 0..w as usize {
                let mut sum = [0.0f64; 3];
                for &(y, weight) in cover {
                    for c in 0..3 {
                        sum[c] += weight * across[y as usize * w as usize + i][c];
                    }
                }
                radiance.push(sum.map(|s| if total > 0.0 { (s / total) as f32 } else { 0.0 }));
            }
        }
        Ok(Self {
            name: name.to_string(),
            source_width: width,
            source_height: height,
            width: w,
            height: h,
            radiance,
        })
    }

    /// Bytes the kept map takes (what a scene's texture budget counts for it).
    pub fn bytes(&self) -> u64 {
        self.radiance.len() as u64 * 12
    }

    /// Largest channel of any texel.
    pub fn peak(&self) -> f32 {
        self.radiance
            .iter()
            .flatten()
            .fold(0.0f32, |m, &c| m.max(c))
    }
}

/// For each of `to` target cells, the source cells of `from` it covers (indices modulo
/// `from`) with the fraction of the target each covers; `range(i)` is target i's span in
/// units of the whole (a span of 1/`to`).
fn overlaps(from: u32, to: u32, range: impl Fn(u32) -> (f64, f64)) -> Vec<Vec<(u32, f64)>> {
    let n = f64::from(from);
    (0..to)
        .map(|i| {
            let (a, b) = range(i);
            let (a, b) = (a * n, b * n);
            let mut cover = Vec::new();
            let mut x = a.floor();
            while x < b {
                let covered = (x + 1.0).min(b) - x.max(a);
                if covered > 0.0 {
                    cover.push((
                        (x as i64).rem_euclid(i64::from(from)) as u32,
                        covered / (b - a),
                    ));
                }
                x += 1.0;
            }
            cover
        })
        .collect()
}

/// For each of `to` target rows (θ ∈ [πj/to, π(j+1)/to]), the source rows it covers with the
/// solid angle per unit azimuth of the part covered (cos θ₀ − cos θ₁).
fn row_weights(from: u32, to: u32) -> Vec<Vec<(u32, f64)>> {
    (0..to)
        .map(|j| {
            let (t0, t1) = (
                PI * f64::from(j) / f64::from(to),
                PI * f64::from(j + 1) / f64::from(to),
            );
            let first = (t0 / PI * f64::from(from)).floor() as u32;
            let last = ((t1 / PI * f64::from(from)).ceil() as u32).min(from);
            (first..last)
                .filter_map(|y| {
                    let s0 = (PI * f64::from(y) / f64::from(from)).max(t0);
                    let s1 = (PI * f64::from(y + 1) / f64::from(from)).min(t1);
                    (s1 > s0).then(|| (y, s0.cos() - s1.cos()))
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::environment::{luminance, texel_of, texel_solid_angle};
    use glam::Vec3;

    /// Power ∫ L dω (luminance) of a map of rows from +Y.
    fn power(w: u32, h: u32, texels: &[[f32; 3]]) -> f64 {
        (0..h)
            .flat_map(|j| (0..w).map(move |i| (i, j)))
            .map(|(i, j)| {
                f64::from(luminance(texels[(j * w + i) as usize]))
                    * f64::from(texel_solid_angle(j, w, h))
            })
            .sum()
    }

    fn image(width: u32, height: u32, f: impl Fn(u32, u32) -> [f32; 3]) -> Vec<[f32; 3]> {
        (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y))
            .collect()
    }

    /// The direction of image texel (x, y)'s centre in the image's own convention.
    fn image_direction(x: u32, y: u32, width: u32, height: u32) -> Vec3 {
        let u = (f64::from(x) + 0.5) / f64::from(width);
        let theta = PI * (f64::from(y) + 0.5) / f64::from(height);
        let phi = 2.0 * PI * u;
        Vec3::new(
            (phi.sin() * theta.sin()) as f32,
            theta.cos() as f32,
            (-phi.cos() * theta.sin()) as f32,
        )
    }

    /// One bright texel lands on the texel of our map that holds its direction, with all of
    /// its power, at the image's own size and reduced.
    #[test]
    fn one_bright_texel_keeps_its_direction_and_power() {
        for (width, height) in [(64, 32), (2048, 1024), (1500, 700)] {
            for (x, y) in [(0, 3), (width / 4, height / 2 - 1), (width - 1, height - 5)] {
                let texels = image(width, height, |i, j| {
                    if (i, j) == (x, y) {
                        [1000.0, 500.0, 250.0]
                    } else {
                        [0.0; 3]
                    }
                });
                let map = EnvironmentImage::from_texels("sun.hdr", width, height, &texels)
                    .expect("valid");
                assert!(map.width <= MAX_WIDTH && map.height <= MAX_HEIGHT);
                let want = power(width, height, &texels);
                let got = power(map.width, map.height, &map.radiance);
                assert!(
                    (got / want - 1.0).abs() < 1e-4,
                    "{width}×{height} ({x},{y}): power {got} vs {want}"
                );
                // The brightest texel of the map is where the bright texel's direction falls.
                let brightest = (0..map.radiance.len())
                    .max_by(|&a, &b| {
                        luminance(map.radiance[a]).total_cmp(&luminance(map.radiance[b]))
                    })
                    .expect("texels");
                let (i, j) = texel_of(image_direction(x, y, width, height), map.width, map.height);
                let (bi, bj) = (brightest as u32 % map.width, brightest as u32 / map.width);
                let wrap = |a: u32, b: u32| a.abs_diff(b).min(map.width - a.abs_diff(b));
                assert!(
                    wrap(bi, i) <= 1 && bj.abs_diff(j) <= 1,
                    "{width}×{height} ({x},{y}): brightest at ({bi},{bj}), direction in ({i},{j})"
                );
                // Colour is kept.
                let c = map.radiance[brightest];
                assert!((c[1] / c[0] - 0.5).abs() < 1e-4 && (c[2] / c[0] - 0.25).abs() < 1e-4);
            }
        }
    }

    /// The convention in the module doc: the image's left edge faces −Z, a quarter across +X,
    /// the centre +Z; the top row is the zenith.
    #[test]
    fn image_columns_face_the_documented_directions() {
        let (width, height) = (256, 128);
        for (x, want) in [
            (0, -Vec3::Z),
            (64, Vec3::X),
            (128, Vec3::Z),
            (192, -Vec3::X),
        ] {
            let d = image_direction(x, height / 2, width, height);
            assert!(d.distance(want) < 0.05, "column {x}: {d}");
            let texels = image(width, height, |i, j| {
                if (i, j) == (x, height / 2) {
                    [1.0; 3]
                } else {
                    [0.0; 3]
                }
            });
            let map = EnvironmentImage::from_texels("x.exr", width, height, &texels).expect("ok");
            let (i, j) = texel_of(want, map.width, map.height);
            assert!(
                map.radiance[(j * map.width + i) as usize][0] > 0.0,
                "column {x}"
            );
        }
    }

    #[test]
    fn bad_texels_and_sizes_are_refused_naming_the_texel() {
        let mut texels = vec![[0.5f32; 3]; 8 * 4];
        texels[8 + 3][1] = f32::NAN;
        let e = EnvironmentImage::from_texels("a.hdr", 8, 4, &texels).expect_err("NaN");
        assert!(
            matches!(e, EnvironmentImageError::Texel { x: 3, y: 1, .. }),
            "{e}"
        );
        texels[8 + 3][1] = -1.0;
        let e = EnvironmentImage::from_texels("a.hdr", 8, 4, &texels).expect_err("negative");
        assert!(e.to_string().contains("(3, 1)"), "{e}");
        assert!(matches!(
            EnvironmentImage::from_texels("a.hdr", 0, 4, &[]),
            Err(EnvironmentImageError::Empty)
        ));
    }

    /// A real file through the `image` crate: written as Radiance RGBE and as OpenEXR, read
    /// back with its texels (RGBE keeps 8 bits of mantissa), the budget checked before
    /// decoding, garbage and a wrong extension refused.
    #[test]
    fn hdr_and_exr_files_decode_within_their_budget() {
        let (width, height) = (32, 16);
        let texels = image(width, height, |x, y| {
            [0.1 * x as f32, 0.05 * y as f32 + 0.01, 2.0]
        });
        for format in [image::ImageFormat::Hdr, image::ImageFormat::OpenExr] {
            let mut bytes = Vec::new();
            let buffer = image::Rgb32FImage::from_raw(
                width,
                height,
                texels.iter().flatten().copied().collect(),
            )
            .expect("size");
            image::DynamicImage::ImageRgb32F(buffer)
                .write_to(&mut Cursor::new(&mut bytes), format)
                .expect("encode");
            let name = if format == image::ImageFormat::Hdr {
                "sky.HDR"
            } else {
                "sky.exr"
            };
            assert!(is_environment_image(name));
            let map = EnvironmentImage::decode(name, &bytes, 1 << 20).expect("decodes");
            assert_eq!((map.width, map.height), (width, height));
            assert_eq!((map.source_width, map.source_height), (width, height));
            // Same texels, shifted a quarter turn (8 of 32 columns).
            for (k, t) in map.radiance.iter().enumerate() {
                let (i, y) = (k as u32 % width, k as u32 / width);
                let source = texels[(y * width + (i + width / 4) % width) as usize];
                // RGBE shares one exponent: 8 bits below the largest channel.
                let largest = source.iter().fold(0.0f32, |m, &c| m.max(c));
                for c in 0..3 {
                    assert!(
                        (t[c] - source[c]).abs() <= largest / 128.0,
                        "{name} ({i},{y}): {t:?} vs {source:?}"
                    );
                }
            }
            let needed = u64::from(width * height) * DECODED_BYTES_PER_TEXEL;
            let e = EnvironmentImage::decode(name, &bytes, needed - 1).expect_err("budget");
            assert!(matches!(e, EnvironmentImageError::Budget { .. }), "{e}");
            let e = EnvironmentImage::decode(name, &bytes[..40], 1 << 20).expect_err("cut");
            assert!(matches!(e, EnvironmentImageError::Decode(_)), "{e}");
        }
        assert!(!is_environment_image("sky.png"));
        assert!(matches!(
            EnvironmentImage::decode("sky.png", b"x", 1 << 20),
            Err(EnvironmentImageError::Extension)
        ));
    }
}
