//! `lightcast loadtest`: many concurrent sessions, each orbiting its camera, measured from the
//! client side.

use crate::api::Client;
use crate::drive::{self, DriveOptions, DriveResult, Motion};
use crate::flags::RenderFlags;
use crate::stats::{median, FrameSplit, Latencies, Percentiles};
use lightcast_protocol::Codec;
use serde::Serialize;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Most sessions one load test opens.
const MAX_SESSIONS: u32 = 256;
/// Longest load test.
const MAX_SECONDS: f64 = 600.0;

#[derive(clap::Args)]
pub struct LoadtestCmd {
    /// Concurrent sessions (1–256); a comma-separated list runs one test per count, in order.
    #[arg(long, default_value = "4", value_delimiter = ',', value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_SESSIONS)))]
    sessions: Vec<u32>,
    /// Also write the results as a markdown table to this file.
    #[arg(long)]
    markdown: Option<std::path::PathBuf>,
    /// Seconds measured after ramp-up (at most 600).
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// End each session once it has received this many frames after ramp-up (or at
    /// `--duration`, whichever comes first): a test that needs some frames on a slow machine
    /// waits for them instead of guessing a duration.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    frames: Option<u64>,
    /// Seconds over which the sessions are opened (not measured).
    #[arg(long, default_value_t = 1.0)]
    ramp: f64,
    /// Camera messages per second per session.
    #[arg(long, default_value_t = 20.0)]
    input_hz: f64,
    /// Orbit speed of each session's camera.
    #[arg(long, default_value_t = 30.0)]
    orbit_degrees_per_second: f64,
    /// Frames per second each session asks for.
    #[arg(long, default_value_t = 60.0)]
    fps_cap: f32,
    #[arg(long, value_enum, default_value = "jpeg")]
    codec: Codec,
    /// JPEG quality 1–100.
    #[arg(long, default_value_t = 80)]
    quality: u8,
    /// Allow a server that is not on this machine (load tests are for your own servers).
    #[arg(long)]
    allow_remote: bool,
    /// Give each session a light of its own: the scene's default light (or `--light`'s) with
    /// its intensity raised by 0.01 % per session index, so that no two sessions can share
    /// passes (the server reuses a shadow map or RSM only for the same lights): the control
    /// run for measuring what sharing saves.
    #[arg(long)]
    distinct_lights: bool,
    #[command(flatten)]
    render: RenderFlags,
}

/// The load test's result (`--json` prints it).
#[derive(Debug, Serialize)]
pub struct LoadReport {
    pub server: String,
    pub sessions: u32,
    pub width: u32,
    pub height: u32,
    pub gi: lightcast_protocol::GiMethod,
    pub seconds: f64,
    pub connect_ms: Percentiles,
    pub first_frame_ms: Percentiles,
    pub input_to_frame_ms: Percentiles,
    /// Frames per second received by each client over the measured window.
    pub fps_min: f64,
    pub fps_median: f64,
    pub fps_total: f64,
    pub frames: u64,
    /// Server counters summed over sessions.
    pub dropped: u64,
    pub throttled: u64,
    pub bytes_per_second: f64,
    pub split: FrameSplit,
    pub failed_sessions: u32,
    pub errors: Vec<String>,
    /// Why no frame arrived at all (`null` when frames did).
    pub no_frames: Option<String>,
}

fn is_loopback(url: &str) -> bool {
    let Some(host) = reqwest::Url::parse(url)
        .ok()
        .and_then(|u| u.host_str().map(str::to_string))
    else {
        return false;
    };
    host == "localhost"
        || host
            .trim_start_matches('[')
            .trim_end_matches(']')
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

impl LoadtestCmd {
    fn check(&self, server: &str) -> anyhow::Result<()> {
        if !self.allow_remote && !is_loopback(server) {
            anyhow::bail!("{server} is not on this machine; pass --allow-remote to load-test it");
        }
        let within = |name: &str, v: f64, lo: f64, hi: f64| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(anyhow::anyhow!("--{name} {v} is outside {lo}..={hi}"))
            }
        };
        within("duration", self.duration, 0.1, MAX_SECONDS)?;
        within("ramp", self.ramp, 0.0, MAX_SECONDS)?;
        within("input-hz", self.input_hz, 0.0, 1000.0)?;
        Ok(())
    }
}

pub async fn run(client: &Client, cmd: LoadtestCmd, json: bool) -> anyhow::Result<()> {
    cmd.check(client.base())?;
    let mut reports = Vec::new();
    for &sessions in &cmd.sessions {
        let report = run_one(client, &cmd, sessions, json).await?;
        if !json {
            print_table(&report);
            println!();
        }
        reports.push(report);
    }
    if json {
        match reports.as_slice() {
            [one] => println!("{}", serde_json::to_string_pretty(one)?),
            all => println!("{}", serde_json::to_string_pretty(all)?),
        }
    }
    if let Some(path) = &cmd.markdown {
        std::fs::write(path, markdown(&reports))
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    }
    Ok(())
}

/// One row per load test.
fn markdown(reports: &[LoadReport]) -> String {
    let mut out = String::from(
        "| sessions | size | GI | fps/client min | fps/client median | fps total | input→frame p50 / p95 / p99 ms | GPU ms | readback ms | encode ms | server ms | network ms | dropped | throttled | KiB/s | failed |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in reports {
        let l = &r.input_to_frame_ms;
        out.push_str(&format!(
            "| {} | {}×{} | {} | {:.1} | {:.1} | {:.1} | {:.1} / {:.1} / {:.1} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {:.0} | {} |\n",
            r.sessions, r.width, r.height, r.gi, r.fps_min, r.fps_median, r.fps_total,
            l.p50, l.p95, l.p99, r.split.gpu_ms, r.split.readback_ms, r.split.encode_ms,
            r.split.server_ms, r.split.network_ms, r.dropped, r.throttled,
            r.bytes_per_second / 1024.0, r.failed_sessions
        ));
    }
    out
}

async fn run_one(
    client: &Client,
    cmd: &LoadtestCmd,
    sessions: u32,
    json: bool,
) -> anyhow::Result<LoadReport> {
    let scene = client.scene(&cmd.render.scene).await?;
    let params = crate::session_params(
        cmd.render
            .params(Some(&scene.default_camera), Some(&scene.default_light)),
        Some(cmd.fps_cap),
        cmd.codec,
        Some(cmd.quality),
    );
    let start = Instant::now();
    let ramp = Duration::from_secs_f64(cmd.ramp);
    let measure_from = start + ramp;
    let deadline = measure_from + Duration::from_secs_f64(cmd.duration);
    let total = ramp + Duration::from_secs_f64(cmd.duration);
    let bar = indicatif::ProgressBar::new(total.as_secs().max(1));
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} s  {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    if json {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let frames_seen = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let mut tasks = Vec::new();
    for i in 0..sessions {
        let client = client.clone();
        let offset = ramp.mul_f64(f64::from(i) / f64::from(sessions));
        let mut params = params.clone();
        if cmd.distinct_lights {
            distinct_light(&mut params, &scene.default_light, i);
        }
        let opts = DriveOptions {
            params,
            // Spread the sessions around the orbit so they render different views.
            motion: Motion::Orbit {
                base: orbit_start(
                    &scene.default_camera,
                    360.0 * f64::from(i) / f64::from(sessions),
                ),
                degrees_per_second: cmd.orbit_degrees_per_second,
            },
            node_path: None,
            input_hz: cmd.input_hz,
            max_frames: cmd.frames,
            save_dir: None,
            video_out: None,
            measure_from,
            deadline,
        };
        let seen = Arc::clone(&frames_seen);
        tasks.push(tokio::spawn(async move {
            tokio::time::sleep(offset).await;
            let count = move || {
                seen.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            };
            drive::drive(&client, &opts, &count).await
        }));
    }
    let ticker = {
        let bar = bar.clone();
        let seen = Arc::clone(&frames_seen);
        tokio::spawn(async move {
            loop {
                tokio::time::sleep(Duration::from_millis(250)).await;
                bar.set_position(start.elapsed().as_secs());
                bar.set_message(format!(
                    "{} frames",
                    seen.load(std::sync::atomic::Ordering::Relaxed)
                ));
            }
        })
    };
    let mut results = Vec::new();
    let mut errors = Vec::new();
    for t in tasks {
        match t.await {
            Ok(Ok(r)) => results.push(r),
            Ok(Err(e)) => errors.push(e.to_string()),
            Err(e) => errors.push(format!("session task failed: {e}")),
        }
    }
    ticker.abort();
    bar.finish_and_clear();
    // What the sessions render: the flags, else the server's defaults.
    let defaults = client.server_info().await?.defaults.render;
    let rendered = Rendered {
        width: cmd.render.width.unwrap_or(defaults.width),
        height: cmd.render.height.unwrap_or(defaults.height),
        gi: cmd.render.gi.unwrap_or(defaults.gi.method),
    };
    let report = summarise(client.base(), &rendered, sessions, &results, errors);
    if report.failed_sessions == sessions {
        anyhow::bail!(
            "every session failed: {}",
            report.errors.first().cloned().unwrap_or_default()
        );
    }
    Ok(report)
}

/// Session `index`'s own lights in `params` (`--distinct-lights`): those the params give
/// (`render.lights`, else `render.light`), else `default`, each one's intensity raised by
/// 0.01 % per index.
fn distinct_light(params: &mut serde_json::Value, default: &lightcast_protocol::Light, index: u32) {
    let render = &mut params["render"];
    let raise = |mut light: lightcast_protocol::Light| {
        light.intensity *= 1.0 + 1e-4 * index as f32;
        light
    };
    let lights = serde_json::from_value::<Vec<lightcast_protocol::Light>>(render["lights"].clone());
    if let Ok(lights) = lights {
        render["lights"] = serde_json::json!(lights.into_iter().map(raise).collect::<Vec<_>>());
        return;
    }
    let light: lightcast_protocol::Light =
        serde_json::from_value(render["light"].clone()).unwrap_or_else(|_| default.clone());
    render["light"] = serde_json::json!(raise(light));
}

/// `base` rotated `degrees` about its target's vertical axis.
fn orbit_start(base: &lightcast_protocol::Camera, degrees: f64) -> lightcast_protocol::Camera {
    Motion::Orbit {
        base: base.clone(),
        degrees_per_second: degrees,
    }
    .camera(1.0)
    .unwrap_or_else(|| base.clone())
}

/// Size and GI method of the sessions' frames.
struct Rendered {
    width: u32,
    height: u32,
    gi: lightcast_protocol::GiMethod,
}

fn summarise(
    server: &str,
    rendered: &Rendered,
    sessions: u32,
    results: &[DriveResult],
    mut errors: Vec<String>,
) -> LoadReport {
    let mut connect = Latencies::default();
    let mut first = Latencies::default();
    let mut latency = Latencies::default();
    let mut split = FrameSplit::default();
    let mut fps = Vec::new();
    let (mut frames, mut bytes, mut dropped, mut throttled) = (0, 0, 0, 0);
    let mut window = 0.0f64;
    for r in results {
        connect.record(r.connect);
        if let Some(f) = r.first_frame {
            first.record(f);
        }
        latency.merge(&r.latencies);
        split.merge(&r.split);
        let secs = r.window.as_secs_f64().max(1e-9);
        window = window.max(secs);
        fps.push(r.frames as f64 / secs);
        frames += r.frames;
        bytes += r.bytes;
        if let Some(s) = &r.server_stats {
            dropped += s.frames_dropped;
            throttled += s.frames_throttled;
        }
        errors.extend(r.errors.iter().cloned());
    }
    errors.truncate(20);
    let fps_total = fps.iter().sum();
    LoadReport {
        server: server.to_string(),
        sessions,
        width: rendered.width,
        height: rendered.height,
        gi: rendered.gi,
        seconds: window,
        connect_ms: connect.summary(),
        first_frame_ms: first.summary(),
        input_to_frame_ms: latency.summary(),
        fps_min: if fps.is_empty() {
            0.0
        } else {
            fps.iter().copied().fold(f64::INFINITY, f64::min)
        },
        fps_median: median(&mut fps),
        fps_total,
        frames,
        dropped,
        throttled,
        bytes_per_second: bytes as f64 / window.max(1e-9),
        split,
        failed_sessions: sessions - results.len() as u32,
        errors,
        no_frames: (frames == 0)
            .then(|| results.iter().find_map(DriveResult::no_frames_reason))
            .flatten(),
    }
}

fn print_table(r: &LoadReport) {
    println!(
        "{} sessions of {}×{} ({}) for {:.1} s against {}",
        r.sessions, r.width, r.height, r.gi, r.seconds, r.server
    );
    let row = |name: &str, p: &Percentiles, none: &str| {
        if p.samples == 0 {
            println!("{name:<16} {none}");
        } else {
            println!("{name:<16} p50 {:>8.1} ms  p95 {:>8.1} ms  p99 {:>8.1} ms  max {:>8.1} ms  ({} samples)", p.p50, p.p95, p.p99, p.max, p.samples);
        }
    };
    row("connect", &r.connect_ms, "no session connected");
    row("first frame", &r.first_frame_ms, "no frames");
    row(
        "input→frame",
        &r.input_to_frame_ms,
        "no frame answered a camera move",
    );
    if let Some(reason) = &r.no_frames {
        println!("no frames: {reason}");
    }
    println!(
        "fps per client: min {:.1}, median {:.1}; total {:.1}",
        r.fps_min, r.fps_median, r.fps_total
    );
    println!(
        "frames {}, dropped {}, throttled {}, {:.0} KiB/s",
        r.frames,
        r.dropped,
        r.throttled,
        r.bytes_per_second / 1024.0
    );
    println!(
        "per frame: GPU {:.2} ms, readback {:.2} ms, encode {:.2} ms, server {:.2} ms, network {:.2} ms",
        r.split.gpu_ms, r.split.readback_ms, r.split.encode_ms, r.split.server_ms, r.split.network_ms
    );
    println!("failed sessions {}", r.failed_sessions);
    for e in &r.errors {
        println!("error: {e}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distinct_lights_differ_by_session_and_keep_the_rest() {
        let light = lightcast_protocol::Light {
            kind: lightcast_protocol::LightKind::Spot,
            position: [0.0, 1.9, 0.0],
            direction: [0.0, -1.0, 0.0],
            color: [1.0; 3],
            intensity: 10.0,
            inner_cone: 0.5,
            outer_cone: 0.7,
        };
        let lit = |index| {
            let mut params = serde_json::json!({"render": {"width": 32}});
            distinct_light(&mut params, &light, index);
            serde_json::from_value::<lightcast_protocol::Light>(params["render"]["light"].clone())
                .expect("a light")
        };
        assert_eq!(lit(0), light);
        let third = lit(3);
        assert!((third.intensity - 10.003).abs() < 1e-5, "{third:?}");
        assert_eq!((third.position, third.kind), (light.position, light.kind));
        assert_ne!(lit(1), lit(2));
        let mut two = serde_json::json!({"render": {"lights": [light.clone(), light.clone()]}});
        distinct_light(&mut two, &light, 2);
        let lights: Vec<lightcast_protocol::Light> =
            serde_json::from_value(two["render"]["lights"].clone()).expect("lights");
        assert!(
            lights.iter().all(|l| (l.intensity - 10.002).abs() < 1e-5),
            "{lights:?}"
        );
        assert!(
            two["render"].get("light").is_none(),
            "no second light field"
        );
    }

    fn rendered() -> Rendered {
        Rendered {
            width: 64,
            height: 48,
            gi: lightcast_protocol::GiMethod::new("brsm"),
        }
    }

    #[test]
    fn a_test_without_frames_says_why() {
        let idle = DriveResult {
            window: Duration::from_secs(3),
            server_stats: Some(lightcast_protocol::SessionStats::default()),
            ..DriveResult::default()
        };
        let report = summarise("http://127.0.0.1:1", &rendered(), 1, &[idle], Vec::new());
        let reason = report.no_frames.expect("a reason");
        assert!(
            reason.contains("no frame arrived within 3.0 s")
                && reason.contains("has not finished a frame"),
            "{reason}"
        );
        let rendering = DriveResult {
            frames: 2,
            window: Duration::from_secs(3),
            ..DriveResult::default()
        };
        let report = summarise(
            "http://127.0.0.1:1",
            &rendered(),
            1,
            &[rendering],
            Vec::new(),
        );
        assert!(report.no_frames.is_none());
    }

    #[test]
    fn methods_are_named_as_requests_name_them() {
        let report = summarise("http://127.0.0.1:1", &rendered(), 1, &[], Vec::new());
        assert!(markdown(&[report]).contains("| 64×48 | brsm |"));
    }

    #[test]
    fn only_loopback_servers_pass_without_allow_remote() {
        assert!(is_loopback("http://127.0.0.1:8080"));
        assert!(is_loopback("http://localhost:1"));
        assert!(is_loopback("http://[::1]:80"));
        assert!(!is_loopback("http://10.0.0.2:8080"));
        assert!(!is_loopback("https://example.com"));
    }
}
