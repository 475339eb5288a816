//! Importing into a store, for every front end: a volume file (any format `voxstream_store::formats` reads, or raw
//! samples with a declared layout), a mesh or particle file baked into a grid ([`crate::geometry_import`]), or a
//! source the caller made (a numpy array), written by `voxstream_store::import_volume`.
//!
//! [`open_input`] opens and checks the input (its size, type and, for meshes and particles, what the bake found) so
//! that a front end can show it before the long part; [`ImportInput::import`] writes the store, reporting input
//! bytes to a progress callback that may stop it (`ControlFlow::Break`): the partial store is then removed and an
//! existing store at `out` is left as it was.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use voxstream_store::formats::dicom::{has_dicom_extension, DicomSeries};
use voxstream_store::formats::dicom_header::has_dicom_magic;
use voxstream_store::formats::sample_type::DTYPE_NAMES;
use voxstream_store::formats::{open_volume, Endian, RawLayout, SampleConversion, SampleType, WithGeometry};
use voxstream_store::{
    import_volume, BrickCodec, ImportOptions, ImportReport, Orientation, SpaceUnit, StoreError, VolumeInfo,
    VolumeSource,
};

use crate::geometry_import::{BakedGeometry, DEFAULT_BAKE_RESOLUTION};
use crate::geometry_source::{self, GeometryOptions};
use crate::source_path::missing_geometry_file;

/// A raw file's layout (`--dims`, `--dtype`, `--endian`, `--header-bytes`).
#[derive(Clone, Debug, PartialEq)]
pub struct RawSettings {
    /// Samples per axis, x fastest.
    pub dims: [u64; 3],
    /// Sample type's name: u8, u16, i16 or f32, or i8, i32, u32 or f64 (converted: see
    /// `voxstream_store::formats::sample_type`).
    pub dtype: String,
    /// Most significant byte first.
    pub big_endian: bool,
    /// Bytes before the samples.
    pub header_bytes: u64,
}

/// How to import; the defaults are `voxstream import`'s.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportSettings {
    /// Read the input as raw samples with this layout.
    pub raw: Option<RawSettings>,
    /// Sample spacing over the file's (`--spacing`).
    pub spacing: Option<[f64; 3]>,
    /// Origin over the file's (`--origin`).
    pub origin: Option<[f64; 3]>,
    /// Unit of the spacing and origin over the file's (`--unit`): an OME-Zarr space unit or an abbreviation of one.
    pub unit: Option<String>,
    /// The anatomical direction of each axis over the file's (`--orientation`): three letters such as `RAS`.
    pub orientation: Option<String>,
    /// Value written for NaN samples (`--nan-as`).
    pub nan_as: Option<f32>,
    /// Brick edge in samples (`--brick-size`).
    pub brick_size: u64,
    /// Replace an existing store (`--overwrite`), once the new one is complete.
    pub overwrite: bool,
    /// Meshes and particles: voxels per axis of the baked grid (`--resolution`).
    pub resolution: Option<u64>,
    /// Meshes: noise amplitude (`--amplify`).
    pub amplify: Option<f64>,
    /// Particles: the kernel's reach in smoothing lengths (`--smoothing-scale`).
    pub smoothing_scale: Option<f64>,
    /// Particles: read out of core with this many MiB (`--particle-memory`).
    pub particle_memory: Option<u64>,
    /// How bricks are compressed (`--codec`, `--max-error`).
    pub codec: BrickCodec,
    /// A DICOM folder's series to import (`--series`): its number in the list of series, or its UID.
    pub series: Option<String>,
}

impl Default for ImportSettings {
    fn default() -> Self {
        ImportSettings {
            raw: None,
            spacing: None,
            origin: None,
            unit: None,
            orientation: None,
            nan_as: None,
            brick_size: ImportOptions::default().brick_size,
            overwrite: false,
            resolution: None,
            amplify: None,
            smoothing_scale: None,
            particle_memory: None,
            series: None,
            codec: BrickCodec::Zstd,
        }
    }
}

/// An opened input, ready to import.
pub struct ImportInput {
    source: Box<dyn VolumeSource>,
    /// What it is called in messages (its path).
    pub name: PathBuf,
    /// Its size, sample type, spacing and origin.
    pub info: VolumeInfo,
    /// For a mesh or particle file: what opening it found (for the front end to show).
    pub description: Option<String>,
}

/// Opens `input` as `settings` say (volume file, raw samples, or a mesh or particle file to bake).
pub fn open_input(input: &Path, settings: &ImportSettings) -> Result<ImportInput> {
    let is_geometry = voxstream_geometry::formats::is_geometry_file_name(input) && settings.raw.is_none();
    if !is_geometry && (settings.resolution.is_some() || settings.amplify.is_some()) {
        bail!("--resolution and --amplify apply to mesh and particle files; {} is not one", input.display());
    }
    // A missing input, with the nearest name beside it (as `render` says of stores and meshes).
    if !is_geometry && std::fs::symlink_metadata(input).is_err() {
        bail!("{}: not found{}", input.display(), crate::near_names::sibling_hint(input, false));
    }
    if is_geometry {
        if settings.spacing.is_some()
            || settings.origin.is_some()
            || settings.nan_as.is_some()
            || settings.unit.is_some()
            || settings.orientation.is_some()
        {
            bail!("--dtype, --spacing, --origin, --unit, --orientation and --nan-as apply to volume files; a mesh or particle file keeps its own units");
        }
        if !input.is_file() {
            return Err(missing_geometry_file(input));
        }
        let options = GeometryOptions {
            amplify: settings.amplify,
            resolution: Some(settings.resolution.unwrap_or(DEFAULT_BAKE_RESOLUTION)),
            attribute: false,
            smoothing_scale: settings.smoothing_scale,
            particle_memory: settings.particle_memory,
            budget_mb: None,
            width: 512,
            height: 512,
            quiet: false,
        };
        let geometry = geometry_source::open(input, &options)?;
        let source = BakedGeometry::new(geometry.producer, geometry.value_range, geometry.bounds)?;
        let info = source.info().clone();
        return Ok(ImportInput {
            source: Box::new(source),
            name: input.to_path_buf(),
            info,
            description: Some(geometry.description),
        });
    }
    let unit = settings.unit.as_deref().map(SpaceUnit::parse).transpose().map_err(|e| anyhow!("--unit: {e}"))?;
    let orientation = settings
        .orientation
        .as_deref()
        .map(Orientation::parse)
        .transpose()
        .map_err(|e| anyhow!("--orientation: {e}"))?;
    let raw = match &settings.raw {
        Some(raw) => {
            let file_type = SampleType::from_name(&raw.dtype)
                .with_context(|| format!("unknown --dtype '{}': expected {DTYPE_NAMES}", raw.dtype))?;
            Some(RawLayout {
                info: VolumeInfo {
                    dims: raw.dims,
                    dtype: file_type.stored(),
                    spacing: settings.spacing.unwrap_or([1.0; 3]),
                    origin: settings.origin.unwrap_or([0.0; 3]),
                    unit,
                    orientation,
                },
                file_type: Some(file_type),
                endian: if raw.big_endian { Endian::Big } else { Endian::Little },
                header_bytes: raw.header_bytes,
            })
        }
        None => None,
    };
    if let (Some(layout), Some(raw)) = (&raw, &settings.raw) {
        check_raw_dims_against_header(input, raw.dims, layout.header_bytes)?;
    }
    let opened = match &settings.series {
        Some(series) => {
            let is_dicom = input.is_dir() || has_dicom_extension(input) || has_dicom_magic(input);
            if raw.is_some() || !is_dicom {
                bail!("--series chooses among the series of a DICOM folder; {} is not one", input.display());
            }
            Box::new(DicomSeries::open_series(input, Some(series))?) as Box<dyn VolumeSource>
        }
        None => open_volume(input, raw.as_ref())?,
    };
    let source: Box<dyn VolumeSource> = Box::new(
        WithGeometry::new(opened, settings.spacing, settings.origin).with_unit(unit).with_orientation(orientation),
    );
    if let Some(s) = settings.spacing.filter(|s| s.iter().any(|v| *v <= 0.0)) {
        bail!("--spacing must be positive, got {s:?}");
    }
    if let Some(v) = settings.nan_as.filter(|v| !v.is_finite()) {
        bail!("--nan-as must be a finite number, got {v}");
    }
    Ok(ImportInput::from_source(source, input))
}

impl ImportInput {
    /// An input the caller made (e.g. an array in memory), called `name` in messages.
    pub fn from_source(source: Box<dyn VolumeSource>, name: &Path) -> ImportInput {
        let info = source.info().clone();
        let description = source.description();
        ImportInput { source, name: name.to_path_buf(), info, description }
    }

    /// Writes the store `out`. `progress(done, total)` hears input bytes read; returning `ControlFlow::Break` stops
    /// the import at the next slab (an error saying so; nothing is left at `out` that was not there before).
    pub fn import(
        self,
        out: &Path,
        settings: &ImportSettings,
        progress: &mut (dyn FnMut(u64, u64) -> ControlFlow<()> + Send),
    ) -> Result<ImportReport> {
        if let Some(v) = settings.nan_as.filter(|v| !v.is_finite()) {
            bail!("--nan-as must be a finite number, got {v}");
        }
        let options = ImportOptions {
            brick_size: settings.brick_size,
            overwrite: settings.overwrite,
            nan_as: settings.nan_as,
            codec: settings.codec,
            ..ImportOptions::default()
        };
        let total = self.info.byte_len();
        let slice_bytes = self.info.slice_len() as u64 * self.info.dtype.size() as u64;
        let mut source = Stoppable { inner: self.source, progress, slice_bytes, total, read: 0, stopped: false, out };
        // The progress is reported before each read (the importer's own report comes after its slabs, too late to
        // stop the last one), so a stop always lands before the store is complete.
        let result = import_volume(&mut source, out, &options, &mut |_, _| {});
        if source.stopped {
            bail!("the import of {} into {} was stopped; nothing was written", self.name.display(), out.display());
        }
        if result.is_ok() {
            let _ = (source.progress)(total, total);
        }
        result.map_err(|error| match error {
            // The only error that does not name a file already.
            StoreError::NonFinite { .. } => anyhow!("{}: {error}", self.name.display()),
            error => error.into(),
        })
    }
}

/// A source that reports progress before each read, and fails the read once asked to stop.
struct Stoppable<'a> {
    inner: Box<dyn VolumeSource>,
    progress: &'a mut (dyn FnMut(u64, u64) -> ControlFlow<()> + Send),
    slice_bytes: u64,
    total: u64,
    /// Input bytes read so far.
    read: u64,
    stopped: bool,
    out: &'a Path,
}

impl VolumeSource for Stoppable<'_> {
    fn info(&self) -> &VolumeInfo {
        self.inner.info()
    }

    fn read_slices(&mut self, count: usize, out: &mut Vec<f32>) -> Result<(), StoreError> {
        if self.stopped || (self.progress)(self.read, self.total).is_break() {
            self.stopped = true;
            return Err(StoreError::Io {
                path: self.out.to_path_buf(),
                error: std::io::Error::new(std::io::ErrorKind::Interrupted, "the import was stopped"),
            });
        }
        self.read += count as u64 * self.slice_bytes;
        self.inner.read_slices(count, out)
    }

    fn conversion(&self) -> Option<SampleConversion> {
        self.inner.conversion()
    }
}

/// Formats whose header is cheap to read (the samples are streamed later), with their names.
const HEADER_FORMATS: [(&str, &str); 9] = [
    (".npy", "NumPy"),
    (".npz", "NumPy"),
    (".nii", "NIfTI"),
    (".nii.gz", "NIfTI"),
    (".nrrd", "NRRD"),
    (".nhdr", "NRRD"),
    (".mha", "MetaImage"),
    (".mhd", "MetaImage"),
    (".inr", "INRIMAGE"),
];

/// `--dims`/`--dtype` read any file as raw. When the file is in fact a format with a header (by its name, or NumPy's
/// magic bytes), the header knows the dimensions: refuse, and say when `--dims` is the header's dimensions reversed
/// (numpy's shape order z,y,x), the mistake that otherwise imports striped garbage. With `--header-bytes`, reading
/// such a file as raw on purpose is allowed, unless the dimensions are reversed.
fn check_raw_dims_against_header(input: &std::path::Path, dims: [u64; 3], header_bytes: u64) -> Result<()> {
    let name = input.file_name().map(|n| n.to_string_lossy().to_lowercase()).unwrap_or_default();
    let mut magic = [0u8; 6];
    let is_numpy_by_magic = std::fs::File::open(input)
        .and_then(|mut file| std::io::Read::read_exact(&mut file, &mut magic))
        .is_ok_and(|()| &magic == b"\x93NUMPY");
    let format = HEADER_FORMATS.iter().find(|(ending, _)| name.ends_with(ending)).map(|(_, format)| *format);
    let (format, opened) = match (format, is_numpy_by_magic) {
        (Some(format), _) => (format, open_volume(input, None)),
        (None, true) => {
            ("NumPy", voxstream_store::formats::npy::open(input).map(|s| Box::new(s) as Box<dyn VolumeSource>))
        }
        (None, false) => return Ok(()),
    };
    let Ok(source) = opened else { return Ok(()) };
    let own = source.info().dims;
    let shown = input.display();
    let [x, y, z] = own;
    if dims != own && dims == [z, y, x] {
        bail!(
            "--dims {},{},{} is {shown}'s dimensions reversed (numpy's shape order z,y,x): voxstream's --dims is x,y,z, \
             i.e. --dims {x},{y},{z}; better, drop --dims and --dtype: the {format} header gives them",
            dims[0],
            dims[1],
            dims[2]
        );
    }
    if header_bytes == 0 {
        bail!(
            "{shown} is a {format} file ({x}x{y}x{z}): import it without --dims and --dtype, which read a file as raw \
             samples"
        );
    }
    Ok(())
}
