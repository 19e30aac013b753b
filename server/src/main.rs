//! `lightcast-server`: the binary. Subcommands: `serve` (the default: the HTTP/WebSocket
//! service), `render` (offline, one frame to a file), `bench` (the paper's evaluation of the
//! GI methods) and `bench-stream` (JPEG against H.264 on one camera path).

use anyhow::Context;
use clap::{Parser, Subcommand};
use lightcast_server::bench::stream::{self as bench_stream, StreamBenchArgs};
use lightcast_server::bench::{self, BenchArgs};
use lightcast_server::offline::{self, RenderArgs};
use lightcast_server::service::{self, config::LogFormat, ServeArgs};

#[derive(Parser)]
#[command(
    name = "lightcast-server",
    version,
    about = "Remote rendering with real-time global illumination",
    args_conflicts_with_subcommands = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// Without a subcommand the server runs `serve` with these options.
    #[command(flatten)]
    serve: ServeArgs,
}

#[derive(Subcommand)]
enum Command {
    /// Run the HTTP/WebSocket service (the default): scenes, streaming sessions, one-shot
    /// renders, /metrics, /openapi.json.
    Serve(ServeArgs),
    /// Print the OpenAPI document of the HTTP API (the same as GET /openapi.json).
    Openapi,
    /// Print the AsyncAPI document of the session WebSocket (the same as GET /asyncapi.json).
    Asyncapi,
    /// Print every GI method's parameters (name, methods, type, defaults, range, unit,
    /// meaning) as a markdown table: the README's, from the methods' tables.
    GiParams,
    /// Print every debug view (name, methods that draw it, what it shows) as a markdown
    /// table: the README's, from the methods' tables.
    GiViews,
    /// Print every GI method's bench sweep (what it measures, its flags and their defaults)
    /// as a markdown table: the README's, from the methods' sweeps.
    BenchSweeps,
    /// Render one frame of a scene to a PNG file (no network) and print per-pass GPU times.
    Render(RenderArgs),
    /// A GI method's evaluation after its seed paper: its sweep's configurations timed per
    /// stage under a moving light and measured against the path-traced reference
    /// (`bench-sweeps` lists every method's).
    Bench(BenchArgs),
    /// Stream one camera path as JPEG and as H.264 at each size: bytes per frame and per
    /// second, encode ms, read-back bytes and GPU ms, PSNR and FLIP against the lossless
    /// frames, and issue 13's targets (input→frame latency: `bench/stream-codecs.sh`).
    BenchStream(StreamBenchArgs),
}

/// Runs a bench as `run(log, progress)` under a progress bar on stderr.
fn with_progress<T>(
    run: impl FnOnce(&mut dyn FnMut(&str), &mut dyn FnMut(u64, u64, &str)) -> anyhow::Result<T>,
) -> anyhow::Result<T> {
    let bar = indicatif::ProgressBar::new(0);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} {msg}")
            .context("progress bar template")?,
    );
    // Without a terminal the bar is hidden and prints nothing: log lines and each new
    // step then go to stderr as plain lines, so a scripted run still shows progress.
    let hidden = bar.is_hidden();
    let mut log = |line: &str| {
        if hidden {
            eprintln!("{line}");
        } else {
            bar.println(line);
        }
    };
    let mut step = String::new();
    let mut progress = |done: u64, total: u64, label: &str| {
        if hidden && step != label {
            eprintln!("{label} ({total})");
            step = label.to_string();
        }
        bar.set_length(total);
        bar.set_position(done);
        bar.set_message(label.to_string());
    };
    let result = run(&mut log, &mut progress);
    bar.finish_and_clear();
    result
}

/// Writes `text` to stdout. A reader that stops early (`lightcast-server openapi | head`)
/// closes the pipe: that ends the output, not the program with a panic as `print!` would.
fn out(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

/// Prints a bench's markdown and writes it and its JSON where asked.
fn write_report(
    markdown: &str,
    json: &str,
    markdown_path: Option<&std::path::Path>,
    json_path: Option<&std::path::Path>,
) -> anyhow::Result<()> {
    out(markdown)?;
    for (path, text) in [(json_path, json), (markdown_path, markdown)] {
        if let Some(path) = path {
            std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
        }
    }
    Ok(())
}

fn serve(args: &ServeArgs) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async {
        let log = |line: &str| tracing::info!("{line}");
        let service = service::Service::start(args, &log)
            .await
            .context("the service could not start")?;
        service::termination_signal().await;
        tracing::info!("shutting down");
        service.shutdown().await.context("shutting down")?;
        tracing::info!("stopped");
        Ok(())
    })
}

fn main() -> anyhow::Result<()> {
    lightcast_server::gpu::context::quiet_headless_device_select();
    let cli = Cli::parse();
    // The service logs what it does; the offline commands only warnings.
    let default_filter = match cli.command {
        None | Some(Command::Serve(_)) => "info",
        Some(_) => "warn",
    };
    let format = match &cli.command {
        None => cli.serve.log_format,
        Some(Command::Serve(args)) => args.log_format,
        Some(_) => LogFormat::Text,
    };
    let log = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default_filter)),
        )
        .with_writer(std::io::stderr);
    match format {
        LogFormat::Text => log.init(),
        LogFormat::Json => log.json().init(),
    }
    let Some(command) = cli.command else {
        return serve(&cli.serve);
    };
    match command {
        Command::Serve(args) => serve(&args)?,
        Command::Openapi => out(&format!("{}\n", service::http::openapi_document()?))?,
        Command::Asyncapi => out(&format!(
            "{}\n",
            service::http::asyncapi::asyncapi_document()?
        ))?,
        Command::GiParams => out(&lightcast_server::gi::params::markdown_table())?,
        Command::GiViews => out(&lightcast_server::gi::views::markdown_table())?,
        Command::BenchSweeps => out(&lightcast_server::gi::bench::markdown_table())?,
        Command::Render(args) => {
            let mut log = |line: &str| eprintln!("{line}");
            let report = offline::render(&args, &mut log).context("render failed")?;
            if args.json {
                out(&format!("{}\n", serde_json::to_string_pretty(&report)?))?;
            } else {
                out(&report.table())?;
                out(&format!(
                    "wrote {} ({}×{}, exposure ×{:.4})\n",
                    report.out.display(),
                    report.width,
                    report.height,
                    report.exposure_scale
                ))?;
            }
        }
        Command::Bench(args) => {
            // Said before the run, not after it: a bench takes minutes.
            #[cfg(not(feature = "plots"))]
            if args.plots.is_some() {
                anyhow::bail!(
                    "--plots needs a build with plots: `cargo build --release -p lightcast-server --features plots`"
                );
            }
            let report = with_progress(|log, progress| {
                bench::run(&args, log, progress).context("bench failed")
            })?;
            #[cfg(feature = "plots")]
            if let Some(prefix) = args.plots.as_deref() {
                for path in lightcast_server::bench::plots::write_plots(&report, prefix)? {
                    eprintln!("wrote {}", path.display());
                }
            }
            let (markdown, json) = (report.markdown(), serde_json::to_string_pretty(&report)?);
            write_report(
                &markdown,
                &json,
                args.markdown.as_deref(),
                args.json.as_deref(),
            )?;
        }
        Command::BenchStream(args) => {
            let report = with_progress(|log, progress| {
                bench_stream::run(&args, log, progress).context("bench-stream failed")
            })?;
            write_report(
                &report.markdown(),
                &serde_json::to_string_pretty(&report)?,
                args.markdown.as_deref(),
                args.json.as_deref(),
            )?;
        }
    }
    Ok(())
}
