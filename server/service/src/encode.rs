//! Frame encoding (JPEG, PNG) on a thread pool of its own, off the render loop.

use crate::debug_views::Image;
use lightcast_protocol::Codec;

#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    #[error("JPEG encoding failed: {0}")]
    Jpeg(#[from] jpeg_encoder::EncodingError),
    #[error("PNG encoding failed: {0}")]
    Png(#[from] image::ImageError),
    #[error("{width}×{height} is too large for JPEG (at most 65535 per side)")]
    TooLarge { width: u32, height: u32 },
    #[error("h264 is a stream codec: a single image is JPEG or PNG")]
    NotAStill,
}

/// Encodes an RGBA8 image as a still; `quality` (1–100) applies to JPEG.
pub fn encode(image: &Image, codec: Codec, quality: u8) -> Result<Vec<u8>, EncodeError> {
    match codec {
        Codec::H264 => Err(EncodeError::NotAStill),
        Codec::Jpeg => {
            let (Ok(w), Ok(h)) = (u16::try_from(image.width), u16::try_from(image.height)) else {
                return Err(EncodeError::TooLarge {
                    width: image.width,
                    height: image.height,
                });
            };
            let mut out = Vec::with_capacity(image.rgba8.len() / 8);
            let encoder = jpeg_encoder::Encoder::new(&mut out, quality.clamp(1, 100));
            encoder.encode(&image.rgba8, w, h, jpeg_encoder::ColorType::Rgba)?;
            Ok(out)
        }
        Codec::Png => {
            use image::ImageEncoder;
            let mut out = Vec::new();
            // Fast compression: stills must not hold up the stream for long.
            image::codecs::png::PngEncoder::new_with_quality(
                &mut out,
                image::codecs::png::CompressionType::Fast,
                image::codecs::png::FilterType::Adaptive,
            )
            .write_image(
                &image.rgba8,
                image.width,
                image.height,
                image::ExtendedColorType::Rgba8,
            )?;
            Ok(out)
        }
    }
}

/// The encoder threads, and the video encoder they use for `h264` streams.
pub struct EncodePool {
    pool: rayon::ThreadPool,
    pub video: super::video::EncoderKind,
}

impl EncodePool {
    pub fn new(
        threads: usize,
        video: super::video::EncoderKind,
    ) -> Result<Self, rayon::ThreadPoolBuildError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .thread_name(|i| format!("encode-{i}"))
            .build()?;
        Ok(Self { pool, video })
    }

    /// Default size: half the CPUs, at least one.
    pub fn default_threads() -> usize {
        std::thread::available_parallelism().map_or(1, |n| (n.get() / 2).max(1))
    }

    pub fn spawn(&self, job: impl FnOnce() + Send + 'static) {
        self.pool.spawn(job);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(width: u32, height: u32) -> Image {
        let rgba8 = (0..width * height)
            .flat_map(|i| {
                let (x, y) = (i % width, i / width);
                [(x * 255 / width) as u8, (y * 255 / height) as u8, 128, 255]
            })
            .collect();
        Image {
            width,
            height,
            rgba8,
        }
    }

    fn mean_abs_diff(a: &[u8], b: &[u8]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| f64::from(x.abs_diff(*y)))
            .sum::<f64>()
            / a.len() as f64
    }

    #[test]
    fn png_is_lossless_and_jpeg_close() {
        let img = gradient(67, 41);
        let png = encode(&img, Codec::Png, 0).expect("png");
        let back = image::load_from_memory(&png)
            .expect("decode png")
            .to_rgba8();
        assert_eq!(back.as_raw(), &img.rgba8);

        let jpeg = encode(&img, Codec::Jpeg, 90).expect("jpeg");
        let back = image::load_from_memory(&jpeg)
            .expect("decode jpeg")
            .to_rgba8();
        assert_eq!((back.width(), back.height()), (67, 41));
        let mad = mean_abs_diff(back.as_raw(), &img.rgba8);
        assert!(mad < 3.0, "JPEG q90 mean abs diff {mad}");
        let low = encode(&img, Codec::Jpeg, 20).expect("jpeg q20");
        assert!(low.len() < jpeg.len(), "{} vs {}", low.len(), jpeg.len());
    }
}
