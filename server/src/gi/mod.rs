//! Global illumination: LightSkin light caches fed by Bidirectional Reflective Shadow Maps
//! (seed paper 004). Per model, [`caches`] are precomputed once and kept by [`cache_store`];
//! per frame, [`sampling`] runs the BRSM stages (RSM, importance, cumulative sums, VAL
//! selection) and [`cache_buffers`] holds the caches and their proxy lights on the GPU. The
//! GPU passes themselves live in `crate::passes`; [`lightskin_cpu`] is their CPU reference.
//!
//! [`reference`] is the path tracer every method is measured against.

pub mod lightskin;
pub mod reference;

pub use lightcast_protocol::GiMethod;

/// Default α of [`GiSettings::defensive`]: the largest weight 1/(N·P) stays below 3.4·M/N
/// for M RSM texels and N VALs. Chosen by measurement (`bench --defensive`, lavapipe, RSM
/// 256², 8,192 VALs, 512 view samples, relative mean absolute difference to LightSkin): on the
/// procedural street α = 0 gave 48 %, 0.1 gave 22 %, 0.3 gave 8.8 %; on the Cornell box
/// 0.94 % and (α = 0.3) 0.58 %.
pub const DEFAULT_DEFENSIVE: f32 = 0.3;

/// Parameters of the GI methods.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct GiSettings {
    pub method: GiMethod,
    /// RSM side per light face, in texels.
    pub rsm_size: u32,
    /// N_VS: view samples for the importance estimate (BRSM).
    pub view_samples: u32,
    /// N_sVAL: VALs drawn from the importance distribution (BRSM).
    pub val_count: u32,
    /// Offset of the stratified VAL draws within their strata, in [0, 1).
    pub jitter: f32,
    /// Weight α of a uniform distribution mixed into the BRSM selection pdf (defensive
    /// importance sampling): bounds the weight of VALs the view samples barely see but
    /// caches do. 0 is the paper's plain importance sampling.
    pub defensive: f32,
    /// Give every RSM texel importance 1 (turns BRSM into plain stratified sampling; with one
    /// draw per texel it equals LightSkin).
    pub uniform_importance: bool,
    /// Dim proxy lights hidden behind other caches (the paper's double projection).
    pub occlusion: bool,
    /// Phong exponent k (eq. 3–4) for every material, in direct and indirect shading alike;
    /// `None` keeps the materials' own.
    pub glossy_exponent: Option<f32>,
}

impl From<&lightcast_protocol::GiParams> for GiSettings {
    /// A request's GI parameters (the light-cache ones are the scene's business, not the
    /// frame's).
    fn from(p: &lightcast_protocol::GiParams) -> Self {
        Self {
            method: p.method,
            rsm_size: p.rsm_size,
            view_samples: p.view_samples,
            val_count: p.val_count,
            jitter: 0.5,
            defensive: p.defensive,
            uniform_importance: false,
            occlusion: p.occlusion,
            glossy_exponent: p.glossy_exponent,
        }
    }
}

impl Default for GiSettings {
    /// The protocol's defaults, which are the paper's evaluation settings: 512 view samples
    /// and 8,192 VALs; a 1024² RSM.
    fn default() -> Self {
        (&lightcast_protocol::GiParams::default()).into()
    }
}

impl GiSettings {
    /// No indirect light.
    pub fn off() -> Self {
        Self {
            method: GiMethod::None,
            ..Self::default()
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_protocol_default_alpha_is_the_measured_one() {
        assert_eq!(
            super::GiSettings::default().defensive,
            super::DEFAULT_DEFENSIVE
        );
    }
}
