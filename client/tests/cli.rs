//! The `lightcast` binary run as a user would, against a real server on loopback.

use lightcast_e2e::{cornell_glb, TestServer};
use serde_json::Value;
use std::process::Output;

/// Runs `lightcast --server URL ARGS…` off the async runtime.
async fn lightcast(server: &str, args: &[&str]) -> Output {
    let mut all = vec!["--server".to_string(), server.to_string()];
    all.extend(args.iter().map(|s| s.to_string()));
    tokio::task::spawn_blocking(move || {
        std::process::Command::new(env!("CARGO_BIN_EXE_lightcast"))
            .args(&all)
            .output()
            .expect("lightcast runs")
    })
    .await
    .expect("join")
}

fn json(o: &Output) -> Value {
    assert!(
        o.status.success(),
        "lightcast failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&o.stdout)))
}

const SMALL: &[&str] = &[
    "--width",
    "64",
    "--height",
    "48",
    "--shadow-map-size",
    "256",
    "--gi-param",
    "rsm_size=32",
    "--gi-param",
    "val_count=256",
    "--gi-param",
    "view_samples=64",
];

fn with<'a>(head: &[&'a str], tail: &[&'a str]) -> Vec<&'a str> {
    head.iter().chain(tail).copied().collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenes_subcommands() {
    let server = TestServer::start(&[]).await;
    let base = server.base.clone();
    let list = json(&lightcast(&base, &["--json", "scenes", "list"]).await);
    assert_eq!(list[0]["id"], "default");
    let table = lightcast(&base, &["scenes", "list"]).await;
    assert!(String::from_utf8_lossy(&table.stdout).contains("cornell"));

    let dir = tempfile::tempdir().expect("tempdir");
    let glb = dir.path().join("box.glb");
    std::fs::write(&glb, cornell_glb()).expect("write glb");
    let (gltf, bin) = lightcast_e2e::glb_to_gltf(&cornell_glb(), "box.bin");
    let gltf_path = dir.path().join("box.gltf");
    std::fs::write(&gltf_path, gltf).expect("write gltf");
    std::fs::write(dir.path().join("box.bin"), bin).expect("write bin");
    let uploaded = json(
        &lightcast(
            &base,
            &[
                "--json",
                "scenes",
                "upload",
                glb.to_str().unwrap(),
                "--name",
                "my box",
            ],
        )
        .await,
    );
    assert_eq!(uploaded["name"], "my box");
    let from_gltf = json(
        &lightcast(
            &base,
            &["--json", "scenes", "upload", gltf_path.to_str().unwrap()],
        )
        .await,
    );
    assert_eq!(from_gltf["triangles"], uploaded["triangles"]);
    let id = uploaded["id"].as_str().expect("id");
    let shown = json(&lightcast(&base, &["--json", "scenes", "show", id]).await);
    assert_eq!(shown["id"], id);
    let removed = lightcast(&base, &["scenes", "rm", id]).await;
    assert!(removed.status.success());
    let missing = lightcast(&base, &["scenes", "show", id]).await;
    assert!(!missing.status.success());
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert!(stderr.contains("404") && stderr.contains(id), "{stderr}");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn render_writes_the_image_and_a_report() {
    let server = TestServer::start(&[]).await;
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("frame.png");
    let args = with(
        &[
            "--json",
            "render",
            "--out",
            out.to_str().unwrap(),
            "--repeat",
            "2",
            "--camera-pos",
            "0.5,1.2,3",
        ],
        SMALL,
    );
    let report = json(&lightcast(&server.base, &args).await);
    assert_eq!(report["repeat"], 2);
    assert_eq!(report["report"]["width"], 64);
    assert!(report["report"]["stages"]
        .as_array()
        .is_some_and(|s| !s.is_empty()));
    let position: Vec<f64> = report["report"]["camera"]["position"]
        .as_array()
        .expect("camera position")
        .iter()
        .filter_map(Value::as_f64)
        .collect();
    let expected = [0.5, 1.2, 3.0];
    assert!(
        position.len() == 3
            && position
                .iter()
                .zip(expected)
                .all(|(a, b)| (a - b).abs() < 1e-5),
        "{position:?}"
    );
    let img = image::open(&out).expect("PNG").to_rgba8();
    assert_eq!(img.dimensions(), (64, 48));
    let table = lightcast(
        &server.base,
        &with(&["render", "--out", out.to_str().unwrap()], SMALL),
    )
    .await;
    let text = String::from_utf8_lossy(&table.stdout);
    assert!(
        text.contains("cache_lighting") && text.contains("wrote"),
        "{text}"
    );
    // Compared with the path-traced reference: the errors are printed.
    let compared = lightcast(
        &server.base,
        &with(
            &[
                "render",
                "--out",
                out.to_str().unwrap(),
                "--compare-to",
                "reference",
                "--compare-spp",
                "8",
            ],
            SMALL,
        ),
    )
    .await;
    let text = String::from_utf8_lossy(&compared.stdout);
    assert!(
        compared.status.success()
            && text.contains("against reference (8 spp")
            && text.contains("relative MAE")
            && text.contains("PSNR"),
        "{text}"
    );
    // Only the reference is offered to compare with (the server refuses the others), before
    // anything is sent.
    let other = lightcast(
        "http://127.0.0.1:9",
        &["render", "--out", "x.png", "--compare-to", "brsm"],
    )
    .await;
    let stderr = String::from_utf8_lossy(&other.stderr);
    assert!(
        !other.status.success() && stderr.contains("possible values: reference"),
        "{stderr}"
    );
    // A parameter the server refuses: exit 1 and the server's reason with the field.
    let bad = lightcast(
        &server.base,
        &["render", "--out", out.to_str().unwrap(), "--width", "0"],
    )
    .await;
    assert!(!bad.status.success());
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(stderr.contains("render.width"), "{stderr}");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stream_replays_a_camera_path_and_saves_frames() {
    let server = TestServer::start(&[]).await;
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("path.json");
    std::fs::write(
        &path,
        r#"{"keyframes": [
            {"t": 0, "camera": {"position": [0, 1, 3.9], "target": [0, 1, 0], "fov_y_degrees": 40}},
            {"t": 2, "camera": {"position": [1.5, 1, 3.5], "target": [0, 1, 0], "fov_y_degrees": 40}}]}"#,
    )
    .expect("path file");
    let frames_dir = dir.path().join("frames");
    let args = with(
        &[
            "--json",
            "stream",
            "--frames",
            "4",
            "--duration",
            "120",
            "--camera-path",
            path.to_str().unwrap(),
            "--input-hz",
            "10",
            "--save",
            frames_dir.to_str().unwrap(),
            "--gi",
            "none",
        ],
        SMALL,
    );
    let summary = json(&lightcast(&server.base, &args).await);
    assert_eq!(summary["frames"], 4);
    assert!(summary["fps"].as_f64().is_some_and(|f| f > 0.0));
    // Four frames arrived one after another: the longest wait between them is a real gap,
    // no longer than the whole stream.
    let gap = summary["longest_gap_ms"].as_f64().expect("longest_gap_ms");
    let total = summary["seconds"].as_f64().expect("seconds") * 1e3;
    assert!(gap > 0.0 && gap <= total, "{gap} of {total}");
    assert!(summary["split"]["gpu_ms"].as_f64().is_some_and(|g| g > 0.0));
    let saved: Vec<_> = std::fs::read_dir(&frames_dir)
        .expect("frames dir")
        .collect();
    assert_eq!(saved.len(), 4);
    let bad_path = dir.path().join("bad.json");
    std::fs::write(&bad_path, r#"{"keyframes": []}"#).expect("write");
    let refused = lightcast(
        &server.base,
        &["stream", "--camera-path", bad_path.to_str().unwrap()],
    )
    .await;
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("no keyframes"));
    server.stop().await;
}

/// `stream --node-path` moves the Cornell box's boxes (node 1 the short box at rest at
/// (0.33, 0, 0.37), node 2 the tall one at (−0.33, 0, −0.28)) by 0.2 m and a quarter turn
/// while a camera path plays; the server takes every `nodes` message (no error comes back).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stream_replays_a_node_path_with_a_camera_path() {
    let server = TestServer::start(&[]).await;
    let dir = tempfile::tempdir().expect("tempdir");
    let nodes = dir.path().join("nodes.json");
    std::fs::write(
        &nodes,
        r#"{"keyframes": [
            {"t": 0, "nodes": [{"node": 1, "translation": [0.33, 0, 0.37]},
                               {"node": 2, "translation": [-0.33, 0, -0.28], "rotation": [0, 0, 0, 1]}]},
            {"t": 0.5, "nodes": [{"node": 1, "translation": [0.13, 0, 0.37], "scale": [1, 0.8, 1]}]},
            {"t": 1, "nodes": [{"node": 2, "translation": [-0.13, 0, -0.28], "rotation": [0, 0.70710677, 0, 0.70710677]}]}]}"#,
    )
    .expect("node path file");
    let camera = dir.path().join("camera.json");
    std::fs::write(
        &camera,
        r#"{"keyframes": [
            {"t": 0, "camera": {"position": [0, 1, 3.9], "target": [0, 1, 0], "fov_y_degrees": 40}},
            {"t": 1, "camera": {"position": [0.5, 1, 3.8], "target": [0, 1, 0], "fov_y_degrees": 40}}]}"#,
    )
    .expect("camera path file");
    let args = with(
        &[
            "--json",
            "stream",
            "--frames",
            "3",
            "--duration",
            "120",
            "--node-path",
            nodes.to_str().unwrap(),
            "--camera-path",
            camera.to_str().unwrap(),
            "--input-hz",
            "10",
            "--gi",
            "none",
        ],
        SMALL,
    );
    let summary = json(&lightcast(&server.base, &args).await);
    assert_eq!(summary["frames"], 3);
    assert_eq!(summary["errors"], serde_json::json!([]), "{summary}");
    // A node the scene does not let move is refused before any session opens, naming the
    // file and the nodes that do move.
    let bad = dir.path().join("bad.json");
    std::fs::write(
        &bad,
        r#"{"keyframes": [{"t": 0, "nodes": [{"node": 0, "translation": [0, 0.1, 0]}]}]}"#,
    )
    .expect("write");
    let refused = lightcast(
        &server.base,
        &["stream", "--node-path", bad.to_str().unwrap()],
    )
    .await;
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("bad.json")
            && stderr.contains("node 0 is not a movable node")
            && stderr.contains("1 'short box'"),
        "{stderr}"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn loadtest_reports_latency_fps_and_refuses_remote_targets() {
    let server = TestServer::start(&[]).await;
    let args = with(
        &[
            "--json",
            "loadtest",
            "--sessions",
            "3",
            // However slow this machine is, each session waits for its frames: at most
            // five minutes, ending at its third frame.
            "--frames",
            "3",
            "--duration",
            "300",
            "--ramp",
            "0.5",
            "--input-hz",
            "10",
            "--gi",
            "none",
        ],
        SMALL,
    );
    let report = json(&lightcast(&server.base, &args).await);
    assert_eq!(report["sessions"], 3);
    assert_eq!(report["failed_sessions"], 0, "{report}");
    assert_eq!(report["frames"], 9, "{report}");
    assert_eq!(report["gi"], "none");
    assert!(report["no_frames"].is_null(), "{report}");
    assert!(
        report["fps_min"].as_f64().is_some_and(|f| f > 0.0),
        "{report}"
    );
    assert!(
        report["input_to_frame_ms"]["samples"]
            .as_u64()
            .is_some_and(|n| n > 0),
        "{report}"
    );
    assert!(report["connect_ms"]["samples"] == 3);
    let remote = lightcast(
        "http://10.255.255.1:8080",
        &["loadtest", "--sessions", "1", "--duration", "1"],
    )
    .await;
    assert!(!remote.status.success());
    assert!(String::from_utf8_lossy(&remote.stderr).contains("--allow-remote"));
    let too_many = lightcast(&server.base, &["loadtest", "--sessions", "100000"]).await;
    assert!(!too_many.status.success());
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unreachable_server_is_reported_plainly() {
    let out = lightcast("http://127.0.0.1:9", &["scenes", "list"]).await;
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("cannot reach"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// Runs `openssl ARGS…` in `dir`, failing the test on an error.
fn openssl(dir: &std::path::Path, args: &[&str]) {
    let out = std::process::Command::new("openssl")
        .current_dir(dir)
        .args(args)
        .output()
        .expect("openssl runs (deploy/setup-debian.sh --tests installs it)");
    assert!(
        out.status.success(),
        "openssl {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `lightcast` reaches a server through TLS (`https://` requests, a `wss://` stream) behind a
/// real nginx terminating TLS with a certificate of a private CA: with `--ca-cert` the CA is
/// trusted, without it the client refuses the certificate and says so.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn render_and_stream_over_tls_with_a_private_ca() {
    let server = TestServer::start(&[]).await;
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    openssl(
        d,
        &[
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "2",
            "-subj",
            "/CN=lightcast test CA",
            "-keyout",
            "ca.key",
            "-out",
            "ca.pem",
        ],
    );
    openssl(
        d,
        &[
            "req",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-subj",
            "/CN=127.0.0.1",
            "-keyout",
            "server.key",
            "-out",
            "server.csr",
        ],
    );
    std::fs::write(
        d.join("san.ext"),
        "subjectAltName=IP:127.0.0.1,DNS:localhost\n",
    )
    .expect("ext");
    openssl(
        d,
        &[
            "x509",
            "-req",
            "-in",
            "server.csr",
            "-CA",
            "ca.pem",
            "-CAkey",
            "ca.key",
            "-CAcreateserial",
            "-days",
            "2",
            "-extfile",
            "san.ext",
            "-out",
            "server.pem",
        ],
    );
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let tmp = d.display();
    let config = format!(
        "daemon off;\nworker_processes 1;\npid {tmp}/nginx.pid;\nerror_log {tmp}/error.log;\n\
         events {{ worker_connections 64; }}\nhttp {{\naccess_log off;\n\
         client_body_temp_path {tmp}/body;\nproxy_temp_path {tmp}/proxy;\n\
         fastcgi_temp_path {tmp}/fastcgi;\nuwsgi_temp_path {tmp}/uwsgi;\nscgi_temp_path {tmp}/scgi;\n\
         map $http_upgrade $connection_upgrade {{ default upgrade; \"\" close; }}\n\
         server {{\n listen 127.0.0.1:{port} ssl;\n ssl_certificate {tmp}/server.pem;\n\
         ssl_certificate_key {tmp}/server.key;\n location / {{\n\
         proxy_pass http://127.0.0.1:{};\n proxy_http_version 1.1;\n\
         proxy_set_header Upgrade $http_upgrade;\n proxy_set_header Connection $connection_upgrade;\n\
         }}\n}}\n}}\n",
        server.port()
    );
    std::fs::write(d.join("nginx.conf"), config).expect("nginx.conf");
    let nginx = std::env::var("NGINX").unwrap_or_else(|_| "/usr/sbin/nginx".into());
    let proxy = std::process::Command::new(&nginx)
        .arg("-e")
        .arg(d.join("error.log"))
        .arg("-c")
        .arg(d.join("nginx.conf"))
        // Not the test's pipes: a child holding them would keep the harness waiting.
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("starting {nginx} ({e}): deploy/setup-debian.sh --tests"));
    let proxy = KillOnDrop(proxy);
    let https = format!("https://127.0.0.1:{port}");
    let ca = d.join("ca.pem").to_string_lossy().into_owned();
    let out = d.join("tls.png").to_string_lossy().into_owned();
    let mut listed = None;
    for _ in 0..100 {
        let o = lightcast(&https, &["--ca-cert", &ca, "--json", "scenes", "list"]).await;
        if o.status.success() {
            listed = Some(o);
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    let listed = listed.expect("the TLS proxy answers with --ca-cert");
    assert_eq!(json(&listed)[0]["id"], "default");

    let render = lightcast(
        &https,
        &with(
            &[
                "--ca-cert",
                &ca,
                "--json",
                "render",
                "--gi",
                "none",
                "--out",
                &out,
            ],
            SMALL,
        ),
    )
    .await;
    assert_eq!(json(&render)["report"]["width"], 64);
    assert!(std::path::Path::new(&out).exists());
    let stream = lightcast(
        &https,
        &[
            "--ca-cert",
            &ca,
            "--json",
            "stream",
            "--frames",
            "3",
            "--duration",
            "120",
            "--width",
            "32",
            "--height",
            "24",
            "--gi",
            "none",
        ],
    )
    .await;
    let report = json(&stream);
    assert!(report["frames"].as_u64().unwrap_or(0) >= 3, "{report}");

    let untrusted = lightcast(&https, &["scenes", "list"]).await;
    assert!(
        !untrusted.status.success(),
        "a private CA is not trusted by default"
    );
    let message = String::from_utf8_lossy(&untrusted.stderr).to_lowercase();
    assert!(message.contains("certificate"), "{message}");
    drop(proxy);
    server.stop().await;
}

/// A child process stopped when the test ends, passing or not.
struct KillOnDrop(std::process::Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `stream --codec h264 --video FILE` writes a raw H.264 stream that an independent decoder
/// plays from its first byte: every frame decodes at the requested size.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stream_saves_h264_video_a_decoder_plays() {
    let server = TestServer::start(&[]).await;
    let dir = tempfile::tempdir().expect("tempdir");
    let video = dir.path().join("out.h264");
    let video_arg = video.to_string_lossy().into_owned();
    let args = [
        "--json",
        "stream",
        "--frames",
        "6",
        "--duration",
        "120",
        "--width",
        "64",
        "--height",
        "48",
        "--gi",
        "none",
        "--codec",
        "h264",
        "--bitrate-kbps",
        "2000",
        "--video",
        &video_arg,
    ];
    let out = lightcast(&server.base, &args).await;
    let report = json(&out);
    assert_eq!(report["video"]["frames"], 6, "{report}");
    assert!(report["video"]["keyframes"].as_u64() >= Some(1), "{report}");
    let bytes = std::fs::read(&video).expect("the video file");
    let mut decoder = openh264::decoder::Decoder::new().expect("decoder");
    let mut pictures = 0;
    for nal in openh264::nal_units(&bytes) {
        if let Some(picture) = decoder.decode(nal).expect("decodes") {
            use openh264::formats::YUVSource;
            assert_eq!(picture.dimensions(), (64, 48));
            pictures += 1;
        }
    }
    assert_eq!(pictures, 6, "one picture per saved frame");

    // Video flags without the video codec are refused before anything is sent.
    let refused = lightcast(&server.base, &["stream", "--video", &video_arg]).await;
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(stderr.contains("--codec h264"), "{stderr}");
    server.stop().await;
}
