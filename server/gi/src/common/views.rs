//! What every method's debug views draw with: an RGBA8 image, auto-exposure, distinct
//! colours, the frame darkened with scene points projected onto it, and the `indirect` view
//! every GI method shows.

use crate::gi::views::{DebugView, ViewInputs};
use crate::passes::{exposure::KEY, frame_uniforms::camera_view_proj, tonemap::tonemap_cpu};
use glam::{Vec3, Vec4Swizzles};
use lightcast_protocol::View;

/// Indirect light alone, at the frame's exposure: every method but `none` lists it.
pub static INDIRECT: DebugView = DebugView {
    name: View::new("indirect"),
    summary: "Indirect light only, at the frame's exposure.",
    reads_indirect: true,
    draw: indirect,
};

/// An RGBA8 image.
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgba8: Vec<u8>,
}

impl Image {
    pub fn from_rgb(width: u32, height: u32, pixels: impl Iterator<Item = [u8; 3]>) -> Self {
        let rgba8 = pixels.flat_map(|[r, g, b]| [r, g, b, 255]).collect();
        Self {
            width,
            height,
            rgba8,
        }
    }

    /// Sets pixel (`x`, `y`) unless it lies outside the image.
    pub fn put(&mut self, x: i64, y: i64, rgb: [u8; 3]) {
        if x < 0 || y < 0 || x >= i64::from(self.width) || y >= i64::from(self.height) {
            return;
        }
        let i = ((y as usize) * self.width as usize + x as usize) * 4;
        self.rgba8[i..i + 3].copy_from_slice(&rgb);
    }
}

/// Exposure that maps the log-average luminance of the positive entries to middle grey.
pub fn auto_exposure(values: impl Iterator<Item = f32>) -> f32 {
    let (sum, n) = values
        .filter(|&l| l > 0.0)
        .fold((0.0f64, 0u64), |(s, n), l| (s + f64::from(l.log2()), n + 1));
    if n == 0 {
        return 1.0;
    }
    KEY / (sum / n as f64).exp2() as f32
}

/// Indirect light alone, tone-mapped with the frame's exposure.
fn indirect(v: &ViewInputs) -> Option<Image> {
    Some(Image::from_rgb(
        v.width,
        v.height,
        v.indirect?
            .iter()
            .map(|c| tonemap_cpu([c[0], c[1], c[2]], v.exposure_scale)),
    ))
}

/// A distinct colour for index `k`: hues a golden-ratio turn apart, so neighbouring indices
/// differ strongly.
pub fn index_colour(k: u32) -> [u8; 3] {
    let hue = (f64::from(k) * 0.618_033_988_749_895).fract() * 6.0;
    let x = (1.0 - (hue % 2.0 - 1.0).abs()) * 255.0;
    let (c, x) = (255u8, x as u8);
    match hue as u32 {
        0 => [c, x, 0],
        1 => [x, c, 0],
        2 => [0, c, x],
        3 => [0, x, c],
        4 => [x, 0, c],
        _ => [c, 0, x],
    }
}

/// The frame at a third of its brightness, and a projection of scene points onto it.
pub struct Overlay {
    pub image: Image,
    pub view_proj: glam::Mat4,
    pub eye: Vec3,
    /// Pixels per scene unit at clip-space depth w = 1.
    pub pixels_per_unit: f32,
}

impl Overlay {
    pub fn new(v: &ViewInputs) -> Self {
        Self {
            image: Image {
                width: v.width,
                height: v.height,
                // Alpha stays opaque.
                rgba8: v
                    .rgba8
                    .chunks_exact(4)
                    .flat_map(|p| [p[0] / 3, p[1] / 3, p[2] / 3, p[3]])
                    .collect(),
            },
            view_proj: camera_view_proj(v.camera, v.width as f32 / v.height as f32, v.bounds),
            eye: Vec3::from(v.camera.position),
            pixels_per_unit: 0.5 * v.height as f32
                / (0.5 * v.camera.fov_y_degrees.to_radians()).tan(),
        }
    }

    /// The pixel of `p`, if it lies in front of the camera.
    pub fn pixel(&self, p: Vec3) -> Option<(i64, i64)> {
        let clip = self.view_proj * p.extend(1.0);
        if clip.w <= 0.0 {
            return None;
        }
        let ndc = clip.xyz() / clip.w;
        Some((
            ((ndc.x * 0.5 + 0.5) * self.image.width as f32) as i64,
            ((0.5 - ndc.y * 0.5) * self.image.height as f32) as i64,
        ))
    }

    /// A square dot of side 2·`radius` + 1 at `p` unless `p` faces away (normal `n`).
    pub fn dot(&mut self, p: Vec3, n: Vec3, radius: i64, rgb: [u8; 3]) {
        if n.dot(self.eye - p) <= 0.0 {
            return;
        }
        if let Some((x, y)) = self.pixel(p) {
            for dy in -radius..=radius {
                for dx in -radius..=radius {
                    self.image.put(x + dx, y + dy, rgb);
                }
            }
        }
    }

    /// The dot radius that keeps `count` dots from covering more than a quarter of the
    /// image: 1 (3×3 pixels) or 0.
    pub fn radius_for(&self, count: usize) -> i64 {
        let pixels = u64::from(self.image.width) * u64::from(self.image.height);
        i64::from(count as u64 * 9 * 4 <= pixels)
    }
}

/// An `out`-sized image of `texels` (row-major, `size`), each output pixel the colour
/// `colour` gives its nearest texel (`None` past the end): for views made at the method's
/// resolution.
pub fn scaled_image<T>(
    out: (u32, u32),
    size: (u32, u32),
    texels: &[T],
    colour: impl Fn(Option<&T>) -> [u8; 3],
) -> Image {
    let texel = |x: u32, y: u32| {
        let sx = u64::from(x) * u64::from(size.0) / u64::from(out.0.max(1));
        let sy = u64::from(y) * u64::from(size.1) / u64::from(out.1.max(1));
        texels.get((sy * u64::from(size.0) + sx) as usize)
    };
    Image::from_rgb(
        out.0,
        out.1,
        (0..out.1)
            .flat_map(|y| (0..out.0).map(move |x| (x, y)))
            .map(|(x, y)| colour(texel(x, y))),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first 64 indices have distinct colours.
    #[test]
    fn index_colours_are_distinct() {
        let colours: std::collections::BTreeSet<[u8; 3]> = (0..64).map(index_colour).collect();
        assert_eq!(colours.len(), 64);
    }

    #[test]
    fn auto_exposure_maps_the_log_average_to_middle_grey() {
        let e = auto_exposure([0.5f32, 2.0, 0.0].into_iter());
        // Geometric mean of 0.5 and 2 is 1; zeros are ignored.
        assert!((e - KEY).abs() < 1e-6);
        assert_eq!(auto_exposure(std::iter::empty()), 1.0);
    }

    #[test]
    fn put_ignores_pixels_outside_the_image() {
        let mut image = Image::from_rgb(2, 2, [[0u8; 3]; 4].into_iter());
        image.put(-1, 0, [9; 3]);
        image.put(2, 1, [9; 3]);
        image.put(1, 1, [9; 3]);
        assert_eq!(image.rgba8.iter().filter(|&&c| c == 9).count(), 3);
    }
}
