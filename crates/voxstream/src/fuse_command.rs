//! `voxstream fuse` (an RGB-D sequence fused into binary bricks and saved as a store, seed 004 ch. 8) and
//! `voxstream synth-rgbd` (a synthetic sequence with ground truth rendered from a mesh), thin layers over
//! [`voxstream_api::depth_fusion`] and [`voxstream_fusion::rgbd`].

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use voxstream_api::depth_fusion::{fuse_dataset, FuseOptions, PoseSource};
use voxstream_fusion::rgbd::{write_sequence, NoiseModel, SyntheticSequence, SyntheticSettings};
use voxstream_fusion::FusionSettings;

/// How `fuse` gets each frame's pose.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PosesArg {
    /// The dataset's groundtruth.txt.
    GroundTruth,
    /// ICP against the surface fused so far (frame to model), from the first frame's ground truth or the origin.
    Track,
}

/// `voxstream fuse`.
#[derive(Args, Debug, Clone)]
pub struct FuseArgs {
    /// A TUM RGB-D benchmark folder: rgb/, depth/, rgb.txt, depth.txt, optional groundtruth.txt (16-bit depth
    /// PNGs in units of 1/5000 m).
    pub dataset: PathBuf,
    /// The store to write (open it with `voxstream render SCENE --iso 128`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace an existing --out.
    #[arg(long)]
    pub overwrite: bool,
    /// Where poses come from.
    #[arg(long, value_enum, default_value_t = PosesArg::GroundTruth)]
    pub poses: PosesArg,
    /// Voxel edge, metres.
    #[arg(long, default_value_t = 0.01)]
    pub voxel: f64,
    /// Frames per window of deferred processing (n; a window every n/2 frames, a ring of 2n frames).
    #[arg(long, default_value_t = 16)]
    pub window: usize,
    /// Frames of the sub-cache that gives new bricks an immediate, non-confident update.
    #[arg(long, default_value_t = 2)]
    pub sub_cache: usize,
    /// Summed frame weight that makes a voxel confident (at most --window).
    #[arg(long, default_value_t = 3.0)]
    pub confidence: f32,
    /// The band around each depth sample within which voxels are updated (the truncation of eq. 8.2), in voxels:
    /// at least this many, more where the sensor's noise is larger (3σ).
    #[arg(long, default_value_t = 3.0, value_name = "VOXELS")]
    pub truncation: f32,
    /// Keep only the thesis' two bits a voxel (sign and confidence), without the surface offsets (each surface
    /// voxel's averaged distance, two bytes): the surface then lies on voxel faces, up to half a voxel from where
    /// the frames saw it, and the bricks take less memory.
    #[arg(long)]
    pub sign_only: bool,
    /// Fuse only the first N frames.
    #[arg(long, value_name = "N")]
    pub frames: Option<usize>,
    /// Intrinsics instead of the benchmark's defaults (525,525,319.5,239.5 at 640x480): fx,fy,cx,cy, and the
    /// image's width,height where it is not 640x480.
    #[arg(long, value_delimiter = ',', value_name = "FX,FY,CX,CY[,W,H]")]
    pub intrinsics: Option<Vec<f64>>,
    /// Memory for the bricks, MiB: beyond it, chunks far from the camera are streamed to disk next to --out.
    #[arg(long, default_value_t = 1024)]
    pub memory_mb: u64,
    /// Also write the surface as points (binary PLY with normals and colours): where the kept distances of two
    /// neighbouring voxels cross zero, and the centres of the faces between voxels behind and in front of it where
    /// neither keeps a distance (all of them with --sign-only), smoothed (see --raw-points).
    #[arg(long, value_name = "PLY")]
    pub points: Option<PathBuf>,
    /// With --points: write the faces' centres as they are (stairs on slanted surfaces), not moved to the average
    /// of their neighbours within 1.5 voxels.
    #[arg(long)]
    pub raw_points: bool,
    /// Also write the poses used (TUM trajectory format).
    #[arg(long, value_name = "FILE")]
    pub trajectory: Option<PathBuf>,
    /// Also render the fused surface as the thesis shows it, from the last frame's pose at the frames' size:
    /// rays through the confident bits, the depth smoothed in screen space (ROF), shaded with the voxels' colours.
    #[arg(long, value_name = "PNG")]
    pub image: Option<PathBuf>,
    /// Write what was done as JSON (frames, windows, memory, times, ATE).
    #[arg(long, value_name = "FILE")]
    pub stats: Option<PathBuf>,
    /// No progress bar or summary.
    #[arg(long)]
    pub quiet: bool,
}

/// `voxstream synth-rgbd`.
#[derive(Args, Debug, Clone)]
pub struct SynthArgs {
    /// A mesh file (PLY, OBJ, OFF, STL, VTK, VTP): the object, scaled to --object-size and set on a floor.
    pub mesh: PathBuf,
    /// The folder to write (TUM RGB-D layout with groundtruth.txt, and the true scene as scene.ply).
    #[arg(long)]
    pub out: PathBuf,
    /// Replace files in an existing --out.
    #[arg(long)]
    pub overwrite: bool,
    /// Frames (30 per second of the orbit).
    #[arg(long, default_value_t = 300)]
    pub frames: usize,
    /// Sensor noise: kinect (Kinect v1: axial noise growing with depth squared, quantisation, holes) or none.
    #[arg(long, value_enum, default_value_t = NoiseArg::Kinect)]
    pub noise: NoiseArg,
    /// The object's largest side, metres.
    #[arg(long, default_value_t = 0.5)]
    pub object_size: f64,
    /// The orbit's radius, metres.
    #[arg(long, default_value_t = 1.2)]
    pub radius: f64,
    /// The camera's height above the floor, metres.
    #[arg(long, default_value_t = 0.5)]
    pub height: f64,
    /// Walls of this height (metres) around the floor: a room, which gives tracking more than a floor to hold
    /// on to (0: none).
    #[arg(long, default_value_t = 0.0)]
    pub walls: f64,
    /// The angle the orbit sweeps, degrees.
    #[arg(long, default_value_t = 360.0)]
    pub sweep: f64,
    /// The mesh's up axis: x, y or z.
    #[arg(long, default_value = "y")]
    pub up: String,
    /// Seed of the noise.
    #[arg(long, default_value_t = 0x5EED)]
    pub seed: u64,
    /// Keep the floor at z = 0 of the world (level) instead of tilting the scene 7° and moving it a few cm
    /// (the default, so no plane of it lies on the voxel faces of a fusion grid, as in a real scan).
    #[arg(long)]
    pub level: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Noise of `synth-rgbd`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum NoiseArg {
    Kinect,
    None,
}

fn bar(quiet: bool, total: usize, message: String) -> ProgressBar {
    let bar = if quiet { ProgressBar::hidden() } else { ProgressBar::new(total as u64) };
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} frames {per_sec} ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(message);
    bar
}

/// Runs `voxstream fuse`.
pub fn run_fuse(args: &FuseArgs) -> Result<()> {
    if args.out.is_none()
        && args.points.is_none()
        && args.stats.is_none()
        && args.trajectory.is_none()
        && args.image.is_none()
    {
        bail!(
            "give --out SCENE (and/or --points, --trajectory, --image, --stats): fusing without saving anything does \
             nothing"
        );
    }
    for (path, flag) in [
        (&args.image, "--image"),
        (&args.points, "--points"),
        (&args.stats, "--stats"),
        (&args.trajectory, "--trajectory"),
    ] {
        if let Some(path) = path {
            crate::output_file::check_output(path, flag)?;
        }
    }
    let mut settings = FusionSettings::default();
    settings.integration.voxel = args.voxel;
    settings.integration.confidence_weight = args.confidence;
    settings.integration.min_band_voxels = args.truncation;
    settings.integration.surface_offsets = !args.sign_only;
    settings.window = args.window;
    settings.sub_cache = args.sub_cache;
    settings.memory_budget = usize::try_from(args.memory_mb.saturating_mul(1 << 20)).unwrap_or(usize::MAX);
    if args.memory_mb < 16 {
        bail!("--memory-mb {}: give at least 16", args.memory_mb);
    }
    settings.validate()?;
    let intrinsics = match &args.intrinsics {
        None => None,
        Some(v) => {
            let (fx, fy, cx, cy, size) = match *v.as_slice() {
                [fx, fy, cx, cy] => (fx, fy, cx, cy, None),
                [fx, fy, cx, cy, w, h] => (fx, fy, cx, cy, Some([w, h])),
                _ => bail!(
                    "--intrinsics: give four numbers fx,fy,cx,cy (e.g. 525,525,319.5,239.5), or six with the image's \
                     width and height, not {}",
                    v.len()
                ),
            };
            if ![fx, fy, cx, cy].iter().all(|x| x.is_finite()) || fx <= 0.0 || fy <= 0.0 {
                bail!(
                    "--intrinsics {fx},{fy},{cx},{cy}: give finite focal lengths above 0 and a finite principal point"
                );
            }
            let [width, height] = match size {
                None => [640, 480],
                Some([w, h])
                    if w.fract() == 0.0
                        && h.fract() == 0.0
                        && (1.0..=16384.0).contains(&w)
                        && (1.0..=16384.0).contains(&h) =>
                {
                    [w as u32, h as u32]
                }
                Some([w, h]) => bail!("--intrinsics: image size {w}x{h}: give whole numbers of pixels, 1 to 16384"),
            };
            Some(voxstream_fusion::Intrinsics { fx, fy, cx, cy, width, height })
        }
    };
    let options = FuseOptions {
        settings,
        poses: match args.poses {
            PosesArg::GroundTruth => PoseSource::GroundTruth,
            PosesArg::Track => PoseSource::Track,
        },
        frames: args.frames,
        intrinsics,
        out: args.out.clone(),
        overwrite: args.overwrite,
        points: args.points.clone(),
        raw_points: args.raw_points,
        trajectory: args.trajectory.clone(),
        image: args.image.is_some(),
    };
    let progress = bar(args.quiet, 0, format!("fusing {}", args.dataset.display()));
    let report = fuse_dataset(&args.dataset, &options, &mut |done, total| {
        progress.set_length(total as u64);
        progress.set_position(done as u64);
        std::ops::ControlFlow::Continue(())
    })?;
    progress.finish_and_clear();
    if let (Some(path), Some((pixels, width, height))) = (&args.image, &report.image) {
        crate::png_output::write_rgb8_png(pixels, *width, *height, path)?;
    }
    let s = &report.stats;
    let fps = s.frames as f64 / report.fuse_seconds.max(1e-9);
    if !args.quiet {
        eprintln!(
            "fused {} frames ({} lost) in {} windows: {:.1} frames/s ({:.2} s fusing{}, {:.2} s reading); bricks: {} \
             resident, peak {:.1} MiB; frame ring {:.1} MiB; chunks streamed out {} / back {}{}{}",
            s.frames,
            report.frames_lost,
            s.windows,
            fps,
            report.fuse_seconds,
            if report.track_seconds > 0.0 {
                format!(", of which {:.2} s tracking", report.track_seconds)
            } else {
                String::new()
            },
            report.read_seconds,
            report.bricks,
            s.peak_brick_bytes as f64 / (1 << 20) as f64,
            s.ring_bytes as f64 / (1 << 20) as f64,
            report.chunks_written,
            report.chunks_read,
            report.ate_rmse.map_or(String::new(), |a| format!("; ATE RMSE {:.1} mm", a * 1e3)),
            args.out.as_ref().map_or(String::new(), |o| format!("; saved {}", o.display())),
        );
    }
    if let Some(path) = &args.stats {
        let json = serde_json::json!({
            "frames": s.frames,
            "frames_lost": report.frames_lost,
            "windows": s.windows,
            "voxel": args.voxel,
            "window": args.window,
            "fuse_seconds": report.fuse_seconds,
            "track_seconds": report.track_seconds,
            "read_seconds": report.read_seconds,
            "frames_per_second": fps,
            "bricks": report.bricks,
            "peak_brick_bytes": s.peak_brick_bytes,
            "ring_bytes": s.ring_bytes,
            "bricks_integrated": s.bricks_integrated,
            "bricks_sub_cache": s.bricks_sub_cache,
            "bricks_removed": s.bricks_removed,
            "chunks_written": report.chunks_written,
            "chunks_read": report.chunks_read,
            "surface_points": report.surface_points,
            "ate_rmse": report.ate_rmse,
            "store_levels": report.store.as_ref().map(|r| r.levels),
            "peak_rss_bytes": crate::memory::peak_rss_bytes(),
            "memory_trace": s.memory_trace.iter().map(|(f, b)| [*f, *b]).collect::<Vec<_>>(),
        });
        std::fs::write(path, serde_json::to_string_pretty(&json)? + "\n")
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    }
    Ok(())
}

/// Runs `voxstream synth-rgbd`.
pub fn run_synth(args: &SynthArgs) -> Result<()> {
    let up_axis = match args.up.as_str() {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        other => bail!("--up {other}: give x, y or z"),
    };
    let settings = SyntheticSettings {
        frames: args.frames,
        object_size: args.object_size,
        radius: args.radius,
        height: args.height,
        sweep_degrees: args.sweep,
        walls: args.walls,
        up_axis,
        seed: args.seed,
        world: if args.level { voxstream_fusion::Pose::IDENTITY } else { SyntheticSettings::tilted_world() },
        noise: match args.noise {
            NoiseArg::Kinect => NoiseModel::KINECT_V1,
            NoiseArg::None => NoiseModel::NONE,
        },
        ..SyntheticSettings::default()
    };
    let sequence = SyntheticSequence::from_mesh_file(&args.mesh, settings)?;
    let progress = bar(args.quiet, sequence.len(), format!("rendering {}", args.out.display()));
    write_sequence(&sequence, &args.out, args.overwrite, &mut |done, _| progress.set_position(done as u64))?;
    progress.finish_and_clear();
    if !args.quiet {
        eprintln!(
            "wrote {} frames of {} (with ground truth and the true scene, scene.ply) to {}",
            sequence.len(),
            args.mesh.display(),
            args.out.display()
        );
    }
    Ok(())
}
