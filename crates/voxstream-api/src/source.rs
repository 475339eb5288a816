//! Opening what a front end draws, by name: a built-in scene, a mesh or particle file, or a store (a local folder or
//! a URL), with typed options and the source's defaults (transfer function, camera, shading, placement). The CLI's
//! `render`, `view` and `info`, and the Python module, open sources here and nowhere else.
//!
//! The producer is boxed (`Box<dyn Producer>`): one call per brick, never per sample, goes through the box
//! (GigaVoxels' producers, Crassin et al. 2009 §5; Reichl's sources beyond grids, ch. 5 and 7).

use std::path::Path;
use std::sync::Arc;

use anyhow::{bail, Result};
use voxstream_core::{Producer, VoxelFormat};
use voxstream_engine::MemoryBudget;
use voxstream_geometry::formats::is_geometry_file_name;
use voxstream_render::{Camera, IsoSurface, Shading, TransferFunction, VolumePlacement};
use voxstream_store::image_planes::PlaneChoice;
use voxstream_store::remote::RemoteStore;
use voxstream_store::remote_access::RemoteAccess;
use voxstream_store::{InMemoryVolume, StoreProducer, StoreReader};

use crate::defaults::{default_store_transfer_function, omero_transfer_function, store_camera, store_placement};
use crate::geometry_source::{self, GeometryOptions};
use crate::scenes::builtin;
use crate::source_path::{check_store_path, missing_geometry_file, warn_about_leftovers};
use crate::store_open::{clipped_warning, open_store, planes_description};

/// How the brick pool keeps a store's voxels (`voxstream_core::VoxelFormat`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum BrickBits {
    /// 8 bits for 8-bit volumes (half the memory), 16 bits otherwise.
    #[default]
    Auto,
    /// Always 16 bits.
    #[cfg_attr(feature = "clap", value(name = "16"))]
    Sixteen,
}

/// How to open a source. The defaults open any source as `voxstream render SOURCE` does.
#[derive(Clone, Debug)]
pub struct SourceOptions {
    /// Data values the full range of an integer OME-Zarr image stands for (`--value-range`; foreign stores only).
    pub value_range: Option<[f64; 2]>,
    /// Load the whole store into memory first (`--in-memory`).
    pub in_memory: bool,
    /// How the brick pool keeps a store's voxels (`--brick-bits`).
    pub brick_bits: BrickBits,
    /// Noise amplitude of a mesh's hypertexture, as a fraction of its largest side (`--amplify`).
    pub amplify: Option<f64>,
    /// Voxels per axis of a mesh's or particles' finest level (`--resolution`).
    pub resolution: Option<u64>,
    /// Particles' scalar attribute instead of their density (`--attribute`).
    pub attribute: bool,
    /// The SPH kernel's reach in smoothing lengths (`--smoothing-scale`).
    pub smoothing_scale: Option<f64>,
    /// Read a binary PLY point file out of core with this many MiB for its particles (`--particle-memory`).
    pub particle_memory: Option<u64>,
    /// The channel and time point of a 4-D/5-D OME-Zarr image (`--channel`, `--time`; the first when `None`).
    pub planes: PlaneChoice,
    /// Timeouts, retries, concurrency and the on-disk cache of a remote store.
    pub remote: RemoteAccess,
    /// The image size the default camera frames the source for.
    pub width: u32,
    /// See `width`.
    pub height: u32,
    /// No progress bar while a foreign store is scanned for its value range.
    pub quiet: bool,
}

impl Default for SourceOptions {
    fn default() -> Self {
        SourceOptions {
            value_range: None,
            in_memory: false,
            brick_bits: BrickBits::Auto,
            amplify: None,
            resolution: None,
            attribute: false,
            smoothing_scale: None,
            particle_memory: None,
            planes: PlaneChoice::default(),
            remote: RemoteAccess::default(),
            width: 512,
            height: 512,
            quiet: true,
        }
    }
}

/// What a front end draws: a built-in scene, a store, or a mesh or particle file: its producer and its defaults.
pub struct Source {
    /// The producer of its bricks.
    pub producer: Box<dyn Producer>,
    /// Everything else: its name, defaults and data range.
    pub meta: SourceMeta,
}

/// A source's name, defaults and data range: what stays with a front end once the producer has gone into a session.
#[derive(Clone)]
pub struct SourceMeta {
    /// The name it was opened by (a remote store's URL without credentials).
    pub name: String,
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
    /// Direction towards the light unless the view names one (`None`: a headlight).
    pub light: Option<[f64; 3]>,
    /// Surfaces drawn when the view names neither isosurfaces nor a transfer function (empty: the volume).
    pub default_surfaces: Vec<IsoSurface>,
    /// The store, for stores (its metadata, and whether samples were clipped to the value range).
    pub store: Option<Arc<StoreReader>>,
    /// The remote store the bricks come from (its requests, bytes and retries go into the statistics).
    pub remote: Option<Arc<RemoteStore>>,
    /// What opening a mesh or particle file found (its size, the tree made of it), for the front end to show.
    pub description: Option<String>,
}

impl SourceMeta {
    /// After a run over a store: the warning that samples lay outside the value range and were clipped.
    pub fn clipped_warning(&self) -> Option<String> {
        self.store.as_deref().and_then(clipped_warning)
    }
}

/// Opens `name` (a built-in scene, a mesh or particle file, or a store's folder or URL) within `budget`.
pub fn open(name: &str, options: &SourceOptions, budget: &MemoryBudget) -> Result<Source> {
    let path = Path::new(name);
    if options.value_range.is_some() && (builtin(name).is_some() || is_geometry_file_name(path)) {
        bail!("--value-range applies to stores (other tools' OME-Zarr images); {name} is not one");
    }
    if options.planes != PlaneChoice::default() && (builtin(name).is_some() || is_geometry_file_name(path)) {
        bail!(
            "--channel and --time apply to 4-D and 5-D OME-Zarr images (and --time to a fluid's time series, with \
             --fluid); {name} is not one"
        );
    }
    if let Some(scene) = builtin(name) {
        check_geometry_flags(options, scene.name)?;
        let producer = Box::new(scene.producer);
        return Ok(Source {
            producer,
            meta: SourceMeta {
                name: scene.name.to_string(),
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
                store: None,
                remote: None,
                description: None,
            },
        });
    }
    if path.is_file() && is_geometry_file_name(path) {
        let geometry_options = GeometryOptions {
            amplify: options.amplify,
            resolution: options.resolution,
            attribute: options.attribute,
            smoothing_scale: options.smoothing_scale,
            particle_memory: options.particle_memory,
            budget_mb: Some(budget.budget_mb()),
            width: options.width,
            height: options.height,
            quiet: options.quiet,
        };
        let geometry = geometry_source::open(path, &geometry_options)?;
        let producer = Box::new(geometry.producer);
        return Ok(Source {
            producer,
            meta: SourceMeta {
                name: name.to_string(),
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
                store: None,
                remote: None,
                description: Some(geometry.description),
            },
        });
    }
    if is_geometry_file_name(path) && !path.exists() {
        return Err(missing_geometry_file(path));
    }
    check_store_path(path, "render")?;
    check_geometry_flags(options, &voxstream_store::remote::redact(name))?;
    let cache_bytes = budget.store_cache_bytes();
    let reader =
        Arc::new(open_store(path, cache_bytes, options.value_range, options.planes, &options.remote, options.quiet)?);
    warn_about_leftovers(path);
    // An image's own display settings (OME-Zarr `omero`: the channel's contrast window and colour) where it has
    // them, else a ramp over the bulk of the values.
    let transfer_function = match reader.image_planes().omero.as_ref().and_then(|o| o.window.map(|w| (w, o.color))) {
        Some((window, color)) => omero_transfer_function(window, color)?,
        None => default_store_transfer_function(reader.attributes().typical_range())?,
    };
    // (A GPU session keeps 16-bit bricks whatever the producer allows: `FrameRenderer::needs_sixteen_bit_bricks`.)
    let format = match options.brick_bits {
        BrickBits::Auto => None,
        BrickBits::Sixteen => Some(VoxelFormat::Wide),
    };
    if options.in_memory {
        let volume = Arc::new(InMemoryVolume::load(&reader)?);
        let producer = StoreProducer::new(volume)?.with_voxel_format(format);
        return Ok(store_source(options, reader, Box::new(producer), 0, transfer_function));
    }
    // Interactive frames over a remote store never wait on the network: missing bricks are fetched behind them
    // while their ancestors stand in (converged frames wait: see `ServeOptions::wait_for_data`).
    reader.set_nonblocking(true);
    let producer = StoreProducer::new(reader.clone())?.with_voxel_format(format);
    Ok(store_source(options, reader, Box::new(producer), cache_bytes, transfer_function))
}

fn store_source(
    options: &SourceOptions,
    reader: Arc<StoreReader>,
    producer: Box<dyn Producer>,
    producer_cache_bytes: u64,
    transfer_function: TransferFunction,
) -> Source {
    let meta = SourceMeta {
        // The store as the reader shows it (a remote store's URL without credentials).
        name: reader.path().display().to_string(),
        transfer_function,
        shading: Shading::None,
        camera: store_camera(reader.info(), options.width, options.height),
        placement: store_placement(&reader),
        value_range: reader.attributes().value_range,
        typical_range: reader.attributes().typical_range(),
        producer_cache_bytes,
        sample_bytes: reader.info().dtype.size() as u64,
        light: None,
        default_surfaces: Vec::new(),
        remote: reader.remote().cloned(),
        description: planes_description(reader.image_planes()),
        store: Some(reader),
    };
    Source { producer, meta }
}

/// The options that shape the trees of mesh and particle files only: given with a scene or a store, they are
/// refused, not ignored.
fn check_geometry_flags(options: &SourceOptions, source: &str) -> Result<()> {
    let flags = [
        ("--amplify", options.amplify.is_some(), "mesh and particle files"),
        ("--resolution", options.resolution.is_some(), "mesh and particle files"),
        ("--attribute", options.attribute, "mesh and particle files"),
        ("--smoothing-scale", options.smoothing_scale.is_some(), "particle files"),
        ("--particle-memory", options.particle_memory.is_some(), "particle files"),
    ];
    for (flag, given, files) in flags {
        if given {
            bail!("{flag} applies to {files}; {source} is not one");
        }
    }
    Ok(())
}
