//! `peers-reference`: a deliberately simple, brute-force reference volume renderer (emission-absorption volume
//! rendering and first-hit isosurfaces of the trilinear interpolant) used to score the image quality of
//! voxstream and peer renderers. It shares no code with voxstream on purpose.
//!
//! Usage: `peers-reference --scene scene.json --out image.png [--float image.f32]`. Prints one JSON line
//! `{"width","height","seconds","rays","samples"}`; `seconds` is the render time (excluding loading and
//! writing). Errors are reported as one line on stderr with a non-zero exit status.

mod camera;
mod integrate;
mod math;
mod output;
mod scene;
mod tf;
mod volume;

#[cfg(test)]
mod tests;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Parser;

use crate::integrate::Renderer;
use crate::scene::Scene;
use crate::volume::Volume;

/// Brute-force reference renderer for scoring volume renderers.
#[derive(Debug, Parser)]
#[command(name = "peers-reference")]
struct Args {
    /// Scene description (JSON).
    #[arg(long)]
    scene: PathBuf,
    /// Output 8-bit RGB PNG (linear, no gamma).
    #[arg(long)]
    out: PathBuf,
    /// Optional raw float RGB image (little-endian f32, row-major, top row first).
    #[arg(long)]
    float: Option<PathBuf>,
}

fn main() -> ExitCode {
    let args = match Args::try_parse() {
        Ok(args) => args,
        Err(error) => {
            use clap::error::ErrorKind;
            if matches!(error.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                let _ = error.print();
                return ExitCode::SUCCESS;
            }
            let text = error.render().to_string();
            eprintln!("{}", text.lines().next().unwrap_or("error: invalid arguments"));
            return ExitCode::from(2);
        }
    };
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("peers-reference: error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> Result<()> {
    let scene = Scene::load(&args.scene)?;
    let volume = Volume::load(&scene.volume)?;
    let renderer =
        Renderer::new(&scene, &volume).with_context(|| format!("invalid scene file {}", args.scene.display()))?;
    let png_file = output::create(&args.out)?;
    let float_file = args.float.as_deref().map(output::create).transpose()?;
    let start = Instant::now();
    let (image, stats) = renderer.render();
    let seconds = start.elapsed().as_secs_f64();
    output::write_png(&image, png_file, &args.out)?;
    if let (Some(file), Some(path)) = (float_file, &args.float) {
        output::write_f32(&image, file, path)?;
    }
    let line = serde_json::json!({
        "width": image.width,
        "height": image.height,
        "seconds": seconds,
        "rays": stats.rays,
        "samples": stats.samples,
    });
    println!("{line}");
    Ok(())
}
