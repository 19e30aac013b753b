//! One-shot renders (`/v1/render`): the request, the optional comparison with the
//! reference, and the report.

use super::*;

/// Output of a one-shot render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ImageFormat {
    #[default]
    Png,
    Jpeg,
    /// Linear float32 RGBA of the final HDR radiance (before exposure), little-endian, rows top
    /// to bottom.
    RawFinal,
    /// Linear float32 RGBA of the indirect light alone; alpha is the share of what the
    /// pixel's surface reflects towards the camera that its specular lobe carries (−1 where
    /// no surface shows: see `Comparison::receivers`).
    RawIndirect,
}

impl ImageFormat {
    pub fn content_type(self) -> &'static str {
        match self {
            Self::Png => "image/png",
            Self::Jpeg => "image/jpeg",
            Self::RawFinal | Self::RawIndirect => "application/octet-stream",
        }
    }
}

/// Body of `POST /v1/render`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(default)]
pub struct RenderRequest {
    pub render: RenderParams,
    pub format: ImageFormat,
    /// JPEG quality 1–100 (default 90).
    pub quality: Option<u8>,
    /// Also render the same view with this method (`reference`: the path-traced truth) and
    /// report the errors of this render against it in the report's `comparison`. The
    /// comparison render is cached by its parameters, so repeating it costs one render.
    pub compare_to: Option<GiMethod>,
    /// Samples per pixel of a `reference` comparison render (default 256; at most the
    /// server's `max_spp`). Its bounces are `render.gi.bounces`; emissive surfaces light it
    /// only when the compared method lights from them (its parameters include `emitters`)
    /// with `render.gi.emitters` on, so both see the same light sources.
    pub compare_spp: Option<u32>,
    /// With `compare_to: reference`, also compare against a reference that models only the
    /// light transport the method does (its senders: `diffuse` for `surfels` and for the
    /// RSM-based methods with `render.gi.senders: diffuse`, whose surfels, VPLs or VALs
    /// reflect the light they receive by the diffuse lobe alone),
    /// reported as `comparison_modelled`: its error is the error in what the method models,
    /// the rest of `comparison`'s is what it leaves out. Costs a second reference render
    /// (cached like the first); ignored for a method that models the full transport.
    pub compare_modelled: bool,
}

/// A render's errors against another method's render of the same view (see
/// `RenderRequest::compare_to`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Comparison {
    pub against: GiMethod,
    /// How the reference reflects the light its surfaces receive straight from a light: `full`
    /// (the truth) or `diffuse` (the transport of methods with diffuse senders).
    #[serde(default)]
    pub senders: Senders,
    /// Samples per pixel of the reference (0 when `against` is not progressive).
    pub reference_samples: u32,
    /// The reference's own convergence: RMS standard error of pixel luminance over the mean.
    pub reference_relative_error: f32,
    /// Mean absolute error of the indirect buffer (linear radiance, per channel).
    pub indirect_mae: f64,
    /// Root-mean-square error of the indirect buffer.
    pub indirect_rmse: f64,
    /// `indirect_mae` over the reference's mean indirect radiance.
    pub indirect_mae_relative: f64,
    /// MAE of 8×8-pixel block means over the reference's mean (the reference's noise
    /// averages out; errors in where the light lands remain).
    pub indirect_block_mae_relative: f64,
    /// Signed difference of the means over the reference's mean (> 0: too bright).
    pub indirect_bias_relative: f64,
    /// PSNR in dB of the final images, both tone-mapped with the reference's exposure;
    /// `null` when they are identical.
    pub final_psnr_db: Option<f64>,
    /// Mean LDR-FLIP error of the same two final images (0: indistinguishable, 1: the
    /// largest perceived difference), at 67 pixels per degree.
    pub final_flip: f64,
    /// The indirect buffer's errors over the pixels of each kind of receiving surface, sorted
    /// by the share of what the surface reflects towards the camera that its specular lobe
    /// carries (below one half: diffuse). A method that places incoming light right but
    /// reflects it through a coarse model of a sharp lobe shows its error on `specular`.
    pub receivers: ReceiverSplit,
}

/// [`Comparison::receivers`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ReceiverSplit {
    /// Surfaces that reflect mostly by their diffuse lobe.
    pub diffuse: ReceiverErrors,
    /// Surfaces that reflect mostly by their specular lobe (metals, polished glass).
    pub specular: ReceiverErrors,
}

/// Errors over one kind of receiver (see [`Comparison::receivers`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ReceiverErrors {
    /// Share of the pixels that show a surface.
    pub pixel_share: f64,
    /// Share of the reference's indirect light (summed over the image) on these pixels.
    pub reference_share: f64,
    /// 8×8-block MAE over these pixels (each block's pixels of this kind) over their
    /// reference light. Times `reference_share` it is their part of the image's
    /// `indirect_block_mae_relative`; the two parts add up to at least it (within a block
    /// that holds both kinds their errors can cancel).
    pub indirect_block_mae_relative: f64,
    /// Signed difference over these pixels' reference light (> 0: too bright).
    pub indirect_bias_relative: f64,
}

/// The timing report of a one-shot render; sent in the `x-lightcast-report` header of the
/// image response.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct RenderReport {
    /// The server build (`lightcast-server` version and git revision).
    pub build: String,
    pub adapter: String,
    /// SHA-256 of the canonical JSON of the request after defaults were applied: equal hashes
    /// on the same build and adapter give identical pixels.
    pub request_hash: String,
    pub width: u32,
    pub height: u32,
    pub format: ImageFormat,
    pub stages: Vec<StageMs>,
    pub gpu_ms: f64,
    /// `gpu_timestamps` or `cpu_wall`.
    pub timing_source: String,
    pub encode_ms: f64,
    /// Time waiting for the render loop (queueing behind sessions).
    pub queue_ms: f64,
    pub exposure_scale: f32,
    /// The camera and lights actually used (after scene defaults); `light` is the first
    /// (absent in a frame without punctual lights: emissive surfaces or an environment alone).
    pub camera: Camera,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light: Option<Light>,
    pub lights: Vec<Light>,
    /// The environment used, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub environment: Option<Environment>,
    /// Samples per pixel of a progressive method (`reference`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples: Option<u32>,
    /// How noisy a progressive method's image still is: the root-mean-square standard error
    /// of the pixels' luminance over their mean luminance (0.05: ±5 %), as the viewer's
    /// "N spp, ±x %" shows it. It falls as 1/√samples.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_error: Option<f64>,
    /// Errors against `compare_to`'s render, when the request asked for one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub comparison: Option<Comparison>,
    /// Errors against the reference of the light transport the method models, when the
    /// request asked for it (`compare_modelled`) and it differs from the full one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub comparison_modelled: Option<Comparison>,
    /// What the request was estimated to cost before it ran (the comparison render included),
    /// in seconds of this server's adapter: the number checked against `max_request_seconds`
    /// (absent from offline renders, which have no such limit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimated_seconds: Option<f64>,
    /// How far `stages` can be trusted, when not fully: a CPU adapter's (lavapipe's) timestamp
    /// queries put the work of some stages into others, so single stages may read hundredths
    /// of a millisecond for seconds of work. The request's wall time is then the measure.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timing_note: Option<String>,
}

/// [`RenderReport::timing_note`] on a CPU adapter that times stages with its timestamps.
pub const CPU_TIMESTAMPS_NOTE: &str = "this CPU adapter's timestamps put the work of some \
    stages into others: single stage times under-report (the request's wall time does not; \
    `lightcast-server bench --stage-clock wall` times each stage by the clock)";
