//! The debug views of `lightskin` and `brsm` (seed 004's Figures 2 and 6): the RSM's flux,
//! the importance map of eq. 10 and the VALs drawn from it (`brsm`), and the light caches in
//! the colour of their diffuse proxy light.

use super::cache_lighting::CacheLighting;
use super::caches::CacheSet;
use super::sampling::SamplingReadback;
use crate::gi::common::views::{auto_exposure, Image, Overlay, INDIRECT};
use crate::gi::views::{DebugView, ViewInputs};
use crate::passes::rsm::GlossySender;
use crate::passes::tonemap::{luminance, tonemap_cpu};
use glam::Vec3;
use lightcast_protocol::View;

pub static RSM_FLUX: DebugView = DebugView {
    name: View::new("rsm-flux"),
    summary: "The reflective shadow map's reflected flux, diffuse and glossy (all light faces \
              side by side), auto-exposed.",
    reads_indirect: false,
    draw: |v| Some(rsm_flux(v.debug()?)),
};

pub static IMPORTANCE: DebugView = DebugView {
    name: View::new("importance"),
    summary: "The VAL importance map of eq. 10 on a log scale: black is zero, white the \
              largest value, six decades below it dark grey.",
    reads_indirect: false,
    draw: |v| Some(importance(v.debug()?)),
};

pub static SELECTED_VALS: DebugView = DebugView {
    name: View::new("selected-vals"),
    summary: "The RSM flux darkened, with every VAL drawn from the importance (eq. 11–15) \
              in magenta.",
    reads_indirect: false,
    draw: |v| Some(selected_vals(v.debug()?)),
};

pub static CACHES: DebugView = DebugView {
    name: View::new("caches"),
    summary: "The frame darkened, with every light cache drawn in the colour of its diffuse \
              proxy light (seed 004's Figure 6 view).",
    reads_indirect: false,
    draw: |v| {
        let caches = v.scene_data::<CacheSet>()?;
        Some(caches_view(v, caches, v.debug::<Vec<CacheLighting>>()?))
    },
};

/// `lightskin`'s views.
pub const LIGHTSKIN_VIEWS: &[&DebugView] = &[&INDIRECT, &RSM_FLUX, &CACHES];
/// `brsm`'s: `lightskin`'s and its importance sampling's.
pub const BRSM_VIEWS: &[&DebugView] = &[&INDIRECT, &RSM_FLUX, &IMPORTANCE, &SELECTED_VALS, &CACHES];

/// The RSM's reflected flux, auto-exposed: the diffuse flux and the glossy lobe's, ρ_g·P·Φ_in
/// with P ≈ n·r (what a metal texel sends is its glossy lobe alone).
pub fn rsm_flux(s: &SamplingReadback) -> Image {
    let flux: Vec<[f32; 3]> = s
        .rsm_flux_area
        .iter()
        .zip(&s.rsm_normal)
        .zip(&s.rsm_glossy)
        .map(|((t, n), g)| {
            let g = GlossySender::decode(*g);
            let cos = Vec3::from_slice(&n[..3]).dot(Vec3::from(g.mirror)).max(0.0);
            (Vec3::from_slice(&t[..3]) + Vec3::from(g.weight) * cos).to_array()
        })
        .collect();
    let exposure = auto_exposure(flux.iter().map(|&t| luminance(t)));
    Image::from_rgb(
        s.rsm_width,
        s.rsm_height,
        flux.iter().map(|&t| tonemap_cpu(t, exposure)),
    )
}

/// The importance map on a log scale: black is zero, white the largest value, six decades
/// below it are dark grey.
pub fn importance(s: &SamplingReadback) -> Image {
    let max = s.importance.iter().copied().fold(0.0f32, f32::max);
    Image::from_rgb(
        s.rsm_width,
        s.rsm_height,
        s.importance.iter().map(|&v| {
            if v <= 0.0 || max <= 0.0 {
                return [0; 3];
            }
            let t = (1.0 + (v / max).log10() / 6.0).clamp(0.0, 1.0);
            let g = (40.0 + 215.0 * t) as u8;
            [g; 3]
        }),
    )
}

/// The RSM flux at a quarter of its brightness with every selected VAL's texel in magenta.
pub fn selected_vals(s: &SamplingReadback) -> Image {
    let mut image = rsm_flux(s);
    for px in image.rgba8.chunks_exact_mut(4) {
        for c in &mut px[..3] {
            *c /= 4;
        }
    }
    for v in s.vals.iter().filter(|v| v.weight > 0.0) {
        let (x, y) = (v.texel % s.rsm_width, v.texel / s.rsm_width);
        image.put(i64::from(x), i64::from(y), [255, 0, 255]);
    }
    image
}

/// The frame at a third of its brightness with every light cache facing the camera drawn as a
/// dot in the colour of its diffuse proxy light (caches behind geometry are drawn too). Dots
/// are 3×3 pixels unless that would cover more than a quarter of the image.
fn caches_view(v: &ViewInputs, caches: &CacheSet, lighting: &[CacheLighting]) -> Image {
    let mut overlay = Overlay::new(v);
    let exposure = auto_exposure(lighting.iter().map(|l| luminance(l.diffuse_flux)));
    let radius = overlay.radius_for(caches.caches.len());
    for (c, l) in caches.caches.iter().zip(lighting) {
        let colour = tonemap_cpu(l.diffuse_flux, exposure);
        overlay.dot(Vec3::from(c.position), Vec3::from(c.normal), radius, colour);
    }
    overlay.image
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::lightskin::{BRSM, LIGHTSKIN};
    use crate::gi::views::{check, drawn_by};

    /// Both methods draw the RSM and the caches; the importance and the drawn VALs are BRSM's.
    #[test]
    fn brsm_adds_the_importance_views_to_lightskins() {
        for v in LIGHTSKIN_VIEWS {
            assert!(check(v.name, LIGHTSKIN).is_ok() && check(v.name, BRSM).is_ok());
        }
        for v in [&IMPORTANCE, &SELECTED_VALS] {
            assert_eq!(drawn_by(v.name), [BRSM]);
            assert!(check(v.name, LIGHTSKIN).is_err());
        }
    }
}
