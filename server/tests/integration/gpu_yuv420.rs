//! The video frame's colour conversion (`shaders/yuv420.wgsl`) against its CPU port, on a whole
//! rendered frame: the GPU's planes must match the CPU's conversion of the same frame's RGBA.

use crate::support::*;

use lightcast_server::passes::exposure::Exposure;
use lightcast_server::passes::yuv420::Yuv420;
use lightcast_server::renderer::Renderer;
use lightcast_server::scene::default_light::{default_camera, default_light};
use lightcast_server::scene::procedural;

/// Per plane: the largest difference and the share of samples that differ at all.
fn differences(gpu: &[u8], cpu: &[u8]) -> (u8, f64) {
    let max = gpu.iter().zip(cpu).map(|(a, b)| a.abs_diff(*b)).max();
    let differ = gpu.iter().zip(cpu).filter(|(a, b)| a != b).count();
    (max.unwrap_or(0), differ as f64 / gpu.len() as f64)
}

#[test]
fn gpu_planes_match_the_cpu_conversion_of_the_same_frame() {
    let scene = procedural::cornell_box();
    // Odd width and height: the last column and row repeat into the chroma blocks.
    let (w, h) = (97, 61);
    let mut settings = settings(w, h, default_camera(&scene), default_light(&scene));
    settings.exposure = Exposure::Auto;
    settings.capture_hdr = false;
    let mut renderer = Renderer::new(gpu(), scene);
    let rgba = renderer.render(&settings).expect("RGBA frame");
    settings.yuv420 = true;
    let video = renderer.render(&settings).expect("video frame");
    assert!(video.rgba8.is_empty(), "a video frame reads back no RGBA");
    assert!(
        video
            .timings
            .iter()
            .any(|t| t.stage == lightcast_server::passes::stages::YUV420),
        "the conversion is timed as its own stage"
    );
    let gpu = video.yuv420.expect("planes");
    let cpu = Yuv420::from_rgba8(&rgba.rgba8, w, h);
    assert_eq!(gpu.layout, cpu.layout);
    assert_eq!(gpu.data.len(), cpu.layout.bytes());
    // The same arithmetic in f32 on both sides; rounding at exactly .5 may still fall apart by
    // one code, which decoders cannot tell from noise.
    for (name, g, c) in [
        ("Y'", gpu.y(), cpu.y()),
        ("Cb", gpu.cb(), cpu.cb()),
        ("Cr", gpu.cr(), cpu.cr()),
    ] {
        // Padding bytes past the width are not part of the image.
        let l = cpu.layout;
        let (stride, cols, rows) = if name == "Y'" {
            (l.luma_stride, l.width, l.height)
        } else {
            (l.chroma_stride, l.width.div_ceil(2), l.chroma_rows())
        };
        let pick = |plane: &[u8]| -> Vec<u8> {
            (0..rows)
                .flat_map(|y| {
                    let start = (y * stride) as usize;
                    plane[start..start + cols as usize].to_vec()
                })
                .collect()
        };
        let (max, share) = differences(&pick(g), &pick(c));
        assert!(max <= 1, "{name}: GPU and CPU differ by {max} codes");
        assert!(
            share < 0.01,
            "{name}: {:.2} % of samples differ",
            share * 100.0
        );
    }
    // The frame is not blank: the walls' colours survive the trip.
    let back = gpu.to_rgba8();
    let mean = |img: &[u8], c: usize| {
        img.chunks(4).map(|p| f64::from(p[c])).sum::<f64>() / f64::from(w * h)
    };
    for c in 0..3 {
        let (a, b) = (mean(&back, c), mean(&rgba.rgba8, c));
        assert!(b > 10.0, "channel {c} lit");
        assert!(
            (a - b).abs() < 3.0,
            "channel {c}: {a:.1} after YUV vs {b:.1}"
        );
    }
}
