//! The `voxstream` binary: parses the command line and reports errors (exit 2 for bad flags, with clap's valid
//! values, suggestions and usage; one line and exit 1 for everything else; exit 3 when `render` wrote an image some
//! of whose bricks could not be read: [`voxstream::exit_status`]). The work is in the `voxstream` library.

use std::process::ExitCode;

use clap::Parser;
use voxstream::cli::{Cli, Command, RenderArgs};
use voxstream::{bench, fuse_command, import_command, info_command, render_command, scenes};

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(error) => {
            use clap::error::ErrorKind;
            if matches!(error.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                let _ = error.print();
                return ExitCode::SUCCESS;
            }
            // clap's whole message: the problem, then the valid values, a "did you mean" and the usage line.
            let text = error.render().to_string();
            eprintln!("{}", text.trim_end());
            return ExitCode::from(2);
        }
    };
    // Before any thread starts and before Vulkan is opened: no libwayland line about XDG_RUNTIME_DIR (see the
    // module). Kept until the end of `main`, which removes the directory.
    #[cfg(unix)]
    let _runtime_dir = if opens_gpu(&cli) { voxstream::runtime_dir::prepare_for_vulkan() } else { None };
    let result = match cli.command {
        None => {
            let args = match Cli::try_parse_from(["voxstream", "render"]) {
                Ok(Cli { command: Some(Command::Render(args)) }) => args,
                _ => unreachable_default(),
            };
            render_command::run(&args)
        }
        Some(Command::Render(args)) => render_command::run(&args),
        Some(Command::Scenes) => {
            for name in scenes::SCENE_NAMES {
                if let Some(scene) = scenes::builtin(name) {
                    println!("{:<14}{}", scene.name, scene.description);
                }
            }
            Ok(())
        }
        Some(Command::Bench(args)) => bench::run(&args),
        Some(Command::Import(args)) => import_command::run(&args),
        Some(Command::Info(args)) => info_command::run(&args),
        Some(Command::Fuse(args)) => fuse_command::run_fuse(&args),
        Some(Command::SynthRgbd(args)) => fuse_command::run_synth(&args),
        #[cfg(feature = "viewer")]
        Some(Command::View(args)) => voxstream::view_command::run(&args),
        #[cfg(not(feature = "viewer"))]
        Some(Command::View(_)) => Err(anyhow::anyhow!(
            "this voxstream was built without the viewer: build it with `cargo build --release` (the `viewer` feature \
             is on by default)"
        )),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {}", voxstream::error_message::user_message(&error));
            ExitCode::from(voxstream::exit_status::exit_code(&error))
        }
    }
}

/// Whether the command opens a GPU (`--backend gpu`).
fn opens_gpu(cli: &Cli) -> bool {
    use voxstream::backend::Backend;
    match &cli.command {
        Some(Command::Render(args)) => args.look.backend == Backend::Gpu,
        Some(Command::View(args)) => args.look.backend == Backend::Gpu,
        Some(Command::Bench(args)) => args.backend == Backend::Gpu,
        _ => false,
    }
}

/// The default render arguments always parse; this only satisfies the type checker.
fn unreachable_default() -> RenderArgs {
    use voxstream::cli::{LookFlags, SourceFlags};
    RenderArgs {
        input: SourceFlags {
            source: scenes::DEFAULT_SCENE.into(),
            remote: voxstream::cli::RemoteArgs::default(),
            amplify: None,
            resolution: None,
            attribute: false,
            smoothing_scale: None,
            particle_memory: None,
            in_memory: false,
            brick_bits: voxstream::cli::BrickBits::Auto,
            value_range: None,
            channel: None,
            time: None,
            fluid: Default::default(),
        },
        out: "frame.png".into(),
        width: 512,
        height: 512,
        budget_mb: 256,
        mode: voxstream_engine::Mode::Converged,
        frames: 1,
        requests_per_frame: 1024,
        path: None,
        video: None,
        fps: 30.0,
        popping: false,
        stats: None,
        quiet: false,
        look: LookFlags {
            camera: None,
            eye: None,
            target: None,
            up: None,
            fov: None,
            view: None,
            azimuth: None,
            elevation: None,
            zoom: None,
            projection: voxstream::cli::ProjectionArg::Composite,
            clip_plane: Vec::new(),
            slice: None,
            with_volume: false,
            color_bar: false,
            scale_bar: false,
            crop: None,
            tf: None,
            iso: Vec::new(),
            iso_color: Vec::new(),
            iso_opacity: Vec::new(),
            shadows: false,
            normals: voxstream::cli::NormalsArg::Cell,
            shading: None,
            light: None,
            background: [0.0; 3],
            step: 0.5,
            preintegrate: false,
            adaptive_step: None,
            faithful: false,
            lod_bias: 0.0,
            colour_by_level: false,
            backend: voxstream::cli::Backend::Cpu,
            gpu_filter: voxstream::cli::GpuFilter::Auto,
            blending: voxstream::cli::Switch::On,
            fade_frames: voxstream_core::DEFAULT_FADE_FRAMES,
        },
    }
}
