//! The codecs under test at one frame size: JPEG per frame, H.264 through one stateful encoder
//! and an independent decoder, each frame timed and measured against the lossless one.

use super::*;

/// A codec's encoder (and decoder) for the frames of one size.
enum CodecState {
    Jpeg {
        quality: u8,
    },
    H264 {
        encoder: Box<dyn VideoEncoder>,
        decoder: Decoder,
    },
}

/// What one codec made of one frame, before it is measured.
struct Delivered {
    bytes: usize,
    encode_ms: f64,
    encode_cpu_ms: f64,
    keyframe: bool,
    /// The frame as the viewer's decoder shows it.
    rgb: Vec<[u8; 3]>,
}

/// Runs `encode`, timing it by the wall clock and by the process's CPU clock (every thread the
/// encoder runs on; the bench runs nothing else meanwhile), both in ms.
fn timed<T>(encode: impl FnOnce() -> T) -> (T, f64, f64) {
    let cpu = || {
        let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
        t.tv_sec as f64 * 1e3 + t.tv_nsec as f64 * 1e-6
    };
    let (wall, cpu_start) = (Instant::now(), cpu());
    let out = encode();
    let cpu_ms = cpu() - cpu_start;
    (out, wall.elapsed().as_secs_f64() * 1e3, cpu_ms)
}

pub(super) fn rgb_of(rgba8: &[u8]) -> Vec<[u8; 3]> {
    rgba8.chunks_exact(4).map(|p| [p[0], p[1], p[2]]).collect()
}

/// The decoder's planes in our layout, so [`Yuv420::to_rgba8`] (BT.709, limited range, as the
/// stream's VUI says) converts them as it converts the encoder's input.
pub(super) fn planes_of(picture: &impl YUVSource, layout: Yuv420Layout) -> Result<Yuv420, String> {
    let (w, h) = picture.dimensions();
    if (w, h) != (layout.width as usize, layout.height as usize) {
        return Err(format!(
            "the decoder made a {w}×{h} picture of a {}×{} stream",
            layout.width, layout.height
        ));
    }
    let (luma_stride, u_stride, v_stride) = picture.strides();
    let mut data = vec![0u8; layout.bytes()];
    let (cols, rows) = (w.div_ceil(2), layout.chroma_rows() as usize);
    let (luma, chroma) = (layout.luma_stride as usize, layout.chroma_stride as usize);
    copy_rows(&mut data, picture.y(), (luma_stride, luma), (w, h));
    let (cb, cr) = data[layout.cb_offset()..].split_at_mut(layout.cr_offset() - layout.cb_offset());
    copy_rows(cb, picture.u(), (u_stride, chroma), (cols, rows));
    copy_rows(cr, picture.v(), (v_stride, chroma), (cols, rows));
    Ok(Yuv420 { layout, data })
}

/// Copies `cols`×`rows` bytes from `from` (rows `strides.0` apart) to `to` (rows `strides.1`
/// apart).
pub(super) fn copy_rows(
    to: &mut [u8],
    from: &[u8],
    strides: (usize, usize),
    (cols, rows): (usize, usize),
) {
    for row in 0..rows {
        to[row * strides.1..][..cols].copy_from_slice(&from[row * strides.0..][..cols]);
    }
}

/// The codecs under test at one frame size, fed that size's frames in order.
pub(crate) struct Codecs {
    /// Frame width (FLIP needs it).
    width: u32,
    states: Vec<(CodecSetting, CodecState)>,
    samples: Vec<Vec<FrameSample>>,
}

impl Codecs {
    /// Encoders for `settings` at `width`×`height`; H.264's rate control assumes `fps`.
    pub fn new(
        settings: &[CodecSetting],
        width: u32,
        height: u32,
        fps: f32,
    ) -> Result<Self, StreamBenchError> {
        let states = settings
            .iter()
            .map(|&setting| {
                let state = match setting {
                    CodecSetting::Jpeg { quality } => CodecState::Jpeg { quality },
                    CodecSetting::H264 { bitrate_kbps, .. } => {
                        let encoding = Encoding {
                            codec: Codec::H264,
                            bitrate_kbps: Some(bitrate_kbps),
                            ..Encoding::default()
                        };
                        let config = VideoConfig::new(width, height, &encoding, fps);
                        // Made here, not in the first timed encode call.
                        let encoder = EncoderKind::OpenH264.create(&config)?;
                        let decoder = Decoder::new().map_err(|e| StreamBenchError::Decode {
                            setting,
                            frame: 0,
                            message: e.to_string(),
                        })?;
                        CodecState::H264 { encoder, decoder }
                    }
                };
                Ok((setting, state))
            })
            .collect::<Result<Vec<_>, StreamBenchError>>()?;
        Ok(Self {
            width,
            samples: vec![Vec::new(); states.len()],
            states,
        })
    }

    /// Encodes the next frame with every codec (`image` for JPEG, `planes` for H.264),
    /// decodes it and measures it against `image`; FLIP too when `flip`.
    pub fn add_frame(
        &mut self,
        image: &Image,
        planes: &Yuv420,
        flip: bool,
    ) -> Result<(), StreamBenchError> {
        let frame = self.samples.first().map_or(0, Vec::len);
        let layout = planes.layout;
        // Encodes one after another, so each encode call has the CPU to itself while timed.
        let mut delivered = Vec::with_capacity(self.states.len());
        for (setting, state) in &mut self.states {
            let decode_error = |message: String| StreamBenchError::Decode {
                setting: *setting,
                frame,
                message,
            };
            delivered.push(match state {
                CodecState::Jpeg { quality } => {
                    let (bytes, encode_ms, encode_cpu_ms) =
                        timed(|| encode::encode(image, Codec::Jpeg, *quality));
                    let bytes = bytes?;
                    let decoded =
                        ::image::load_from_memory_with_format(&bytes, ::image::ImageFormat::Jpeg)
                            .map_err(|e| decode_error(e.to_string()))?;
                    Delivered {
                        bytes: bytes.len(),
                        encode_ms,
                        encode_cpu_ms,
                        keyframe: true,
                        rgb: decoded.to_rgb8().pixels().map(|p| p.0).collect(),
                    }
                }
                CodecState::H264 { encoder, decoder } => {
                    let (unit, encode_ms, encode_cpu_ms) = timed(|| encoder.encode(planes, false));
                    let unit = unit?;
                    let picture = decoder
                        .decode(&unit.data)
                        .map_err(|e| decode_error(e.to_string()))?
                        .ok_or_else(|| decode_error("no picture for an access unit".into()))?;
                    let decoded = planes_of(&picture, layout).map_err(decode_error)?;
                    Delivered {
                        bytes: unit.data.len(),
                        encode_ms,
                        encode_cpu_ms,
                        keyframe: unit.keyframe,
                        rgb: rgb_of(&decoded.to_rgba8()),
                    }
                }
            });
        }
        let reference = rgb_of(&image.rgba8);
        let width = self.width;
        // The measurements are independent of each other: FLIP dominates, so spread them.
        let errors: Vec<(f64, Option<f64>)> = delivered
            .par_iter()
            .map(|d| {
                (
                    psnr(&reference, &d.rgb),
                    flip.then(|| flip_mean(&reference, &d.rgb, width)),
                )
            })
            .collect();
        for ((samples, d), (psnr_db, flip)) in self.samples.iter_mut().zip(&delivered).zip(errors) {
            samples.push(FrameSample {
                bytes: d.bytes,
                encode_ms: d.encode_ms,
                encode_cpu_ms: d.encode_cpu_ms,
                psnr_db,
                flip,
                keyframe: d.keyframe,
            });
        }
        Ok(())
    }

    /// One row per codec setting; bytes per second at `fps` frames a second.
    pub fn rows(self, fps: f32) -> Vec<CodecRow> {
        self.states
            .into_iter()
            .zip(self.samples)
            .map(|((setting, _), frames)| {
                let n = frames.len().max(1) as f64;
                let bytes_per_frame = frames.iter().map(|f| f.bytes as f64).sum::<f64>() / n;
                let flips: Vec<f64> = frames.iter().filter_map(|f| f.flip).collect();
                CodecRow {
                    setting,
                    bytes_per_frame,
                    first_frame_bytes: frames.first().map_or(0, |f| f.bytes),
                    max_frame_bytes: frames.iter().map(|f| f.bytes).max().unwrap_or(0),
                    bytes_per_second: bytes_per_frame * f64::from(fps),
                    encode: stats(frames.iter().map(|f| f.encode_ms).collect()),
                    encode_cpu_mean_ms: frames.iter().map(|f| f.encode_cpu_ms).sum::<f64>() / n,
                    psnr_mean_db: frames.iter().map(|f| f.psnr_db).sum::<f64>() / n,
                    psnr_min_db: frames
                        .iter()
                        .map(|f| f.psnr_db)
                        .fold(f64::INFINITY, f64::min),
                    flip_mean: flips.iter().sum::<f64>() / flips.len().max(1) as f64,
                    keyframes: frames.iter().filter(|f| f.keyframe).count(),
                    frames,
                }
            })
            .collect()
    }
}
