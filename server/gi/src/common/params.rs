//! The parameters several methods read, each written once (see [`crate::gi::params`]); a
//! method lists the ones it reads in its own table.

use crate::gi::params::{Default, Param};
use lightcast_protocol::GiParams;

/// The reflective shadow map's side (the RSM-based methods). The software profile's
/// 112²: at 128² `lightskin`'s frame on the Cornell box (every texel a VAL lighting every
/// cache) was estimated at 2.08 s, over a CPU adapter's 2 s frame limit, so a newcomer's
/// one-shot of it was refused (issue 31); at 112² it is 1.7 s, and BRSM's frames at the
/// defaults take the same time within noise (1.0–1.2 s for `curl -d '{}'` on lavapipe).
pub const RSM_SIZE: Param = Param::integer(
    "rsm_size",
    1024,
    (16, crate::passes::rsm::MAX_RSM_SIZE),
    "RSM side per light face; every texel is a virtual light (a VAL or a VPL candidate)",
)
.limit(&super::limits::MAX_RSM_SIZE)
.software(Default::Int(112))
.unit("texels");

/// Largest Phong exponent accepted (a mirror-like lobe; beyond it the lobe is a single texel).
pub const MAX_GLOSSY_EXPONENT: f32 = 10_000.0;

/// Every frame's: the materials' lobe sharpness, in direct and indirect shading alike.
pub const GLOSSY_EXPONENT: Param = Param::optional_number(
    "glossy_exponent",
    (0.0, MAX_GLOSSY_EXPONENT as f64),
    "Phong exponent k (seed 004, eq. 3-4) for every material: the methods' Phong lobes take k \
     and the BRDF the roughness of the same sharpness (GGX alpha = sqrt(2/(4k+2))), in direct \
     and indirect shading alike; null keeps the materials' own",
)
.above_min();

/// The frame's glossy exponent override (`None`: the materials' own).
pub fn glossy_exponent(gi: &GiParams) -> Option<f32> {
    gi.get(GLOSSY_EXPONENT.name)
        .and_then(serde_json::Value::as_f64)
        .map(|k| k as f32)
}

/// The roughness [`glossy_exponent`] gives every material (`None`: their own).
pub fn roughness_override(gi: &GiParams) -> Option<f32> {
    glossy_exponent(gi).map(crate::scene::brdf::roughness_for_exponent)
}

/// The RSM-based methods': what a directional light's shadow map and RSM cover.
pub const LIGHT_FIT: Param = Param::choice(
    "light_fit",
    "scene",
    LightFit::NAMES,
    "What a directional light's shadow map and RSM cover: scene (the whole scene's bounding \
     sphere, one face, as the papers do) or view (what the camera sees of the scene and a 5 % \
     margin, in two cascades: a near face up to a quarter of the way to the farthest surface \
     in view and a far face over all in view, whose RSM leaves the near face's part to it; \
     the same texels, VPLs and VALs over less ground \
     where much of the scene is out of view, e.g. a city seen from its streets, at twice the \
     RSM texels; moves in whole texels as the camera does)",
);

/// How the light a surface receives straight from a light leaves it (the reference and the
/// RSM-based methods; see [`crate::gi::params::Senders`]).
pub const SENDERS: Param = Param::choice(
    "senders",
    "full",
    crate::gi::params::Senders::NAMES,
    "How the light a surface receives straight from a light (punctual or the sky) leaves it: \
     full (the whole BRDF) or diffuse (its diffuse lobe alone). The RSM-based methods: with \
     full an RSM texel also sends its glossy part, as the Phong lobe of LightSkin's eq. 4 \
     fitted to its material about the light's mirror direction (the sun's reflection off glass \
     or metal onto the street; beyond the papers, whose VALs and VPLs are diffuse: diffuse). \
     The reference: full is the truth; diffuse is the light transport of diffuse VALs, VPLs \
     or surfels, which comparisons also render (`compare_modelled`) to part the error of what \
     a method leaves out from the error in what it models; light from emissive surfaces and \
     light of later bounces still leave by the whole BRDF there",
);

/// See [`LIGHT_FIT`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LightFit {
    View,
    Scene,
}

impl LightFit {
    const NAMES: &'static [&'static str] = &["view", "scene"];
}

/// What the frame's directional lights cover: [`LightFit::Scene`] for a method without
/// `light_fit` in its table, whatever the request carries for other methods (`surfels` lights
/// every surfel of the scene through the shadow map; `none` and `reference` draw direct light
/// only).
pub fn light_fit(gi: &GiParams) -> LightFit {
    let reads = crate::gi::params::of(gi.method)
        .iter()
        .any(|p| p.name == LIGHT_FIT.name);
    match gi.get(LIGHT_FIT.name).and_then(serde_json::Value::as_str) {
        Some("view") if reads => LightFit::View,
        _ => LightFit::Scene,
    }
}

/// The renderer's, for the methods that approximate (`MethodEntry::downscales`). The software
/// profile's 2: a quarter of the pixels, about 2 GI frames a second in a viewer-sized stream
/// on lavapipe instead of 0.25 (`bench/first-minute.sh`).
pub const INDIRECT_DOWNSCALE: Param = Param::integer(
    "indirect_downscale",
    1,
    (1, crate::passes::indirect_resolution::MAX_DOWNSCALE),
    "Indirect light at 1/n of the output's width and height (n is 1, 2 or 4), brought back \
     with an edge-aware (joint bilateral) upsample; 1: full resolution",
)
.software(Default::Int(2));

/// The frame's indirect downscale (1 for a method that does not downscale, whatever it says).
pub fn indirect_downscale(gi: &GiParams) -> u32 {
    if crate::gi::entry(gi.method).1.downscales {
        INDIRECT_DOWNSCALE.u32(gi)
    } else {
        1
    }
}

/// Reflections after the visible surface (the multi-bounce methods).
pub const BOUNCES: Param = Param::integer(
    "bounces",
    1,
    (1, super::limits::BOUNCES_CAP),
    "Reflections after the visible surface (1: the single bounce seed 004 approximates); \
     progressive methods add one per frame while the light stays put, a render and a \
     session's still compute all",
)
.limit(&super::limits::MAX_BOUNCES);

/// Emissive surfaces as area lights (the methods that light from them list it).
pub const EMITTERS: Param = Param::boolean(
    "emitters",
    true,
    "Emissive surfaces light the scene as area lights besides the punctual lights (the \
     RSM-based methods: as VALs/VPLs of one more RSM face, sampled from the emissive triangles \
     by power); null (the default): on unless the light is the scene's stand-in for them (its \
     default light when it has no lights of its own), whose light would count twice",
)
.or_null();

/// Whether the frame's emissive surfaces light the scene: `null` is resolved by the service
/// from the scene (`default_light::emitters_for`); without a scene, on.
pub fn emitters(gi: &GiParams) -> bool {
    gi.get(EMITTERS.name)
        .and_then(serde_json::Value::as_bool)
        .unwrap_or(true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use lightcast_protocol::GiMethod;

    /// A request may carry other methods' parameters (a session keeps them across methods):
    /// `light_fit: view` fits the maps only for a method that reads it.
    #[test]
    fn only_methods_with_light_fit_fit_the_sun_to_the_view() {
        let with = |method| GiParams::new(GiMethod::new(method)).with(LIGHT_FIT.name, "view");
        assert_eq!(light_fit(&with("clustered")), LightFit::View);
        assert_eq!(light_fit(&with("brsm")), LightFit::View);
        assert_eq!(light_fit(&with("surfels")), LightFit::Scene);
        assert_eq!(light_fit(&with("reference")), LightFit::Scene);
        let default = GiParams::new(GiMethod::new("clustered"));
        assert_eq!(light_fit(&default), LightFit::Scene);
    }
}
