//! Writes the equirectangular map an environment evaluates into (`EnvironmentMap::new`) as a
//! PFM file, for comparison with other renderers (bench/mitsuba/validate_environment.py).
//!
//! ```text
//! cargo run -p lightcast-server --example environment_map -- \
//!     --kind sky --intensity 0.2 --turbidity 3 --sun-direction=0.4,-0.6,0.3 --sun-intensity 3 \
//!     --output sky.pfm
//! ```
//! The PFM's rows are stored bottom to top as the format requires, so a reader shows the
//! zenith (+Y) on top: texel (i, j) from the top covers θ ∈ [π j/h, π (j+1)/h] from +Y and
//! φ ∈ [2π i/w, 2π (i+1)/w], d = (sin θ cos φ, cos θ, sin θ sin φ).
use clap::Parser;
use lightcast_protocol::{Environment, EnvironmentKind, Light, LightKind};
use lightcast_server::scene::environment::EnvironmentMap;
use lightcast_server::scene::environment_image::EnvironmentImage;
use std::io::Write;

#[derive(Parser)]
struct Args {
    #[arg(long, value_enum, default_value = "uniform")]
    kind: EnvironmentKind,
    /// Default: 1 for `uniform`, 0.2 for `sky`.
    #[arg(long)]
    intensity: Option<f32>,
    #[arg(long, value_parser = triple, default_value = "1,1,1")]
    color: [f32; 3],
    #[arg(long, default_value_t = 3.0)]
    turbidity: f32,
    /// Direction the sun's light travels (a sky's sun; need not be unit).
    #[arg(long, value_parser = triple, default_value = "0.4,-0.6,0.3")]
    sun_direction: [f32; 3],
    /// The sun's illuminance (lux).
    #[arg(long, default_value_t = 3.0)]
    sun_intensity: f32,
    #[arg(long, value_parser = triple, default_value = "1,1,1")]
    sun_color: [f32; 3],
    /// The `.hdr`/`.exr` file of `--kind image`.
    #[arg(long)]
    image: Option<std::path::PathBuf>,
    #[arg(long)]
    output: std::path::PathBuf,
}

/// `x,y,z`.
fn triple(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{e}"))?;
    v.try_into()
        .map_err(|_| "expected three numbers: x,y,z".to_string())
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let env = Environment {
        kind: args.kind,
        color: args.color,
        intensity: args.intensity,
        turbidity: args.turbidity,
        ..Environment::default()
    };
    let sun = Light {
        kind: LightKind::Directional,
        position: [0.0; 3],
        direction: args.sun_direction,
        color: args.sun_color,
        intensity: args.sun_intensity,
        inner_cone: 0.0,
        outer_cone: 0.0,
    };
    let image = match &args.image {
        Some(path) => Some(EnvironmentImage::decode(
            &path.to_string_lossy(),
            &std::fs::read(path)?,
            lightcast_server::offline::MAX_ENVIRONMENT_IMAGE_BYTES,
        )?),
        None => None,
    };
    let map = EnvironmentMap::new(&env, &[sun], image.as_ref())?;
    let mut out = std::io::BufWriter::new(std::fs::File::create(&args.output)?);
    write!(out, "PF\n{} {}\n-1.0\n", map.width, map.height)?;
    for row in map.radiance.chunks(map.width as usize).rev() {
        for v in row.iter().flatten() {
            out.write_all(&v.to_le_bytes())?;
        }
    }
    out.flush()?;
    println!(
        "{}×{} map, horizontal illuminance {} → {}",
        map.width,
        map.height,
        map.horizontal_illuminance(),
        args.output.display()
    );
    Ok(())
}
