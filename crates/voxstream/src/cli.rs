//! Command-line definitions (clap). Flags are validated here; objects are built in `render_command`.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use voxstream_engine::Mode;

/// voxstream: render volumes far larger than memory, loading only what the rays reach.
#[derive(Parser, Debug)]
#[command(name = "voxstream", version, about, long_about = None)]
pub struct Cli {
    /// What to do (default: render the default scene to frame.png).
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// Subcommands.
// Parsed once per run: the size of the largest variant costs nothing worth a Box.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render a built-in scene, a store, or a mesh or particle file to PNG.
    Render(RenderArgs),
    /// Import a volume file into a multiresolution OME-Zarr brick store.
    Import(ImportArgs),
    /// Describe a store: dimensions, type, spacing, levels, bricks, bytes, value range.
    Info(InfoArgs),
    /// List the built-in scenes.
    Scenes,
    /// Measure converged time, frames to converge, interactive frame times and throughput per scene (all scenes
    /// at the defaults take about 4.5 minutes on 2 cores; --scenes, --warm-frames and --path-frames shorten it).
    Bench(BenchArgs),
    /// Open a window on a built-in scene, a store, or a mesh or particle file: orbit, zoom and fly through it while
    /// data streams in, edit the transfer function, save screenshots, cameras and transfer functions for `render`.
    View(ViewArgs),
    /// Fuse an RGB-D sequence (a TUM RGB-D benchmark folder) into binary bricks and save it as a store: windowed
    /// fusion of sign and confidence bits (Reichl ch. 8), poses from ground truth or ICP tracking.
    Fuse(crate::fuse_command::FuseArgs),
    /// Render a synthetic RGB-D sequence from a mesh on a floor along an orbit, with Kinect-like noise, ground-truth
    /// poses and the true scene, in the TUM RGB-D layout `fuse` reads.
    SynthRgbd(crate::fuse_command::SynthArgs),
}

/// `voxstream view`.
#[derive(Args, Debug, Clone)]
pub struct ViewArgs {
    /// SOURCE and how it is opened (as `render`'s).
    #[command(flatten)]
    pub input: SourceFlags,
    /// A scripted session: one camera move or action per line (see the README's "Viewer" section), e.g. for
    /// demonstrations and end-to-end tests.
    #[arg(long, value_name = "FILE")]
    pub script: Option<PathBuf>,
    /// When the window closes, write a frame log here (JSON: every frame's time, size and state; the first image,
    /// the first final image, the median moving frame, and input-to-final times).
    #[arg(long, value_name = "FILE")]
    pub stats: Option<PathBuf>,
    /// Render size in pixels (the image is scaled to the window; moving frames are smaller).
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    /// Render height in pixels.
    #[arg(long, default_value_t = 640)]
    pub height: u32,
    /// Memory budget of the node and brick pools, MiB.
    #[arg(long, default_value_t = 512)]
    pub budget_mb: u64,
    /// Requests served per frame (more: detail arrives in fewer frames, each frame takes longer).
    #[arg(long, default_value_t = 256)]
    pub requests_per_frame: usize,
    /// How a view at rest reaches its final image: converged (passes that trace again only what still misses data,
    /// interrupted by any input; the final image appears at once, as fast as `render`) or blended (interactive
    /// frames until final: detail fades in, several times slower).
    #[arg(long, value_enum, default_value_t = RefineArg::Converged)]
    pub refine: RefineArg,
    /// How it is drawn (as `render`'s).
    #[command(flatten)]
    pub look: LookFlags,
}

/// Shading choice on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ShadingArg {
    /// Emission-absorption only.
    None,
    /// Phong with the density gradient.
    Phong,
}

/// Isosurface normals on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum NormalsArg {
    /// The analytic gradient of the trilinear cell hit.
    Cell,
    /// Central differences at the cell's corners, interpolated trilinearly.
    Central,
}

/// What `render` and `view` draw and how it is opened: SOURCE and the flags that shape it (one set, flattened into
/// both commands, turned into the facade's `SourceOptions` by [`crate::view_flags::source_options`]).
#[derive(Args, Debug, Clone)]
pub struct SourceFlags {
    /// A built-in scene (sponge, hypertexture, shell), a store (a folder made by `voxstream import` or another
    /// tool's OME-Zarr image, or its URL: https://…, s3://BUCKET/PREFIX, gs://…, az://…), or a mesh (.ply,
    /// .obj, .off, .stl) or particle file (.ply points, .xyz/.csv, .gro, .pdb, .vtk, .vtp, .vtu; any of them .gz).
    #[arg(default_value = crate::scenes::DEFAULT_SCENE)]
    pub source: String,
    /// Mesh files: add multi-octave noise to the distance field (GigaVoxels' hypertexture), amplitude as a fraction
    /// of the mesh's largest side, e.g. 0.02.
    #[arg(long, value_name = "AMPLITUDE")]
    pub amplify: Option<f64>,
    /// Mesh and particle files: voxels per axis of the finest level (default: from the triangles' size or the
    /// smoothing lengths).
    #[arg(long, value_name = "VOXELS")]
    pub resolution: Option<u64>,
    /// Particle files: render the particles' scalar attribute (SPH-interpolated) instead of their density.
    #[arg(long)]
    pub attribute: bool,
    /// Particle files: the SPH kernel reaches FACTOR times the file's smoothing length. 1 (the default) where the
    /// file's `h` is the kernel's support radius (Gadget's `hsml`); 2 for codes whose cubic spline reaches 2h
    /// (PySPH, Monaghan's convention). Molecular files (.gro, .pdb): 2 times the atomic radius unless given.
    #[arg(long, value_name = "FACTOR")]
    pub smoothing_scale: Option<f64>,
    /// Binary PLY point files and columns of text (.xyz, .csv, .txt): read the particles out of core, binned once into
    /// superbricks in a spill file (24
    /// bytes per particle, in $TMPDIR), holding about MIB of them in memory. Chosen by itself, with a quarter of the
    /// machine's memory, for a PLY point file that would take more than half of it.
    #[arg(long, value_name = "MIB")]
    pub particle_memory: Option<u64>,
    /// Stores only: decode every level into RAM first and render from there (a baseline for benchmarks; ignores
    /// --budget-mb for the volume itself).
    #[arg(long)]
    pub in_memory: bool,
    /// Stores only: how the brick pool keeps voxels: auto (8 bits for 8-bit volumes, half the memory; 16 bits
    /// otherwise, and with --backend gpu, whose atlas is 16-bit) or 16 (always 16 bits, as before 8-bit bricks).
    #[arg(long, value_enum, default_value_t = BrickBits::Auto)]
    pub brick_bits: BrickBits,
    /// Other tools' OME-Zarr images: normalise by this value range instead of level 0's (which is then not read
    /// at open); samples beyond it are clipped, with a warning.
    #[arg(long, value_name = "LO,HI", value_parser = crate::store_open::parse_value_range, allow_hyphen_values = true)]
    pub value_range: Option<[f64; 2]>,
    /// 4-D and 5-D OME-Zarr images: the channel to draw (0 by default; `info` lists them).
    #[arg(long, value_name = "C")]
    pub channel: Option<u64>,
    /// The time point to draw (0 by default): of a 5-D (or 4-D) OME-Zarr image, or, with --fluid, the step of a time
    /// series (0-based, in file-name order).
    #[arg(long, value_name = "T")]
    pub time: Option<u64>,
    /// Remote stores: the on-disk cache and the client's patience.
    #[command(flatten)]
    pub remote: RemoteArgs,
    /// Particle files as a fluid (binary voxels and smoothed spheres).
    #[command(flatten)]
    pub fluid: FluidFlags,
}

/// `--fluid` and its settings: a particle file drawn as a liquid (Reichl ch. 6).
#[derive(Args, Debug, Clone)]
pub struct FluidFlags {
    /// Particle files: draw them as a fluid (FLIP/SPH liquids): binned once into bricks of one bit per cell, drawn
    /// as spheres of --particle-radius, the surface smoothed in screen space, isolated particles as foam. SOURCE
    /// may be a folder of particle files or a pattern such as 'splash_*.ply': a time series (see --time).
    #[arg(long)]
    pub fluid: bool,
    /// With --fluid: sphere radius in the file's units (default: 0.6 times the particles' estimated spacing).
    #[arg(long, value_name = "R", allow_negative_numbers = true)]
    pub particle_radius: Option<f64>,
    /// With --fluid: cell edge of the binary grid in the file's units (default: the radius; smaller is more exact
    /// and slower).
    #[arg(long, value_name = "EDGE", allow_negative_numbers = true)]
    pub fluid_cell: Option<f64>,
    /// With --fluid: screen-space smoothing of the surface: rof (total variation, Rudin–Osher–Fatemi, depth-
    /// adaptive), bilateral, or none (the spheres as they are).
    #[arg(long, value_enum, default_value_t = SmoothArg::Rof)]
    pub smooth: SmoothArg,
    /// With --smooth rof: iterations of the solver.
    #[arg(long, default_value_t = 75, value_name = "N")]
    pub smooth_iterations: u32,
    /// With --smooth rof: strength relative to the estimate from the spheres' size on screen (4, the default, was
    /// measured best on a ball of particles; larger flattens droplets).
    #[arg(long, default_value_t = 4.0, value_name = "FACTOR")]
    pub smooth_strength: f32,
    /// With --fluid: a particle whose neighbourhood holds less than this fraction of what the fluid's interior
    /// holds is foam, drawn as white translucent spray (0: no foam).
    #[arg(long, default_value_t = 0.2, value_name = "FRACTION", allow_negative_numbers = true)]
    pub foam: f64,
}

impl Default for FluidFlags {
    fn default() -> Self {
        FluidFlags {
            fluid: false,
            particle_radius: None,
            fluid_cell: None,
            smooth: SmoothArg::Rof,
            smooth_iterations: 75,
            smooth_strength: 4.0,
            foam: 0.2,
        }
    }
}

/// `--smooth`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SmoothArg {
    /// Total variation (Rudin–Osher–Fatemi), stronger near the camera.
    Rof,
    /// A depth-aware bilateral filter.
    Bilateral,
    /// None.
    None,
}

/// How `render` and `view` draw it: camera, transfer function, isosurfaces, shading, sampling, backend and level
/// blending (one set, flattened into both commands; [`crate::view_flags::view_options`]).
#[derive(Args, Debug, Clone)]
pub struct LookFlags {
    /// Camera JSON {"eye": [x,y,z], "target": [x,y,z], "up": [x,y,z], "fov": 30}, as `voxstream view` saves it;
    /// --eye, --target, --up and --fov override its fields.
    #[arg(long, value_name = "FILE")]
    pub camera: Option<PathBuf>,
    /// Eye position x,y,z (world units; the built-in scenes fill the unit cube [0,1]^3).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<[f64; 3]>,
    /// Point looked at, x,y,z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<[f64; 3]>,
    /// Up direction x,y,z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<[f64; 3]>,
    /// Vertical field of view in degrees.
    #[arg(long)]
    pub fov: Option<f64>,
    /// Frame the volume looking along an axis of the data (ParaView's view-direction buttons): +x, -x, +y, -y (+z
    /// up), +z, -z (+y up), or iso (a three-quarter view from the +x, -y, +z corner); or at a side of the patient
    /// where the store says its anatomical orientation (3D Slicer's views): anterior, posterior, left, right (head
    /// up), superior, inferior (the front up). Replaces --camera and the default view; --fov, --azimuth, --elevation
    /// and --zoom apply over it.
    #[arg(long, value_name = "DIR", value_parser = parse_view_direction, allow_hyphen_values = true)]
    pub view: Option<voxstream_api::camera_presets::ViewDirection>,
    /// Turn the camera this many degrees about its up direction through the point looked at (positive: the eye
    /// moves to its right), keeping its distance.
    #[arg(long, value_name = "DEGREES", allow_negative_numbers = true)]
    pub azimuth: Option<f64>,
    /// Raise the camera this many degrees towards its up direction (90: straight down on the target; negative:
    /// from below), keeping its distance and its up direction (no roll).
    #[arg(long, value_name = "DEGREES", allow_negative_numbers = true)]
    pub elevation: Option<f64>,
    /// Move the camera towards what it looks at: 2 is twice as close, 0.5 twice as far (applied last).
    #[arg(long, value_name = "FACTOR", allow_negative_numbers = true)]
    pub zoom: Option<f64>,
    /// How the samples along each ray make its pixel: composite (volume rendering, the default), max (maximum
    /// intensity projection, MIP), min (minimum intensity projection) or mean. A projection shows its value in the
    /// transfer function's colour, with the function's opacity relative to its most opaque point. CPU backend.
    #[arg(long, value_enum, default_value_t = ProjectionArg::Composite)]
    pub projection: ProjectionArg,
    /// Cut the volume open: keep the side of the plane through the point X,Y,Z (world units) that the normal
    /// NX,NY,NZ points to. Repeat for up to 6 planes. CPU backend.
    #[arg(long, value_name = "X,Y,Z,NX,NY,NZ", value_parser = parse_clip_plane, allow_hyphen_values = true)]
    pub clip_plane: Vec<voxstream_render::ClipPlane>,
    /// Stores: draw only the box of level-0 samples X0..X1, Y0..Y1, Z0..Z1 (sample indices as `voxstream info`
    /// gives the dimensions, upper bounds excluded); the rest stays transparent.
    #[arg(long, value_name = "X0,Y0,Z0,X1,Y1,Z1", value_parser = parse_crop)]
    pub crop: Option<[[u64; 3]; 2]>,
    /// Stores: draw one plane of level-0 samples alone, face-on: x=K, y=K, z=K (or sagittal=K, coronal=K, axial=K:
    /// the body's planes where the store says its anatomical orientation), as the mean through the one-sample slab
    /// around it, in the transfer function's colours (--with-volume: inside the volume). CPU backend.
    #[arg(long, value_name = "AXIS=INDEX", value_parser = voxstream_api::slices::parse_slice)]
    pub slice: Option<voxstream_api::slices::Slice>,
    /// With --slice: draw the plane inside the volume rendering, seen from the default view (or the one given): the
    /// volume between the eye and the plane cut away, the plane's values over the volume beyond it. CPU backend.
    #[arg(long, requires = "slice")]
    pub with_volume: bool,
    /// Draw the transfer function's colour bar at the right edge: its colours from its first to its last point
    /// (labelled, data units) and its opacity as a white curve.
    #[arg(long, alias = "colour-bar")]
    pub color_bar: bool,
    /// Draw a scale bar at the bottom left: a round length in the data's units (a store's OME-Zarr unit), as long as
    /// it appears at the camera's target.
    #[arg(long)]
    pub scale_bar: bool,
    /// Transfer function JSON: {"points": [[value, r, g, b, alpha], ...], "unit_distance": u}, or a ParaView
    /// colour-map preset (RGBPoints, optional Points), rescaled onto the data's value range.
    #[arg(long)]
    pub tf: Option<PathBuf>,
    /// Draw isosurfaces of these data values instead of the volume (exact ray-cell intersection, Knoll et al.):
    /// one value or several, comma-separated (e.g. --iso 70 or --iso 40,110). With --tf, the surfaces are drawn
    /// inside that volume rendering.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true, value_name = "V1,V2,...")]
    pub iso: Vec<f64>,
    /// Isosurface colours, one r,g,b in [0,1] (linear) per value, separated by ';' (e.g. "0.9,0.75,0.65;1,1,1") or
    /// given as repeated flags. Default: a palette.
    #[arg(long, value_delimiter = ';', value_parser = parse_color, value_name = "R,G,B;...")]
    pub iso_color: Vec<[f64; 3]>,
    /// Isosurface opacities in (0,1], one per value, comma-separated: below 1 a surface shows the ones inside it.
    /// Default: 1 (opaque).
    #[arg(long, value_delimiter = ',', value_name = "A1,A2,...")]
    pub iso_opacity: Vec<f32>,
    /// Isosurfaces: hard shadows from the light given by --light (Phong shading).
    #[arg(long)]
    pub shadows: bool,
    /// Isosurfaces: normals from the trilinear cell's own gradient (cell), or from central differences at its
    /// corners interpolated trilinearly (central: smoother shading).
    #[arg(long, value_enum, default_value_t = NormalsArg::Cell)]
    pub normals: NormalsArg,
    /// Lighting (default: the scene's; Phong for isosurfaces).
    #[arg(long, value_enum)]
    pub shading: Option<ShadingArg>,
    /// Direction towards the light x,y,z (default: a headlight).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub light: Option<[f64; 3]>,
    /// Background colour r,g,b in [0,1] (linear).
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0", allow_hyphen_values = true)]
    pub background: [f64; 3],
    /// Ray-march step as a fraction of the sampled voxel.
    #[arg(long, default_value_t = 0.5)]
    pub step: f64,
    /// Volume rendering: integrate the transfer function over each segment between two samples, the field taken as
    /// linear between them (pre-integration, Engel et al. 2001), so that thin features of the transfer function
    /// are not missed between samples at longer steps. CPU backend.
    #[arg(long)]
    pub preintegrate: bool,
    /// Volume rendering: the error-bounded adaptive step's tolerance. By default each brick steps by up to four
    /// times --step where the transfer function varies little over the brick's values, keeping the error of each
    /// monotone stretch of a ray within 0.05 of optical depth; give another TOLERANCE here, or --faithful for fixed
    /// steps. Both backends.
    #[arg(long, value_name = "TOLERANCE", num_args = 0..=1, default_missing_value = "0.05")]
    pub adaptive_step: Option<f64>,
    /// Volume rendering: fixed steps of --step everywhere (no adaptive step): the reference-quality march, slower
    /// where the transfer function is smooth.
    #[arg(long)]
    pub faithful: bool,
    /// Level-of-detail bias (positive = finer than one voxel per pixel).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub lod_bias: f64,
    /// A diagnostic: colour the volume by the tree level each sample's data came from (eight hues, repeating),
    /// keeping the transfer function's opacity.
    #[arg(long)]
    pub colour_by_level: bool,
    /// cpu: the cone-tracing ray caster on every core; gpu: the same traversal in a compute shader (wgpu on
    /// Vulkan): volumes, isosurfaces, shadows and level blending, with the CPU's image as its reference.
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    pub backend: Backend,
    /// With --backend gpu: how bricks are filtered: auto (the texture units where the adapter can), hardware, or
    /// exact (in the shader, as the CPU).
    #[arg(long, value_enum, default_value_t = GpuFilter::Auto)]
    pub gpu_filter: GpuFilter,
    /// Interactive mode: level blending (Thiele et al.): bricks fade in from their parents over --fade-frames frames
    /// and blend towards coarser neighbours still loading (unless the camera approaches faster than the fades), so
    /// nothing pops. Converged frames are the same either way.
    #[arg(long, value_enum, default_value_t = Switch::On)]
    pub blending: Switch,
    /// Interactive mode with --blending on: frames over which an arriving brick fades in.
    #[arg(long, default_value_t = voxstream_core::DEFAULT_FADE_FRAMES)]
    pub fade_frames: u32,
}

/// `voxstream render`.
#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    /// SOURCE and how it is opened.
    #[command(flatten)]
    pub input: SourceFlags,
    /// Output PNG (with --path, frames are numbered: frame_0000.png, …).
    #[arg(long, default_value = "frame.png")]
    pub out: PathBuf,
    /// Image width in pixels.
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 512)]
    pub height: u32,
    /// Memory budget of the node and brick pools, MiB (on the GPU too: the pools are uploaded at this size).
    #[arg(long, default_value_t = 256)]
    pub budget_mb: u64,
    /// converged: iterate until exact; interactive: bounded production per frame.
    #[arg(long, value_enum, default_value_t = Mode::Converged)]
    pub mode: Mode,
    /// Interactive mode with a single camera: at most this many frames (stops once a frame is complete; the last
    /// is written, and `frame_ms` in --stats has one entry per frame).
    #[arg(long, default_value_t = 1)]
    pub frames: u32,
    /// Interactive mode: requests served per frame.
    #[arg(long, default_value_t = 1024)]
    pub requests_per_frame: usize,
    /// Camera path JSON (a list of cameras), rendered in sequence reusing the cache; or a path generated around the
    /// view: rest:N (the view N times), orbit:N (a quarter turn), orbit:N:DEGREES (e.g. orbit:120:360, a whole
    /// turn whose frames loop), zoom:N (down to a thousandth of the distance), fly:N (through the volume).
    #[arg(long)]
    pub path: Option<PathBuf>,
    /// With --path: encode the frames as a movie here (.mp4, .mov, .mkv: H.264; .webm: VP9) instead of numbered
    /// PNGs, through ffmpeg (on PATH, or named by VOXSTREAM_FFMPEG), e.g. --path orbit:120:360 --video spin.mp4.
    #[arg(long, value_name = "FILE")]
    pub video: Option<PathBuf>,
    /// With --video: frames per second.
    #[arg(long, default_value_t = 30.0, value_name = "FPS")]
    pub fps: f64,
    /// Interactive mode: measure popping and seams against the converged images at the same cameras (rendered after
    /// the run), into the --stats file. Keeps every frame as 8-bit RGB until then, outside --budget-mb.
    #[arg(long)]
    pub popping: bool,
    /// Write statistics JSON here.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// No progress bar, no list of files written and no summary line (warnings and errors are still printed).
    #[arg(long)]
    pub quiet: bool,
    /// How it is drawn.
    #[command(flatten)]
    pub look: LookFlags,
}

/// `--projection`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ProjectionArg {
    /// Emission-absorption compositing (volume rendering), or isosurfaces.
    Composite,
    /// The largest value along each ray (MIP).
    Max,
    /// The smallest value along each ray (MinIP).
    Min,
    /// The mean value along each ray.
    Mean,
}

impl ProjectionArg {
    /// The renderer's projection.
    pub fn projection(self) -> voxstream_render::Projection {
        match self {
            ProjectionArg::Composite => voxstream_render::Projection::Composite,
            ProjectionArg::Max => voxstream_render::Projection::Maximum,
            ProjectionArg::Min => voxstream_render::Projection::Minimum,
            ProjectionArg::Mean => voxstream_render::Projection::Mean,
        }
    }
}

/// `view --refine`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RefineArg {
    /// Converged passes, interrupted by input.
    Converged,
    /// Blended interactive frames.
    Blended,
}

pub use voxstream_api::{Backend, BrickBits, GpuFilter};

/// On or off.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Switch {
    /// On.
    On,
    /// Off.
    Off,
}

/// Byte order of a raw file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum EndianArg {
    /// Least significant byte first.
    Little,
    /// Most significant byte first.
    Big,
}

/// `voxstream import`.
#[derive(Args, Debug, Clone)]
pub struct ImportArgs {
    /// Input: .nrrd/.nhdr, .nii/.nii.gz, .mha/.mhd, .inr/.inr.gz, .vti, .npy, .npz, .tif/.tiff (or a folder of slices),
    /// a raw file with --dims and --dtype, or a mesh or particle file (baked at --resolution).
    pub input: PathBuf,
    /// Mesh and particle files: voxels per axis of the cube the object's largest side fills 80% of (default 512).
    #[arg(long, value_name = "VOXELS")]
    pub resolution: Option<u64>,
    /// Mesh files: noise amplitude as a fraction of the mesh's largest side (as `render --amplify`).
    #[arg(long, value_name = "AMPLITUDE")]
    pub amplify: Option<f64>,
    /// Particle files: the kernel's reach in smoothing lengths (as `render --smoothing-scale`).
    #[arg(long, value_name = "FACTOR")]
    pub smoothing_scale: Option<f64>,
    /// Binary PLY point files and columns of text: read them out of core, holding about MIB of particles in memory (as `render
    /// --particle-memory`).
    #[arg(long, value_name = "MIB")]
    pub particle_memory: Option<u64>,
    /// The store folder to create.
    #[arg(long)]
    pub out: PathBuf,
    /// Raw input: samples along x,y,z, x varying fastest in the file (numpy's shape reversed: an array of shape
    /// (z, y, x) in C order is --dims x,y,z).
    #[arg(long, value_parser = parse_dims)]
    pub dims: Option<[u64; 3]>,
    /// Raw input: sample type u8, u16, i16 or f32 (stored as they are), or i8, i32, u32 or f64 (converted: i8 to
    /// i16, the others to f32; the import prints a note saying what the conversion did).
    #[arg(long)]
    pub dtype: Option<String>,
    /// Raw input: byte order.
    #[arg(long, value_enum, default_value_t = EndianArg::Little)]
    pub endian: EndianArg,
    /// Raw input: bytes to skip before the samples.
    #[arg(long, default_value_t = 0)]
    pub header_bytes: u64,
    /// Distance between samples along x,y,z, in world units (e.g. mm): for a raw file (which has none) default
    /// 1,1,1; for other files it replaces the spacing the file gives.
    #[arg(long, value_parser = parse_vec3)]
    pub spacing: Option<[f64; 3]>,
    /// World position of sample (0,0,0): default 0,0,0 for raw input; replaces the file's otherwise.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub origin: Option<[f64; 3]>,
    /// Unit of --spacing and --origin, written to the store's OME-Zarr axes: an OME-Zarr space unit (millimeter,
    /// micrometer, nanometer, meter, …) or mm, µm, nm, cm, m. Replaces the file's (NIfTI and NRRD give one).
    #[arg(long)]
    pub unit: Option<String>,
    /// The anatomical direction each axis (x, y, z) points to, as three letters: RAS (NIfTI's MNI space: x to the
    /// patient's right, y to the front, z up), LPS (DICOM's), PIR, … Written to the store's OME-Zarr axes; the
    /// default view then looks at the front, head up. Replaces the file's (NIfTI, DICOM, NRRD, MetaImage give one).
    #[arg(long, value_name = "LETTERS")]
    pub orientation: Option<String>,
    /// Brick edge in samples (even, 4..=256).
    #[arg(long, default_value_t = 32)]
    pub brick_size: u64,
    /// Replace an existing store.
    #[arg(long)]
    pub overwrite: bool,
    /// Store NaN, +inf and -inf samples as this finite value (without it they are refused, naming the first one).
    #[arg(long, value_name = "VALUE", allow_negative_numbers = true)]
    pub nan_as: Option<f32>,
    /// How bricks are compressed: zstd (lossless; every Zarr v3 reader opens the store) or wavelet (Reichl's brick
    /// codec, a Zarr extension only voxstream reads: lossless, or lossy with --max-error).
    #[arg(long, value_enum, default_value_t = CodecArg::Zstd)]
    pub codec: CodecArg,
    /// With --codec wavelet: every stored sample within this absolute error of its value, in the data's units
    /// (integer samples: its whole part); 0, the default, is lossless.
    #[arg(long, value_name = "E", allow_negative_numbers = true)]
    pub max_error: Option<f64>,
    /// A DICOM folder holding several series: the one to import, by its number in the list the import prints
    /// when it is not given (1, 2, …), or by its Series Instance UID.
    #[arg(long, value_name = "N|UID")]
    pub series: Option<String>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// `import --codec`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CodecArg {
    /// zstd, lossless.
    Zstd,
    /// The wavelet brick codec.
    Wavelet,
}

/// `voxstream info`.
#[derive(Args, Debug, Clone)]
pub struct InfoArgs {
    /// The store: a folder, or a URL (https://…, s3://BUCKET/PREFIX, gs://…, az://…).
    pub store: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Other tools' OME-Zarr images: normalise by this value range (as `render --value-range`).
    #[arg(long, value_name = "LO,HI", value_parser = crate::store_open::parse_value_range, allow_hyphen_values = true)]
    pub value_range: Option<[f64; 2]>,
    /// 4-D and 5-D OME-Zarr images: the channel whose value range is shown (as `render --channel`).
    #[arg(long, value_name = "C")]
    pub channel: Option<u64>,
    /// 4-D and 5-D OME-Zarr images: the time point whose value range is shown (as `render --time`).
    #[arg(long, value_name = "T")]
    pub time: Option<u64>,
    /// Remote stores: the on-disk cache and the client's patience.
    #[command(flatten)]
    pub remote: RemoteArgs,
}

/// `voxstream bench`.
#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// Scenes to measure (default: all built-in scenes): built-in scene names, or any source `render` opens — a
    /// store's folder or URL (http(s)://, s3://…: each cold measurement fetches afresh), a mesh or particle file.
    #[arg(long, value_delimiter = ',')]
    pub scenes: Vec<String>,
    /// Image edge in pixels.
    #[arg(long, default_value_t = 512)]
    pub size: u32,
    /// Frames of the interactive camera path.
    #[arg(long, default_value_t = 60)]
    pub path_frames: usize,
    /// Warm frames timed once the data is resident.
    #[arg(long, default_value_t = 20)]
    pub warm_frames: u32,
    /// Memory budget, MiB.
    #[arg(long, default_value_t = 512)]
    pub budget_mb: u64,
    /// cpu: the CPU ray caster; gpu: the GPU ray caster (wgpu on Vulkan).
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    pub backend: Backend,
    /// With --backend gpu: how bricks are filtered: auto (the texture units where the adapter can), hardware, or
    /// exact (in the shader, as the CPU).
    #[arg(long, value_enum, default_value_t = GpuFilter::Auto)]
    pub gpu_filter: GpuFilter,
    /// Also write the figures as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Instead of speed: popping and seams (Thiele et al.) along camera paths from a cold cache (at rest, orbit,
    /// zoom, fly-through), with level blending off and on, against the converged images at the same cameras.
    #[arg(long)]
    pub popping: bool,
    /// Level blending in the interactive frames (--popping measures both and ignores this).
    #[arg(long, value_enum, default_value_t = Switch::On)]
    pub blending: Switch,
    /// With blending: frames over which an arriving brick fades in (as `render --fade-frames`; --popping too).
    #[arg(long, default_value_t = voxstream_core::DEFAULT_FADE_FRAMES)]
    pub fade_frames: u32,
    /// --popping: also measure this store (a folder made by `voxstream import`).
    #[arg(long, value_name = "STORE")]
    pub store: Option<PathBuf>,
    /// --popping: requests served per interactive frame (bounded, so that detail arrives over many frames).
    #[arg(long, default_value_t = 64)]
    pub requests_per_frame: usize,
    /// --popping: write a strip of consecutive frames without (top) and with (bottom) blending here (PNG).
    #[arg(long, value_name = "PNG")]
    pub strip: Option<PathBuf>,
    /// Measure isosurfaces of these values (in (0, 1], the built-in scenes' data range) instead of each scene's
    /// volume: Phong-shaded from a fixed light, in the colours of `render --iso`.
    #[arg(long, value_delimiter = ',', value_name = "V1,V2,…")]
    pub iso: Vec<f64>,
    /// With --iso: hard shadows from that light.
    #[arg(long)]
    pub shadows: bool,
}

/// Parses `x,y,z` positive integers.
pub fn parse_dims(text: &str) -> Result<[u64; 3], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected three comma-separated sizes x,y,z, got '{text}'"));
    }
    let mut out = [0u64; 3];
    for (slot, part) in out.iter_mut().zip(&parts) {
        *slot = part.parse().map_err(|_| format!("'{part}' is not a positive integer"))?;
        if *slot == 0 {
            return Err("sizes must be positive".into());
        }
    }
    Ok(out)
}

/// Parses `r,g,b` (each component in [0, 1]).
pub fn parse_color(text: &str) -> Result<[f64; 3], String> {
    let color = parse_vec3(text)?;
    if color.iter().any(|c| !(0.0..=1.0).contains(c)) {
        return Err(format!("colour components must be in [0, 1], got '{}'", text.trim()));
    }
    Ok(color)
}

/// Parses a `--view` preset.
pub fn parse_view_direction(text: &str) -> Result<voxstream_api::camera_presets::ViewDirection, String> {
    voxstream_api::camera_presets::ViewDirection::parse(text).map_err(|e| {
        let message = e.to_string();
        message.split_once(": ").map_or(message.clone(), |(_, rest)| rest.to_string())
    })
}

/// Parses comma-separated finite numbers, exactly `count` of them.
fn parse_numbers(text: &str, count: usize, form: &str) -> Result<Vec<f64>, String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != count {
        return Err(format!("expected {count} comma-separated numbers {form}, got '{text}'"));
    }
    parts
        .iter()
        .map(|part| match part.parse::<f64>() {
            Ok(value) if value.is_finite() => Ok(value),
            _ => Err(format!("'{part}' is not a finite number (expected {form})")),
        })
        .collect()
}

/// Parses `--clip-plane X,Y,Z,NX,NY,NZ`.
pub fn parse_clip_plane(text: &str) -> Result<voxstream_render::ClipPlane, String> {
    let v = parse_numbers(text, 6, "X,Y,Z,NX,NY,NZ")?;
    let plane = voxstream_render::ClipPlane { point: [v[0], v[1], v[2]], normal: [v[3], v[4], v[5]] };
    if !plane.is_valid() {
        return Err(format!("the normal {},{},{} must not be zero", v[3], v[4], v[5]));
    }
    Ok(plane)
}

/// Parses `--crop X0,Y0,Z0,X1,Y1,Z1` (sample indices, upper bounds excluded).
pub fn parse_crop(text: &str) -> Result<[[u64; 3]; 2], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 6 {
        return Err(format!("expected six comma-separated sample indices X0,Y0,Z0,X1,Y1,Z1, got '{text}'"));
    }
    let mut v = [0u64; 6];
    for (slot, part) in v.iter_mut().zip(&parts) {
        *slot = part.parse().map_err(|_| format!("'{part}' is not a sample index (a whole number from 0)"))?;
    }
    let (lower, upper) = ([v[0], v[1], v[2]], [v[3], v[4], v[5]]);
    if (0..3).any(|a| lower[a] >= upper[a]) {
        return Err(format!("each lower index must be below its upper one, got {lower:?} to {upper:?}"));
    }
    Ok([lower, upper])
}

/// Parses `x,y,z`.
pub fn parse_vec3(text: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected three comma-separated numbers x,y,z, got '{text}'"));
    }
    let mut out = [0.0; 3];
    for (slot, part) in out.iter_mut().zip(&parts) {
        let value: f64 = part.parse().map_err(|_| format!("'{part}' is not a number"))?;
        if !value.is_finite() {
            return Err(format!("'{part}' is not a finite number"));
        }
        *slot = value;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vec3_parsing() {
        assert_eq!(parse_vec3("1, -2.5,3e1").unwrap(), [1.0, -2.5, 30.0]);
        assert!(parse_vec3("1,2").is_err());
        assert!(parse_vec3("1,2,x").is_err());
        assert!(parse_vec3("1,2,inf").is_err());
    }

    #[test]
    fn color_parsing() {
        assert_eq!(parse_color(" 0,0.5,1").unwrap(), [0.0, 0.5, 1.0]);
        assert!(parse_color("1,0,2").unwrap_err().contains("[0, 1]"));
        assert!(parse_color("1,0").is_err());
    }

    #[test]
    fn cli_definition_is_consistent() {
        use clap::CommandFactory;
        Cli::command().debug_assert();
    }
}

/// How remote stores (`https://…`, `s3://…`, `gs://…`, `az://…`) are read: `render`, `view` and `info`.
#[derive(Args, Debug, Clone)]
pub struct RemoteArgs {
    /// Remote stores: keep fetched bricks in this folder (created if missing), so that the next run over the same
    /// store starts warm; none by default. Safe to share between processes.
    #[arg(long, value_name = "DIR")]
    pub cache_dir: Option<PathBuf>,
    /// The most MiB --cache-dir holds; the least recently used bricks leave first.
    #[arg(long, value_name = "MIB", default_value_t = 4096, value_parser = clap::value_parser!(u64).range(1..))]
    pub cache_mb: u64,
    /// Remote stores: seconds one request may take, body included, before it is retried.
    #[arg(long, value_name = "SECONDS", default_value_t = 30, value_parser = clap::value_parser!(u64).range(1..=3600))]
    pub request_timeout: u64,
    /// Remote stores: retries of a request that failed (5xx, 429, reset, timeout, short body), with backoff.
    #[arg(long, value_name = "N", default_value_t = 5, value_parser = clap::value_parser!(u64).range(0..=20))]
    pub retries: u64,
    /// Remote stores: requests kept in flight at once (bricks fetched in parallel).
    #[arg(long, value_name = "N", default_value_t = 128, value_parser = clap::value_parser!(u64).range(1..=256))]
    pub concurrent_requests: u64,
    /// Any voxstream store, local or remote: keep up to MIB of bricks in memory as stored (compressed), besides
    /// --budget-mb, so that bricks read once are not read again; without it, half of the store's share of
    /// --budget-mb does this.
    #[arg(long, value_name = "MIB", value_parser = clap::value_parser!(u64).range(1..=1 << 20))]
    pub compressed_cache_mb: Option<u64>,
}

impl Default for RemoteArgs {
    /// The flags' defaults.
    fn default() -> Self {
        RemoteArgs {
            cache_dir: None,
            cache_mb: 4096,
            request_timeout: 30,
            retries: 5,
            concurrent_requests: 128,
            compressed_cache_mb: None,
        }
    }
}

impl RemoteArgs {
    /// The store reader's settings for these flags.
    pub fn access(&self) -> voxstream_store::remote_access::RemoteAccess {
        let mut access = voxstream_store::remote_access::RemoteAccess::default();
        access.options.request_timeout = std::time::Duration::from_secs(self.request_timeout);
        access.options.retries = self.retries as usize;
        access.options.concurrency = self.concurrent_requests as usize;
        access.cache_dir = self.cache_dir.clone();
        access.cache_limit_bytes = self.cache_mb.saturating_mul(1 << 20);
        access.compressed_cache_bytes = self.compressed_cache_mb.map(|mb| mb << 20);
        access
    }
}
