//! `voxstream render`: builds the session from the flags, renders a frame or a camera path, writes PNGs and stats.

use std::io::Write;
use std::path::Path;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use voxstream_core::json_limits::read_json_file;
use voxstream_core::{Producer, VoxelFormat};
use voxstream_engine::{FrameRenderer, LoopLimits, MemoryBudget, Mode, Session, MAX_BUDGET_MB};
use voxstream_geometry::formats::is_geometry_file_name;
use voxstream_render::{
    Camera, IsoSurface, RenderSettings, Shading, SurfaceNormals, TransferFunction, VolumePlacement,
};
use voxstream_store::{InMemoryVolume, StoreProducer, StoreReader};

use crate::backend::open_renderer;
use crate::camera_path::{generated_path, parse_generated_path, read_camera_file, read_camera_path};
use crate::cli::{BrickBits, NormalsArg, RenderArgs, ShadingArg, Switch};
use crate::exit_status::IncompleteImage;
use crate::geometry_source;
use crate::iso_flags;
use crate::memory::{bytes_read, peak_rss_bytes};
use crate::output_file::{check_output, write_output};
use crate::png_output::{numbered_path, write_png};
use crate::popping_run::FrameRecorder;
use crate::render_budget::{check_budget, plan_budget};
use crate::render_progress::RenderProgress;
use crate::render_warnings::{empty_image, transfer_function_mismatch};
use crate::scenes::builtin;
use crate::source_path::{check_store_path, missing_geometry_file, warn_about_leftovers};
use crate::stats::RemoteStats;
use crate::stats::RunStats;
use crate::store_open::{clipped_warning, open_store};

/// What `voxstream render` and `voxstream view` draw: a built-in scene, a store, or a mesh or particle file, with
/// its defaults.
pub struct Source<P> {
    /// The name given on the command line.
    pub name: String,
    /// The producer of its bricks.
    pub producer: P,
    /// Its default transfer function.
    pub transfer_function: TransferFunction,
    /// Its default shading.
    pub shading: Shading,
    /// Its default camera.
    pub camera: Camera,
    /// Where its tree cube sits in the world.
    pub placement: VolumePlacement,
    /// Data values the voxel values 0 and 1 stand for.
    pub value_range: [f64; 2],
    /// Span of the bulk of the values (0.5th to 99.5th percentile where the store keeps them).
    pub typical_range: [f64; 2],
    /// Bytes of the budget taken by the producer's own cache (the rest goes to the pools).
    pub producer_cache_bytes: u64,
    /// Bytes per sample of the source data.
    pub sample_bytes: u64,
    /// Direction towards the light unless `--light` is given (`None`: a headlight).
    pub light: Option<[f64; 3]>,
    /// Surfaces drawn when neither `--iso` nor `--tf` is given (empty: the volume).
    pub default_surfaces: Vec<IsoSurface>,
    /// The remote store the bricks come from (its requests, bytes and retries go into the statistics).
    pub remote: Option<Arc<voxstream_store::remote::RemoteStore>>,
}

/// The transfer function, settings and camera the flags make of a source's defaults.
pub struct PreparedView {
    /// `--tf`, or the source's.
    pub transfer_function: TransferFunction,
    /// The render settings.
    pub settings: RenderSettings,
    /// `--camera` with `--eye/--target/--up/--fov` over it, or the source's camera.
    pub camera: Camera,
    /// Whether isosurfaces are drawn (instead of the volume, or inside it with `--tf`).
    pub drawing_surfaces: bool,
}

/// Runs `voxstream render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    check_flags(args)?;
    let budget = check_budget(args.budget_mb, args.width, args.height, "--width/--height")?;
    open_source(args, &budget, RenderToFiles)
}

/// What is done with an opened source: `render` draws it to files, `view` shows it in a window.
pub trait SourceUser {
    /// Uses `source`, opened from `args.source` within `budget`.
    fn use_source<P: Producer + 'static>(
        self,
        args: &RenderArgs,
        source: Source<P>,
        budget: &MemoryBudget,
    ) -> Result<()>;
}

/// `render`'s use: frames to PNG files, statistics.
struct RenderToFiles;

impl SourceUser for RenderToFiles {
    fn use_source<P: Producer + 'static>(
        self,
        args: &RenderArgs,
        source: Source<P>,
        budget: &MemoryBudget,
    ) -> Result<()> {
        render_source(args, source, budget)
    }
}

/// Opens `args.source` (a built-in scene, a mesh or particle file, or a store) with its defaults, and hands it to
/// `user`.
pub fn open_source(args: &RenderArgs, budget: &MemoryBudget, user: impl SourceUser) -> Result<()> {
    let path = Path::new(&args.source);
    if args.value_range.is_some() && (builtin(&args.source).is_some() || is_geometry_file_name(path)) {
        bail!("--value-range applies to stores (other tools' OME-Zarr images); {} is not one", args.source);
    }
    if let Some(scene) = builtin(&args.source) {
        let source = Source {
            name: scene.name.to_string(),
            producer: scene.producer,
            transfer_function: scene.transfer_function,
            shading: scene.shading,
            camera: scene.camera,
            light: scene.light,
            placement: VolumePlacement::default(),
            value_range: [0.0, 1.0],
            typical_range: [0.0, 1.0],
            producer_cache_bytes: 0,
            sample_bytes: 2,
            default_surfaces: Vec::new(),
            remote: None,
        };
        check_geometry_flags(args, &source.name)?;
        return user.use_source(args, source, budget);
    }
    if path.is_file() && is_geometry_file_name(path) {
        let options = geometry_source::GeometryOptions {
            amplify: args.amplify,
            resolution: args.resolution,
            attribute: args.attribute,
            smoothing_scale: args.smoothing_scale,
            particle_memory: args.particle_memory,
            budget_mb: Some(args.budget_mb),
            width: args.width,
            height: args.height,
        };
        let geometry = geometry_source::open(path, &options)?;
        if !args.quiet {
            eprintln!("{}", geometry.description);
        }
        let source = Source {
            name: args.source.clone(),
            producer: geometry.producer,
            transfer_function: geometry.transfer_function,
            shading: Shading::Phong,
            camera: geometry.camera,
            placement: geometry.placement,
            value_range: geometry.value_range,
            typical_range: geometry.value_range,
            // The triangles' or particles' index is held for the whole run: it comes out of the budget.
            producer_cache_bytes: geometry.index_bytes,
            sample_bytes: 2,
            light: None,
            default_surfaces: geometry.default_surfaces,
            remote: None,
        };
        return user.use_source(args, source, budget);
    }
    if is_geometry_file_name(path) && !path.exists() {
        return Err(missing_geometry_file(path));
    }
    check_store_path(path, "render")?;
    check_geometry_flags(args, &voxstream_store::remote::redact(&args.source))?;
    let cache_bytes = budget.store_cache_bytes();
    let reader = Arc::new(open_store(path, cache_bytes, args.value_range, &args.remote, args.quiet)?);
    warn_about_leftovers(path);
    let attributes = reader.attributes().clone();
    let transfer_function = default_store_transfer_function(attributes.typical_range())?;
    // (A GPU session keeps 16-bit bricks whatever the producer allows: `FrameRenderer::needs_sixteen_bit_bricks`.)
    let format = match args.brick_bits {
        BrickBits::Auto => None,
        BrickBits::Sixteen => Some(VoxelFormat::Wide),
    };
    if args.in_memory {
        let volume = Arc::new(InMemoryVolume::load(&reader)?);
        let producer = StoreProducer::new(volume)?.with_voxel_format(format);
        let source = store_source(args, &reader, producer, 0, transfer_function);
        let result = user.use_source(args, source, budget);
        if let Some(warning) = clipped_warning(&reader) {
            eprintln!("{warning}");
        }
        return result;
    }
    // Interactive frames over a remote store never wait on the network: missing bricks are fetched behind them
    // while their ancestors stand in (converged frames, `render`'s default and the viewer's at rest, wait: see
    // `ServeOptions::wait_for_data`).
    reader.set_nonblocking(true);
    let producer = StoreProducer::new(reader.clone())?.with_voxel_format(format);
    let source = store_source(args, &reader, producer, cache_bytes, transfer_function);
    let result = user.use_source(args, source, budget);
    if let Some(warning) = clipped_warning(&reader) {
        eprintln!("{warning}");
    }
    result
}

fn store_source<P>(
    args: &RenderArgs,
    reader: &StoreReader,
    producer: P,
    producer_cache_bytes: u64,
    transfer_function: TransferFunction,
) -> Source<P> {
    Source {
        // The store as the reader shows it (a remote store's URL without credentials).
        name: reader.path().display().to_string(),
        producer,
        transfer_function,
        shading: Shading::None,
        camera: store_camera(reader.info(), args.width, args.height),
        placement: store_placement(reader),
        value_range: reader.attributes().value_range,
        typical_range: reader.attributes().typical_range(),
        producer_cache_bytes,
        sample_bytes: reader.info().dtype.size() as u64,
        light: None,
        default_surfaces: Vec::new(),
        remote: reader.remote().cloned(),
    }
}

/// `--amplify`, `--resolution`, `--attribute`, `--smoothing-scale` and `--particle-memory` shape the trees of mesh
/// and particle files only: given with a scene or a store, they are refused, not ignored.
fn check_geometry_flags(args: &RenderArgs, source: &str) -> Result<()> {
    let flags = [
        ("--amplify", args.amplify.is_some(), "mesh and particle files"),
        ("--resolution", args.resolution.is_some(), "mesh and particle files"),
        ("--attribute", args.attribute, "mesh and particle files"),
        ("--smoothing-scale", args.smoothing_scale.is_some(), "particle files"),
        ("--particle-memory", args.particle_memory.is_some(), "particle files"),
    ];
    for (flag, given, files) in flags {
        if given {
            bail!("{flag} applies to {files}; {source} is not one");
        }
    }
    Ok(())
}

/// `render`'s checks of the flags (also `view`'s, on the arguments it builds).
pub fn check_flags(args: &RenderArgs) -> Result<()> {
    crate::backend::check_backend_flags(args.backend, args.gpu_filter)?;
    if args.width == 0 || args.height == 0 {
        bail!("image size must be positive, got {}x{}", args.width, args.height);
    }
    if args.budget_mb == 0 {
        bail!("--budget-mb must be at least 1");
    }
    if args.budget_mb > MAX_BUDGET_MB {
        bail!("--budget-mb {} is larger than 1 TiB", args.budget_mb);
    }
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    if args.requests_per_frame == 0 {
        bail!("--requests-per-frame must be at least 1");
    }
    if args.popping && (args.mode != Mode::Interactive || args.stats.is_none()) {
        bail!("--popping measures interactive frames into the stats file: add --mode interactive and --stats FILE");
    }
    check_fade_frames(args.fade_frames)
}

/// `--fade-frames` (render and bench): at least 1.
pub fn check_fade_frames(fade_frames: u32) -> Result<()> {
    if fade_frames == 0 {
        bail!("--fade-frames must be at least 1 (1 replaces a parent at once; use --blending off for no blending)");
    }
    Ok(())
}

/// Where a store's tree cube sits in the world: sample `(i, j, k)` at `origin + spacing·(i, j, k)` (VTK/ITK), the
/// rays clipped to the box of the sample centres, as VTK's ray casters do.
pub fn store_placement(reader: &StoreReader) -> VolumePlacement {
    let info = reader.info();
    let layout = reader.layout();
    let span = (layout.brick_size << layout.max_tree_level()) as f64;
    VolumePlacement {
        origin: [0, 1, 2].map(|a| info.origin[a] - 0.5 * info.spacing[a]),
        scale: [0, 1, 2].map(|a| info.spacing[a] * span),
        clip_lower: [0.5 / span; 3],
        clip_upper: [0, 1, 2].map(|a| ((info.dims[a] as f64 - 0.5) / span).max(0.5 / span + 1e-9)),
    }
}

/// Direction from a store's centre towards the default eye: a three-quarter view from the front (−y), right (+x)
/// and above (+z).
pub const STORE_VIEW_DIRECTION: [f64; 3] = [0.55, -0.65, 0.52];

/// Fraction of the image's half-width and half-height the volume's box may fill in the default store view.
const STORE_FRAME_FILL: f64 = 0.95;

/// A three-quarter view of the volume's centre, `+z` up, 30° vertical field of view, just far enough that all eight
/// corners of the volume's box (the sample centres) fall inside a `width × height` image.
pub fn store_camera(info: &voxstream_store::VolumeInfo, width: u32, height: u32) -> Camera {
    let lower = info.origin;
    let upper = [0, 1, 2].map(|a| info.origin[a] + (info.dims[a] as f64 - 1.0) * info.spacing[a]);
    frame_box(lower, upper, width, height, STORE_VIEW_DIRECTION, [0.0, 0.0, 1.0])
}

/// A view of the box `lower..upper` from its centre's side `towards_eye`, `up` up, 30° vertical field of view, just
/// far enough that all eight corners fall inside a `width × height` image.
pub fn frame_box(
    lower: [f64; 3],
    upper: [f64; 3],
    width: u32,
    height: u32,
    towards_eye: [f64; 3],
    up: [f64; 3],
) -> Camera {
    use glam::DVec3;
    let lower = DVec3::from(lower);
    let upper = DVec3::from(upper);
    let centre = (lower + upper) * 0.5;
    let fov: f64 = 30.0;
    let up_hint = DVec3::from(up);
    let towards_eye = DVec3::from(towards_eye).normalize();
    // The camera's basis (as `Camera::frame` builds it): forward = −towards_eye, right = forward × up.
    let forward = -towards_eye;
    let right = forward.cross(up_hint).normalize();
    let up = right.cross(forward);
    let tan_vertical = (fov.to_radians() * 0.5).tan() * STORE_FRAME_FILL;
    let tan_horizontal = tan_vertical * width.max(1) as f64 / height.max(1) as f64;
    // A corner at offset r from the centre lies at depth D − r·towards_eye from an eye at distance D; it is inside
    // the image when |r·right| ≤ tan_h·depth and |r·up| ≤ tan_v·depth.
    let mut distance: f64 = 1e-9;
    for corner in 0..8 {
        let pick = |axis: usize| if corner >> axis & 1 == 1 { upper[axis] } else { lower[axis] };
        let r = DVec3::new(pick(0), pick(1), pick(2)) - centre;
        let along = r.dot(towards_eye);
        distance =
            distance.max(r.dot(right).abs() / tan_horizontal + along).max(r.dot(up).abs() / tan_vertical + along);
    }
    let eye = centre + towards_eye * distance;
    Camera { eye: eye.to_array(), target: centre.to_array(), up: up_hint.to_array(), fov }
}

/// A soft ramp over the upper 80% of `range` (the data's 0.5th to 99.5th percentile), reaching opacity 0.12 per
/// sample spacing at its top.
pub fn default_store_transfer_function(range: [f64; 2]) -> Result<TransferFunction> {
    let [lo, hi] = range;
    let hi = if hi > lo { hi } else { lo + 1.0 };
    let at = |f: f64| lo + (hi - lo) * f;
    Ok(TransferFunction::new(
        vec![
            [lo, 0.0, 0.0, 0.0, 0.0],
            [at(0.2), 0.55, 0.35, 0.25, 0.0],
            [at(0.6), 0.95, 0.8, 0.6, 0.05],
            [hi, 1.0, 1.0, 1.0, 0.12],
        ],
        None,
    )?)
}

/// Applies the flags to a source's defaults.
pub fn prepare_view<P>(args: &RenderArgs, source: &Source<P>) -> Result<PreparedView> {
    let transfer_function = match &args.tf {
        Some(path) => read_transfer_function(path, source.value_range)?,
        None => source.transfer_function.clone(),
    };
    let mut surfaces = iso_flags::surfaces(args, source.value_range)?;
    if surfaces.is_empty() && args.tf.is_none() {
        surfaces = source.default_surfaces.clone();
    }
    let drawing_surfaces = !surfaces.is_empty();
    let settings = RenderSettings {
        width: args.width,
        height: args.height,
        shading: match args.shading {
            Some(ShadingArg::None) => Shading::None,
            Some(ShadingArg::Phong) => Shading::Phong,
            None if drawing_surfaces => Shading::Phong,
            None => source.shading,
        },
        surfaces,
        shadows: args.shadows,
        surface_normals: match args.normals {
            NormalsArg::Cell => SurfaceNormals::Cell,
            NormalsArg::Central => SurfaceNormals::CentralDifferences,
        },
        // --iso with --tf: the surfaces inside the volume.
        surfaces_in_volume: drawing_surfaces && args.tf.is_some(),
        light_direction: args.light.or(source.light),
        background: args.background.map(|c| c as f32),
        step_factor: args.step,
        lod_bias: args.lod_bias,
        colour_by_level: args.colour_by_level,
        placement: source.placement,
        ..RenderSettings::default()
    };
    check_placement(&source.name, &source.placement)?;
    settings.validate().context("invalid flags")?;
    let mut view = match &args.camera {
        Some(path) => read_camera_file(path)?,
        None => source.camera,
    };
    if let Some(eye) = args.eye {
        view.eye = eye;
    }
    if let Some(target) = args.target {
        view.target = target;
    }
    if let Some(up) = args.up {
        view.up = up;
    }
    if let Some(fov) = args.fov {
        view.fov = fov;
    }
    view.frame(args.width, args.height).with_context(|| format!("invalid camera ({})", camera_origin(args, source)))?;
    Ok(PreparedView { transfer_function, settings, camera: view, drawing_surfaces })
}

/// Where the camera came from, for its error: the flags that set parts of it over `--camera FILE` or the source's
/// default view (e.g. "--eye 1e308,0,0 over sponge's default view").
fn camera_origin<P>(args: &RenderArgs, source: &Source<P>) -> String {
    let vector = |v: [f64; 3]| v.map(shown_number).join(",");
    let flags: Vec<String> = [
        args.eye.map(|v| format!("--eye {}", vector(v))),
        args.target.map(|v| format!("--target {}", vector(v))),
        args.up.map(|v| format!("--up {}", vector(v))),
        args.fov.map(|f| format!("--fov {}", shown_number(f))),
    ]
    .into_iter()
    .flatten()
    .collect();
    let base = match &args.camera {
        Some(path) => format!("--camera {}", path.display()),
        None => format!("{}'s default view", source.name),
    };
    if flags.is_empty() {
        base
    } else {
        format!("{} over {base}", flags.join(", "))
    }
}

/// A number as a user would type it: `1500`, `0.25`, but `1e30` rather than thirty-one digits.
pub fn shown_number(value: f64) -> String {
    if value == 0.0 || (1e-4..1e15).contains(&value.abs()) || !value.is_finite() {
        format!("{value}")
    } else {
        format!("{value:e}")
    }
}

/// The volume's place in the world is the source's (a store's spacing and origin, a mesh's bounds), not the flags':
/// a bad one is blamed on the source.
fn check_placement(name: &str, placement: &VolumePlacement) -> Result<()> {
    let finite = placement.origin.iter().chain(&placement.scale).all(|v| v.is_finite());
    if !(finite && placement.scale.iter().all(|s| *s > 0.0)) {
        bail!(
            "{name}: its place in the world is not finite (origin {:?}, size {:?}): its coordinates are too large \
             (for a store, its spacing and origin: see `voxstream info`)",
            placement.origin,
            placement.scale
        );
    }
    Ok(())
}

/// Whether interactive frames blend arriving bricks in (Thiele et al.): `--blending on`, on either backend.
fn blending(args: &RenderArgs) -> bool {
    args.blending == Switch::On
}

fn render_source<P: Producer>(args: &RenderArgs, source: Source<P>, budget: &MemoryBudget) -> Result<()> {
    let PreparedView { transfer_function, settings, camera: view, drawing_surfaces } = prepare_view(args, &source)?;
    let surfaces_in_volume = settings.surfaces_in_volume;
    let cameras = match &args.path {
        Some(path) => match path.to_str().filter(|_| !path.exists()).and_then(parse_generated_path) {
            Some(generated) => {
                let (kind, frames) = generated?;
                generated_path(kind, frames, &view)
            }
            None => read_camera_path(path)?,
        },
        None => vec![view],
    };
    // Before the work: a folder, a disk or a missing folder as an output is refused now, not after the render.
    check_output(&if args.path.is_some() { numbered_path(&args.out, 0) } else { args.out.clone() }, "--out")?;
    if let Some(path) = &args.stats {
        check_output(path, "--stats")?;
    }

    let budget_bytes = budget.total_bytes();
    let limits = LoopLimits {
        requests_per_frame: args.requests_per_frame,
        blending_fade_frames: blending(args).then_some(args.fade_frames),
        ..LoopLimits::default()
    };
    let plan = plan_budget(budget, &source.producer.shape(), source.producer_cache_bytes)?;
    let renderer = open_renderer(args.backend, args.gpu_filter)?;
    let mut session = Session::with_renderer(
        renderer,
        source.producer,
        &transfer_function,
        settings,
        plan.pool_bytes,
        limits,
        source.value_range,
    )?;
    let mut stats = RunStats {
        source: source.name.clone(),
        mode: format!("{:?}", args.mode).to_lowercase(),
        budget_bytes,
        threads: rayon::current_num_threads(),
        backend: session.renderer().describe(),
        ..RunStats::default()
    };
    stats.camera = cameras.first().copied();
    let read_before = bytes_read();
    let sequence = args.path.is_some();
    let repeats = if sequence || args.mode == Mode::Converged { 1 } else { args.frames };
    let progress = RenderProgress::new(cameras.len() as u64 * u64::from(repeats), args.quiet);
    let mismatch = transfer_function_mismatch(&transfer_function, source.typical_range, source.value_range);
    if let Some(warning) = mismatch.filter(|_| !drawing_surfaces || surfaces_in_volume) {
        progress.warn(&warning);
    }
    // --popping: popping and seams against the converged images, rendered afterwards.
    let mut recorder = None;
    if args.popping {
        match FrameRecorder::new(args.width, args.height, cameras.len() as u64 * u64::from(repeats)) {
            Ok(r) => recorder = Some(r),
            Err(warning) => progress.warn(&warning),
        }
    }
    stats.blending = args.mode == Mode::Interactive && blending(args);
    let mut empty_images = 0usize;
    let mut reported_failures = 0usize;
    let mut written = Vec::new();
    for (index, camera) in cameras.iter().enumerate() {
        for repeat in 0..repeats {
            let result = session.render_observed(camera, args.mode, &mut |pass| progress.pass(pass))?;
            for failure in &result.failures {
                // Each failed brick is reported once; its ancestor stands in.
                if reported_failures < 20 {
                    progress.warn(&format!("{failure}; drawing its coarser ancestor instead"));
                }
                reported_failures += 1;
            }
            stats.frame_ms.push(result.elapsed_ms);
            stats.passes.push(result.passes);
            stats.rays += result.rays;
            stats.samples += result.samples;
            stats.requests += result.requests;
            stats.bricks_produced += result.bricks_produced;
            stats.forced_steps += result.forced_steps;
            stats.restriction_yielded += result.restriction_yielded;
            stats.converged = result.is_converged();
            if let Some(recorder) = &mut recorder {
                recorder.record(camera, &result.image);
            }
            // A single camera stops early once a frame is final (nothing missing, nothing blending): later frames
            // would be identical.
            if repeat + 1 == repeats || (!sequence && result.is_final()) {
                let out = if sequence { numbered_path(&args.out, index) } else { args.out.clone() };
                write_png(&result.image, &out)?;
                let volume = !drawing_surfaces || surfaces_in_volume;
                if let Some(warning) = empty_image(&result.image, drawing_surfaces, volume) {
                    if empty_images == 0 {
                        progress.warn(&format!("{}: {warning}", out.display()));
                    }
                    empty_images += 1;
                }
                stats.frames += 1;
                // A sequence lists each file as it is written; a single image is named in the summary.
                progress.frame_done(sequence.then_some(out.as_path()));
                written.push(out);
                break;
            }
            progress.frame_done(None);
        }
    }
    if let Some(recorder) = &recorder {
        stats.popping = Some(recorder.measure(&mut session)?);
    }
    let residency = session.residency();
    stats.bricks_resident = residency.bricks as u64;
    stats.nodes_resident = residency.nodes;
    stats.resident_bytes_peak = session.peak_resident_bytes();
    stats.bytes_uploaded = session.renderer().bytes_uploaded();
    stats.producer_failures = reported_failures;
    stats.peak_rss_bytes = peak_rss_bytes();
    stats.first_frame_ms = stats.frame_ms.first().copied();
    if let (Some(before), Some(after)) = (read_before, bytes_read()) {
        if source.producer_cache_bytes > 0 {
            stats.file_bytes_read = Some(after - before);
            let m = session.cache().shape().brick_size as u64;
            stats.brick_bytes_used = Some(residency.bricks as u64 * m * m * m * source.sample_bytes);
        }
    }
    stats.remote = source.remote.as_ref().map(|remote| RemoteStats::from(remote.counts()));
    if !stats.converged && args.mode == Mode::Converged {
        progress.warn(&format!(
            "the last frame did not converge: the budget of {} MiB cannot hold what the view needs; coarser data \
             stands in (raise --budget-mb)",
            args.budget_mb
        ));
    }
    if empty_images > 1 {
        progress.warn(&format!("{empty_images} of the {} images written are empty", written.len()));
    }
    if let Some(path) = &args.stats {
        let text = serde_json::to_string_pretty(&stats)?;
        write_output(path, |file| Ok(file.write_all(text.as_bytes())?))
            .with_context(|| format!("cannot write stats to {}", path.display()))?;
    }
    progress.finish(&summary_line(&written, args, &stats));
    if reported_failures > 0 {
        return Err(IncompleteImage { failed_bricks: reported_failures }.into());
    }
    Ok(())
}

/// `wrote frame.png (512x512, converged, 10 passes, 6198 bricks loaded)`, or for a sequence the first and last file.
fn summary_line(written: &[std::path::PathBuf], args: &RenderArgs, stats: &RunStats) -> String {
    let files = match written {
        [one] => one.display().to_string(),
        [first, .., last] => format!("{} frames, {} … {}", written.len(), first.display(), last.display()),
        [] => "nothing".into(),
    };
    let state = if stats.producer_failures > 0 {
        format!("incomplete: {} bricks unreadable, coarser data stands in", stats.producer_failures)
    } else if stats.converged {
        "complete".into()
    } else {
        "incomplete: coarser data stands in".into()
    };
    let passes: u32 = stats.passes.iter().sum();
    format!(
        "wrote {files} ({}x{}, {state}, {passes} passes, {} bricks loaded)",
        args.width, args.height, stats.bricks_produced
    )
}

/// Reads `--tf`: voxstream's JSON, or a ParaView colour-map preset rescaled onto `value_range`.
fn read_transfer_function(path: &Path, value_range: [f64; 2]) -> Result<TransferFunction> {
    let text = read_json_file(path, "transfer function")?;
    TransferFunction::from_json_or_paraview(&text, value_range).with_context(|| format!("in {}", path.display()))
}
