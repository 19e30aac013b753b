//! `lightcast-server bench-stream` end to end at tiny sizes: frames rendered on the GPU both
//! ways, every codec's stream decoded and measured, and the report consistent with itself.

use clap::Parser;
use lightcast_server::bench::stream::{self, Basis, CodecSetting, StreamBenchArgs};
use lightcast_server::passes::yuv420::Yuv420Layout;

#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    args: StreamBenchArgs,
}

#[test]
fn the_stream_bench_measures_every_codec_at_every_size() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let path_file = dir.path().join("path.json");
    let cli = Cli::try_parse_from([
        "bench-stream",
        "--sizes",
        "64x48,96x64",
        "--frames",
        "4",
        "--flip-every",
        "2",
        "--jpeg-qualities",
        "70,95",
        "--h264-kbps",
        "8000",
        "--shadow-map-size",
        "256",
        "--path-seconds",
        "1",
        "--write-path",
        path_file.to_str().expect("a UTF-8 path"),
    ])
    .expect("the flags parse");
    let report = stream::run(&cli.args, &mut |_| {}, &mut |_, _, _| {}).expect("runs");

    let sizes: Vec<(u32, u32)> = report.sizes.iter().map(|s| (s.width, s.height)).collect();
    assert_eq!(sizes, [(64, 48), (96, 64)]);
    for size in &report.sizes {
        let (w, h) = (size.width, size.height);
        let pixels = (w * h) as usize;
        assert_eq!(size.rgba8.bytes_per_frame, 4 * pixels);
        assert_eq!(size.yuv420.bytes_per_frame, Yuv420Layout::new(w, h).bytes());
        assert_eq!(size.yuv420.bytes_per_frame, pixels * 3 / 2, "1.5 B/px");
        assert_eq!(size.rows.len(), 3);
        for row in &size.rows {
            assert_eq!(row.frames.len(), 4, "{}", row.setting);
            assert!(row.frames.iter().all(|f| f.bytes > 0), "{}", row.setting);
            let flips: Vec<bool> = row.frames.iter().map(|f| f.flip.is_some()).collect();
            assert_eq!(flips, [true, false, true, false]);
            assert!(row.flip_mean > 0.0 && row.flip_mean < 0.5, "{row:?}");
            assert!(row.psnr_min_db <= row.psnr_mean_db);
        }
        let [q70, q95, video] = &size.rows[..] else {
            unreachable!("three rows")
        };
        assert_eq!(q70.setting, CodecSetting::Jpeg { quality: 70 });
        assert!(q95.bytes_per_frame > q70.bytes_per_frame);
        assert!(q95.psnr_mean_db > q70.psnr_mean_db, "{q95:?} vs {q70:?}");
        assert_eq!((q70.keyframes, video.keyframes), (4, 1));
        // H.264 encodes the GPU's 4:2:0 planes: at 8 Mbit/s it loses little beyond them.
        assert!(
            video.psnr_mean_db > size.yuv420_psnr_db - 2.0
                && video.psnr_mean_db <= size.yuv420_psnr_db + 0.1,
            "{video:?} vs 4:2:0 alone {:.2} dB",
            size.yuv420_psnr_db
        );
        assert!(video.psnr_min_db > 25.0, "{video:?}");
        let moving = size
            .comparisons
            .iter()
            .find(|c| c.bases.contains(&Basis::MovingQuality))
            .expect("compared with JPEG at the moving quality");
        assert_eq!((moving.h264_kbps, moving.jpeg_quality), (8000, 70));
        let ratio = video.bytes_per_frame / q70.bytes_per_frame;
        assert!((moving.bytes_ratio - ratio).abs() < 1e-12);
    }
    assert!(report.targets.is_none(), "no 1920×1080 in this run");
    let markdown = report.markdown();
    for heading in ["## 64×48", "## 96×64", "## Targets"] {
        assert!(markdown.contains(heading), "{heading} in\n{markdown}");
    }
    let json = serde_json::to_value(&report).expect("serializes");
    assert_eq!(json["sizes"][0]["rows"][2]["setting"]["codec"], "h264");

    // The path the service is driven along starts at the bench's first camera.
    let path: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path_file).expect("written")).expect("JSON");
    let keyframes = path["keyframes"].as_array().expect("keyframes");
    assert_eq!(keyframes.len(), 31, "a keyframe every 1/30 s for 1 s");
    let first: lightcast_protocol::Camera =
        serde_json::from_value(keyframes[0]["camera"].clone()).expect("a camera");
    assert_eq!(first, report.motion.base);
}
