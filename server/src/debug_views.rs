//! Debug images a researcher expects next to the final frame (the paper's Figures 2 and 6
//! views): indirect light alone, RSM flux, importance map, selected VALs, the light caches
//! and, for `clustered`, the VPLs coloured by VAL (seed 003's Figure 9, centre); for
//! `surfels` the surfels by radiosity, one cache's links as a cut of the hierarchy and the
//! caches' SH along the normal (seed 001's Figures 3 and 5).
//! They are built on the CPU from buffers read back after a frame.

use crate::gi::clustered::{ClusterView, LightShadowTexel, LightShadowView};
use crate::gi::lightskin::{
    cache_lighting::CacheLighting,
    caches::{CacheSet, LightCache},
    sampling::SamplingReadback,
};
use crate::gi::precompute::SceneData;
use crate::gi::surfels::{self, links::NO_NODE, SurfelSet, SurfelView};
use crate::gi::{lightskin::uses_light_caches, reference::luminance, GiMethod};
use crate::gpu::GpuError;
use crate::passes::{exposure::KEY, frame_uniforms::camera_view_proj, tonemap::tonemap_cpu};
use crate::renderer::Frame;
use crate::scene::Aabb;
use glam::{Vec3, Vec4Swizzles};
use lightcast_protocol::Camera;

pub use lightcast_protocol::View;

/// Why a debug view cannot be shown.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error("view {view} needs global illumination; use a GI method other than none")]
    NeedsGi { view: View },
    #[error("view {view} shows light-cache data; use GI method lightskin or brsm")]
    NeedsLightCaches { view: View },
    #[error("view {view} shows a BRSM stage; use GI method brsm")]
    NeedsBrsm { view: View },
    #[error("view {view} shows the VPL clusters; use GI method clustered")]
    NeedsClustered { view: View },
    #[error("view {view} shows the surfels' data; use GI method surfels")]
    NeedsSurfels { view: View },
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// Refuses a view the GI method does not produce, before anything is rendered.
pub fn check(view: View, method: GiMethod) -> Result<(), ViewError> {
    if view.needs_gi() && method == crate::gi::none::NONE {
        return Err(ViewError::NeedsGi { view });
    }
    if view.needs_clustered() {
        return if method == crate::gi::clustered::CLUSTERED {
            Ok(())
        } else {
            Err(ViewError::NeedsClustered { view })
        };
    }
    if view.needs_surfels() {
        return if method == crate::gi::surfels::SURFELS {
            Ok(())
        } else {
            Err(ViewError::NeedsSurfels { view })
        };
    }
    if view.needs_gi() && view != View::Indirect && !uses_light_caches(method) {
        return Err(ViewError::NeedsLightCaches { view });
    }
    if view.needs_brsm() && method != crate::gi::lightskin::BRSM {
        return Err(ViewError::NeedsBrsm { view });
    }
    Ok(())
}

/// The image of `view` for `frame`, rendered with `capture_hdr` for the indirect view and
/// with `debug_view` = `view` for the others; `bounds` are the scene's and `caches` its light
/// caches.
pub fn compose(
    view: View,
    frame: Frame,
    camera: &Camera,
    bounds: &Aabb,
    scene_data: Option<&SceneData>,
) -> Result<Image, ViewError> {
    let needs_gi = ViewError::NeedsGi { view };
    let debug = frame.debug.clone();
    Ok(match view {
        View::Final => Image {
            width: frame.width,
            height: frame.height,
            rgba8: frame.rgba8,
        },
        View::Indirect => indirect(&frame).ok_or(needs_gi)?,
        View::RsmFlux | View::Importance | View::SelectedVals => {
            let sampling = debug
                .as_ref()
                .and_then(|d| d.0.downcast_ref::<SamplingReadback>())
                .ok_or(needs_gi)?;
            match view {
                View::RsmFlux => rsm_flux(sampling),
                View::Importance => importance(sampling),
                _ => selected_vals(sampling),
            }
        }
        View::Caches => {
            let lighting = debug
                .as_ref()
                .and_then(|d| d.0.downcast_ref::<Vec<CacheLighting>>());
            let caches = scene_data.and_then(|d| d.downcast_ref::<CacheSet>());
            let (Some(lighting), Some(caches)) = (lighting, caches) else {
                return Err(needs_gi);
            };
            self::caches(&frame, camera, bounds, &caches.caches, lighting)
        }
        View::Clusters | View::Vpls => {
            let captured = debug
                .as_ref()
                .and_then(|d| d.0.downcast_ref::<ClusterView>())
                .ok_or(needs_gi)?;
            if view == View::Clusters {
                clusters(captured)
            } else {
                vpls(&frame, camera, bounds, captured)
            }
        }
        View::ValShadow => light_shadow(
            (frame.width, frame.height),
            debug
                .as_ref()
                .and_then(|d| d.0.downcast_ref::<LightShadowView>())
                .ok_or(needs_gi)?,
        ),
        View::Surfels | View::SurfelLinks | View::CacheSh => {
            let set = scene_data.and_then(|d| d.downcast_ref::<SurfelSet>());
            let captured = debug
                .as_ref()
                .and_then(|d| d.0.downcast_ref::<SurfelView>());
            match (view, set, captured) {
                (View::Surfels, Some(set), Some(SurfelView::Radiosity(radiosity))) => {
                    surfel_radiosity(&frame, camera, bounds, set, radiosity)
                }
                (View::SurfelLinks, Some(set), _) => surfel_links(&frame, camera, bounds, set),
                (
                    View::CacheSh,
                    _,
                    Some(SurfelView::CacheSh {
                        width,
                        height,
                        radiance,
                    }),
                ) => cache_sh((frame.width, frame.height), *width, *height, radiance),
                _ => return Err(needs_gi),
            }
        }
    })
}

/// An RGBA8 image.
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgba8: Vec<u8>,
}

impl Image {
    fn from_rgb(width: u32, height: u32, pixels: impl Iterator<Item = [u8; 3]>) -> Self {
        let rgba8 = pixels.flat_map(|[r, g, b]| [r, g, b, 255]).collect();
        Self {
            width,
            height,
            rgba8,
        }
    }

    fn put(&mut self, x: i64, y: i64, rgb: [u8; 3]) {
        if x < 0 || y < 0 || x >= i64::from(self.width) || y >= i64::from(self.height) {
            return;
        }
        let i = ((y as usize) * self.width as usize + x as usize) * 4;
        self.rgba8[i..i + 3].copy_from_slice(&rgb);
    }
}

/// Exposure that maps the log-average luminance of the positive entries to middle grey.
fn auto_exposure(values: impl Iterator<Item = f32>) -> f32 {
    let (sum, n) = values
        .filter(|&l| l > 0.0)
        .fold((0.0f64, 0u64), |(s, n), l| (s + f64::from(l.log2()), n + 1));
    if n == 0 {
        return 1.0;
    }
    KEY / (sum / n as f64).exp2() as f32
}

/// Indirect light alone, tone-mapped with the frame's exposure.
pub fn indirect(frame: &Frame) -> Option<Image> {
    let indirect = frame.indirect.as_ref()?;
    Some(Image::from_rgb(
        frame.width,
        frame.height,
        indirect
            .iter()
            .map(|c| tonemap_cpu([c[0], c[1], c[2]], frame.exposure_scale)),
    ))
}

/// The RSM's reflected flux, auto-exposed.
pub fn rsm_flux(s: &SamplingReadback) -> Image {
    let rgb = |t: &[f32; 4]| [t[0], t[1], t[2]];
    let exposure = auto_exposure(s.rsm_flux_area.iter().map(|t| luminance(rgb(t))));
    Image::from_rgb(
        s.rsm_width,
        s.rsm_height,
        s.rsm_flux_area
            .iter()
            .map(|t| tonemap_cpu(rgb(t), exposure)),
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
pub fn vpls(frame: &Frame, camera: &Camera, bounds: &Aabb, v: &ClusterView) -> Image {
    let mut overlay = Overlay::new(frame, camera, bounds);
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

/// The frame at a third of its brightness, and a projection of scene points onto it.
struct Overlay {
    image: Image,
    view_proj: glam::Mat4,
    eye: Vec3,
    /// Pixels per scene unit at clip-space depth w = 1.
    pixels_per_unit: f32,
}

impl Overlay {
    fn new(frame: &Frame, camera: &Camera, bounds: &Aabb) -> Self {
        Self {
            image: Image {
                width: frame.width,
                height: frame.height,
                // Alpha stays opaque.
                rgba8: frame
                    .rgba8
                    .chunks_exact(4)
                    .flat_map(|p| [p[0] / 3, p[1] / 3, p[2] / 3, p[3]])
                    .collect(),
            },
            view_proj: camera_view_proj(camera, frame.width as f32 / frame.height as f32, bounds),
            eye: Vec3::from(camera.position),
            pixels_per_unit: 0.5 * frame.height as f32
                / (0.5 * camera.fov_y_degrees.to_radians()).tan(),
        }
    }

    /// Every surfel facing the camera as a disc of its area's projected size in the colour
    /// `colour` gives its index (none: not drawn), on black, the farthest first so that nearer
    /// surfels cover them (surfels behind geometry show where nothing nearer covers them).
    fn splat_surfels(&mut self, set: &SurfelSet, colour: impl Fn(usize) -> Option<[u8; 3]>) {
        self.image
            .rgba8
            .chunks_exact_mut(4)
            .for_each(|p| p[..3].fill(0));
        let radius = (set.surfel_area / std::f64::consts::PI).sqrt() as f32;
        let mut discs: Vec<(f32, usize)> = set
            .surfels
            .iter()
            .enumerate()
            .filter(|(_, s)| s.normal.dot(self.eye - s.position) > 0.0)
            .filter_map(|(k, s)| {
                let w = (self.view_proj * s.position.extend(1.0)).w;
                (w > 0.0).then_some((w, k))
            })
            .collect();
        discs.sort_by(|a, b| b.0.total_cmp(&a.0));
        for (w, k) in discs {
            let (Some(rgb), Some((x, y))) = (colour(k), self.pixel(set.surfels[k].position)) else {
                continue;
            };
            // At most 32 pixels across, so a surfel next to the camera does not fill the view.
            let r = (radius * self.pixels_per_unit / w).clamp(0.5, 16.0);
            let ri = r.ceil() as i64;
            for dy in -ri..=ri {
                for dx in -ri..=ri {
                    if ((dx * dx + dy * dy) as f32) <= r * r {
                        self.image.put(x + dx, y + dy, rgb);
                    }
                }
            }
        }
    }

    /// The pixel of `p`, if it lies in front of the camera.
    fn pixel(&self, p: Vec3) -> Option<(i64, i64)> {
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
    fn dot(&mut self, p: Vec3, n: Vec3, radius: i64, rgb: [u8; 3]) {
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
    fn radius_for(&self, count: usize) -> i64 {
        let pixels = u64::from(self.image.width) * u64::from(self.image.height);
        i64::from(count as u64 * 9 * 4 <= pixels)
    }
}

/// The surfels facing the camera as discs in the colour of their radiosity (auto-exposed) on
/// black: what the caches are lit from.
pub fn surfel_radiosity(
    frame: &Frame,
    camera: &Camera,
    bounds: &Aabb,
    set: &SurfelSet,
    radiosity: &[Vec3],
) -> Image {
    let exposure = auto_exposure(radiosity.iter().map(|b| luminance(b.to_array())));
    let mut overlay = Overlay::new(frame, camera, bounds);
    overlay.splat_surfels(set, |k| {
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
        .filter(|&c| surfels::cpu::usable(set, c))
        .min_by(|&a, &b| {
            let d = |c: usize| set.grid.position(c).distance_squared(point);
            d(a).total_cmp(&d(b))
        })
}

/// The hierarchy cut of one cache's links (seed 001's Figure 3): the surfels under each
/// linked node as discs in that node's colour on black, the surfels under no link in dark
/// grey, and the cache ([`centre_cache`]) as a white cross.
pub fn surfel_links(frame: &Frame, camera: &Camera, bounds: &Aabb, set: &SurfelSet) -> Image {
    let mut overlay = Overlay::new(frame, camera, bounds);
    let Some(cache) = centre_cache(set, camera) else {
        overlay.splat_surfels(set, |_| Some(UNLINKED));
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
    overlay.splat_surfels(set, |k| colour.get(k).copied());
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

/// An `out`-sized image of `texels` (row-major, `size`), each output pixel the colour
/// `colour` gives its nearest texel (`None` past the end): for views made at the method's
/// resolution.
fn scaled_image<T>(
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

/// The frame at a third of its brightness with every light cache facing the camera drawn as a
/// dot in the colour of its diffuse proxy light (caches behind geometry are drawn too). Dots
/// are 3×3 pixels unless that would cover more than a quarter of the image.
pub fn caches(
    frame: &Frame,
    camera: &Camera,
    bounds: &Aabb,
    caches: &[LightCache],
    lighting: &[CacheLighting],
) -> Image {
    let mut overlay = Overlay::new(frame, camera, bounds);
    let exposure = auto_exposure(lighting.iter().map(|l| luminance(l.diffuse_flux)));
    let radius = overlay.radius_for(caches.len());
    for (c, l) in caches.iter().zip(lighting) {
        let colour = tonemap_cpu(l.diffuse_flux, exposure);
        overlay.dot(Vec3::from(c.position), Vec3::from(c.normal), radius, colour);
    }
    overlay.image
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each lit VPL is a dot of its VAL's colour at its texel; unlit ones are not drawn; the
    /// first 64 VALs have distinct colours.
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
        let colours: std::collections::BTreeSet<[u8; 3]> = (0..64).map(index_colour).collect();
        assert_eq!(colours.len(), 64);
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

    #[test]
    fn the_clusters_view_needs_clustered_and_clustered_has_no_light_caches() {
        assert!(check(View::Clusters, crate::gi::clustered::CLUSTERED).is_ok());
        assert!(check(View::Indirect, crate::gi::clustered::CLUSTERED).is_ok());
        assert!(matches!(
            check(View::Clusters, crate::gi::lightskin::BRSM),
            Err(ViewError::NeedsClustered { .. })
        ));
        assert!(matches!(
            check(View::Caches, crate::gi::clustered::CLUSTERED),
            Err(ViewError::NeedsLightCaches { .. })
        ));
    }

    #[test]
    fn the_surfel_views_need_surfels_and_surfels_has_no_light_caches() {
        for view in [View::Surfels, View::SurfelLinks, View::CacheSh] {
            assert!(check(view, crate::gi::surfels::SURFELS).is_ok());
            for other in [
                crate::gi::lightskin::BRSM,
                crate::gi::clustered::CLUSTERED,
                crate::gi::reference::REFERENCE,
            ] {
                assert!(matches!(
                    check(view, other),
                    Err(ViewError::NeedsSurfels { .. })
                ));
            }
        }
        assert!(check(View::Indirect, crate::gi::surfels::SURFELS).is_ok());
        assert!(matches!(
            check(View::Caches, crate::gi::surfels::SURFELS),
            Err(ViewError::NeedsLightCaches { .. })
        ));
        assert!(View::CacheSh.reads_indirect() && View::Indirect.reads_indirect());
        assert!(!View::Surfels.reads_indirect());
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
