//! `voxstream import`: a volume file into a store, with a progress bar (throughput and ETA).

use anyhow::{anyhow, bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use voxstream_store::formats::{open_volume, Endian, RawLayout, WithGeometry};
use voxstream_store::{import_volume, DType, ImportOptions, StoreError, VolumeInfo, VolumeSource};

use crate::cli::{EndianArg, ImportArgs};
use crate::geometry_import::{BakedGeometry, DEFAULT_BAKE_RESOLUTION};
use crate::geometry_source::{self, GeometryOptions};
use crate::source_path::missing_geometry_file;

/// Runs `voxstream import`.
pub fn run(args: &ImportArgs) -> Result<()> {
    let is_geometry = voxstream_geometry::formats::is_geometry_file_name(&args.input) && args.dims.is_none();
    if !is_geometry && (args.resolution.is_some() || args.amplify.is_some()) {
        bail!("--resolution and --amplify apply to mesh and particle files; {} is not one", args.input.display());
    }
    if is_geometry {
        if args.dtype.is_some() || args.spacing.is_some() || args.origin.is_some() || args.nan_as.is_some() {
            bail!("--dtype, --spacing, --origin and --nan-as apply to volume files; a mesh or particle file keeps its own units");
        }
        if !args.input.is_file() {
            return Err(missing_geometry_file(&args.input));
        }
        let options = GeometryOptions {
            amplify: args.amplify,
            resolution: Some(args.resolution.unwrap_or(DEFAULT_BAKE_RESOLUTION)),
            attribute: false,
            smoothing_scale: args.smoothing_scale,
            particle_memory: args.particle_memory,
            budget_mb: None,
            width: 512,
            height: 512,
        };
        let geometry = geometry_source::open(&args.input, &options)?;
        if !args.quiet {
            eprintln!("{}", geometry.description);
        }
        let mut source = BakedGeometry::new(geometry.producer, geometry.value_range, geometry.bounds)?;
        return import_source(args, &mut source);
    }
    let raw = match (&args.dims, &args.dtype) {
        (Some(dims), Some(dtype)) => {
            let dtype = DType::from_name(dtype)
                .with_context(|| format!("unknown --dtype '{dtype}': expected u8, u16, i16 or f32"))?;
            Some(RawLayout {
                info: VolumeInfo {
                    dims: *dims,
                    dtype,
                    spacing: args.spacing.unwrap_or([1.0; 3]),
                    origin: args.origin.unwrap_or([0.0; 3]),
                },
                endian: if args.endian == EndianArg::Big { Endian::Big } else { Endian::Little },
                header_bytes: args.header_bytes,
            })
        }
        (None, None) => None,
        _ => bail!("a raw input needs both --dims and --dtype"),
    };
    if let (Some(layout), Some(dims)) = (&raw, args.dims) {
        check_raw_dims_against_header(&args.input, dims, layout.header_bytes)?;
    }
    let mut source: Box<dyn VolumeSource> =
        Box::new(WithGeometry::new(open_volume(&args.input, raw.as_ref())?, args.spacing, args.origin));
    if let Some(s) = args.spacing.filter(|s| s.iter().any(|v| *v <= 0.0)) {
        bail!("--spacing must be positive, got {s:?}");
    }
    if let Some(v) = args.nan_as.filter(|v| !v.is_finite()) {
        bail!("--nan-as must be a finite number, got {v}");
    }
    import_source(args, source.as_mut())
}

/// Imports an opened source into the store `args.out`, with a progress bar.
fn import_source(args: &ImportArgs, source: &mut dyn VolumeSource) -> Result<()> {
    let info = source.info().clone();
    let options = ImportOptions {
        brick_size: args.brick_size,
        overwrite: args.overwrite,
        nan_as: args.nan_as,
        ..ImportOptions::default()
    };
    let bar = if args.quiet { ProgressBar::hidden() } else { ProgressBar::new(info.byte_len()) };
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {bytes}/{total_bytes} {binary_bytes_per_sec} ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(format!("importing {}", args.input.display()));
    let mut progress = |done: u64, _total: u64| bar.set_position(done);
    let report = import_volume(source, &args.out, &options, &mut progress).map_err(|error| match error {
        // The only error that does not name a file already.
        StoreError::NonFinite { .. } => anyhow!("{}: {error}", args.input.display()),
        error => error.into(),
    })?;
    bar.finish_and_clear();
    if !args.quiet {
        eprintln!(
            "imported {} ({}x{}x{} {}) into {}: {} levels, {} bricks written, {} empty, values {} to {}",
            args.input.display(),
            info.dims[0],
            info.dims[1],
            info.dims[2],
            info.dtype.name(),
            args.out.display(),
            report.levels,
            report.bricks_written.iter().sum::<u64>(),
            report.bricks_empty.iter().sum::<u64>(),
            report.value_range[0],
            report.value_range[1]
        );
    }
    Ok(())
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
