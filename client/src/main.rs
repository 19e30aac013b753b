//! `lightcast`: the command-line client of a lightcast server (scenes, one-shot renders,
//! streaming and load tests). It speaks only the public protocol.

mod api;
mod drive;
mod flags;
mod loadtest;
mod node_path;
mod stats;

use anyhow::Context;
use api::Client;
use clap::{Parser, Subcommand};
use flags::RenderFlags;
use lightcast_protocol::{Codec, GiMethod, ImageFormat, StreamMode};
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(Parser)]
#[command(
    name = "lightcast",
    version,
    about = "Client of a lightcast remote-rendering server"
)]
struct Cli {
    /// Server URL.
    #[arg(
        long,
        global = true,
        env = "LIGHTCAST_SERVER",
        default_value = "http://127.0.0.1:8080"
    )]
    server: String,
    /// Bearer token (when the server has auth on).
    #[arg(long, global = true, env = "LIGHTCAST_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Print results as JSON instead of tables.
    #[arg(long, global = true)]
    json: bool,
    /// PEM certificate(s) to trust for an https:// server besides the system's (a private CA
    /// or a self-signed certificate).
    #[arg(long, global = true, env = "LIGHTCAST_CA_CERT")]
    ca_cert: Option<std::path::PathBuf>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List, upload, show or delete scenes.
    #[command(subcommand)]
    Scenes(ScenesCommand),
    /// Render one frame to a file and print its timing report.
    Render(RenderCmd),
    /// Open a session and receive frames; print fps, latency and drops.
    Stream(StreamCmd),
    /// Many concurrent sessions with a moving camera; report latency percentiles, fps and drops.
    Loadtest(loadtest::LoadtestCmd),
}

#[derive(Subcommand)]
enum ScenesCommand {
    /// List the scenes.
    List,
    /// Upload a .glb, or a .gltf with the files it references.
    Upload {
        file: PathBuf,
        /// Display name (default: the file's stem).
        #[arg(long)]
        name: Option<String>,
        /// An equirectangular Radiance `.hdr` or OpenEXR image to upload with the scene, which
        /// `--environment image` lights it with.
        #[arg(long)]
        environment_image: Option<PathBuf>,
    },
    /// Show a scene.
    Show { id: String },
    /// Delete a scene.
    Rm { id: String },
}

#[derive(clap::Args)]
struct RenderCmd {
    /// Output file.
    #[arg(long)]
    out: PathBuf,
    /// png, jpeg, raw_final or raw_indirect (float32 RGBA, little-endian).
    #[arg(long, default_value = "png", value_parser = parse_format)]
    format: ImageFormat,
    /// JPEG quality 1–100.
    #[arg(long)]
    quality: Option<u8>,
    /// Render this many times and report timing statistics (the last image is written).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    repeat: u32,
    /// Also render the same view with the path-traced reference and print the errors against
    /// it (MAE, RMSE, relative MAE and bias of the indirect light; PSNR of the final image).
    #[arg(long, value_enum)]
    compare_to: Option<CompareTo>,
    /// Samples per pixel of the comparison's reference (server default 256).
    #[arg(long)]
    compare_spp: Option<u32>,
    /// Also compare with a reference of the light transport the method models (diffuse
    /// senders for `surfels` and the RSM-based methods with `senders: diffuse`), to part the
    /// error of what it leaves out from the error in what it models; one more reference
    /// render.
    #[arg(long, requires = "compare_to")]
    compare_modelled: bool,
    #[command(flatten)]
    render: RenderFlags,
}

/// What `render --compare-to` measures against: the server compares only with its
/// path-traced reference (the truth), so that is the one choice offered.
#[derive(Clone, Copy, clap::ValueEnum)]
enum CompareTo {
    Reference,
}

impl From<CompareTo> for GiMethod {
    fn from(c: CompareTo) -> Self {
        match c {
            CompareTo::Reference => GiMethod::new("reference"),
        }
    }
}

fn parse_format(s: &str) -> Result<ImageFormat, String> {
    serde_json::from_value(serde_json::Value::String(s.to_string()))
        .map_err(|_| format!("'{s}' is not one of png, jpeg, raw_final, raw_indirect"))
}

#[derive(clap::Args)]
struct StreamCmd {
    /// Seconds to stream (Ctrl-C ends it sooner, with the summary).
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// Stop after this many frames.
    #[arg(long)]
    frames: Option<u64>,
    /// Save every frame into this directory (NNNNNN.jpg / .png / .h264 by sequence number).
    #[arg(long)]
    save: Option<PathBuf>,
    /// With `--codec h264`: write the stream to this file as raw H.264 (Annex B, from its first
    /// keyframe), which ffmpeg, ffplay and VLC play (`ffplay -f h264 FILE`).
    #[arg(long)]
    video: Option<PathBuf>,
    /// Replay a camera path: JSON `{"keyframes": [{"t": SECONDS, "camera": {...}}, ...]}`.
    #[arg(long)]
    camera_path: Option<PathBuf>,
    /// Replay a path of movable nodes (`lightcast scenes show` lists them): JSON
    /// `{"keyframes": [{"t": SECONDS, "nodes": [{"node": ID, "translation": [X, Y, Z],
    /// "rotation": [X, Y, Z, W], "scale": [X, Y, Z]}, ...]}, ...]}`, each field optional (one
    /// left out keeps the node's own). Per node, translation and scale interpolate linearly
    /// and rotation by slerp between the keyframes that give them, held at the ends; sent on
    /// the --camera-path's ticks, with which it combines.
    #[arg(long)]
    node_path: Option<PathBuf>,
    /// Input messages per second while replaying a camera or node path.
    #[arg(long, default_value_t = 30.0)]
    input_hz: f64,
    /// Most frames per second the server sends (default the server's, 30).
    #[arg(long)]
    fps_cap: Option<f32>,
    /// Frame codec: jpeg, png, or h264 (video).
    #[arg(long, value_enum, default_value = "jpeg")]
    codec: Codec,
    /// JPEG quality 1–100 (default the server's).
    #[arg(long)]
    quality: Option<u8>,
    /// With `--codec h264`: target bitrate in kbit/s (100–200000; default the server's).
    #[arg(long)]
    bitrate_kbps: Option<u32>,
    #[command(flatten)]
    render: RenderFlags,
}

/// Session parameters for streaming commands: a continuous stream without stills, and only
/// what was asked for besides (the server fills in its defaults). A session plays the
/// `--animation` it is given (from its time), so the first frame is already under way.
pub fn session_params(
    mut render: serde_json::Value,
    fps_cap: Option<f32>,
    codec: Codec,
    quality: Option<u8>,
) -> serde_json::Value {
    if let Some(animation) = render.get_mut("animation").filter(|a| a.is_object()) {
        animation["playing"] = true.into();
    }
    let mut params = serde_json::json!({
        "render": render,
        "mode": StreamMode::Continuous,
        "encoding": {"codec": codec, "still_after_ms": 0},
    });
    if let Some(fps) = fps_cap {
        params["fps_cap"] = fps.into();
    }
    if let Some(q) = quality {
        params["encoding"]["quality"] = q.into();
        params["encoding"]["moving_quality"] = q.into();
    }
    params
}

/// The scene's default camera and light, when the flags change part of them.
async fn scene_defaults(
    client: &Client,
    flags: &RenderFlags,
) -> anyhow::Result<(
    Option<lightcast_protocol::Camera>,
    Option<lightcast_protocol::Light>,
)> {
    if !flags.needs_scene_defaults() {
        return Ok((None, None));
    }
    let scene = client.scene(&flags.scene).await?;
    Ok((Some(scene.default_camera), Some(scene.default_light)))
}

/// That a `--node-path` poses only the scene's movable nodes, and none a `--node` flag poses
/// too (the path would take it over after its first tick).
async fn check_node_path(
    client: &Client,
    flags: &RenderFlags,
    path: &node_path::NodePath,
    file: &std::path::Path,
) -> anyhow::Result<()> {
    if let Some(id) = path
        .node_ids()
        .find(|id| flags.nodes.iter().any(|(n, _)| n == id))
    {
        anyhow::bail!(
            "{}: node {id} is posed by --node too; give it in one of the two",
            file.display()
        );
    }
    let scene = client.scene(&flags.scene).await?;
    let movable = |id: u32| scene.nodes.iter().any(|n| n.id == id && n.movable);
    if let Some(id) = path.node_ids().find(|&id| !movable(id)) {
        let list: Vec<String> = scene
            .nodes
            .iter()
            .filter(|n| n.movable)
            .map(|n| format!("{} '{}'", n.id, n.name))
            .collect();
        anyhow::bail!(
            "{}: node {id} is not a movable node of scene {} ({})",
            file.display(),
            scene.id,
            if list.is_empty() {
                "it has none".to_string()
            } else {
                format!("movable: {}", list.join(", "))
            }
        );
    }
    Ok(())
}

async fn run(cli: Cli) -> anyhow::Result<()> {
    let client = Client::new(&cli.server, cli.token.clone(), cli.ca_cert.as_deref())?;
    match cli.command {
        Command::Scenes(cmd) => scenes(&client, cmd, cli.json).await,
        Command::Render(cmd) => render(&client, cmd, cli.json).await,
        Command::Stream(cmd) => stream(&client, cmd, cli.json).await,
        Command::Loadtest(cmd) => loadtest::run(&client, cmd, cli.json).await,
    }
}

fn print_json<T: serde::Serialize>(value: &T) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string_pretty(value)?);
    Ok(())
}

async fn scenes(client: &Client, cmd: ScenesCommand, json: bool) -> anyhow::Result<()> {
    match cmd {
        ScenesCommand::List => {
            let list = client.scenes().await?;
            if json {
                return print_json(&list);
            }
            println!(
                "{:<22} {:<20} {:>10} {:>8}  caches",
                "id", "name", "triangles", "sessions"
            );
            for s in list {
                let caches = s.caches.first().map_or("-".to_string(), |c| {
                    format!(
                        "{:?}{}",
                        c.state,
                        c.caches.map(|n| format!(" ({n})")).unwrap_or_default()
                    )
                    .to_lowercase()
                });
                println!(
                    "{:<22} {:<20} {:>10} {:>8}  {caches}",
                    s.id, s.name, s.triangles, s.sessions
                );
            }
        }
        ScenesCommand::Upload {
            file,
            name,
            environment_image,
        } => {
            let info = client
                .upload_scene(&file, name.as_deref(), environment_image.as_deref())
                .await?;
            if json {
                return print_json(&info);
            }
            println!(
                "uploaded {} as {} ({} triangles); light caches: {}",
                file.display(),
                info.id,
                info.triangles,
                info.caches
                    .first()
                    .map_or("none".to_string(), |c| format!("{:?}", c.state)
                        .to_lowercase())
            );
        }
        ScenesCommand::Show { id } => {
            let info = client.scene(&id).await?;
            if json {
                return print_json(&info);
            }
            println!("{} ({}), source {}", info.id, info.name, info.source);
            println!(
                "  {} triangles, {} vertices, {} materials, {} textures",
                info.triangles, info.vertices, info.materials, info.textures
            );
            println!("  bounds {:?} … {:?}", info.bounds.min, info.bounds.max);
            println!(
                "  {} lights, {} cameras, used by {} sessions",
                info.lights.len(),
                info.cameras.len(),
                info.sessions
            );
            // Movable nodes first: they are what a client may move; a large file's static
            // hierarchy is summed up.
            let movable: Vec<String> = info
                .nodes
                .iter()
                .filter(|n| n.movable)
                .map(|n| format!("{} '{}'", n.id, n.name))
                .collect();
            if !info.nodes.is_empty() {
                println!(
                    "  {} nodes, {} movable{}{}",
                    info.nodes.len(),
                    movable.len(),
                    if movable.is_empty() { "" } else { ": " },
                    movable.join(", ")
                );
            }
            for a in &info.animations {
                println!(
                    "  animation '{}': {:.2} s, moves nodes {:?}",
                    a.name, a.duration, a.nodes
                );
            }
            for p in &info.precomputed {
                let params: Vec<String> = p
                    .params
                    .iter()
                    .map(|(name, value)| format!(" {name} {value}"))
                    .collect();
                println!(
                    "  {}{}: {}{}{}{}",
                    p.label,
                    params.join(","),
                    format!("{:?}", p.state).to_lowercase(),
                    p.step
                        .as_ref()
                        .map(|s| format!(" ({s} {:.0} %)", p.progress.unwrap_or(0.0) * 100.0))
                        .unwrap_or_default(),
                    p.units
                        .map(|n| format!(", {n} {}", p.unit.as_deref().unwrap_or("units")))
                        .unwrap_or_default(),
                    p.seconds.map(|s| format!(", {s:.2} s")).unwrap_or_default()
                );
            }
        }
        ScenesCommand::Rm { id } => {
            client.delete_scene(&id).await?;
            if json {
                return print_json(&serde_json::json!({"deleted": id}));
            }
            println!("deleted {id}");
        }
    }
    Ok(())
}

async fn render(client: &Client, cmd: RenderCmd, json: bool) -> anyhow::Result<()> {
    let (camera, light) = scene_defaults(client, &cmd.render).await?;
    // Only what the flags set: the server fills in its defaults.
    let mut request = serde_json::json!({
        "render": cmd.render.params(camera.as_ref(), light.as_ref()),
        "format": cmd.format,
    });
    if let Some(q) = cmd.quality {
        request["quality"] = q.into();
    }
    if let Some(method) = cmd.compare_to {
        request["compare_to"] = serde_json::to_value(GiMethod::from(method))?;
    }
    if cmd.compare_modelled {
        request["compare_modelled"] = true.into();
    }
    if let Some(spp) = cmd.compare_spp {
        request["compare_spp"] = spp.into();
    }
    let mut reports = Vec::new();
    let mut walls = Vec::new();
    let mut image = Vec::new();
    for _ in 0..cmd.repeat {
        let started = Instant::now();
        let (bytes, report) = client.render(&request).await?;
        walls.push(started.elapsed().as_secs_f64() * 1e3);
        image = bytes;
        reports.push(report);
    }
    std::fs::write(&cmd.out, &image).with_context(|| format!("writing {}", cmd.out.display()))?;
    let last = reports.last().context("no render")?;
    let mut gpu: Vec<f64> = reports.iter().map(|r| r.gpu_ms).collect();
    let gpu_median = stats::median(&mut gpu);
    let wall_median = stats::median(&mut walls.clone());
    if json {
        return print_json(&serde_json::json!({
            "out": cmd.out, "report": last, "repeat": cmd.repeat,
            "gpu_ms_median": gpu_median, "wall_ms_median": wall_median, "wall_ms": walls,
        }));
    }
    println!("{} on {}", last.build, last.adapter);
    println!("request {}", last.request_hash);
    println!("{:<18} {:>10}", "stage", "GPU ms");
    for s in &last.stages {
        println!("{:<18} {:>10.3}", s.stage, s.ms);
    }
    println!(
        "{:<18} {:>10.3}  ({})",
        "total", last.gpu_ms, last.timing_source
    );
    if let Some(note) = &last.timing_note {
        println!("note: {note}");
    }
    println!(
        "queue {:.1} ms, encode {:.1} ms",
        last.queue_ms, last.encode_ms
    );
    if let Some(n) = last.samples {
        match last.relative_error {
            Some(e) => println!("{n} samples per pixel, ±{:.1} % noise", e * 100.0),
            None => println!("{n} samples per pixel"),
        }
    }
    for c in last.comparison.iter().chain(&last.comparison_modelled) {
        println!(
            "against {}{} ({} spp, its own relative error {:.2} %):",
            c.against,
            match c.senders {
                lightcast_protocol::Senders::Full => "",
                lightcast_protocol::Senders::Diffuse =>
                    " of diffuse senders (the light transport the method models)",
            },
            c.reference_samples,
            c.reference_relative_error * 100.0
        );
        println!(
            "  indirect MAE {:.4e}, RMSE {:.4e}, relative MAE {:.2} %, 8×8-block {:.2} %, bias {:+.2} %",
            c.indirect_mae,
            c.indirect_rmse,
            c.indirect_mae_relative * 100.0,
            c.indirect_block_mae_relative * 100.0,
            c.indirect_bias_relative * 100.0
        );
        for (kind, r) in [
            ("diffuse", &c.receivers.diffuse),
            ("specular", &c.receivers.specular),
        ]
        .into_iter()
        .filter(|(_, r)| r.pixel_share > 0.0)
        {
            println!(
                "  on {kind} receivers ({:.1} % of pixels, {:.1} % of the light): 8×8-block {:.2} %, bias {:+.2} %",
                r.pixel_share * 100.0,
                r.reference_share * 100.0,
                r.indirect_block_mae_relative * 100.0,
                r.indirect_bias_relative * 100.0
            );
        }
        match c.final_psnr_db {
            Some(p) => println!("  final image PSNR {p:.2} dB, FLIP {:.4}", c.final_flip),
            None => println!("  final image identical"),
        }
    }
    if cmd.repeat > 1 {
        println!(
            "{} renders: GPU median {gpu_median:.3} ms, request median {wall_median:.1} ms",
            cmd.repeat
        );
    }
    // A debug view may be of another size than the frame (the RSM views are the RSM's).
    let (width, height) = image_dimensions(&image).unwrap_or((last.width, last.height));
    println!(
        "wrote {} ({width}×{height}, {:?})",
        cmd.out.display(),
        last.format
    );
    Ok(())
}

/// The width and height an encoded image (PNG, JPEG) declares; `None` for raw buffers.
fn image_dimensions(bytes: &[u8]) -> Option<(u32, u32)> {
    image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .ok()?
        .into_dimensions()
        .ok()
}

async fn stream(client: &Client, cmd: StreamCmd, json: bool) -> anyhow::Result<()> {
    if !(cmd.duration.is_finite() && cmd.duration > 0.0 && cmd.duration <= 86_400.0) {
        anyhow::bail!("--duration must be between 0 and 86400 seconds");
    }
    let motion = match &cmd.camera_path {
        Some(p) => drive::Motion::Path(drive::CameraPath::load(p).map_err(anyhow::Error::msg)?),
        None => drive::Motion::Still,
    };
    let node_path = match &cmd.node_path {
        Some(p) => Some(node_path::NodePath::load(p).map_err(anyhow::Error::msg)?),
        None => None,
    };
    if !cmd.codec.is_video() && (cmd.video.is_some() || cmd.bitrate_kbps.is_some()) {
        anyhow::bail!("--video and --bitrate-kbps need --codec h264");
    }
    if let (Some(path), Some(file)) = (&node_path, &cmd.node_path) {
        check_node_path(client, &cmd.render, path, file).await?;
    }
    let (camera, light) = scene_defaults(client, &cmd.render).await?;
    let now = Instant::now();
    let mut render = cmd.render.params(camera.as_ref(), light.as_ref());
    if let Some(path) = &node_path {
        // The path's first poses from the first frame on (the flags' --node entries are for
        // other nodes: checked above).
        let mut nodes = render["nodes"].as_array().cloned().unwrap_or_default();
        nodes.extend(
            path.at(0.0)
                .iter()
                .filter_map(|n| serde_json::to_value(n).ok()),
        );
        render["nodes"] = nodes.into();
    }
    let mut params = session_params(render, cmd.fps_cap, cmd.codec, cmd.quality);
    if let Some(kbps) = cmd.bitrate_kbps {
        params["encoding"]["bitrate_kbps"] = kbps.into();
    }
    let replaying = cmd.camera_path.is_some() || node_path.is_some();
    let opts = drive::DriveOptions {
        params,
        motion,
        node_path,
        input_hz: if replaying { cmd.input_hz } else { 0.0 },
        max_frames: cmd.frames,
        save_dir: cmd.save.clone(),
        video_out: cmd.video.clone(),
        measure_from: now,
        deadline: now + Duration::from_secs_f64(cmd.duration),
    };
    let result = drive::drive(client, &opts, &|| {}).await?;
    let secs = result.window.as_secs_f64().max(1e-9);
    let server = result.server_stats.clone().unwrap_or_default();
    let summary = serde_json::json!({
        "frames": result.frames,
        "seconds": secs,
        "fps": result.frames as f64 / secs,
        "bytes_per_second": result.bytes as f64 / secs,
        "connect_ms": result.connect.as_secs_f64() * 1e3,
        "first_frame_ms": result.first_frame.map(|d| d.as_secs_f64() * 1e3),
        "longest_gap_ms": result.longest_gap.as_secs_f64() * 1e3,
        "input_to_frame_ms": result.latencies.summary(),
        "split": result.split,
        "dropped": server.frames_dropped,
        "throttled": server.frames_throttled,
        "errors": result.errors,
        "no_frames": result.no_frames_reason(),
        "saved_to": cmd.save,
        "video": cmd.video.as_ref().map(|path| serde_json::json!({
            "path": path,
            "frames": result.video_frames,
            "keyframes": result.keyframes,
        })),
    });
    if json {
        return print_json(&summary);
    }
    if let Some(reason) = result.no_frames_reason() {
        println!("no frames: {reason}");
        for e in result.errors.iter().skip(1) {
            println!("error: {e}");
        }
        return Ok(());
    }
    println!(
        "{} frames in {secs:.1} s: {:.1} fps, {:.0} KiB/s, longest gap {:.0} ms",
        result.frames,
        result.frames as f64 / secs,
        result.bytes as f64 / secs / 1024.0,
        result.longest_gap.as_secs_f64() * 1e3
    );
    let l = result.latencies.summary();
    if l.samples > 0 {
        println!(
            "input→frame: p50 {:.1} ms, p95 {:.1} ms, p99 {:.1} ms ({} samples)",
            l.p50, l.p95, l.p99, l.samples
        );
    }
    println!(
        "per frame: GPU {:.2} ms, readback {:.2} ms, encode {:.2} ms, server {:.2} ms, network {:.2} ms",
        result.split.gpu_ms, result.split.readback_ms, result.split.encode_ms, result.split.server_ms, result.split.network_ms
    );
    println!(
        "dropped {}, throttled {} (server counters)",
        server.frames_dropped, server.frames_throttled
    );
    for e in &result.errors {
        println!("error: {e}");
    }
    Ok(())
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("lightcast: starting the async runtime: {e}");
            return std::process::ExitCode::FAILURE;
        }
    };
    match runtime.block_on(run(cli)) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("lightcast: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The size printed is the image's own (a view of the RSM is the RSM's size, not the
    /// frame's); raw buffers have none.
    #[test]
    fn written_images_report_their_own_size() {
        let mut png = Vec::new();
        image::RgbImage::new(7, 3)
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .expect("encodes");
        assert_eq!(image_dimensions(&png), Some((7, 3)));
        assert_eq!(image_dimensions(&[0u8; 64]), None);
    }

    #[test]
    fn unset_stream_flags_are_left_out_of_the_session() {
        let params = session_params(serde_json::json!({}), None, Codec::Jpeg, None);
        assert!(params.get("fps_cap").is_none(), "{params}");
        assert!(params["encoding"].get("quality").is_none(), "{params}");
        assert!(
            params["encoding"].get("moving_quality").is_none(),
            "{params}"
        );
        let set = session_params(serde_json::json!({}), Some(12.0), Codec::Jpeg, Some(70));
        assert_eq!(set["fps_cap"], 12.0);
        assert_eq!(set["encoding"]["quality"], 70);
        assert_eq!(set["encoding"]["moving_quality"], 70);
        // What the client sends is a valid session for the server's own type.
        serde_json::from_value::<lightcast_protocol::SessionParams>(params).expect("parses");
    }

    #[test]
    fn a_session_plays_its_animation_from_the_time_given() {
        #[derive(Parser)]
        struct Wrapper {
            #[command(flatten)]
            flags: RenderFlags,
        }
        for (arg, time) in [("walk", 0.0), ("walk@1.5", 1.5)] {
            let flags = Wrapper::parse_from(["t", "--animation", arg]).flags;
            let params = session_params(flags.params(None, None), None, Codec::Jpeg, None);
            assert_eq!(
                params["render"]["animation"],
                serde_json::json!({"name": "walk", "time": time, "playing": true}),
                "{arg}"
            );
            let parsed: lightcast_protocol::SessionParams =
                serde_json::from_value(params).expect("parses");
            let animation = parsed.render.animation.expect("an animation");
            assert!(animation.playing && animation.time == time);
        }
    }

    #[test]
    fn stream_takes_a_node_path_with_a_camera_path() {
        let cli = Cli::try_parse_from([
            "lightcast",
            "stream",
            "--camera-path",
            "cam.json",
            "--node-path",
            "nodes.json",
            "--animation",
            "spin",
        ])
        .unwrap_or_else(|e| panic!("{e}"));
        let Command::Stream(cmd) = cli.command else {
            panic!("not stream");
        };
        assert_eq!(cmd.node_path, Some(PathBuf::from("nodes.json")));
        assert_eq!(cmd.camera_path, Some(PathBuf::from("cam.json")));
        assert_eq!(cmd.render.animation, Some(("spin".into(), 0.0)));
    }
}
