//! `lightcast-server`: the binary. Subcommands: `render` (offline, one frame to a file).

use anyhow::Context;
use clap::{Parser, Subcommand};
use lightcast_server::offline::{self, RenderArgs};

#[derive(Parser)]
#[command(
    name = "lightcast-server",
    version,
    about = "Remote rendering with real-time global illumination"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render one frame of a scene to a PNG file (no network) and print per-pass GPU times.
    Render(RenderArgs),
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::Render(args) => {
            let mut log = |line: &str| eprintln!("{line}");
            let report = offline::render(&args, &mut log).context("render failed")?;
            if args.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                print!("{}", report.table());
                println!(
                    "wrote {} ({}×{}, exposure ×{:.4})",
                    report.out.display(),
                    report.width,
                    report.height,
                    report.exposure_scale
                );
            }
        }
    }
    Ok(())
}
