//! `fuse`: an RGB-D sequence (a TUM RGB-D benchmark folder) fused into binary bricks and saved as a store
//! (seed 004 ch. 8; [`voxstream_fusion`]). Poses come from the dataset's ground truth or from tracking each frame
//! against the surface fused so far (§8.2); the scene is saved as a store `render` and `view` open, and optionally as
//! surface points and a trajectory.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use voxstream_fusion::caster::{self, Surface};
use voxstream_fusion::export::FusedVolume;
use voxstream_fusion::rgbd::TumDataset;
use voxstream_fusion::surface::{smooth_points, surface_points, write_points_ply};
use voxstream_fusion::tracking::{ate_rmse, prepare_frame, track, ModelView, TrackingSettings};
use voxstream_fusion::{Fusion, FusionSettings, FusionStats, Intrinsics, Pose};
use voxstream_store::{import_volume, ImportOptions, ImportReport};

/// Where each frame's pose comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseSource {
    /// The dataset's `groundtruth.txt`.
    GroundTruth,
    /// ICP against the fused surface, starting at the first frame's ground truth (or the origin without one).
    Track,
}

/// What `fuse` is asked to do.
#[derive(Clone, Debug)]
pub struct FuseOptions {
    pub settings: FusionSettings,
    pub poses: PoseSource,
    /// Fuse only the first this many frames.
    pub frames: Option<usize>,
    /// Intrinsics instead of the benchmark's defaults.
    pub intrinsics: Option<Intrinsics>,
    /// The store to write (`None`: only measure).
    pub out: Option<PathBuf>,
    pub overwrite: bool,
    /// Surface points (PLY) to write.
    pub points: Option<PathBuf>,
    /// Write the voxel faces' centres as they are, without [`smooth_points`].
    pub raw_points: bool,
    /// The estimated trajectory (TUM format) to write.
    pub trajectory: Option<PathBuf>,
    /// Render the fused surface from the last frame's pose (confident voxels, ROF-smoothed, shaded) into
    /// [`FuseReport::image`].
    pub image: bool,
}

/// What `fuse` did.
#[derive(Clone, Debug)]
pub struct FuseReport {
    pub stats: FusionStats,
    /// Frames skipped because tracking lost them.
    pub frames_lost: usize,
    /// Seconds spent fusing (and tracking), without reading frames.
    pub fuse_seconds: f64,
    /// Seconds spent reading frames.
    pub read_seconds: f64,
    /// Seconds spent tracking (included in `fuse_seconds`).
    pub track_seconds: f64,
    /// Resident bricks at the end, and chunks streamed out and back in.
    pub bricks: usize,
    pub chunks_written: u64,
    pub chunks_read: u64,
    /// Surface points written to `points`.
    pub surface_points: Option<usize>,
    /// ATE RMSE (metres) of the tracked poses against ground truth, where both exist.
    pub ate_rmse: Option<f64>,
    pub store: Option<ImportReport>,
    /// RGB8 pixels, width and height of the view asked for by [`FuseOptions::image`].
    pub image: Option<(Vec<u8>, u32, u32)>,
}

/// The scratch folder chunks stream to while this process fuses into `out`: `OUT.fusion-chunks-PID`, unique to the
/// process, so that nothing of anyone else's is ever reused or deleted.
pub fn chunk_folder(out: &Path) -> PathBuf {
    let mut name = out.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(format!(".fusion-chunks-{}", std::process::id()));
    out.with_file_name(name)
}

/// Tracks `frame` against the surface seen from `previous`; `None` when tracking is lost.
fn track_frame(fusion: &Fusion, depth: &[f32], k: &Intrinsics, previous: Pose) -> Option<Pose> {
    // The model is rendered at half the frame's resolution: ICP's finest level pairs frame pixels with it.
    let half = Intrinsics {
        width: k.width / 2,
        height: k.height / 2,
        fx: k.fx / 2.0,
        fy: k.fy / 2.0,
        cx: (k.cx + 0.5) / 2.0 - 0.5,
        cy: (k.cy + 0.5) / 2.0 - 0.5,
    };
    let far = f64::from(fusion.settings().depth_range[1]);
    let view = caster::render(fusion.map(), &previous, &half, Surface::Any, far);
    let smoothed = caster::smooth_depth(&view, fusion.settings().integration.voxel, 30);
    let model = ModelView::from_depth(&smoothed, half, previous);
    let frame = prepare_frame(depth, k);
    track(&frame, k, &model, previous, &TrackingSettings::default()).ok().map(|r| r.pose)
}

/// Fuses the sequence in `dataset`; `progress(done, total)` is called after every frame, and stops the fusion
/// (an error, nothing saved) by answering `Break`.
pub fn fuse_dataset(
    dataset: &Path,
    options: &FuseOptions,
    progress: &mut dyn FnMut(usize, usize) -> ControlFlow<()>,
) -> Result<FuseReport> {
    let mut data = TumDataset::open(dataset)?;
    if let Some(k) = options.intrinsics {
        data = data.with_intrinsics(k);
    }
    if data.is_empty() {
        bail!("{}: the dataset has no depth frame with a colour frame within 0.02 s", dataset.display());
    }
    if options.poses == PoseSource::GroundTruth && !data.has_ground_truth() {
        bail!("{}: no groundtruth.txt; fuse with --poses track to estimate the poses", dataset.display());
    }
    if let Some(out) = &options.out {
        if out.exists() && !options.overwrite {
            bail!("{} exists; give --overwrite to replace it", out.display());
        }
    }
    let mut settings = options.settings.clone();
    let scratch = options.out.as_ref().map(|out| chunk_folder(out));
    if let Some(dir) = &scratch {
        // Never someone else's: a folder of this name left by an earlier process of the same number is an error.
        std::fs::create_dir(dir).with_context(|| {
            format!(
                "creating the scratch folder {} for streamed chunks (remove it if a crashed fuse left it)",
                dir.display()
            )
        })?;
    }
    settings.spill_dir = scratch.clone();
    let result = fuse_into(&data, options, settings, progress);
    if let Some(dir) = &scratch {
        let _ = std::fs::remove_dir_all(dir);
    }
    result
}

fn fuse_into(
    data: &TumDataset,
    options: &FuseOptions,
    settings: FusionSettings,
    progress: &mut dyn FnMut(usize, usize) -> ControlFlow<()>,
) -> Result<FuseReport> {
    let memory = settings.memory_budget as u64;
    let mut fusion = Fusion::new(settings)?;
    let total = options.frames.map_or(data.len(), |n| n.min(data.len()));
    let (mut read_seconds, mut fuse_seconds, mut track_seconds) = (0.0, 0.0, 0.0);
    let mut frames_lost = 0;
    // Every fused frame's timestamp, pose used and ground truth.
    let mut fused: Vec<(f64, Pose, Option<Pose>)> = Vec::new();
    let mut previous: Option<Pose> = None;
    for i in 0..total {
        let start = Instant::now();
        let frame = data.frame(i)?;
        read_seconds += start.elapsed().as_secs_f64();
        let start = Instant::now();
        let pose = match (options.poses, previous) {
            (PoseSource::GroundTruth, _) => match frame.pose {
                Some(p) => Some(p),
                None => {
                    frames_lost += 1;
                    None
                }
            },
            (PoseSource::Track, None) => Some(frame.pose.unwrap_or(Pose::IDENTITY)),
            (PoseSource::Track, Some(prev)) => {
                let t = Instant::now();
                let tracked = track_frame(&fusion, &frame.depth, &frame.intrinsics, prev);
                track_seconds += t.elapsed().as_secs_f64();
                if tracked.is_none() {
                    frames_lost += 1;
                }
                tracked
            }
        };
        if let Some(pose) = pose {
            fusion.add_frame(&frame, pose)?;
            previous = Some(pose);
            fused.push((frame.timestamp, pose, frame.pose));
        }
        fuse_seconds += start.elapsed().as_secs_f64();
        if progress(i + 1, total).is_break() {
            bail!("fusion stopped after {} of {total} frames; nothing was saved", i + 1);
        }
    }
    let start = Instant::now();
    fusion.finish()?;
    fuse_seconds += start.elapsed().as_secs_f64();
    if let Some(path) = &options.trajectory {
        write_trajectory(path, &fused)?;
    }
    let (estimated, truth): (Vec<Pose>, Vec<Pose>) = fused.iter().filter_map(|(_, p, t)| t.map(|t| (*p, t))).unzip();
    let ate = (options.poses == PoseSource::Track && estimated.len() >= 2).then(|| ate_rmse(&estimated, &truth));
    let (chunks_written, chunks_read) = (fusion.map().chunks_written, fusion.map().chunks_read);
    // Saving reads every streamed chunk back: refuse before that if the bricks cannot fit this machine.
    let all_bricks = fusion.map().resident_bytes() as u64 + fusion.map().spilled_bytes();
    if let Some(machine) = voxstream_engine::machine_memory_bytes() {
        if all_bricks > machine / 4 * 3 {
            bail!(
                "the fused scene holds {:.1} GiB of bricks, more than three quarters of this machine's {:.1} GiB: \
                 saving it needs them all in memory; fuse with a coarser --voxel or fewer --frames",
                all_bricks as f64 / f64::from(1u32 << 30),
                machine as f64 / f64::from(1u32 << 30)
            );
        }
    }
    fusion.map_mut().read_all_back()?;
    let image = match (options.image, fused.last()) {
        (true, Some((_, pose, _))) => {
            let k = data.intrinsics();
            let far = f64::from(fusion.settings().depth_range[1]);
            let view = caster::render(fusion.map(), pose, &k, Surface::Confident, far);
            let smoothed = caster::smooth_depth(&view, fusion.settings().integration.voxel, 75);
            Some((caster::shade(&view, &smoothed), k.width, k.height))
        }
        _ => None,
    };
    let surface = match &options.points {
        Some(path) => {
            let mut points = surface_points(fusion.map());
            if !options.raw_points {
                points = smooth_points(&points, 1.5 * fusion.settings().integration.voxel);
            }
            write_points_ply(path, &points)?;
            Some(points.len())
        }
        None => None,
    };
    let store = match &options.out {
        Some(out) => {
            let Some(mut volume) = FusedVolume::new(fusion.map(), memory)? else {
                bail!("nothing was fused with confidence: no frame saw a surface within the depth range (check the depth scale and --frames)");
            };
            let import = ImportOptions { overwrite: options.overwrite, ..ImportOptions::default() };
            let report = import_volume(&mut volume, out, &import, &mut |_, _| {})
                .with_context(|| format!("saving the fused scene to {}", out.display()))?;
            Some(report)
        }
        None => None,
    };
    Ok(FuseReport {
        stats: fusion.stats.clone(),
        frames_lost,
        fuse_seconds,
        read_seconds,
        track_seconds,
        bricks: fusion.map().len(),
        chunks_written,
        chunks_read,
        surface_points: surface,
        ate_rmse: ate,
        store,
        image,
    })
}

/// Writes the poses used, one line per fused frame (`timestamp tx ty tz qx qy qz qw`).
fn write_trajectory(path: &Path, fused: &[(f64, Pose, Option<Pose>)]) -> Result<()> {
    let mut text = String::from("# timestamp tx ty tz qx qy qz qw (voxstream fuse)\n");
    for (stamp, pose, _) in fused {
        let q = glam::DQuat::from_mat3(&pose.matrix3);
        let t = pose.translation;
        text.push_str(&format!(
            "{stamp:.6} {:.6} {:.6} {:.6} {:.6} {:.6} {:.6} {:.6}\n",
            t.x, t.y, t.z, q.x, q.y, q.z, q.w
        ));
    }
    std::fs::write(path, text).with_context(|| format!("writing the trajectory to {}", path.display()))
}
