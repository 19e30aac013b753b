//! The debug view of `rsm_gather`: which RSM texels one pixel gathers.

use super::pattern::{sample_texels, GatherSample};
use crate::gi::common::views::{auto_exposure, Image, INDIRECT};
use crate::gi::views::DebugView;
use crate::passes::tonemap::{luminance, tonemap_cpu};
use glam::Vec2;
use lightcast_protocol::View;

pub static GATHER_SAMPLES: DebugView = DebugView {
    name: View::new("gather-samples"),
    summary: "The RSM's diffuse flux (all light faces side by side) at a quarter of its \
              brightness, with the texels the pixel at the image's centre gathers in magenta \
              (the paper's sampling pattern around the texel the pixel projects to).",
    reads_indirect: false,
    draw: |v| Some(gather_samples(v.debug()?)),
};

/// `rsm_gather`'s views.
pub const VIEWS: &[&DebugView] = &[&INDIRECT, &GATHER_SAMPLES];

/// What the `gather-samples` view shows of a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct GatherView {
    /// Side of one face, and the faces side by side.
    pub rsm_size: u32,
    pub faces: u32,
    /// The RSM atlas's flux (rgb) and disk area, row-major.
    pub flux_area: Vec<[f32; 4]>,
    /// The centre pixel's face and texel coordinates in it; `None` where it shows no surface.
    pub probe: Option<(usize, Vec2)>,
    pub samples: Vec<GatherSample>,
    /// r_max in texels.
    pub radius: f32,
}

/// The RSM flux auto-exposed and darkened to a quarter, with every texel the probe pixel
/// gathers in magenta.
pub fn gather_samples(g: &GatherView) -> Image {
    let rgb = |t: &[f32; 4]| [t[0], t[1], t[2]];
    let exposure = auto_exposure(g.flux_area.iter().map(|t| luminance(rgb(t))));
    let width = g.rsm_size * g.faces;
    let mut image = Image::from_rgb(
        width,
        g.rsm_size,
        g.flux_area
            .iter()
            .map(|t| tonemap_cpu(rgb(t), exposure).map(|c| c / 4)),
    );
    if let Some((face, centre)) = g.probe {
        for (texel, _) in sample_texels(&g.samples, g.rsm_size, g.faces, face, centre, g.radius) {
            let (x, y) = (texel as u32 % width, texel as u32 / width);
            image.put(i64::from(x), i64::from(y), [255, 0, 255]);
        }
    }
    image
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::views::check;

    #[test]
    fn rsm_gather_draws_its_views() {
        for v in VIEWS {
            assert!(
                check(v.name, super::super::RSM_GATHER).unwrap().is_some(),
                "{}",
                v.name
            );
        }
    }

    /// The gathered texels are magenta in the probe's face; the rest is the darkened flux.
    #[test]
    fn gathered_texels_are_marked_in_the_probes_face() {
        let samples = super::super::pattern::pattern(16);
        let view = GatherView {
            rsm_size: 8,
            faces: 2,
            flux_area: vec![[1.0, 1.0, 1.0, 1.0]; 16 * 8],
            probe: Some((1, Vec2::splat(4.0))),
            samples,
            radius: 3.0,
        };
        let image = gather_samples(&view);
        assert_eq!((image.width, image.height), (16, 8));
        let magenta: Vec<(u32, u32)> = (0..16 * 8)
            .filter(|i| image.rgba8[*i as usize * 4..][..3] == [255, 0, 255])
            .map(|i| (i % 16, i / 16))
            .collect();
        assert!(magenta.len() > 4, "{magenta:?}");
        assert!(
            magenta.iter().all(|&(x, _)| (8..16).contains(&x)),
            "{magenta:?}"
        );
        assert!(image.rgba8[..3].iter().all(|&c| c < 255 / 4 + 1));
        let none = GatherView {
            probe: None,
            ..view
        };
        assert!(!gather_samples(&none)
            .rgba8
            .chunks(4)
            .any(|p| p[..3] == [255, 0, 255]));
    }
}
