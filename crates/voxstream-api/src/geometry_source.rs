//! `voxstream render` of a mesh or particle file: reads it, builds its producer, and chooses the defaults (camera
//! around its bounds in the file's own units, a surface for meshes and molecules, a density ramp for particles).
//!
//! The producers are those of `voxstream-geometry` (seed 004, ch. 5 and 7; GigaVoxels' amplified meshes): bricks are
//! made when rays ask for them, so nothing is voxelised in advance.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use voxstream_core::{NodeKey, ProduceError, Produced, Producer, TreeShape};
use voxstream_geometry::formats::ply::{declared_points, PlyPointStream};
use voxstream_geometry::formats::{read_geometry, RawGeometry};
use voxstream_geometry::particle_producer::{BUILD_BYTES_PER_PARTICLE, SMOOTHING_SCALE_RANGE};
use voxstream_geometry::superbrick_particles::{
    open_out_of_core, OutOfCoreSettings, MIN_MEMORY_BYTES, STREAMED_FILE_ENDINGS,
};
use voxstream_geometry::{
    Amplification, MeshProducer, MeshTreeSettings, ParticleProducer, ParticleSet, ParticleTreeSettings,
    SuperbrickParticleProducer, TriangleMesh, UnitCubeFit,
};
use voxstream_render::{Camera, IsoSurface, TransferFunction, VolumePlacement, FRAME_BYTES_PER_PIXEL};

use crate::defaults::frame_box;
use crate::loading_spinner::LoadingSpinner;

/// The flags that shape a geometry file's tree (from `render` or `import`).
#[derive(Clone, Copy, Debug)]
pub struct GeometryOptions {
    /// `--amplify`: noise amplitude as a fraction of the mesh's largest side.
    pub amplify: Option<f64>,
    /// `--resolution`: voxels per axis of the finest level.
    pub resolution: Option<u64>,
    /// `--attribute`: particles' scalar attribute instead of their density.
    pub attribute: bool,
    /// `--smoothing-scale`: the kernel's reach in the file's smoothing lengths (`None`: 1, or 2 for molecules).
    pub smoothing_scale: Option<f64>,
    /// `--particle-memory`: read a binary PLY point file out of core with this many MiB for its particles.
    pub particle_memory: Option<u64>,
    /// `--budget-mb` of `render`: particles held in memory must fit it beside the image (`None`: no budget).
    pub budget_mb: Option<u64>,
    /// Image size, for the default camera.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// No spinner while a large file is read and indexed.
    pub quiet: bool,
}

/// A producer over a mesh or particles (a closed set, dispatched through an enum).
#[derive(Clone, Debug)]
pub enum GeometryProducer {
    /// Signed-distance bricks of a triangle mesh.
    Mesh(MeshProducer),
    /// SPH density bricks of particles.
    Particles(ParticleProducer),
    /// SPH density bricks of particles read out of core (superbricks in a spill file; shared, not copied).
    StreamedParticles(Arc<SuperbrickParticleProducer>),
}

impl GeometryProducer {
    /// How far beyond the object's bounds (unit-cube units) its values can be non-zero.
    pub fn margin(&self) -> f64 {
        match self {
            GeometryProducer::Mesh(p) => p.margin(),
            GeometryProducer::Particles(p) => p.margin(),
            GeometryProducer::StreamedParticles(p) => p.margin(),
        }
    }

    /// Where the object sits in the unit cube.
    pub fn fit(&self) -> UnitCubeFit {
        match self {
            GeometryProducer::Mesh(p) => p.fit(),
            GeometryProducer::Particles(p) => p.fit(),
            GeometryProducer::StreamedParticles(p) => p.fit(),
        }
    }
}

impl Producer for GeometryProducer {
    fn shape(&self) -> TreeShape {
        match self {
            GeometryProducer::Mesh(p) => p.shape(),
            GeometryProducer::Particles(p) => p.shape(),
            GeometryProducer::StreamedParticles(p) => p.shape(),
        }
    }

    fn oracle(&self, key: NodeKey) -> Option<f32> {
        match self {
            GeometryProducer::Mesh(p) => p.oracle(key),
            GeometryProducer::Particles(p) => p.oracle(key),
            GeometryProducer::StreamedParticles(p) => p.oracle(key),
        }
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        match self {
            GeometryProducer::Mesh(p) => p.produce(key, voxels),
            GeometryProducer::Particles(p) => p.produce(key, voxels),
            GeometryProducer::StreamedParticles(p) => p.produce(key, voxels),
        }
    }
}

/// A geometry file ready to render, with its defaults.
pub struct GeometrySource {
    /// The producer.
    pub producer: GeometryProducer,
    /// What the voxel values 0 and 1 stand for (meshes: 0 outside, ½ on the surface, 1 inside; particles: density).
    pub value_range: [f64; 2],
    /// Surfaces drawn unless `--iso` or `--tf` says otherwise (meshes: the surface; molecules: the atoms' surface).
    pub default_surfaces: Vec<IsoSurface>,
    /// Transfer function for volume rendering (with `--tf` absent and no surfaces).
    pub transfer_function: TransferFunction,
    /// Tree cube in file units.
    pub placement: VolumePlacement,
    /// Default view.
    pub camera: Camera,
    /// Bytes held by the producer's index (triangles and hierarchy, or particles and grid).
    pub index_bytes: u64,
    /// The object's bounds, file units.
    pub bounds: ([f64; 3], [f64; 3]),
    /// One line saying what was read.
    pub description: String,
}

/// The view direction for geometry (file coordinates, `+y` up as most mesh and particle files are): front right,
/// from above.
const GEOMETRY_VIEW_DIRECTION: [f64; 3] = [0.55, 0.45, 0.7];

/// Whether the file is a molecular structure (atoms with radii).
fn is_molecular(path: &Path) -> bool {
    let name = path.to_string_lossy().to_lowercase();
    let name = name.strip_suffix(".gz").unwrap_or(&name);
    name.ends_with(".gro") || name.ends_with(".pdb")
}

/// Reads `path` and builds its producer with the flags of `args`.
pub fn open(path: &Path, args: &GeometryOptions) -> Result<GeometrySource> {
    let started = Instant::now();
    let shown = path.display();
    if let Some(resolution) = args.resolution {
        if !(16..=1 << 20).contains(&resolution) {
            bail!("--resolution {resolution} is out of range: give 16 to 1048576 voxels per axis");
        }
    }
    if let Some(memory) = out_of_core_memory(path, args)? {
        let _spinner = LoadingSpinner::start(path, "binning into superbricks (three passes over)", args.quiet);
        return open_streamed(path, args, memory, started);
    }
    // A point file's header says how many particles it holds: refuse before reading a file whose index cannot fit.
    if let Some(count) = declared_points(path) {
        check_particle_budget(path, count, "declares", args)?;
    }
    let spinner = LoadingSpinner::start(path, "reading", args.quiet);
    let raw = read_geometry(path)?;
    spinner.stage(match &raw {
        RawGeometry::Mesh(mesh) => {
            format!("building the distance index of {shown}'s {} triangles", mesh.triangles.len())
        }
        RawGeometry::Particles(particles) => format!("indexing {shown}'s {} particles", particles.positions.len()),
    });
    match raw {
        RawGeometry::Mesh(raw) => {
            if args.attribute {
                bail!("--attribute applies to particle files; {shown} holds a mesh");
            }
            if args.smoothing_scale.is_some() {
                bail!("--smoothing-scale applies to particle files; {shown} holds a mesh");
            }
            let mesh = TriangleMesh::new(raw).with_context(|| format!("in {shown}"))?;
            let (lower, upper) = mesh.bounds();
            let settings = MeshTreeSettings::default();
            let amplify = match args.amplify {
                Some(k) if !(k > 0.0 && k <= 0.1) => {
                    bail!("--amplify {k} is out of range: give the noise amplitude as a fraction of the mesh's size, in (0, 0.1]")
                }
                // The mesh's largest side is `fill` of the cube.
                Some(k) => Some(Amplification::with_amplitude(k * settings.fill)),
                None => None,
            };
            let settings = MeshTreeSettings { amplify, resolution: args.resolution, ..settings };
            let producer = MeshProducer::new(&mesh, settings)?;
            let fit = producer.fit();
            let description = format!(
                "{shown}: {} triangles{}, {}³ virtual voxels{}, distance index built in {:.1} s",
                mesh.triangles().len(),
                match (mesh.degenerate_dropped, mesh.repeated_dropped) {
                    (0, 0) => String::new(),
                    (n, 0) => format!(" ({n} of zero area dropped)"),
                    (0, r) => format!(" ({r} repeated dropped)"),
                    (n, r) => format!(" ({n} of zero area and {r} repeated dropped)"),
                },
                producer.shape().virtual_resolution(),
                if amplify.is_some() { ", amplified" } else { "" },
                started.elapsed().as_secs_f64()
            );
            let index_bytes = producer.field().heap_bytes();
            let camera = default_camera(&producer.fit(), producer.margin(), (lower, upper), args);
            Ok(GeometrySource {
                producer: GeometryProducer::Mesh(producer),
                value_range: [0.0, 1.0],
                default_surfaces: vec![IsoSurface { value: 0.5, color: [0.85, 0.78, 0.68], opacity: 1.0 }],
                transfer_function: mesh_transfer_function()?,
                placement: placement(fit),
                camera,
                index_bytes,
                bounds: (lower, upper),
                description,
            })
        }
        RawGeometry::Particles(raw) => {
            if args.amplify.is_some() {
                bail!("--amplify applies to meshes; {shown} holds particles");
            }
            let molecular = is_molecular(path);
            let smoothing_scale = smoothing_scale(args, molecular)?;
            // Formats without a count in a header are checked once read, before the index is built.
            check_particle_budget(path, raw.positions.len() as u64, "holds", args)?;
            let particles = ParticleSet::new(raw).with_context(|| format!("in {shown}"))?;
            let settings = ParticleTreeSettings {
                resolution: args.resolution,
                smoothing_scale,
                attribute: args.attribute,
                ..ParticleTreeSettings::default()
            };
            let producer = ParticleProducer::new(&particles, settings).with_context(|| format!("in {shown}"))?;
            let (lower, upper) = particles.bounds();
            let value_range = producer.value_range();
            let default_surfaces = if molecular && !args.attribute {
                // An isolated atom's density (unit mass, kernel support 2r) crosses 2/(π(2r)³) at its radius r:
                // the surface of the median atom, as VMD's QuickSurf draws it.
                let mut radii = particles.smoothing().to_vec();
                let middle = radii.len() / 2;
                radii.select_nth_unstable_by(middle, f32::total_cmp);
                let h = 2.0 * f64::from(radii[middle]);
                let value = (2.0 / (std::f64::consts::PI * h * h * h)).min(value_range[1] * 0.5);
                vec![IsoSurface { value, color: [0.55, 0.7, 0.95], opacity: 1.0 }]
            } else {
                Vec::new()
            };
            let (field, transfer_function) =
                particle_field(args.attribute, particles.values().1, value_range, producer.typical_density())?;
            let description = format!(
                "{shown}: {} particles, {}³ virtual voxels, grid built in {:.1} s; {field}",
                particles.len(),
                producer.shape().virtual_resolution(),
                started.elapsed().as_secs_f64(),
            );
            let (fit, margin) = (producer.fit(), producer.margin());
            Ok(GeometrySource {
                index_bytes: producer.heap_bytes(),
                placement: placement(producer.fit()),
                producer: GeometryProducer::Particles(producer),
                value_range,
                default_surfaces,
                transfer_function,
                camera: default_camera(&fit, margin, (lower, upper), args),
                bounds: (lower, upper),
                description,
            })
        }
    }
}

/// Refuses `count` particles whose in-memory index would not fit `--budget-mb` beside the image while it is built
/// ([`BUILD_BYTES_PER_PARTICLE`] each, the file's columns included; it holds less once built), naming the count, the
/// bytes and the flags that help (`verb`: "declares" for a header's count, "holds" for particles read).
fn check_particle_budget(path: &Path, count: u64, verb: &str, args: &GeometryOptions) -> Result<()> {
    let Some(budget_mb) = args.budget_mb else { return Ok(()) };
    let held = count.saturating_mul(BUILD_BYTES_PER_PARTICLE);
    let image = FRAME_BYTES_PER_PIXEL * u64::from(args.width) * u64::from(args.height);
    let needed_mb = held.saturating_add(image).div_ceil(1 << 20);
    if needed_mb < budget_mb {
        return Ok(());
    }
    let name = path.to_string_lossy().to_lowercase();
    let out_of_core = if STREAMED_FILE_ENDINGS.iter().any(|e| name.ends_with(e)) {
        ", or read it out of core with --particle-memory MIB"
    } else {
        ""
    };
    bail!(
        "{} {verb} {count} particles: built in memory their index takes {} MiB ({BUILD_BYTES_PER_PARTICLE} bytes \
         each), which with the {}x{} image leaves nothing of --budget-mb {budget_mb} for the bricks: raise \
         --budget-mb above {needed_mb}{out_of_core}",
        path.display(),
        held.div_ceil(1 << 20),
        args.width,
        args.height,
    )
}

/// `--smoothing-scale` checked, or its default (2 for molecules, 1 otherwise).
fn smoothing_scale(args: &GeometryOptions, molecular: bool) -> Result<f64> {
    Ok(match args.smoothing_scale {
        None if molecular => 2.0,
        None => 1.0,
        Some(scale) if SMOOTHING_SCALE_RANGE.contains(&scale) => scale,
        Some(scale) => bail!(
            "--smoothing-scale {scale}: the kernel's reach must be between {} and {} smoothing lengths (1 where the \
             file's h is the support, 2 for PySPH)",
            SMOOTHING_SCALE_RANGE.start(),
            SMOOTHING_SCALE_RANGE.end()
        ),
    })
}

/// Whether to read `path` out of core, and with how many bytes: `--particle-memory` (binary PLY point files only),
/// or by itself for a binary PLY point file whose particles would take more than half of the machine's memory.
fn out_of_core_memory(path: &Path, args: &GeometryOptions) -> Result<Option<u64>> {
    let shown = path.display();
    let name = path.to_string_lossy().to_lowercase();
    let is_ply = name.ends_with(".ply");
    if let Some(mib) = args.particle_memory {
        if !STREAMED_FILE_ENDINGS.iter().any(|e| name.ends_with(e)) {
            bail!(
                "--particle-memory reads binary PLY point files and columns of text (.xyz, .csv, .txt) out of core; \
                 {shown} is read whole (convert it to a binary PLY with x y z [h] [mass] [value] vertex properties \
                 to stream it)"
            );
        }
        let bytes = mib.checked_mul(1 << 20).filter(|&b| b >= MIN_MEMORY_BYTES);
        let Some(bytes) = bytes.filter(|&b| b <= 1 << 50) else {
            bail!("--particle-memory {mib}: give {} MiB or more (and less than 1 PiB)", MIN_MEMORY_BYTES >> 20);
        };
        return Ok(Some(bytes));
    }
    if !is_ply {
        return Ok(None);
    }
    // A PLY the streaming reader refuses (ASCII, a mesh, a malformed header) is read whole, as before, and its own
    // reader names any problem.
    let Ok(stream) = PlyPointStream::open(path) else { return Ok(None) };
    let machine = voxstream_engine::memory_budget::machine_memory_bytes().unwrap_or(u64::MAX);
    Ok(automatic_particle_memory(stream.count(), machine))
}

/// The memory to read `count` particles out of core with, on a machine of `machine` bytes: a quarter of it where
/// reading them into memory would take more than half; `None` (read into memory) otherwise.
fn automatic_particle_memory(count: u64, machine: u64) -> Option<u64> {
    let needed = count.saturating_mul(BUILD_BYTES_PER_PARTICLE);
    (needed > machine / 2).then(|| (machine / 4).max(MIN_MEMORY_BYTES))
}

/// Reads a binary PLY point file or columns of text out of core with `memory` bytes for its particles.
fn open_streamed(path: &Path, args: &GeometryOptions, memory: u64, started: Instant) -> Result<GeometrySource> {
    let shown = path.display();
    if args.amplify.is_some() {
        bail!("--amplify applies to meshes; {shown} holds particles");
    }
    let settings = ParticleTreeSettings {
        resolution: args.resolution,
        smoothing_scale: smoothing_scale(args, false)?,
        attribute: args.attribute,
        ..ParticleTreeSettings::default()
    };
    let out_of_core = OutOfCoreSettings { memory_bytes: memory, spill_directory: std::env::temp_dir() };
    let (producer, value_name) =
        open_out_of_core(path, settings, &out_of_core).with_context(|| format!("in {shown} (read out of core)"))?;
    let statistics = producer.statistics();
    let value_range = producer.value_range();
    let fit = producer.fit();
    let margin = producer.margin();
    let bounds = producer.bounds();
    let (field, transfer_function) =
        particle_field(args.attribute, &value_name, value_range, producer.typical_density())?;
    let description = format!(
        "{shown}: {} particles read out of core ({}³ superbricks in a {} MiB spill file, {} MiB for particles), {}³ \
         virtual voxels, binned in {:.1} s; {field}",
        statistics.particles,
        statistics.superbricks_per_axis,
        statistics.spill_bytes >> 20,
        memory >> 20,
        producer.shape().virtual_resolution(),
        started.elapsed().as_secs_f64(),
    );
    Ok(GeometrySource {
        index_bytes: producer.heap_bytes(),
        placement: placement(fit),
        transfer_function,
        camera: default_camera(&fit, margin, bounds, args),
        producer: GeometryProducer::StreamedParticles(Arc::new(producer)),
        value_range,
        default_surfaces: Vec::new(),
        bounds,
        description,
    })
}

/// What a particle file shows (its attribute `value_name`, or its density) over `value_range`: the words for the
/// description, and the default transfer function.
fn particle_field(
    attribute: bool,
    value_name: &str,
    value_range: [f64; 2],
    typical_density: f64,
) -> Result<(String, TransferFunction)> {
    Ok(if attribute {
        (
            format!("{value_name} {:.4e} to {:.4e}", value_range[0], value_range[1]),
            attribute_transfer_function(value_range)?,
        )
    } else {
        (
            format!("density 0 to {:.4e} (mass per file unit³)", value_range[1]),
            particle_transfer_function(typical_density, value_range[1])?,
        )
    })
}

/// The default view of the object's bounds widened by its margin (the band or the kernels), so that a single
/// particle or a flat mesh is framed too.
fn default_camera(
    fit: &UnitCubeFit,
    margin: f64,
    (lower, upper): ([f64; 3], [f64; 3]),
    args: &GeometryOptions,
) -> Camera {
    let pad = margin * fit.size;
    let lower = lower.map(|v| v - pad);
    let upper = upper.map(|v| v + pad);
    frame_box(lower, upper, args.width, args.height, GEOMETRY_VIEW_DIRECTION, [0.0, 1.0, 0.0])
}

/// The tree's unit cube in file units.
fn placement(fit: UnitCubeFit) -> VolumePlacement {
    VolumePlacement::cube(fit.origin, fit.size)
}

/// A mesh as a volume: a soft solid (values above ½ are inside).
fn mesh_transfer_function() -> Result<TransferFunction> {
    Ok(TransferFunction::new(
        vec![
            [0.0, 0.0, 0.0, 0.0, 0.0],
            [0.45, 0.85, 0.6, 0.4, 0.0],
            [0.6, 0.9, 0.8, 0.7, 0.6],
            [1.0, 1.0, 0.95, 0.9, 0.8],
        ],
        None,
    )?)
}

/// Particle density: transparent below a tenth of the median density at the particles, blue to orange up to four
/// times it, then white and more opaque up to the peak (often orders of magnitude above the median).
fn particle_transfer_function(typical: f64, max_density: f64) -> Result<TransferFunction> {
    let mut points = vec![[0.0, 0.0, 0.0, 0.0, 0.0]];
    for (f, r, g, b, a) in [(0.1, 0.2, 0.3, 0.8, 0.0), (1.0, 0.9, 0.5, 0.2, 0.05), (4.0, 1.0, 0.8, 0.5, 0.2)] {
        if typical * f < max_density {
            points.push([typical * f, r, g, b, a]);
        }
    }
    points.push([max_density, 1.0, 0.95, 0.85, 0.4]);
    TransferFunction::new(points, None).context("no density ramp fits the particles' densities")
}

/// A particle attribute: transparent at 0 (where no particle reaches), blue towards negative values, orange towards
/// positive ones.
fn attribute_transfer_function([lower, upper]: [f64; 2]) -> Result<TransferFunction> {
    let mut points = Vec::new();
    if lower < 0.0 {
        points.push([lower, 0.2, 0.4, 1.0, 0.25]);
    }
    points.push([0.0, 0.0, 0.0, 0.0, 0.0]);
    if upper > 0.0 {
        points.push([upper, 1.0, 0.55, 0.15, 0.25]);
    }
    TransferFunction::new(points, None).context("no colour map fits the attribute's range")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn particle_sets_larger_than_half_the_memory_are_read_out_of_core() {
        let gib = 1u64 << 30;
        // 24 GiB: up to half of it in memory (about 80 million particles); beyond, out of core with 6 GiB.
        let most = 12 * gib / BUILD_BYTES_PER_PARTICLE;
        assert_eq!(automatic_particle_memory(1_000_000, 24 * gib), None);
        assert_eq!(automatic_particle_memory(most, 24 * gib), None);
        assert_eq!(automatic_particle_memory(most + 1, 24 * gib), Some(6 * gib));
        assert_eq!(automatic_particle_memory(u64::MAX, 24 * gib), Some(6 * gib));
        // A tiny machine still gets the smallest budget.
        assert_eq!(automatic_particle_memory(1_000_000, 16 << 20), Some(MIN_MEMORY_BYTES));
    }
}
