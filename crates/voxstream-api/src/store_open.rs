//! Opening a store for `render`, `view` and `info`: `--value-range` for other tools' OME-Zarr images, a progress bar
//! while level 0 is scanned for its value range (when that takes a while), and the warning after a run that samples
//! lay outside the range and were clipped.

use std::path::Path;

use anyhow::{bail, Result};
use indicatif::{ProgressBar, ProgressStyle};
use voxstream_store::foreign::ForeignOptions;
use voxstream_store::image_planes::{ImagePlanes, LeadingKind, PlaneChoice};
use voxstream_store::StoreReader;

use voxstream_store::remote_access::RemoteAccess;

/// Level-0 bricks above which the value-range scan shows a progress bar (2^15 bricks of 32³: 1 Gi samples).
const SCAN_BAR_BRICKS: u64 = 1 << 15;

/// Parses `--value-range LO,HI`: two finite numbers, LO below HI.
pub fn parse_value_range(text: &str) -> Result<[f64; 2], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let numbers: Option<Vec<f64>> = parts.iter().map(|p| p.parse::<f64>().ok().filter(|v| v.is_finite())).collect();
    match numbers.as_deref() {
        Some(&[lo, hi]) if lo < hi => Ok([lo, hi]),
        Some(&[_, _]) => Err(format!("'{text}': LO must be below HI, e.g. --value-range 0,2000")),
        _ => Err(format!("'{text}' is not LO,HI (two finite numbers, e.g. --value-range 0,2000)")),
    }
}

/// Opens the store at `path` with a host cache of `cache_bytes`; `value_range` (`--value-range`) and `planes`
/// (`--channel`, `--time`) apply to foreign OME-Zarr images only (a voxstream store's range is exact, and it is
/// 3-D). `quiet` hides the scan's progress bar.
pub fn open_store(
    path: &Path,
    cache_bytes: u64,
    value_range: Option<[f64; 2]>,
    planes: PlaneChoice,
    remote: &RemoteAccess,
    quiet: bool,
) -> Result<StoreReader> {
    let bar = ProgressBar::hidden();
    let show = |done: u64, total: u64| {
        if done == 1 && total >= SCAN_BAR_BRICKS && !quiet {
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template(
                    "reading the image for its value range {bar:30} {pos}/{len} bricks ({eta})",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            bar.set_length(total);
        }
        bar.set_position(done);
    };
    let options =
        ForeignOptions { value_range, progress: Some(&show), remote: Some(remote), planes, ..Default::default() };
    let reader = StoreReader::open_with_options(path, cache_bytes, &options)?;
    bar.finish_and_clear();
    if value_range.is_some() && reader.is_native() {
        bail!(
            "--value-range: {} is a voxstream store, whose value range is exact ({} to {}); the flag is for other \
             tools' OME-Zarr images",
            reader.path().display(),
            reader.attributes().value_range[0],
            reader.attributes().value_range[1]
        );
    }
    if planes != PlaneChoice::default() && reader.is_native() {
        bail!(
            "--channel and --time choose a volume of a 4-D or 5-D OME-Zarr image; {} is a voxstream store (one \
             3-D volume)",
            reader.path().display()
        );
    }
    if reader.value_range_level() > 0 {
        let [lo, hi] = reader.attributes().value_range;
        eprintln!(
            "note: {}: level 0 holds more samples than are read when a store is opened, so the value range ({lo} to \
             {hi}) is level {}'s; samples beyond it saturate and are counted after the run. --value-range LO,HI sets \
             it",
            reader.path().display(),
            reader.value_range_level()
        );
    }
    Ok(reader)
}

/// What a 4-D or 5-D image shows of its channels and time points: `channel 1 of 3 ("GFP"), time point 0 of 2 (the
/// others: --channel C, --time T)`; `None` for a 3-D image.
pub fn planes_description(planes: &ImagePlanes) -> Option<String> {
    let mut parts = Vec::new();
    let mut flags = Vec::new();
    // The channel first, then the time point, then any other axis.
    let order = |kind: LeadingKind| {
        [LeadingKind::Channel, LeadingKind::Time, LeadingKind::Other].iter().position(|k| *k == kind)
    };
    let mut axes: Vec<_> = planes.axes.iter().collect();
    axes.sort_by_key(|a| order(a.kind));
    for axis in axes {
        let (noun, flag) = match axis.kind {
            LeadingKind::Channel => ("channel", "--channel C"),
            LeadingKind::Time => ("time point", "--time T"),
            LeadingKind::Other if axis.extent > 1 => ("index", ""),
            LeadingKind::Other => continue,
        };
        let label = match (&axis.kind, planes.omero.as_ref().and_then(|o| o.label.as_ref())) {
            (LeadingKind::Channel, Some(label)) => format!(" (\"{label}\")"),
            _ => String::new(),
        };
        let of_axis = if axis.kind == LeadingKind::Other { format!(" of axis {}", axis.name) } else { String::new() };
        parts.push(format!("{noun} {}{of_axis} of {}{label}", axis.index, axis.extent));
        if axis.extent > 1 && !flag.is_empty() {
            flags.push(flag);
        }
    }
    if parts.is_empty() {
        return None;
    }
    let others = if flags.is_empty() { String::new() } else { format!(" (the others: {})", flags.join(", ")) };
    Some(format!("{}{others}", parts.join(", ")))
}

/// The warning after a run when samples read lay outside the value range (they saturated), else `None`.
pub fn clipped_warning(reader: &StoreReader) -> Option<String> {
    let clipped = reader.clipped_samples();
    let [lo, hi] = reader.attributes().value_range;
    (clipped > 0).then(|| {
        format!(
            "warning: {clipped} samples read from {} lay outside the value range {lo} to {hi} and were clipped; widen \
             it with --value-range LO,HI",
            reader.path().display()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_ranges_parse_or_say_why_not() {
        assert_eq!(parse_value_range("0,2000"), Ok([0.0, 2000.0]));
        assert_eq!(parse_value_range("-1024, 3071.5"), Ok([-1024.0, 3071.5]));
        assert!(parse_value_range("5,5").unwrap_err().contains("below"));
        assert!(parse_value_range("0").unwrap_err().contains("LO,HI"));
        assert!(parse_value_range("0,inf").is_err());
        assert!(parse_value_range("a,b").is_err());
    }
}
