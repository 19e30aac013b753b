//! Quality of an image against the truth: error statistics of a GI method's indirect buffer
//! against the path-traced reference's (`bench`, `render --compare-to`, `POST /v1/render`
//! with `compare_to`) and PSNR and FLIP of tone-mapped frames.

use crate::passes::tonemap::tonemap_cpu;
use crate::renderer::{Frame, FrameProgress};
use lightcast_protocol::{Comparison, GiMethod, ReceiverErrors, ReceiverSplit};

/// Errors of an indirect buffer against the reference's, per channel over all pixels.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ErrorStats {
    /// Mean absolute error.
    pub mae: f64,
    /// Root-mean-square error.
    pub rmse: f64,
    /// `mae` divided by the reference's mean.
    pub mae_relative: f64,
    /// MAE of the means of 8×8-pixel blocks over the reference's mean: the reference's noise
    /// averages out over a block while errors in the light's distribution remain.
    pub block_mae_relative: f64,
    /// Signed difference of the image means over the reference's mean (too bright > 0).
    pub bias_relative: f64,
}

/// Side of the pixel blocks of [`ErrorStats::block_mae_relative`].
const BLOCK: usize = 8;

/// Errors of `other` against `truth`, both `width` pixels wide (RGB channels).
pub fn errors(truth: &[[f32; 3]], other: &[[f32; 4]], width: usize) -> ErrorStats {
    errors_where(truth, other, width, |_| true)
}

/// [`errors`] over the pixels `keep` accepts (by index), relative to their own reference
/// light; a block's error is that of its kept pixels.
fn errors_where(
    truth: &[[f32; 3]],
    other: &[[f32; 4]],
    width: usize,
    keep: impl Fn(usize) -> bool,
) -> ErrorStats {
    let (mut abs, mut sq, mut sum, mut other_sum) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let height = truth.len() / width.max(1);
    let (bw, bh) = (width.div_ceil(BLOCK), height.div_ceil(BLOCK));
    let mut blocks = vec![[0.0f64; 3]; bw * bh];
    let mut kept = 0usize;
    for (i, (a, b)) in truth.iter().zip(other).enumerate() {
        if !keep(i) {
            continue;
        }
        kept += 1;
        let block = &mut blocks[(i / width / BLOCK) * bw + (i % width) / BLOCK];
        for k in 0..3 {
            let d = f64::from(a[k] - b[k]);
            abs += d.abs();
            sq += d * d;
            sum += f64::from(a[k]);
            other_sum += f64::from(b[k]);
            block[k] += d;
        }
    }
    let n = (kept * 3).max(1) as f64;
    let relative = |v: f64| if sum > 0.0 { v / sum } else { 0.0 };
    // Block sums of differences; their absolute values summed over the image's sum is the
    // MAE of block means over the mean.
    let block_abs: f64 = blocks.iter().flatten().map(|d| d.abs()).sum();
    ErrorStats {
        mae: abs / n,
        rmse: (sq / n).sqrt(),
        mae_relative: relative(abs),
        block_mae_relative: relative(block_abs),
        bias_relative: relative(other_sum - sum),
    }
}

/// A pixel's specular share at or above which it counts as a specular receiver.
const SPECULAR_RECEIVER: f32 = 0.5;

/// [`errors`] split by receiver: `other`'s alpha is each pixel's specular share seen from the
/// camera, negative where no surface shows (`shaders/direct_light.wgsl`).
pub fn receiver_errors(truth: &[[f32; 3]], other: &[[f32; 4]], width: usize) -> ReceiverSplit {
    let covered = other.iter().filter(|p| p[3] >= 0.0).count().max(1) as f64;
    let total: f64 = truth.iter().flatten().map(|&c| f64::from(c)).sum();
    let kind = |specular: bool| {
        let keep = |i: usize| {
            let share = other[i][3];
            share >= 0.0 && (share >= SPECULAR_RECEIVER) == specular
        };
        let e = errors_where(truth, other, width, keep);
        let light: f64 = (0..truth.len().min(other.len()))
            .filter(|&i| keep(i))
            .flat_map(|i| truth[i])
            .fold(0.0, |s, c| s + f64::from(c));
        ReceiverErrors {
            pixel_share: (0..other.len()).filter(|&i| keep(i)).count() as f64 / covered,
            reference_share: if total > 0.0 { light / total } else { 0.0 },
            indirect_block_mae_relative: e.block_mae_relative,
            indirect_bias_relative: e.bias_relative,
        }
    };
    ReceiverSplit {
        diffuse: kind(false),
        specular: kind(true),
    }
}

/// Peak signal-to-noise ratio in dB of two RGB8 images (infinite when equal).
pub fn psnr(a: &[[u8; 3]], b: &[[u8; 3]]) -> f64 {
    let n = (a.len() * 3).max(1) as f64;
    let sq: f64 = a
        .iter()
        .zip(b)
        .flat_map(|(x, y)| (0..3).map(move |k| f64::from(x[k]) - f64::from(y[k])))
        .map(|d| d * d)
        .sum();
    if sq == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0 * 255.0 / (sq / n)).log10()
    }
}

/// Errors of a frame's tone-mapped final image against the truth.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct FinalErrors {
    /// PSNR in dB; `None` when the images are identical.
    pub psnr_db: Option<f64>,
    /// Mean of the LDR-FLIP error map (0: indistinguishable, 1: the largest perceived
    /// difference), at FLIP's default 67 pixels per degree (a 0.7 m distant 24" monitor).
    pub flip_mean: f64,
}

/// A frame's final image against the same frame with the reference's indirect light in place
/// of its own, both tone-mapped with `exposure`: exact, because direct light and emission come
/// from stages every method shares. `width` is the frame's width in pixels.
pub fn final_errors(
    hdr: &[[f32; 4]],
    indirect: &[[f32; 4]],
    truth_indirect: &[[f32; 3]],
    exposure: f32,
    width: u32,
) -> FinalErrors {
    let (mut own, mut truth) = (Vec::with_capacity(hdr.len()), Vec::with_capacity(hdr.len()));
    for ((h, i), t) in hdr.iter().zip(indirect).zip(truth_indirect) {
        own.push(tonemap_cpu([h[0], h[1], h[2]], exposure));
        let swapped = [0, 1, 2].map(|k| (h[k] - i[k] + t[k]).max(0.0));
        truth.push(tonemap_cpu(swapped, exposure));
    }
    FinalErrors {
        psnr_db: Some(psnr(&own, &truth)).filter(|p| p.is_finite()),
        flip_mean: flip_mean(&truth, &own, width),
    }
}

/// Mean LDR-FLIP error of `test` against `reference`, sRGB images `width` pixels wide.
/// FLIP (Andersson et al. 2020) models what a viewer notices (contrast sensitivity, edges,
/// colour), which PSNR does not; NVIDIA's implementation is used through `nv-flip` rather
/// than a port, so the numbers match the published tool.
pub fn flip_mean(reference: &[[u8; 3]], test: &[[u8; 3]], width: u32) -> f64 {
    let height = reference.len() / width.max(1) as usize;
    if width == 0 || height == 0 || reference.len() != test.len() {
        return 0.0;
    }
    let image = |pixels: &[[u8; 3]]| {
        nv_flip::FlipImageRgb8::with_data(width, height as u32, pixels.as_flattened())
    };
    let map = nv_flip::flip(
        image(reference),
        image(test),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    f64::from(nv_flip::FlipPool::from_image(&map).mean())
}

/// Why two frames cannot be compared.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    #[error("the frames differ in size ({0}×{1} vs {2}×{3})")]
    Size(u32, u32, u32, u32),
    #[error("frames to compare must be rendered with capture_hdr")]
    NotCaptured,
}

/// What a comparison keeps of the frame it compares with: its indirect light, exposure and
/// convergence (16 bytes per pixel; the rest of the frame is the same shared stages).
#[derive(Clone, Debug)]
pub struct Truth {
    pub width: u32,
    pub height: u32,
    pub indirect: Vec<[f32; 3]>,
    pub exposure_scale: f32,
    pub progress: Option<FrameProgress>,
}

impl Truth {
    /// Keeps what comparisons need of `frame` (rendered with `capture_hdr`).
    pub fn from_frame(frame: Frame) -> Result<Self, CompareError> {
        let indirect = frame.indirect.ok_or(CompareError::NotCaptured)?;
        Ok(Self {
            width: frame.width,
            height: frame.height,
            indirect: indirect.iter().map(|p| [p[0], p[1], p[2]]).collect(),
            exposure_scale: frame.exposure_scale,
            progress: frame.progress,
        })
    }

    /// Bytes held (for cache budgets).
    pub fn bytes(&self) -> usize {
        self.indirect.len() * std::mem::size_of::<[f32; 3]>()
    }
}

/// `frame` (of any GI method) against `truth` (the same view rendered by `against`, its senders
/// reflecting direct light as `senders` says): errors
/// of the indirect buffers, and PSNR of the final image against the same frame with the
/// truth's indirect light (PSNR and FLIP), tone-mapped with the truth's exposure (so automatic exposure does
/// not count as error).
pub fn compare(
    frame: &Frame,
    truth: &Truth,
    against: GiMethod,
    senders: lightcast_protocol::Senders,
) -> Result<Comparison, CompareError> {
    if (frame.width, frame.height) != (truth.width, truth.height) {
        return Err(CompareError::Size(
            frame.width,
            frame.height,
            truth.width,
            truth.height,
        ));
    }
    let (Some(indirect), Some(hdr)) = (&frame.indirect, &frame.hdr) else {
        return Err(CompareError::NotCaptured);
    };
    let e = errors(&truth.indirect, indirect, frame.width as usize);
    let finals = final_errors(
        hdr,
        indirect,
        &truth.indirect,
        truth.exposure_scale,
        frame.width,
    );
    let progress = truth.progress;
    Ok(Comparison {
        against,
        senders,
        reference_samples: progress.map_or(0, |p| p.samples),
        reference_relative_error: progress.map_or(0.0, |p| p.relative_standard_error),
        indirect_mae: e.mae,
        indirect_rmse: e.rmse,
        indirect_mae_relative: e.mae_relative,
        indirect_block_mae_relative: e.block_mae_relative,
        indirect_bias_relative: e.bias_relative,
        final_psnr_db: finals.psnr_db,
        final_flip: finals.flip_mean,
        receivers: receiver_errors(&truth.indirect, indirect, frame.width as usize),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_against_the_reference() {
        // Two pixels in one block: +1 in red on the first, −1 in blue on the second... and a
        // third pixel in the next block exactly right.
        let truth = [[1.0, 2.0, 3.0], [0.0, 0.0, 2.0], [1.0; 3], [1.0; 3]];
        let other = [
            [2.0, 2.0, 3.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
            [1.0, 1.0, 1.0, 1.0],
            [1.0, 1.0, 1.0, 1.0],
        ];
        let e = errors(&truth, &other, 2);
        assert!((e.mae - 2.0 / 12.0).abs() < 1e-12);
        assert!((e.rmse - (2.0f64 / 12.0).sqrt()).abs() < 1e-12);
        assert!((e.mae_relative - 2.0 / 14.0).abs() < 1e-12);
        // All four pixels share one 8×8 block: red +1 and blue −1 do not cancel (per channel).
        assert!((e.block_mae_relative - 2.0 / 14.0).abs() < 1e-12);
        assert!(e.bias_relative.abs() < 1e-12);
    }

    #[test]
    fn receivers_split_by_specular_share() {
        // 16×8 pixels, two 8×8 blocks: the left block diffuse (share 0.1) and 25 % too bright,
        // the right block specular (share 0.9) and half as bright, holding three times the
        // light; one uncovered pixel (share −1) on the right, where both are dark.
        let width = 16;
        let mut truth = vec![[1.0f32; 3]; 128];
        let mut other = vec![[0.0f32; 4]; 128];
        for i in 0..128 {
            let left = i % width < 8;
            truth[i] = [if left { 1.0 } else { 3.0 }; 3];
            let c = if left { 1.25 } else { 1.5 };
            other[i] = [c, c, c, if left { 0.1 } else { 0.9 }];
        }
        truth[15] = [0.0; 3];
        other[15] = [0.0, 0.0, 0.0, -1.0];
        let split = receiver_errors(&truth, &other, width);
        let (d, s) = (split.diffuse, split.specular);
        assert!((d.pixel_share - 64.0 / 127.0).abs() < 1e-12, "{d:?}");
        assert!((s.pixel_share - 63.0 / 127.0).abs() < 1e-12, "{s:?}");
        let total = 64.0 + 63.0 * 3.0;
        assert!((d.reference_share - 64.0 / total).abs() < 1e-12);
        assert!((s.reference_share - 189.0 / total).abs() < 1e-12);
        assert!((d.indirect_bias_relative - 0.25).abs() < 1e-12);
        assert!((d.indirect_block_mae_relative - 0.25).abs() < 1e-12);
        assert!((s.indirect_bias_relative + 0.5).abs() < 1e-12);
        assert!((s.indirect_block_mae_relative - 0.5).abs() < 1e-12);
        // The two parts add up to the whole image's block error (no block mixes them here).
        let whole = errors(&truth, &other, width).block_mae_relative;
        let parts = d.indirect_block_mae_relative * d.reference_share
            + s.indirect_block_mae_relative * s.reference_share;
        assert!((whole - parts).abs() < 1e-12, "{whole} vs {parts}");
    }

    #[test]
    fn final_errors_swap_in_the_reference_indirect_light() {
        let hdr = [[0.3, 0.2, 0.1, 1.0], [0.5, 0.5, 0.5, 1.0]];
        let indirect = [[0.1, 0.1, 0.0, 1.0], [0.2, 0.2, 0.2, 1.0]];
        let same = indirect.map(|p| [p[0], p[1], p[2]]);
        let identical = final_errors(&hdr, &indirect, &same, 1.0, 2);
        assert_eq!(identical.psnr_db, None);
        assert_eq!(identical.flip_mean, 0.0);
        let close = same.map(|p| p.map(|c| c * 1.1));
        let far = same.map(|p| p.map(|c| c * 2.0));
        let (near, away) = (
            final_errors(&hdr, &indirect, &close, 1.0, 2),
            final_errors(&hdr, &indirect, &far, 1.0, 2),
        );
        let (near_db, away_db) = (
            near.psnr_db.expect("differs"),
            away.psnr_db.expect("differs"),
        );
        assert!(near_db > away_db && away_db > 0.0, "{near_db} vs {away_db}");
        assert!(
            0.0 < near.flip_mean && near.flip_mean < away.flip_mean && away.flip_mean < 1.0,
            "{near:?} vs {away:?}"
        );
        // The swapped image itself: hdr − indirect + truth, tone-mapped alike.
        let own: Vec<[u8; 3]> = hdr
            .iter()
            .map(|h| tonemap_cpu([h[0], h[1], h[2]], 1.0))
            .collect();
        let truth: Vec<[u8; 3]> = hdr
            .iter()
            .zip(&indirect)
            .zip(&far)
            .map(|((h, i), t)| tonemap_cpu([0, 1, 2].map(|k| h[k] - i[k] + t[k]), 1.0))
            .collect();
        assert_eq!(Some(psnr(&own, &truth)), away.psnr_db);
        assert_eq!(flip_mean(&truth, &own, 2), away.flip_mean);
    }

    /// FLIP is perceptual where PSNR is not: a one-pixel checkerboard of ±12 is masked by
    /// the eye's falloff in contrast sensitivity at high frequencies, while the same ±12 as
    /// two halves (one edge across a 64-pixel image) is plainly visible. Both have the same
    /// squared error, so the same PSNR.
    #[test]
    fn flip_sees_what_a_viewer_sees() {
        let (w, h) = (64usize, 64usize);
        let grey = vec![[128u8; 3]; w * h];
        let shade = |up: bool| [if up { 140u8 } else { 116 }; 3];
        let checker: Vec<[u8; 3]> = (0..w * h)
            .map(|i| shade((i % w + i / w) % 2 == 0))
            .collect();
        let halves: Vec<[u8; 3]> = (0..w * h).map(|i| shade(i % w < w / 2)).collect();
        assert_eq!(psnr(&grey, &checker), psnr(&grey, &halves));
        let (flip_checker, flip_halves) = (
            flip_mean(&grey, &checker, w as u32),
            flip_mean(&grey, &halves, w as u32),
        );
        assert!(
            flip_checker < 0.5 * flip_halves,
            "checker {flip_checker} vs halves {flip_halves}"
        );
        // The extremes: identical images and black against white.
        assert_eq!(flip_mean(&grey, &grey, w as u32), 0.0);
        let (black, white) = (vec![[0u8; 3]; w * h], vec![[255u8; 3]; w * h]);
        assert!(flip_mean(&black, &white, w as u32) > 0.9);
    }

    #[test]
    fn psnr_of_a_known_difference() {
        let a = [[10u8, 20, 30], [0, 0, 0]];
        assert!(psnr(&a, &a).is_infinite());
        // One channel off by 255 out of six: MSE = 255²/6, PSNR = 10·log10(6).
        let b = [[10u8, 20, 30], [255, 0, 0]];
        assert!((psnr(&a, &b) - 10.0 * 6f64.log10()).abs() < 1e-9);
    }
}
