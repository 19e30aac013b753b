//! The offline `render` command, run as a user would run the binary.

use crate::support::not_exercised;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const CORNELL_GLB: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../tests/data/cornell-box/cornell-box.glb"
);

fn out_dir() -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("lightcast-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

fn run(args: &[&str]) -> Output {
    let output = Command::new(env!("CARGO_BIN_EXE_lightcast-server"))
        .args(args)
        .env("LIGHTCAST_CACHE_DIR", out_dir().join("light-caches"))
        .output()
        .expect("run lightcast-server");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        !stderr.contains("panicked"),
        "the binary panicked: {stderr}"
    );
    output
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Runs `render` into `name` under the temp dir with `extra` options; returns the image.
fn render_ok(name: &str, extra: &[&str]) -> (image::RgbaImage, String, String) {
    let out = out_dir().join(name);
    let out_s = out.to_string_lossy().into_owned();
    let mut args = vec![
        "render",
        "--width",
        "96",
        "--height",
        "64",
        "--shadow-map-size",
        "256",
        "--out",
        &out_s,
    ];
    args.extend_from_slice(extra);
    let o = run(&args);
    assert!(o.status.success(), "render failed: {}", text(&o.stderr));
    let img = image::open(&out)
        .expect("output decodes as an image")
        .to_rgba8();
    (img, text(&o.stdout), text(&o.stderr))
}

fn mean_abs_diff(a: &image::RgbaImage, b: &image::RgbaImage) -> f64 {
    let sum: u64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| u64::from(x.abs_diff(*y)))
        .sum();
    sum as f64 / a.as_raw().len() as f64
}

fn mean_level(a: &image::RgbaImage) -> f64 {
    let sum: u64 = a
        .pixels()
        .map(|p| u64::from(p[0]) + u64::from(p[1]) + u64::from(p[2]))
        .sum();
    sum as f64 / (3 * a.width() * a.height()) as f64
}

#[test]
fn renders_the_shared_glb_and_prints_adapter_and_stage_times() {
    let (img, stdout, stderr) = render_ok("glb.png", &["--scene", CORNELL_GLB]);
    assert_eq!(img.dimensions(), (96, 64));
    assert!(stderr.contains("adapter:"), "{stderr}");
    assert!(stderr.contains("cornell-box"), "{stderr}");
    for stage in ["shadow_map", "gbuffer", "direct_light", "tonemap", "total"] {
        assert!(stdout.contains(stage), "missing {stage} in {stdout}");
    }
    assert!(stdout.contains("wrote"), "{stdout}");
}

#[test]
fn without_a_scene_renders_the_builtin_cornell_box() {
    let (img, _, stderr) = render_ok("default.png", &[]);
    assert!(stderr.contains("scene cornell"), "{stderr}");
    assert!(mean_level(&img) > 10.0, "image is black");
}

#[test]
fn json_report_is_machine_readable() {
    let (_, stdout, _) = render_ok(
        "json.png",
        &["--json", "--scene", "procedural:street?blocks=2"],
    );
    let report: serde_json::Value = serde_json::from_str(&stdout).expect("stdout is JSON");
    assert_eq!(report["width"], 96);
    assert!(report["adapter"].as_str().is_some_and(|a| !a.is_empty()));
    let stages = report["stages"].as_array().expect("stages");
    assert!(stages.len() >= 5);
    assert!(report["timing_source"].as_str().is_some());
    assert!(report["triangles"].as_u64().is_some_and(|t| t > 100));
    // The built-in Cornell box has one light (its lamp's stand-in): every light is listed,
    // the first also as `light`.
    let lights = report["lights"].as_array().expect("lights");
    assert_eq!(lights.len(), 1, "{report}");
    assert_eq!(lights[0], report["light"]);
}

#[test]
fn camera_and_light_options_change_the_image() {
    let fixed = [
        "--exposure",
        "1",
        "--light-type",
        "directional",
        "--light-dir",
        "0.2,-1,-0.3",
    ];
    let base = [&fixed[..], &["--light-intensity", "2"]].concat();
    let brighter = [&fixed[..], &["--light-intensity", "4"]].concat();
    let (a, _, _) = render_ok("light-a.png", &base);
    let (b, _, _) = render_ok("light-b.png", &brighter);
    assert!(
        mean_level(&b) > mean_level(&a) + 2.0,
        "{} vs {}",
        mean_level(&b),
        mean_level(&a)
    );

    let moved = [
        &base[..],
        &[
            "--camera-pos",
            "0.5,1.5,3",
            "--camera-target",
            "0,0.8,0",
            "--fov",
            "60",
        ],
    ]
    .concat();
    let (c, _, _) = render_ok("camera.png", &moved);
    assert!(
        mean_abs_diff(&a, &c) > 5.0,
        "moving the camera barely changed the image"
    );

    for kind in ["spot", "point"] {
        let (img, _, _) = render_ok(
            &format!("{kind}.png"),
            &["--light-type", kind, "--light-pos", "0,1.7,0.2"],
        );
        assert!(mean_level(&img) > 5.0, "{kind} light left the image black");
    }
}

/// Each bad invocation fails with a non-zero exit and a message naming the problem.
#[test]
fn bad_input_is_reported_precisely_without_panicking() {
    let dir = out_dir();
    let truncated = dir.join("truncated.glb");
    let bytes = std::fs::read(CORNELL_GLB).expect("read glb");
    std::fs::write(&truncated, &bytes[..bytes.len() / 3]).expect("write truncated");
    let garbage = dir.join("garbage.gltf");
    std::fs::write(&garbage, b"{ this is not json").expect("write garbage");
    let missing = dir.join("does-not-exist.glb");
    let out = dir.join("bad.png").to_string_lossy().into_owned();
    let _ = std::fs::remove_file(&out);
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["--scene".into(), missing.to_string_lossy().into()],
            "does-not-exist.glb",
        ),
        (
            vec!["--scene".into(), truncated.to_string_lossy().into()],
            "truncated.glb",
        ),
        (
            vec!["--scene".into(), garbage.to_string_lossy().into()],
            "garbage.gltf",
        ),
        (
            vec!["--scene".into(), "procedural:castle".into()],
            "known scenes",
        ),
        (
            vec!["--scene".into(), "procedural:street?blocks=0".into()],
            "blocks",
        ),
        (vec!["--width".into(), "0".into()], "width"),
        (vec!["--height".into(), "100000".into()], "height"),
        (
            vec!["--shadow-map-size".into(), "4".into()],
            "shadow_map_size",
        ),
        (vec!["--camera-pos".into(), "1,2".into()], "three"),
        (vec!["--fov".into(), "0".into()], "fov"),
        (vec!["--light-type".into(), "laser".into()], "laser"),
        (
            vec!["--light-dir".into(), "0,0,0".into()],
            "light.direction",
        ),
        (
            vec!["--light-intensity".into(), "-3".into()],
            "light.intensity",
        ),
        (vec!["--exposure".into(), "-1".into()], "exposure"),
        (vec!["--backend".into(), "directx9".into()], "directx9"),
        (
            vec!["--out".into(), "/nonexistent-dir/x.png".into()],
            "nonexistent-dir",
        ),
        (vec!["--gi-param".into(), "val_count=0".into()], "val_count"),
        (vec!["--gi-param".into(), "rsm_size=5".into()], "rsm_size"),
        (
            vec!["--gi-param".into(), "view_samples=100000".into()],
            "view_samples",
        ),
        (
            vec!["--gi-param".into(), "cache_distance=nan".into()],
            "cache_distance",
        ),
        (
            vec!["--gi-param".into(), "cache_distance=0.00001".into()],
            "d_eps",
        ),
        (
            vec!["--gi-param".into(), "cache_angle=120".into()],
            "cache_angle",
        ),
        (
            vec![
                "--gi".into(),
                "none".into(),
                "--view".into(),
                "indirect".into(),
            ],
            "--view indirect",
        ),
        (vec!["--gi".into(), "fancy".into()], "fancy"),
        (
            vec![
                "--gi".into(),
                "clustered".into(),
                "--gi-param".into(),
                "vpl_count=100".into(),
            ],
            "vpl_count",
        ),
        (
            vec![
                "--gi".into(),
                "clustered".into(),
                "--gi-param".into(),
                "visibility=soft".into(),
            ],
            "soft",
        ),
        (
            vec![
                "--gi".into(),
                "brsm".into(),
                "--view".into(),
                "clusters".into(),
            ],
            "--gi clustered",
        ),
        (
            vec![
                "--gi".into(),
                "lightskin".into(),
                "--view".into(),
                "importance".into(),
            ],
            "--gi brsm",
        ),
    ];
    for (extra, needle) in cases {
        let mut args: Vec<String> = ["render", "--width", "32", "--height", "32"]
            .map(String::from)
            .to_vec();
        if !extra.iter().any(|a| a == "--out") {
            args.extend(["--out".to_string(), out.clone()]);
        }
        args.extend(extra.iter().cloned());
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run(&refs);
        let stderr = text(&o.stderr);
        assert!(!o.status.success(), "{extra:?} should fail");
        assert!(
            stderr.contains(needle),
            "{extra:?}: error should mention '{needle}': {stderr}"
        );
    }
    assert!(
        !Path::new(&out).exists(),
        "a failed render must not leave an output file"
    );
}

/// `--gi clustered` with its flags: they reach the renderer (the JSON report's settings),
/// its stages run and indirect light brightens the image.
#[test]
fn clustered_renders_with_its_flags() {
    let common = ["--gi-param", "rsm_size=32", "--exposure", "1"];
    let (none, _, _) = render_ok(
        "clustered-none.png",
        &[&common[..], &["--gi", "none"]].concat(),
    );
    let flags = [
        "--gi",
        "clustered",
        "--gi-param",
        "vpl_count=512",
        "--gi-param",
        "cluster_count=8",
        "--gi-param",
        "kmeans_iterations=2",
        "--gi-param",
        "interleave=4",
        "--gi-param",
        "paraboloid_size=32",
        "--json",
    ];
    let (lit, stdout, _) = render_ok("clustered.png", &[&common[..], &flags[..]].concat());
    let report: serde_json::Value = serde_json::from_str(&stdout).expect("stdout is JSON");
    let gi = &report["gi"];
    assert_eq!(gi["method"], "clustered");
    assert_eq!(
        (
            &gi["vpl_count"],
            &gi["cluster_count"],
            &gi["kmeans_iterations"],
            &gi["interleave"]
        ),
        (&512.into(), &8.into(), &2.into(), &4.into())
    );
    assert_eq!(gi["visibility"], "cssm");
    assert_eq!(gi["paraboloid_size"], 32);
    for stage in [
        "rsm",
        "vpl_generation",
        "clustering",
        "paraboloid_maps",
        "cssm_basis",
        "clustered_indirect",
        "geometry_blur",
    ] {
        assert!(stdout.contains(stage), "missing {stage}: {stdout}");
    }
    assert!(
        mean_level(&lit) > mean_level(&none) + 1.0,
        "{} vs {}",
        mean_level(&lit),
        mean_level(&none)
    );
    let (clusters, _, _) = render_ok(
        "clustered-view.png",
        &[&common[..], &flags[..10], &["--view", "clusters"]].concat(),
    );
    assert_eq!(clusters.dimensions(), (32, 32), "the RSM's size");
    assert!(mean_level(&clusters) > 1.0, "the clusters view is black");
    for view in ["vpls", "val-shadow"] {
        let (image, _, _) = render_ok(
            &format!("clustered-{view}.png"),
            &[&common[..], &flags[..12], &["--view", view]].concat(),
        );
        assert!(mean_level(&image) > 1.0, "the {view} view is black");
    }
}

#[test]
fn gi_methods_and_debug_views_write_images() {
    let small = [
        "--gi-param",
        "rsm_size=32",
        "--gi-param",
        "val_count=256",
        "--gi-param",
        "view_samples=32",
        "--exposure",
        "1",
    ];
    let (none, _, _) = render_ok("gi-none.png", &[&small[..], &["--gi", "none"]].concat());
    let (brsm, stdout, stderr) =
        render_ok("gi-brsm.png", &[&small[..], &["--gi", "brsm"]].concat());
    let (lightskin, _, _) = render_ok(
        "gi-lightskin.png",
        &[&small[..], &["--gi", "lightskin"]].concat(),
    );
    assert!(stderr.contains("light caches:"), "{stderr}");
    for stage in [
        "rsm",
        "importance",
        "cumulative_sums",
        "val_select",
        "cache_lighting",
        "proxy_occlusion",
        "indirect_light",
    ] {
        assert!(stdout.contains(stage), "missing {stage}: {stdout}");
    }
    // Indirect light only adds: both GI images are brighter than direct light alone.
    assert!(
        mean_level(&brsm) > mean_level(&none) + 1.0,
        "{} vs {}",
        mean_level(&brsm),
        mean_level(&none)
    );
    assert!(mean_level(&lightskin) > mean_level(&none) + 1.0);
    for (view, size) in [
        ("indirect", (96, 64)),
        ("rsm-flux", (32, 32)),
        ("importance", (32, 32)),
        ("selected-vals", (32, 32)),
        ("caches", (96, 64)),
    ] {
        let (img, _, _) = render_ok(
            &format!("view-{view}.png"),
            &[&small[..], &["--view", view]].concat(),
        );
        assert_eq!(img.dimensions(), size, "{view}");
        assert!(mean_level(&img) > 1.0, "{view} is black");
    }
}

/// A Vulkan driver that is installed but opens no adapter (here an ICD file naming a library
/// that does not exist, as after a half-removed GPU driver) falls back to lavapipe instead of
/// failing. Needs lavapipe installed (as `deploy/setup-debian.sh` does without a GPU).
#[test]
fn a_broken_vulkan_driver_falls_back_to_lavapipe() {
    let installed = lightcast_server::gpu::context::lavapipe_icd().is_some();
    if !installed {
        not_exercised("lavapipe is not installed here: the fallback cannot be exercised");
        return;
    }
    let broken = out_dir().join("broken_icd.json");
    std::fs::write(
        &broken,
        r#"{"file_format_version": "1.0.0", "ICD": {"library_path": "/nonexistent/libvulkan_broken.so", "api_version": "1.3.0"}}"#,
    )
    .expect("write ICD file");
    let out = out_dir().join("fallback.png");
    let output = Command::new(env!("CARGO_BIN_EXE_lightcast-server"))
        .args([
            "render", "--width", "32", "--height", "32", "--gi", "none", "--out",
        ])
        .arg(&out)
        .env("LIGHTCAST_CACHE_DIR", out_dir().join("light-caches"))
        .env("VK_DRIVER_FILES", &broken)
        .env("VK_ICD_FILENAMES", &broken)
        .output()
        .expect("run lightcast-server");
    let stderr = text(&output.stderr);
    assert!(output.status.success(), "render failed: {stderr}");
    assert!(stderr.contains("falling back to lavapipe"), "{stderr}");
    image::open(&out).expect("the fallback rendered an image");
}

/// A reader that stops early (`lightcast-server openapi | head -c 1`) ends the output, not the
/// program with a panic.
#[test]
fn a_closed_stdout_ends_the_output_quietly() {
    use std::io::Read;
    use std::process::Stdio;
    let mut child = Command::new(env!("CARGO_BIN_EXE_lightcast-server"))
        .arg("openapi")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let mut first = [0u8; 1];
    child
        .stdout
        .take()
        .expect("stdout")
        .read_exact(&mut first)
        .expect("one byte");
    // The pipe is closed here, long before the document's ~100 kB are written.
    let output = child.wait_with_output().expect("wait");
    assert_eq!(first[0], b'{');
    assert!(output.status.success(), "{}", text(&output.stderr));
    assert!(
        !text(&output.stderr).contains("panicked"),
        "{}",
        text(&output.stderr)
    );
}

/// `--environment image --environment-image FILE`: a uniform `.hdr` lights the frame as a
/// uniform environment of its radiance does; without the file, or with a broken one, the
/// command says which flag is wrong.
#[test]
fn an_environment_image_file_lights_the_render() {
    let dir = out_dir();
    let hdr = dir.join("uniform.hdr");
    let texels = vec![0.5f32; 32 * 16 * 3];
    let buffer = image::Rgb32FImage::from_raw(32, 16, texels).expect("size");
    image::DynamicImage::ImageRgb32F(buffer)
        .save_with_format(&hdr, image::ImageFormat::Hdr)
        .expect("write .hdr");
    let hdr_s = hdr.to_string_lossy().into_owned();
    let common = [
        "--gi",
        "none",
        "--exposure",
        "0.5",
        "--environment-directions",
        "4",
    ];
    let (image_lit, _, _) = render_ok(
        "env-image.png",
        &[
            &common[..],
            &["--environment", "image", "--environment-image", &hdr_s],
        ]
        .concat(),
    );
    let (uniform_lit, _, _) = render_ok(
        "env-uniform.png",
        &[
            &common[..],
            &["--environment", "uniform", "--environment-intensity", "0.5"],
        ]
        .concat(),
    );
    let (dark, _, _) = render_ok("env-none.png", &common[..4]);
    assert!(
        mean_level(&image_lit) > mean_level(&dark) + 2.0,
        "{} vs {}",
        mean_level(&image_lit),
        mean_level(&dark)
    );
    let diff = mean_abs_diff(&image_lit, &uniform_lit);
    assert!(
        diff < 1.0,
        "image vs uniform of its radiance: {diff} levels"
    );

    let broken = dir.join("broken.hdr");
    std::fs::write(&broken, b"#?RADIANCE\nnot an image").expect("write");
    let out = dir.join("env-bad.png").to_string_lossy().into_owned();
    let broken_s = broken.to_string_lossy().into_owned();
    for (extra, needle) in [
        (vec!["--environment", "image"], "environment.kind"),
        (
            vec!["--environment", "image", "--environment-image", &broken_s],
            "--environment-image",
        ),
    ] {
        let o = run(&[&["render", "--out", &out][..], &extra].concat());
        assert!(!o.status.success(), "{extra:?} succeeded");
        let err = text(&o.stderr);
        assert!(err.contains(needle), "{extra:?}: {err}");
    }
}

/// `--no-lights`: the Cornell box lit by its lamp alone (emitters on by default without the
/// stand-in spot), far brighter than with `emitters=false` (where only the lamp itself glows);
/// a light flag beside it is refused.
#[test]
fn no_lights_renders_the_lamp_alone() {
    let common = [
        "--no-lights",
        "--gi",
        "clustered",
        "--gi-param",
        "rsm_size=32",
        "--exposure",
        "1",
    ];
    let (lamp, stdout, _) = render_ok("no-lights.png", &[&common[..], &["--json"]].concat());
    let report: serde_json::Value = serde_json::from_str(&stdout).expect("JSON report");
    assert_eq!(report["lights"], serde_json::json!([]));
    assert!(report.get("light").is_none(), "{report}");
    assert_eq!(report["gi"]["emitters"], serde_json::json!(true));
    let (glow, _, _) = render_ok(
        "no-lights-no-emitters.png",
        &[&common[..], &["--gi-param", "emitters=false"]].concat(),
    );
    assert!(
        mean_level(&lamp) > mean_level(&glow) * 1.5,
        "{} vs {}",
        mean_level(&lamp),
        mean_level(&glow)
    );
    let out = out_dir()
        .join("no-lights-bad.png")
        .to_string_lossy()
        .into_owned();
    let o = run(&[
        "render",
        "--no-lights",
        "--light-intensity",
        "3",
        "--out",
        &out,
    ]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("--no-lights"),
        "{}",
        text(&o.stderr)
    );
}
