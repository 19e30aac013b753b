//! The debug views of `clustered`: the VPLs coloured by the VAL they are clustered into (seed
//! 003's Figure 9, centre), the lit VPLs on the frame, and one light's visibility.

use super::{ClusterView, LightShadowTexel, LightShadowView};
use crate::gi::common::views::{
    auto_exposure, index_colour, scaled_image, Image, Overlay, INDIRECT,
};
use crate::gi::views::{DebugView, ViewInputs};
use crate::passes::tonemap::{luminance, tonemap_cpu};
use glam::Vec3;
use lightcast_protocol::View;

pub static CLUSTERS: DebugView = DebugView {
    name: View::new("clusters"),
    summary: "The RSM's VPLs, each in the colour of the VAL it is clustered into (seed 003's \
              Figure 9, centre).",
    reads_indirect: false,
    draw: |v| Some(clusters(v.debug()?)),
};

pub static VPLS: DebugView = DebugView {
    name: View::new("vpls"),
    summary: "The frame at a third of its brightness with every lit VPL as a dot at its \
              surface point in the colour of its diffuse flux (black on metal, which sends \
              light by its glossy lobe alone).",
    reads_indirect: false,
    draw: |v| Some(vpls(v, v.debug()?)),
};

pub static VAL_SHADOW: DebugView = DebugView {
    name: View::new("val-shadow"),
    summary: "The visibility of one light at every pixel's surface, white where it sees the \
              light and black in its shadow, dark blue where the light and the surface face \
              away from each other: the soft shadow of VAL `shadow_light` (`cssm`, seed 003's \
              Figure 9, left), the hard shadow of VPL `shadow_light` (`vpl_shadows`), white \
              everywhere with visibility off.",
    reads_indirect: false,
    draw: |v| Some(light_shadow((v.width, v.height), v.debug()?)),
};

/// `clustered`'s views.
pub const VIEWS: &[&DebugView] = &[&INDIRECT, &CLUSTERS, &VPLS, &VAL_SHADOW];

/// The RSM atlas in black with every lit VPL drawn at its texel in the colour of its VAL:
/// square dots about half the spacing of N VPLs in the atlas, so the clusters read as
/// patches on the surfaces the light sees.
pub fn clusters(v: &ClusterView) -> Image {
    let (w, h) = (v.rsm_width, v.rsm_height);
    let mut image = Image::from_rgb(w, h, std::iter::repeat_n([0; 3], (w * h) as usize));
    let spacing = (f64::from(w) * f64::from(h) / v.texels.len().max(1) as f64).sqrt();
    let side = ((spacing / 2.0) as i64).clamp(1, 8);
    for (&texel, &val) in v.texels.iter().zip(&v.mapping) {
        let Some(val) = val else { continue };
        let (x, y) = (i64::from(texel % w), i64::from(texel / w));
        for dy in 0..side {
            for dx in 0..side {
                image.put(x + dx - side / 2, y + dy - side / 2, index_colour(val));
            }
        }
    }
    image
}

/// The frame at a third of its brightness with every lit VPL as a dot at its surface point in
/// the colour of its flux (auto-exposed over the VPLs): where the light's first bounce starts.
fn vpls(inputs: &ViewInputs, v: &ClusterView) -> Image {
    let mut overlay = Overlay::new(inputs);
    let lit: Vec<usize> = (0..v.mapping.len())
        .filter(|&i| v.mapping[i].is_some())
        .collect();
    let exposure = auto_exposure(lit.iter().map(|&i| luminance(v.flux[i])));
    let radius = overlay.radius_for(lit.len());
    for i in lit {
        overlay.dot(
            Vec3::from(v.positions[i]),
            Vec3::from(v.normals[i]),
            radius,
            tonemap_cpu(v.flux[i], exposure),
        );
    }
    overlay.image
}

/// Colour of `val-shadow` pixels the light cannot reach whatever the visibility.
pub const FACING_AWAY: [u8; 3] = [0, 0, 96];

/// One light's visibility as grey (white: sees the light), dark blue where the light and the
/// surface face away from each other, black where no geometry is; scaled from the method's
/// resolution to `out`.
pub fn light_shadow(out: (u32, u32), v: &LightShadowView) -> Image {
    scaled_image(out, (v.width, v.height), &v.texels, |texel| match texel {
        Some(LightShadowTexel::Visibility(v)) => [(v.clamp(0.0, 1.0) * 255.0).round() as u8; 3],
        Some(LightShadowTexel::FacingAway) => FACING_AWAY,
        Some(LightShadowTexel::Empty) | None => [0; 3],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::views::{check, ViewError};

    #[test]
    fn clustered_draws_its_views_and_not_the_light_caches() {
        let clustered = crate::gi::clustered::CLUSTERED;
        for v in VIEWS {
            assert!(check(v.name, clustered).unwrap().is_some(), "{}", v.name);
        }
        let err = check(CLUSTERS.name, crate::gi::lightskin::BRSM).unwrap_err();
        assert_eq!(
            err.to_string(),
            "view clusters is drawn by GI method clustered, not by brsm"
        );
        assert!(matches!(
            check(crate::gi::lightskin::views::CACHES.name, clustered),
            Err(ViewError::NotDrawn { .. })
        ));
    }

    /// Each lit VPL is a dot of its VAL's colour at its texel; unlit ones are not drawn.
    #[test]
    fn clusters_view_colours_vpls_by_their_val() {
        let view = ClusterView {
            rsm_width: 16,
            rsm_height: 8,
            texels: vec![3, 7 * 16 + 2, 5 * 16 + 12, 7 * 16 + 15],
            mapping: vec![Some(0), Some(5), None, Some(5)],
            positions: vec![[0.0; 3]; 4],
            normals: vec![[0.0, 1.0, 0.0]; 4],
            flux: vec![[1.0; 3]; 4],
        };
        let image = clusters(&view);
        assert_eq!((image.width, image.height), (16, 8));
        let at = |texel: u32| {
            let i = texel as usize * 4;
            [image.rgba8[i], image.rgba8[i + 1], image.rgba8[i + 2]]
        };
        assert_eq!(at(3), index_colour(0));
        assert_eq!(at(7 * 16 + 2), index_colour(5));
        assert_eq!(at(7 * 16 + 15), index_colour(5));
        assert_eq!(at(5 * 16 + 12), [0; 3], "an unlit VPL is not drawn");
    }

    /// Visibility is grey, facing-away pixels dark blue, empty ones black; a 2×1 view scaled
    /// to 4×2 repeats each texel.
    #[test]
    fn the_light_shadow_view_shows_visibility_as_grey() {
        let view = LightShadowView {
            width: 2,
            height: 1,
            texels: vec![
                LightShadowTexel::Visibility(0.5),
                LightShadowTexel::FacingAway,
            ],
        };
        let image = light_shadow((4, 2), &view);
        let at = |x: usize, y: usize| {
            let i = (y * 4 + x) * 4;
            [image.rgba8[i], image.rgba8[i + 1], image.rgba8[i + 2]]
        };
        assert_eq!(at(0, 0), [128; 3]);
        assert_eq!(at(1, 1), [128; 3]);
        assert_eq!(at(2, 0), FACING_AWAY);
        assert_eq!(at(3, 1), FACING_AWAY);
        let empty = LightShadowView {
            width: 1,
            height: 1,
            texels: vec![LightShadowTexel::Empty],
        };
        assert_eq!(light_shadow((1, 1), &empty).rgba8[..3], [0, 0, 0]);
    }
}
