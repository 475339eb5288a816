//! `voxstream import`: a volume file into a store, with a progress bar (throughput and ETA).

use std::ops::ControlFlow;

use anyhow::{bail, Result};
use indicatif::{ProgressBar, ProgressStyle};
use voxstream_api::defaults::{counted, shown_value};
use voxstream_api::import_input::{open_input, ImportSettings, RawSettings};
use voxstream_api::remote_output::remote_output;

use voxstream_store::BrickCodec;

use crate::cli::{CodecArg, EndianArg, ImportArgs};

/// The codec `--codec` and `--max-error` ask for.
fn brick_codec(args: &ImportArgs) -> Result<BrickCodec> {
    let name = match args.codec {
        CodecArg::Zstd => "zstd",
        CodecArg::Wavelet => "wavelet",
    };
    BrickCodec::from_choice(name, args.max_error).map_err(|e| anyhow::anyhow!("--codec {name} --max-error: {e}"))
}

/// Runs `voxstream import`.
pub fn run(args: &ImportArgs) -> Result<()> {
    let is_geometry = voxstream_geometry::formats::is_geometry_file_name(&args.input) && args.dims.is_none();
    if is_geometry && args.dtype.is_some() {
        bail!("--dtype, --spacing, --origin, --unit, --orientation and --nan-as apply to volume files; a mesh or particle file keeps its own units");
    }
    let raw = match (&args.dims, &args.dtype) {
        (Some(dims), Some(dtype)) => Some(RawSettings {
            dims: *dims,
            dtype: dtype.clone(),
            big_endian: args.endian == EndianArg::Big,
            header_bytes: args.header_bytes,
        }),
        (None, None) => None,
        _ => bail!("a raw input needs both --dims and --dtype"),
    };
    let settings = ImportSettings {
        raw,
        spacing: args.spacing,
        origin: args.origin,
        unit: args.unit.clone(),
        orientation: args.orientation.clone(),
        nan_as: args.nan_as,
        brick_size: args.brick_size,
        overwrite: args.overwrite,
        resolution: args.resolution,
        amplify: args.amplify,
        smoothing_scale: args.smoothing_scale,
        particle_memory: args.particle_memory,
        codec: brick_codec(args)?,
        series: args.series.clone(),
    };
    // A remote --out is checked (and its bucket asked) before the input is read.
    let remote = remote_output(&args.out, &settings)?;
    let input = open_input(&args.input, &settings)?;
    if let Some(description) = input.description.as_ref().filter(|_| !args.quiet) {
        eprintln!("{description}");
    }
    let info = input.info.clone();
    let bar = if args.quiet { ProgressBar::hidden() } else { ProgressBar::new(info.byte_len()) };
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {bytes}/{total_bytes} {binary_bytes_per_sec} ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(format!("importing {}", args.input.display()));
    let mut progress = |done, _total| {
        bar.set_position(done);
        ControlFlow::Continue(())
    };
    let (report, uploaded) = match &remote {
        None => (input.import(&args.out, &settings, &mut progress)?, None),
        Some(remote) => {
            let upload_bar = bar.clone();
            let mut started = false;
            let (report, uploaded) = remote.import(input, &settings, &mut progress, &mut |done, total| {
                if !started {
                    started = true;
                    upload_bar.reset();
                    upload_bar.set_length(total);
                    upload_bar.set_message(format!("uploading to {}", remote.shown()));
                }
                upload_bar.set_position(done);
            })?;
            (report, Some(uploaded))
        }
    };
    bar.finish_and_clear();
    // Said even with --quiet: the store holds other values than the file's type could suggest.
    if let Some(conversion) = &report.conversion {
        eprintln!("note: {conversion}");
    }
    if !args.quiet {
        let out = match &remote {
            Some(remote) => remote.shown().to_string(),
            None => args.out.display().to_string(),
        };
        let codec = match settings.codec {
            BrickCodec::Zstd => String::new(),
            BrickCodec::Wavelet { max_error } if max_error > 0.0 => {
                format!("; bricks wavelet-coded, every sample within {max_error} of its value")
            }
            BrickCodec::Wavelet { .. } => "; bricks wavelet-coded, lossless".into(),
        };
        let oriented = info.orientation.map(|o| format!(", oriented {}", o.code())).unwrap_or_default();
        eprintln!(
            "imported {} ({}x{}x{} {}{oriented}) into {}: {}, {} written, {} empty, values {} to {}{codec}{}",
            args.input.display(),
            info.dims[0],
            info.dims[1],
            info.dims[2],
            info.dtype.name(),
            out,
            counted(report.levels as u64, "level", "levels"),
            counted(report.bricks_written.iter().sum::<u64>(), "brick", "bricks"),
            report.bricks_empty.iter().sum::<u64>(),
            shown_value(report.value_range[0]),
            shown_value(report.value_range[1]),
            uploaded.map(|u| format!("; {} objects ({} bytes) uploaded", u.objects, u.bytes)).unwrap_or_default()
        );
    }
    Ok(())
}
