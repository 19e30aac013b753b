//! The debug views of `surfels` (seed 001's Figures 3 and 5): the surfels in the colour of
//! their radiosity, one cache's links as a cut of the hierarchy, and the caches' SH along each
//! pixel's normal.

use super::{links::NO_NODE, SurfelSet, SurfelView};
use crate::gi::common::views::{
    auto_exposure, index_colour, scaled_image, Image, Overlay, INDIRECT,
};
use crate::gi::views::{DebugView, ViewInputs};
use crate::passes::tonemap::{luminance, tonemap_cpu};
use glam::Vec3;
use lightcast_protocol::{Camera, View};

pub static SURFEL_RADIOSITY: DebugView = DebugView {
    name: View::new("surfels"),
    summary: "Every surfel facing the camera as a disc of its projected size in the colour of \
              its radiosity, on black.",
    reads_indirect: false,
    draw: |v| {
        let SurfelView::Radiosity(radiosity) = v.debug()? else {
            return None;
        };
        Some(surfel_radiosity(v, v.scene_data()?, radiosity))
    },
};

pub static SURFEL_LINKS: DebugView = DebugView {
    name: View::new("surfel-links"),
    summary: "The hierarchy cut of one cache's links: on black, the surfels under each linked \
              node in that node's colour (the others dark grey) and the cache as a white \
              cross; the cache is the usable one nearest the surface at the image's centre \
              (seed 001's Figure 3).",
    reads_indirect: false,
    draw: |v| Some(surfel_links(v, v.scene_data()?)),
};

pub static CACHE_SH: DebugView = DebugView {
    name: View::new("cache-sh"),
    summary: "The caches' SH radiance interpolated at each pixel's surface point and evaluated \
              along its normal, before any lobe (what the caches say arrives from straight \
              above the surface); where SH ringing makes a channel negative it shows as \
              missing.",
    reads_indirect: true,
    draw: |v| {
        let SurfelView::CacheSh {
            width,
            height,
            radiance,
        } = v.debug()?
        else {
            return None;
        };
        Some(cache_sh((v.width, v.height), *width, *height, radiance))
    },
};

/// `surfels`' views.
pub const VIEWS: &[&DebugView] = &[&INDIRECT, &SURFEL_RADIOSITY, &SURFEL_LINKS, &CACHE_SH];

/// Every surfel facing the camera as a disc of its area's projected size in the colour
/// `colour` gives its index (none: not drawn), on black, the farthest first so that nearer
/// surfels cover them (surfels behind geometry show where nothing nearer covers them).
fn splat_surfels(
    overlay: &mut Overlay,
    set: &SurfelSet,
    colour: impl Fn(usize) -> Option<[u8; 3]>,
) {
    overlay
        .image
        .rgba8
        .chunks_exact_mut(4)
        .for_each(|p| p[..3].fill(0));
    let radius = (set.surfel_area / std::f64::consts::PI).sqrt() as f32;
    let mut discs: Vec<(f32, usize)> = set
        .surfels
        .iter()
        .enumerate()
        .filter(|(_, s)| s.normal.dot(overlay.eye - s.position) > 0.0)
        .filter_map(|(k, s)| {
            let w = (overlay.view_proj * s.position.extend(1.0)).w;
            (w > 0.0).then_some((w, k))
        })
        .collect();
    discs.sort_by(|a, b| b.0.total_cmp(&a.0));
    for (w, k) in discs {
        let (Some(rgb), Some((x, y))) = (colour(k), overlay.pixel(set.surfels[k].position)) else {
            continue;
        };
        // At most 32 pixels across, so a surfel next to the camera does not fill the view.
        let r = (radius * overlay.pixels_per_unit / w).clamp(0.5, 16.0);
        let ri = r.ceil() as i64;
        for dy in -ri..=ri {
            for dx in -ri..=ri {
                if ((dx * dx + dy * dy) as f32) <= r * r {
                    overlay.image.put(x + dx, y + dy, rgb);
                }
            }
        }
    }
}

/// The surfels facing the camera as discs in the colour of their radiosity (auto-exposed) on
/// black: what the caches are lit from.
pub fn surfel_radiosity(v: &ViewInputs, set: &SurfelSet, radiosity: &[Vec3]) -> Image {
    let exposure = auto_exposure(radiosity.iter().map(|b| luminance(b.to_array())));
    let mut overlay = Overlay::new(v);
    splat_surfels(&mut overlay, set, |k| {
        radiosity
            .get(k)
            .map(|b| tonemap_cpu(b.to_array(), exposure))
    });
    overlay.image
}

/// The cache whose links [`surfel_links`] shows: the usable cache nearest the point half a
/// cache spacing above the surfel the camera's central ray meets first (surfels read their
/// caches from there), or, where the ray meets none, nearest the camera's target.
pub fn centre_cache(set: &SurfelSet, camera: &Camera) -> Option<usize> {
    let eye = Vec3::from(camera.position);
    let target = Vec3::from(camera.target);
    let dir = (target - eye).normalize_or_zero();
    // A surfel stands for a disc of its area; 1.5 × its radius closes the gaps between them.
    let radius = 1.5 * (set.surfel_area / std::f64::consts::PI).sqrt() as f32;
    let hit = set
        .surfels
        .iter()
        .filter_map(|s| {
            let facing = s.normal.dot(-dir);
            if facing <= 1e-4 {
                return None;
            }
            let t = s.normal.dot(s.position - eye) / -facing;
            let on_plane = eye + t * dir;
            (t > 0.0 && on_plane.distance(s.position) <= radius).then_some((t, s))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0));
    let point = hit.map_or(target, |(t, s)| {
        eye + t * dir + 0.5 * set.grid.spacing * s.normal
    });
    (0..set.grid.count())
        .filter(|&c| super::cpu::usable(set, c))
        .min_by(|&a, &b| {
            let d = |c: usize| set.grid.position(c).distance_squared(point);
            d(a).total_cmp(&d(b))
        })
}

/// The hierarchy cut of one cache's links (seed 001's Figure 3): the surfels under each
/// linked node as discs in that node's colour on black, the surfels under no link in dark
/// grey, and the cache ([`centre_cache`]) as a white cross.
pub fn surfel_links(v: &ViewInputs, set: &SurfelSet) -> Image {
    let mut overlay = Overlay::new(v);
    let Some(cache) = centre_cache(set, v.camera) else {
        splat_surfels(&mut overlay, set, |_| Some(UNLINKED));
        return overlay.image;
    };
    let per_cache = set.links.per_cache as usize;
    let mut colour = vec![UNLINKED; set.surfels.len()];
    let linked = set.links.nodes[cache * per_cache..(cache + 1) * per_cache]
        .iter()
        .filter(|&&n| n != NO_NODE);
    for (rank, &node) in linked.enumerate() {
        let first = set.tree.first_leaf[node as usize] as usize;
        let count = set.tree.leaf_count[node as usize] as usize;
        colour[first..first + count].fill(index_colour(rank as u32));
    }
    splat_surfels(&mut overlay, set, |k| colour.get(k).copied());
    if let Some((x, y)) = overlay.pixel(set.grid.position(cache)) {
        for d in -4..=4 {
            overlay.image.put(x + d, y, [255; 3]);
            overlay.image.put(x, y + d, [255; 3]);
        }
    }
    overlay.image
}

/// Surfels under none of the shown cache's links.
const UNLINKED: [u8; 3] = [48; 3];

/// The caches' SH radiance along each pixel's normal, auto-exposed; black where no geometry
/// is. `radiance` is `width` × `height` (the method's resolution, reduced by
/// `indirect_downscale`), shown at the frame's `out` size by nearest neighbour.
pub fn cache_sh(out: (u32, u32), width: u32, height: u32, radiance: &[[f32; 4]]) -> Image {
    let rgb = |c: &[f32; 4]| [c[0], c[1], c[2]];
    let exposure = auto_exposure(radiance.iter().map(|c| luminance(rgb(c))));
    scaled_image(out, (width, height), radiance, |texel| match texel {
        Some(c) if c[3] != 0.0 => tonemap_cpu(rgb(c), exposure),
        _ => [0; 3],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::surfels::SURFELS;
    use crate::gi::views::{check, reads_indirect};

    /// Only `surfels` draws its views; of them only `cache-sh` needs the indirect buffer read
    /// back.
    #[test]
    fn surfels_draw_their_views_and_only_cache_sh_reads_the_indirect_buffer() {
        for v in VIEWS {
            assert!(check(v.name, SURFELS).is_ok(), "{}", v.name);
        }
        for other in crate::gi::methods().filter(|&m| m != SURFELS) {
            for v in [&SURFEL_RADIOSITY, &SURFEL_LINKS, &CACHE_SH] {
                assert!(check(v.name, other).is_err(), "{} for {other}", v.name);
            }
        }
        assert!(reads_indirect(CACHE_SH.name) && !reads_indirect(SURFEL_RADIOSITY.name));
    }

    /// A half-resolution view is shown at the frame's size, each value over 2×2 pixels.
    #[test]
    fn the_cache_sh_view_fills_the_frame_from_a_reduced_resolution() {
        let radiance = [[1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0]];
        let image = cache_sh((4, 2), 2, 1, &radiance);
        assert_eq!((image.width, image.height), (4, 2));
        let at = |x: usize, y: usize| {
            let i = (y * 4 + x) * 4;
            [image.rgba8[i], image.rgba8[i + 1], image.rgba8[i + 2]]
        };
        for y in 0..2 {
            assert!(at(0, y)[0] > 0 && at(1, y)[0] > 0, "row {y}");
            assert_eq!(at(2, y), [0; 3], "no geometry");
            assert_eq!(at(3, y), [0; 3], "no geometry");
        }
    }
}
