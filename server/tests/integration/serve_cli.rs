//! `lightcast-server` (serve, the default) run as a user would: it starts on the built-in scene,
//! logs the adapter and URL, answers HTTP, and stops cleanly on SIGTERM.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

fn server(args: &[&str], env: &[(&str, &str)]) -> (Child, mpsc::Receiver<String>) {
    let cache = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("lightcast-serve-cli-{}", std::process::id()));
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_lightcast-server"));
    cmd.args(args)
        .env("LIGHTCAST_CACHE_DIR", &cache)
        .env("RUST_LOG", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let mut child = cmd.spawn().expect("lightcast-server starts");
    let stderr = child.stderr.take().expect("stderr");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    (child, rx)
}

/// Waits for a log line containing `needle`; returns it.
fn wait_for(lines: &mpsc::Receiver<String>, needle: &str, seen: &mut Vec<String>) -> String {
    loop {
        let line = lines
            .recv_timeout(Duration::from_secs(120))
            .unwrap_or_else(|_| panic!("no log line with '{needle}'; saw:\n{}", seen.join("\n")));
        seen.push(line.clone());
        if line.contains(needle) {
            return line;
        }
    }
}

fn get(addr: &str, path: &str) -> String {
    let mut stream = TcpStream::connect(addr).expect("connect");
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .expect("write");
    let mut response = String::new();
    stream.read_to_string(&mut response).expect("read");
    response
}

#[test]
fn serves_by_default_and_stops_on_sigterm() {
    let (mut child, lines) = server(&[], &[("LIGHTCAST_LISTEN", "127.0.0.1:0")]);
    let mut seen = Vec::new();
    wait_for(&lines, "adapter:", &mut seen);
    let listening = wait_for(&lines, "listening on http://", &mut seen);
    let addr = listening
        .rsplit("http://")
        .next()
        .expect("address")
        .trim()
        .to_string();
    let health = get(&addr, "/healthz");
    assert!(health.starts_with("HTTP/1.1 200"), "{health}");
    let scenes = get(&addr, "/v1/scenes");
    assert!(scenes.contains("\"id\":\"default\""), "{scenes}");

    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill");
    assert!(status.success());
    wait_for(&lines, "stopped", &mut seen);
    let exit = child.wait().expect("exit status");
    assert!(exit.success(), "exit {exit:?}; log:\n{}", seen.join("\n"));
}

/// `--log-format json`: every line the service logs is one JSON object with a level and the
/// message. (The Vulkan driver may print plain lines of its own to stderr; they are not ours.)
#[test]
fn logs_json_lines_for_collectors() {
    let (mut child, lines) = server(
        &["--log-format", "json"],
        &[("LIGHTCAST_LISTEN", "127.0.0.1:0")],
    );
    let mut seen = Vec::new();
    wait_for(&lines, "listening on http://", &mut seen);
    child.kill().expect("kill");
    let _ = child.wait();
    let messages: Vec<String> = seen
        .iter()
        .filter(|line| line.starts_with('{'))
        .map(|line| {
            let v: serde_json::Value = serde_json::from_str(line)
                .unwrap_or_else(|e| panic!("not a JSON log line ({e}): {line}"));
            assert!(v["level"].is_string(), "{line}");
            v["fields"]["message"]
                .as_str()
                .unwrap_or_else(|| panic!("{line}"))
                .to_string()
        })
        .collect();
    for expected in ["adapter:", "listening on http://"] {
        assert!(
            messages.iter().any(|m| m.starts_with(expected)),
            "no JSON line '{expected}…' in:\n{}",
            seen.join("\n")
        );
    }
    assert!(
        !seen.iter().any(|l| l.contains(" INFO ")),
        "text-format lines: {seen:?}"
    );
}

#[test]
fn refuses_bad_options_with_a_reason() {
    let cases: &[(&[&str], &str)] = &[
        (&["--listen", "not-an-address"], "invalid socket address"),
        (&["serve", "--max-width", "0"], "--max-width"),
        (&["serve", "--token", "short"], "too easy to guess"),
        (&["serve", "--default-scene", "procedural:teapot"], "teapot"),
        (
            &["serve", "--backend", "gl"],
            "OpenGL backend is not supported",
        ),
        (&["serve", "--frames-in-flight", "4"], "--frames-in-flight"),
        (&["serve", "--frames-in-flight", "0"], "--frames-in-flight"),
        (&["serve", "--visibility-buffer", "maybe"], "auto, on, off"),
    ];
    for (args, needle) in cases {
        let mut all = args.to_vec();
        all.extend(
            ["--listen", "127.0.0.1:0"]
                .iter()
                .filter(|_| !args.contains(&"--listen")),
        );
        let output = Command::new(env!("CARGO_BIN_EXE_lightcast-server"))
            .args(&all)
            .output()
            .expect("runs");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "{args:?} must fail");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}

/// A long path-traced one-shot render is accumulated in chunks of samples (issue 30); when its
/// client has gone, it stops at the next chunk instead of running to its end, and says so.
#[test]
fn a_chunked_render_nobody_waits_for_stops_between_chunks() {
    let (mut child, lines) = server(
        &["--allow-cpu-adapter"],
        &[("LIGHTCAST_LISTEN", "127.0.0.1:0")],
    );
    let mut seen = Vec::new();
    let listening = wait_for(&lines, "listening on http://", &mut seen);
    let addr = listening
        .rsplit("http://")
        .next()
        .expect("address")
        .trim()
        .to_string();
    // About 8 s of estimated path tracing on lavapipe, in chunks of about 1 s.
    let body = r#"{"render": {"width": 96, "height": 64, "gi": {"method": "reference", "spp": 120, "bounces": 4}}}"#;
    let mut stream = TcpStream::connect(&addr).expect("connect");
    write!(
        stream,
        "POST /v1/render HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .expect("send");
    std::thread::sleep(Duration::from_millis(500));
    drop(stream);
    let stopped = wait_for(&lines, "stopped between chunks", &mut seen);
    assert!(stopped.contains("samples"), "{stopped}");
    child.kill().expect("kill");
    let _ = child.wait();
}
