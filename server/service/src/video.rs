//! Video streams (`encoding.codec: h264`): one stateful encoder per session, fed the session's
//! frames in order, each frame one Annex B access unit.
//!
//! The encoder is one interface ([`VideoEncoder`]) behind `--encoder`; the one that always
//! builds is Cisco's OpenH264, compiled from the source the `openh264` crate bundles (software,
//! constrained baseline). A hardware encoder (NVENC, VA-API, e.g. through Debian's libavcodec)
//! would be another [`EncoderKind`]: none is here because the Hopper GPUs this project deploys
//! on have no NVENC and none could be tested without the hardware (README, "Video streams").

use crate::passes::yuv420::Yuv420;
use lightcast_protocol::{Codec, Encoding};

mod software;
pub use software::slices_for;

/// The codecs a session's frames can be encoded in (`encoding.codec`).
pub const STREAM_CODECS: &[Codec] = &[Codec::Jpeg, Codec::Png, Codec::H264];

/// Largest frame OpenH264 encodes (its level 5.2 limit): 3840 on the longer side, 2160 on the
/// shorter.
pub const MAX_LONG_SIDE: u32 = 3840;
pub const MAX_SHORT_SIDE: u32 = 2160;

#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    #[error("H.264 encoder ({encoder}): {message}")]
    Encoder {
        encoder: &'static str,
        message: String,
    },
    #[error("H.264 needs even frame sizes and at most {MAX_LONG_SIDE}×{MAX_SHORT_SIDE}; got {width}×{height}")]
    Size {
        width: u32,
        height: u32,
        /// The side at fault (`width` or `height`).
        side: &'static str,
    },
}

/// Which encoder makes `h264` streams (`--encoder`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum EncoderChoice {
    /// The best encoder this machine has: OpenH264 until a hardware encoder is added.
    #[default]
    Auto,
    /// Cisco's OpenH264 on the CPU, built into the server.
    Openh264,
}

/// An encoder implementation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EncoderKind {
    OpenH264,
}

impl EncoderKind {
    /// The encoder `choice` selects on this machine.
    pub fn select(choice: EncoderChoice) -> Self {
        match choice {
            EncoderChoice::Auto | EncoderChoice::Openh264 => Self::OpenH264,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::OpenH264 => "openh264",
        }
    }

    pub fn hardware(self) -> bool {
        match self {
            Self::OpenH264 => false,
        }
    }

    /// A new encoder for frames of `config`; its first access unit is a keyframe.
    pub fn create(self, config: &VideoConfig) -> Result<Box<dyn VideoEncoder>, VideoError> {
        match self {
            Self::OpenH264 => Ok(Box::new(software::SoftwareEncoder::new(config)?)),
        }
    }
}

/// Encoder threads (each taking slices of every frame) for a stream of `width`×`height` on this
/// machine: [`software::threads_for`] its pixels and CPUs.
pub fn encoder_threads(width: u32, height: u32) -> u16 {
    software::threads_for(
        u64::from(width) * u64::from(height),
        std::thread::available_parallelism().map_or(1, |n| n.get()),
    )
}

/// What an encoder is made for; a stream whose config changes gets a new encoder (and so a
/// keyframe).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VideoConfig {
    pub width: u32,
    pub height: u32,
    pub bitrate_kbps: u32,
    pub max_qp: u8,
    pub keyframe_interval: u32,
    /// The session's fps cap: the rate control spreads the bitrate over this many frames.
    pub fps: f32,
    /// Encoder threads; each frame is [`software::slices_for`] them slices.
    pub threads: u16,
}

impl VideoConfig {
    pub fn new(width: u32, height: u32, encoding: &Encoding, fps: f32) -> Self {
        Self {
            width,
            height,
            bitrate_kbps: encoding.bitrate_kbps_for(width, height, fps),
            max_qp: encoding.max_qp,
            keyframe_interval: encoding.keyframe_interval,
            fps,
            threads: encoder_threads(width, height),
        }
    }

    /// Whether H.264 can carry frames of `width`×`height` (4:2:0 needs even sides).
    pub fn check_size(width: u32, height: u32) -> Result<(), VideoError> {
        // The longer side may reach MAX_LONG_SIDE, the other MAX_SHORT_SIDE.
        let limits = if width >= height {
            (MAX_LONG_SIDE, MAX_SHORT_SIDE)
        } else {
            (MAX_SHORT_SIDE, MAX_LONG_SIDE)
        };
        let fits = |side: u32, limit: u32| side.is_multiple_of(2) && side <= limit;
        let side = if !fits(width, limits.0) {
            "width"
        } else if !fits(height, limits.1) {
            "height"
        } else {
            return Ok(());
        };
        Err(VideoError::Size {
            width,
            height,
            side,
        })
    }
}

/// One encoded frame.
#[derive(Clone, Debug)]
pub struct AccessUnit {
    /// Annex B NAL units (start codes included).
    pub data: Vec<u8>,
    /// An IDR access unit, with SPS and PPS: decoding can start here.
    pub keyframe: bool,
}

/// A stateful video encoder: frames must come in display order.
pub trait VideoEncoder: Send {
    /// Encodes the next frame, as a keyframe when `keyframe` (else the encoder decides).
    fn encode(&mut self, frame: &Yuv420, keyframe: bool) -> Result<AccessUnit, VideoError>;
}

impl VideoEncoder for software::SoftwareEncoder {
    fn encode(&mut self, frame: &Yuv420, keyframe: bool) -> Result<AccessUnit, VideoError> {
        software::SoftwareEncoder::encode(self, frame, keyframe)
    }
}

/// A session's video encoder and what it was made for.
#[derive(Default)]
pub struct VideoStream {
    encoder: Option<(VideoConfig, Box<dyn VideoEncoder>)>,
}

impl VideoStream {
    /// Encodes the session's next frame with `kind`, making a new encoder (so a keyframe)
    /// when `config` differs from the last frame's.
    pub fn encode(
        &mut self,
        kind: EncoderKind,
        config: VideoConfig,
        frame: &Yuv420,
        keyframe: bool,
    ) -> Result<AccessUnit, VideoError> {
        if self.encoder.as_ref().is_none_or(|(c, _)| *c != config) {
            self.encoder = None;
            self.encoder = Some((config, kind.create(&config)?));
        }
        let Some((_, encoder)) = self.encoder.as_mut() else {
            unreachable!("made above");
        };
        let result = encoder.encode(frame, keyframe);
        if result.is_err() {
            // The next frame starts afresh with a keyframe rather than after a broken one.
            self.encoder = None;
        }
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use openh264::decoder::Decoder;
    use openh264::formats::YUVSource;

    /// A moving gradient with a square, `t` frames in.
    fn frame(width: u32, height: u32, t: u32) -> Yuv420 {
        textured(width, height, t, 0)
    }

    /// [`frame`] plus noise of ±`grain` levels that changes every frame: content that costs
    /// whatever bits the rate control allows.
    fn textured(width: u32, height: u32, t: u32, grain: u32) -> Yuv420 {
        let rgba: Vec<u8> = (0..width * height)
            .flat_map(|i| {
                let (x, y) = (i % width, i / width);
                let hash = (i ^ (t << 20)).wrapping_mul(2_654_435_761) >> 24;
                let noise =
                    |c: u32| (c + hash % (2 * grain + 1)).saturating_sub(grain).min(255) as u8;
                let square = (x + 3 * t) % width < width / 4 && y > height / 3 && y < height / 2;
                if square {
                    [230, 200, 40, 255]
                } else {
                    [
                        noise((x + 2 * t) * 255 / width),
                        noise(y * 255 / height),
                        noise(((x + y) / 2) % 256),
                        255,
                    ]
                }
            })
            .collect();
        Yuv420::from_rgba8(&rgba, width, height)
    }

    fn psnr(a: &[u8], b: &[u8]) -> f64 {
        let mse = a
            .iter()
            .zip(b)
            .map(|(x, y)| (f64::from(*x) - f64::from(*y)).powi(2))
            .sum::<f64>()
            / a.len() as f64;
        10.0 * (255.0 * 255.0 / mse.max(1e-9)).log10()
    }

    /// The luma plane a decoder returned, rows packed.
    fn decoded_luma(decoder: &mut Decoder, unit: &[u8], width: u32, height: u32) -> Vec<u8> {
        let picture = decoder
            .decode(unit)
            .expect("decodes")
            .expect("a picture per access unit");
        let (w, h) = picture.dimensions();
        assert_eq!((w, h), (width as usize, height as usize));
        let stride = picture.strides().0;
        (0..h)
            .flat_map(|y| picture.y()[y * stride..y * stride + w].to_vec())
            .collect()
    }

    fn luma_rows(frame: &Yuv420) -> Vec<u8> {
        let l = frame.layout;
        (0..l.height as usize)
            .flat_map(|y| {
                let start = y * l.luma_stride as usize;
                frame.y()[start..start + l.width as usize].to_vec()
            })
            .collect()
    }

    /// A stream at 8 Mbit/s: tiny test frames would get the automatic bitrate's floor.
    fn config(width: u32, height: u32) -> VideoConfig {
        let encoding = Encoding {
            bitrate_kbps: Some(8000),
            ..Encoding::default()
        };
        VideoConfig::new(width, height, &encoding, 30.0)
    }

    #[test]
    fn a_stream_round_trips_through_an_independent_decoder() {
        let (w, h) = (160, 96);
        let mut stream = VideoStream::default();
        let mut decoder = Decoder::new().expect("decoder");
        let mut sizes = Vec::new();
        for t in 0..12 {
            let input = frame(w, h, t);
            let unit = stream
                .encode(EncoderKind::OpenH264, config(w, h), &input, false)
                .expect("encodes");
            assert_eq!(unit.keyframe, t == 0, "only the first frame is a keyframe");
            assert_eq!(&unit.data[..4], &[0, 0, 0, 1], "Annex B start code");
            let luma = decoded_luma(&mut decoder, &unit.data, w, h);
            let p = psnr(&luma, &luma_rows(&input));
            // At 8 Mbit/s a 160×96 frame is nearly lossless; 35 dB is visually transparent.
            assert!(p > 35.0, "frame {t}: PSNR {p:.1} dB");
            sizes.push(unit.data.len());
        }
        assert!(
            sizes[1..].iter().all(|&s| s < sizes[0]),
            "P-frames are smaller than the keyframe: {sizes:?}"
        );
    }

    #[test]
    fn keyframes_on_request_and_on_a_new_size() {
        let mut stream = VideoStream::default();
        let kind = EncoderKind::OpenH264;
        let first = stream.encode(kind, config(64, 48), &frame(64, 48, 0), false);
        assert!(first.expect("encodes").keyframe);
        let delta = stream.encode(kind, config(64, 48), &frame(64, 48, 1), false);
        assert!(!delta.expect("encodes").keyframe);
        let asked = stream.encode(kind, config(64, 48), &frame(64, 48, 2), true);
        assert!(asked.expect("encodes").keyframe);
        // A resize makes a new encoder, whose stream a fresh decoder starts on.
        let resized = stream
            .encode(kind, config(96, 64), &frame(96, 64, 3), false)
            .expect("encodes");
        assert!(resized.keyframe);
        let mut decoder = Decoder::new().expect("decoder");
        assert_eq!(
            decoded_luma(&mut decoder, &resized.data, 96, 64).len(),
            96 * 64
        );
    }

    #[test]
    fn a_lower_bitrate_sends_fewer_bytes() {
        let (w, h) = (192, 128);
        let bytes = |kbps: u32| {
            let mut stream = VideoStream::default();
            let cfg = VideoConfig {
                bitrate_kbps: kbps,
                max_qp: 51,
                ..config(w, h)
            };
            (0..20)
                .map(|t| {
                    stream
                        .encode(EncoderKind::OpenH264, cfg, &textured(w, h, t, 40), false)
                        .expect("encodes")
                        .data
                        .len()
                })
                .sum::<usize>()
        };
        let (low, high) = (bytes(100), bytes(4_000));
        assert!(low * 2 < high, "100 kbit/s: {low} B, 4 Mbit/s: {high} B");
    }

    #[test]
    fn frames_get_a_thread_per_half_megapixel_up_to_the_cpus_and_four_slices_each() {
        let threads = |w: u64, h: u64, cpus| software::threads_for(w * h, cpus);
        assert_eq!(threads(640, 360, 16), 1);
        assert_eq!(threads(1280, 720, 16), 2);
        assert_eq!(threads(1920, 1080, 16), 4);
        assert_eq!(threads(3840, 2160, 16), 4, "at most OpenH264's four");
        assert_eq!(threads(1920, 1080, 2), 2, "at most the CPUs");
        assert_eq!(threads(1920, 1080, 0), 1);
        assert_eq!(software::slices_for(1), 1, "one thread, one slice");
        assert_eq!(software::slices_for(2), 8);
        assert_eq!(software::slices_for(4), 16);
    }

    /// The slices of each access unit: NAL unit types 1 (non-IDR) and 5 (IDR).
    fn slices(unit: &[u8]) -> usize {
        openh264::nal_units(unit)
            .filter(|nal| {
                let header = nal.iter().position(|&b| b == 1).map(|i| nal[i + 1]);
                matches!(header.map(|h| h & 0x1f), Some(1 | 5))
            })
            .count()
    }

    /// Streams `frames` frames of `w`×`h` on `threads` encoder threads through OpenH264's
    /// decoder: each access unit's slice count and luma PSNR.
    fn sliced_stream(w: u32, h: u32, threads: u16, frames: u32) -> Vec<(usize, f64)> {
        let cfg = VideoConfig {
            threads,
            ..config(w, h)
        };
        let mut stream = VideoStream::default();
        let mut decoder = Decoder::new().expect("decoder");
        (0..frames)
            .map(|t| {
                let input = frame(w, h, t);
                let unit = stream
                    .encode(EncoderKind::OpenH264, cfg, &input, false)
                    .expect("encodes");
                let p = psnr(
                    &decoded_luma(&mut decoder, &unit.data, w, h),
                    &luma_rows(&input),
                );
                (slices(&unit.data), p)
            })
            .collect()
    }

    /// With several threads each frame has four slices per thread, and decodes as well as one
    /// slice. (OpenH264 gives each slice at least one rate-control group of 2–4 macroblock
    /// rows and lowers the count for frames too small for that: 320×384 fits 12.)
    #[test]
    fn threaded_streams_are_sliced_and_decode() {
        for (threads, expected) in [(1, 1), (3, 12)] {
            for (t, (n, p)) in sliced_stream(320, 384, threads, 6).into_iter().enumerate() {
                assert_eq!(n, expected, "{threads} threads, frame {t}");
                assert!(p > 35.0, "{threads} threads, frame {t}: PSNR {p:.1} dB");
            }
        }
    }

    /// The widest, shortest frame that gets several threads (9 macroblock rows) has room for
    /// two rate-control row groups, not sixteen slices: OpenH264 lowers the count and encodes.
    #[test]
    fn a_frame_too_short_for_its_slices_gets_fewer() {
        let (w, h) = (3840, 144);
        assert!(software::threads_for(u64::from(w * h), 16) >= 2);
        for (t, (n, p)) in sliced_stream(w, h, 4, 3).into_iter().enumerate() {
            assert!((2..16).contains(&n), "frame {t}: {n} slices");
            assert!(p > 35.0, "frame {t}: PSNR {p:.1} dB");
        }
    }

    /// Reads an H.264 bit string (emulation-prevention bytes already removed).
    struct Bits<'a> {
        bytes: &'a [u8],
        at: usize,
    }

    impl Bits<'_> {
        fn bit(&mut self) -> u32 {
            let b = (self.bytes[self.at / 8] >> (7 - self.at % 8)) & 1;
            self.at += 1;
            u32::from(b)
        }

        fn bits(&mut self, n: u32) -> u32 {
            (0..n).fold(0, |v, _| (v << 1) | self.bit())
        }

        /// ue(v), H.264 §9.1.
        fn ue(&mut self) -> u32 {
            let mut zeros = 0;
            while self.bit() == 0 {
                zeros += 1;
            }
            (1 << zeros) - 1 + self.bits(zeros)
        }
    }

    /// (video_full_range_flag, colour_primaries, transfer_characteristics,
    /// matrix_coefficients) of a baseline SPS, H.264 §7.3.2.1.1 and Annex E.1.1.
    fn colour_description(sps: &[u8]) -> (u32, u32, u32, u32) {
        let mut rbsp = Vec::new();
        for &b in &sps[1..] {
            if b == 3 && rbsp.ends_with(&[0, 0]) {
                continue;
            }
            rbsp.push(b);
        }
        let mut r = Bits {
            bytes: &rbsp,
            at: 0,
        };
        assert_eq!(r.bits(8), 66, "baseline profile");
        r.bits(16); // constraint flags, level
        r.ue(); // seq_parameter_set_id
        r.ue(); // log2_max_frame_num_minus4
        match r.ue() {
            0 => {
                r.ue();
            }
            2 => {}
            other => panic!("pic_order_cnt_type {other}"),
        }
        r.ue(); // max_num_ref_frames
        r.bit(); // gaps_in_frame_num_value_allowed_flag
        r.ue(); // pic_width_in_mbs_minus1
        r.ue(); // pic_height_in_map_units_minus1
        assert_eq!(r.bit(), 1, "frame_mbs_only_flag");
        r.bit(); // direct_8x8_inference_flag
        if r.bit() == 1 {
            (0..4).for_each(|_| {
                r.ue();
            });
        }
        assert_eq!(r.bit(), 1, "vui_parameters_present_flag");
        if r.bit() == 1 && r.bits(8) == 255 {
            r.bits(32);
        }
        if r.bit() == 1 {
            r.bit();
        }
        assert_eq!(r.bit(), 1, "video_signal_type_present_flag");
        r.bits(3); // video_format
        let full_range = r.bit();
        assert_eq!(r.bit(), 1, "colour_description_present_flag");
        (full_range, r.bits(8), r.bits(8), r.bits(8))
    }

    /// Every keyframe's SPS says what the GPU conversion wrote (`shaders/yuv420.wgsl`): limited
    /// range, BT.709 primaries and matrix, the sRGB transfer, so decoders colour it right.
    #[test]
    fn keyframes_signal_bt709_limited_range_with_the_srgb_transfer() {
        let mut stream = VideoStream::default();
        // 1080p has a cropping window (1088 coded rows): the parse must pass it.
        for (w, h) in [(160, 96), (1920, 1080)] {
            let unit = stream
                .encode(EncoderKind::OpenH264, config(w, h), &frame(w, h, 0), true)
                .expect("encodes");
            let sps: Vec<&[u8]> = openh264::nal_units(&unit.data)
                .map(|nal| &nal[nal.iter().position(|&b| b == 1).map_or(0, |i| i + 1)..])
                .filter(|nal| nal[0] & 0x1f == 7)
                .collect();
            assert_eq!(sps.len(), 1, "{w}×{h}: one SPS before the IDR");
            assert_eq!(colour_description(sps[0]), (0, 1, 13, 1), "{w}×{h}");
        }
    }

    #[test]
    fn odd_and_oversized_frames_are_refused() {
        assert!(VideoConfig::check_size(1920, 1080).is_ok());
        assert!(VideoConfig::check_size(2160, 3840).is_ok());
        let side = |w, h| match VideoConfig::check_size(w, h) {
            Err(VideoError::Size { side, .. }) => side,
            other => panic!("{w}×{h}: {other:?}"),
        };
        assert_eq!(side(641, 480), "width");
        assert_eq!(side(640, 481), "height");
        assert_eq!(side(4096, 2160), "width");
        assert_eq!(side(3840, 2162), "height");
        assert_eq!(side(2162, 3840), "width");
        assert_eq!(side(2160, 3842), "height");
    }
}
