//! `bench-stream`'s own logic without a GPU: sizes and rates parsed, comparisons and targets,
//! the report's markdown.

use super::*;

#[test]
fn frame_sizes_parse_and_reject() {
    let size = |s: &str| s.parse::<FrameSize>();
    assert_eq!(
        size("1920x1080"),
        Ok(FrameSize {
            width: 1920,
            height: 1080
        })
    );
    assert_eq!(size("64×48").map(|s| s.to_string()), Ok("64×48".into()));
    for bad in ["1920", "0x10", "10x", "axb", "-2x4"] {
        assert!(size(bad).is_err(), "{bad}");
    }
}

#[test]
fn the_camera_orbits_or_dollies_and_the_path_file_follows_it() {
    let base = Camera {
        position: [1.0, 2.0, 5.0],
        target: [1.0, 1.0, 1.0],
        fov_y_degrees: 45.0,
    };
    let distance = |c: &Camera| {
        let d = [0, 1, 2].map(|k| c.position[k] - c.target[k]);
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    };
    let orbit = CameraMotion {
        motion: Motion::Orbit,
        speed: 30.0,
        base: base.clone(),
    };
    let quarter = orbit.at(3.0);
    assert!((distance(&quarter) - distance(&base)).abs() < 1e-5);
    assert_eq!(quarter.position[1], base.position[1], "height kept");
    assert!(
        (quarter.position[0] - (1.0 - 4.0)).abs() < 1e-5,
        "{quarter:?}"
    );
    assert_eq!(quarter.target, base.target);
    let dolly = CameraMotion {
        motion: Motion::Dolly,
        speed: 0.1,
        base: base.clone(),
    };
    let ahead = dolly.at(5.0);
    assert_eq!(
        ahead.position,
        [1.0, 1.5, 3.0],
        "half way to the old target"
    );
    assert!(
        (distance(&ahead) - distance(&base)).abs() < 1e-5,
        "the target moves on"
    );
    let path = orbit.to_json(12.0, 30.0);
    let keyframes = path["keyframes"].as_array().expect("keyframes");
    assert_eq!(keyframes.len(), 361);
    assert_eq!(keyframes[360]["t"], 12.0);
    let last: Camera = serde_json::from_value(keyframes[90]["camera"].clone()).expect("a camera");
    assert_eq!(last, quarter);
}

fn row(setting: CodecSetting, bytes: f64, psnr_db: f64) -> CodecRow {
    CodecRow {
        setting,
        bytes_per_frame: bytes,
        first_frame_bytes: bytes as usize,
        max_frame_bytes: bytes as usize,
        bytes_per_second: bytes * 30.0,
        encode: stats(vec![1.0]),
        encode_cpu_mean_ms: 1.0,
        psnr_mean_db: psnr_db,
        psnr_min_db: psnr_db,
        flip_mean: 0.0,
        keyframes: 1,
        frames: Vec::new(),
    }
}

#[test]
fn h264_rates_are_auto_or_kbit_per_second_in_the_sessions_range() {
    assert_eq!("auto".parse(), Ok(H264Rate::Auto));
    assert_eq!("3000".parse(), Ok(H264Rate::Kbps(3000)));
    for bad in ["99", "200001", "fast", "", "-5"] {
        let e = bad.parse::<H264Rate>().expect_err(bad);
        assert!(e.contains("100..=200000"), "{bad}: {e}");
    }
    // `auto` is what a session with `bitrate_kbps: null` gets at each size.
    assert_eq!(H264Rate::Auto.kbps(1920, 1080, 30.0), 3110);
    assert_eq!(H264Rate::Auto.kbps(1280, 720, 30.0), 1382);
    assert_eq!(H264Rate::Kbps(8000).kbps(1280, 720, 30.0), 8000);
}

#[test]
fn h264_is_compared_with_the_moving_quality_and_the_closest_psnr_below() {
    let jpeg = |quality| CodecSetting::Jpeg { quality };
    let h264 = |bitrate_kbps| CodecSetting::H264 {
        bitrate_kbps,
        auto: false,
    };
    let rows = [
        row(jpeg(50), 60_000.0, 36.0),
        row(jpeg(70), 80_000.0, 38.0),
        row(jpeg(80), 100_000.0, 39.5),
        row(jpeg(90), 150_000.0, 42.0),
        row(h264(8000), 15_000.0, 40.0),
        row(h264(3000), 9_000.0, 38.5),
        row(h264(300), 1_000.0, 30.0),
    ];
    let c = compare(&rows, 70);
    assert_eq!(c.len(), 4, "{c:?}");
    // 8000: q70 (moving), and q80 as the closest below 40 dB.
    assert_eq!((c[0].h264_kbps, c[0].jpeg_quality), (8000, 70));
    assert_eq!(c[0].bases, [Basis::MovingQuality]);
    assert!((c[0].bytes_ratio - 15.0 / 80.0).abs() < 1e-12);
    assert!((c[0].psnr_delta_db - 2.0).abs() < 1e-12);
    assert!(c[0].meets_bytes_target);
    assert_eq!(
        (c[1].jpeg_quality, &c[1].bases[..]),
        (80, &[Basis::ClosestPsnrAtOrBelow][..])
    );
    assert!(c[1].meets_bytes_target, "0.15 of the bytes at +0.5 dB");
    // 3000: q70 is both, in one row.
    assert_eq!((c[2].h264_kbps, c[2].jpeg_quality), (3000, 70));
    assert_eq!(
        c[2].bases,
        [Basis::MovingQuality, Basis::ClosestPsnrAtOrBelow]
    );
    // 300 kbit/s: an eightieth of the bytes, but below every JPEG's PSNR: no closest
    // JPEG, and the moving comparison fails on PSNR.
    assert_eq!(
        (c[3].h264_kbps, &c[3].bases[..]),
        (300, &[Basis::MovingQuality][..])
    );
    assert!(c[3].bytes_ratio < TARGET_BYTES_RATIO && !c[3].meets_bytes_target);
}

#[test]
fn targets_check_every_bitrate_at_1080p_against_the_moving_quality() {
    let readback = || Readback {
        bytes_per_frame: 1,
        copy_gpu: stats(vec![1.0]),
        frame_gpu: stats(vec![1.0]),
        wait: stats(vec![1.0]),
    };
    let size = |width, height| {
        let h264 = |bitrate_kbps, auto| CodecSetting::H264 { bitrate_kbps, auto };
        let mut fast = row(h264(3000, false), 9_000.0, 38.5);
        fast.encode = stats(vec![5.0, 6.0]);
        fast.encode_cpu_mean_ms = 11.0;
        let rows = vec![
            row(CodecSetting::Jpeg { quality: 70 }, 80_000.0, 38.0),
            // The automatic bitrate (the service's default) came to 8000 here.
            row(h264(8000, true), 20_000.0, 41.0),
            fast,
        ];
        SizeReport {
            width,
            height,
            rgba8: readback(),
            yuv420: readback(),
            conversion_gpu: stats(vec![1.0]),
            yuv420_psnr_db: 45.0,
            h264_threads: 2,
            comparisons: compare(&rows, 70),
            rows,
        }
    };
    let defaults = Encoding::default();
    assert!(
        targets(&[size(1280, 720)], &defaults, 30.0).is_none(),
        "1080p only"
    );
    let t = targets(&[size(1280, 720), size(1920, 1080)], &defaults, 30.0).expect("1080p ran");
    assert_eq!(t.jpeg_quality, 70);
    let checks: Vec<_> = t
        .checks
        .iter()
        .map(|c| (c.h264_kbps, c.default_bitrate, c.bytes_met, c.encode_met))
        .collect();
    // 8000: a quarter of the bytes; 3000: under a fifth at +0.5 dB, encoded in 6 ms.
    assert_eq!(
        checks,
        [(8000, true, false, true), (3000, false, true, true)]
    );
    // 11 ms of CPU per frame, 30 frames a second: a third of a core.
    assert!((t.checks[1].cores_per_stream - 0.33).abs() < 1e-9);
    let markdown = StreamBenchReport {
        adapter: "test".into(),
        timing_source: TimingSource::CpuWallClock,
        scene: "test".into(),
        triangles: 0,
        gi: crate::gi::none::NONE,
        shadow_map_size: 256,
        exposure: "auto".into(),
        frames: 1,
        fps: 30.0,
        motion: CameraMotion {
            motion: Motion::Orbit,
            speed: 30.0,
            base: Camera {
                position: [0.0, 0.0, 1.0],
                target: [0.0; 3],
                fov_y_degrees: 45.0,
            },
        },
        flip_every: 1,
        max_qp: defaults.max_qp,
        keyframe_interval: defaults.keyframe_interval,
        cpu_threads: 1,
        sizes: Vec::new(),
        targets: Some(t),
    }
    .markdown();
    assert!(
        markdown.contains(
            "Bytes target met at: 3000 kbit/s. Encode target met at: 8000 kbit/s, 3000 kbit/s."
        ),
        "{markdown}"
    );
}

/// A moving gradient with a bright square: frame `t` of a tiny synthetic path.
fn frame(width: u32, height: u32, t: u32) -> Image {
    let rgba8 = (0..width * height)
        .flat_map(|i| {
            let (x, y) = (i % width, i / width);
            if (x + 3 * t) % width < width / 4 && y > height / 3 && y < height / 2 {
                [230, 200, 40, 255]
            } else {
                [
                    ((x + 2 * t) * 255 / width) as u8,
                    (y * 255 / height) as u8,
                    (((x + y) / 2) % 256) as u8,
                    255,
                ]
            }
        })
        .collect();
    Image {
        width,
        height,
        rgba8,
    }
}

#[test]
fn codecs_measure_a_stream_of_frames() {
    let (w, h, n) = (64, 48, 6);
    let settings = [
        CodecSetting::Jpeg { quality: 50 },
        CodecSetting::Jpeg { quality: 95 },
        CodecSetting::H264 {
            bitrate_kbps: 8000,
            auto: false,
        },
    ];
    let mut codecs = Codecs::new(&settings, w, h, 30.0).expect("encoders");
    let mut ceiling = 0.0;
    for t in 0..n {
        let image = frame(w, h, t);
        let planes = Yuv420::from_rgba8(&image.rgba8, w, h);
        ceiling += psnr(&rgb_of(&image.rgba8), &rgb_of(&planes.to_rgba8())) / f64::from(n);
        codecs
            .add_frame(&image, &planes, t % 2 == 0)
            .expect("frame");
    }
    let rows = codecs.rows(30.0);
    assert_eq!(rows.len(), 3);
    for r in &rows {
        assert_eq!(r.frames.len(), n as usize, "{}", r.setting);
        assert!(r.frames.iter().all(|f| f.bytes > 0), "{}", r.setting);
        assert_eq!(r.frames.iter().filter(|f| f.flip.is_some()).count(), 3);
        assert!((r.bytes_per_second - 30.0 * r.bytes_per_frame).abs() < 1e-9);
        assert!(r.psnr_min_db <= r.psnr_mean_db);
        assert!(r.flip_mean > 0.0 && r.flip_mean < 0.5, "{}", r.setting);
        assert!(r.encode_cpu_mean_ms > 0.0, "{}: {r:?}", r.setting);
    }
    let (q50, q95, video) = (&rows[0], &rows[1], &rows[2]);
    assert!(q95.bytes_per_frame > q50.bytes_per_frame);
    assert!(q95.psnr_mean_db > q50.psnr_mean_db + 3.0, "{q95:?}");
    assert!(q95.flip_mean < q50.flip_mean);
    // One keyframe, then P-frames smaller than it; at 8 Mbit/s a 64×48 frame loses next
    // to nothing beyond what 4:2:0 loses (the square's sharp chroma edges: under 30 dB).
    assert_eq!(video.keyframes, 1);
    assert!(video.frames[0].keyframe);
    assert!(video.frames[1..]
        .iter()
        .all(|f| f.bytes < video.first_frame_bytes));
    assert!(
        video.psnr_mean_db > ceiling - 1.0 && video.psnr_mean_db <= ceiling + 0.1,
        "{video:?}, 4:2:0 alone {ceiling:.2} dB"
    );
    assert_eq!(video.max_frame_bytes, video.first_frame_bytes);
}

#[test]
fn frames_are_written_as_i420_without_the_layout_padding() {
    // 6 wide: chroma rows of 3 samples padded to 4, luma rows of 6 padded to 8.
    let (w, h) = (6, 4);
    let rgba8: Vec<u8> = (0..w * h * 4).map(|i| (i * 7 % 251) as u8).collect();
    let frame = Yuv420::from_rgba8(&rgba8, w, h);
    assert_eq!(
        (frame.layout.luma_stride, frame.layout.chroma_stride),
        (8, 4)
    );
    let mut written = Vec::new();
    write_i420(&mut written, &frame).expect("written");
    assert_eq!(written.len(), (w * h + 2 * (w / 2) * (h / 2)) as usize);
    let (y, c) = ((w * h) as usize, ((w / 2) * (h / 2)) as usize);
    assert_eq!(&written[6..12], &frame.y()[8..14], "luma row 1");
    assert_eq!(&written[y + 3..y + 6], &frame.cb()[4..7], "Cb row 1");
    assert_eq!(&written[y + c..y + c + 3], &frame.cr()[..3], "Cr row 0");
}

#[test]
fn decoded_planes_are_copied_row_by_row() {
    let (w, h) = (10, 6);
    let source = Yuv420::from_rgba8(&frame(w, h, 0).rgba8, w, h);
    // A decoder's rows are padded otherwise than ours: the copy drops its padding.
    let decoded = Padded::of(&source, 7);
    assert_eq!(planes_of(&decoded, source.layout), Ok(source.clone()));
    assert!(planes_of(&decoded, Yuv420Layout::new(12, 6)).is_err());
}

/// The planes of a [`Yuv420`] with `pad` more bytes per row, as a decoder may hand out
/// its picture; the padding is 0xEE.
struct Padded {
    width: usize,
    height: usize,
    planes: [(Vec<u8>, usize); 3],
}

impl Padded {
    fn of(source: &Yuv420, pad: usize) -> Self {
        let l = source.layout;
        let (w, h) = (l.width as usize, l.height as usize);
        let repad = |plane: &[u8], stride: usize, cols: usize, rows: usize| {
            let mut out = vec![0xEE; rows * (cols + pad)];
            copy_rows(&mut out, plane, (stride, cols + pad), (cols, rows));
            (out, cols + pad)
        };
        let (cols, rows, chroma) = (w.div_ceil(2), h.div_ceil(2), l.chroma_stride as usize);
        Self {
            width: w,
            height: h,
            planes: [
                repad(source.y(), l.luma_stride as usize, w, h),
                repad(source.cb(), chroma, cols, rows),
                repad(source.cr(), chroma, cols, rows),
            ],
        }
    }
}

impl YUVSource for Padded {
    fn dimensions(&self) -> (usize, usize) {
        (self.width, self.height)
    }
    fn strides(&self) -> (usize, usize, usize) {
        let [y, u, v] = &self.planes;
        (y.1, u.1, v.1)
    }
    fn y(&self) -> &[u8] {
        &self.planes[0].0
    }
    fn u(&self) -> &[u8] {
        &self.planes[1].0
    }
    fn v(&self) -> &[u8] {
        &self.planes[2].0
    }
}
