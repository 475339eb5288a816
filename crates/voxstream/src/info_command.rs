//! `voxstream info`: what a store holds.

use anyhow::Result;
use serde::Serialize;
use voxstream_api::defaults::shown_value;
use voxstream_store::image_planes::PlaneChoice;
use voxstream_store::{BrickCodec, StoreReader};

use crate::cli::InfoArgs;
use crate::source_path::{check_store_path, warn_about_leftovers};
use crate::store_open::{open_store, planes_description};

/// Bricks of one level: for native stores, what its per-brick min/max say of them; for foreign stores, the chunk
/// files of the dataset behind it (counted on disk, never looped over as declared).
#[derive(Serialize)]
struct LevelInfo {
    level: usize,
    dims: [u64; 3],
    bricks: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    stored: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    constant: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    empty: Option<u64>,
    /// Foreign stores: the dataset read for this level (absent: averaged from the level below).
    #[serde(skip_serializing_if = "Option::is_none")]
    dataset: Option<String>,
    /// Foreign stores: chunks (or shards) the dataset declares.
    #[serde(skip_serializing_if = "Option::is_none")]
    chunks: Option<u64>,
    /// Foreign stores: chunk (or shard) files present.
    #[serde(skip_serializing_if = "Option::is_none")]
    chunks_stored: Option<u64>,
}

/// What the per-brick min/max of a native store's `level` say: bricks stored, constant and empty.
fn native_level(reader: &StoreReader, level: usize) -> LevelInfo {
    let layout = reader.layout();
    let b = layout.bricks(level);
    let (mut stored, mut constant, mut empty) = (0, 0, 0);
    // Bounded by the min/max arrays, whose files' sizes were checked against these counts at open.
    for z in 0..b[2] {
        for y in 0..b[1] {
            for x in 0..b[0] {
                match reader.brick_range(level, [x, y, z]) {
                    Some([0.0, 0.0]) => empty += 1,
                    Some([min, max]) if min == max => constant += 1,
                    _ => stored += 1,
                }
            }
        }
    }
    LevelInfo {
        level,
        dims: layout.level_dims[level],
        bricks: b.iter().product(),
        stored: Some(stored),
        constant: Some(constant),
        empty: Some(empty),
        dataset: None,
        chunks: None,
        chunks_stored: None,
    }
}

/// A foreign store's `level`: the dataset behind it and its chunk files, listed on disk.
fn foreign_level(reader: &StoreReader, level: usize) -> Result<LevelInfo> {
    let layout = reader.layout();
    let chunks = reader.stored_chunks(level)?;
    Ok(LevelInfo {
        level,
        dims: layout.level_dims[level],
        bricks: layout.bricks(level).iter().product(),
        stored: None,
        constant: None,
        empty: None,
        dataset: chunks.as_ref().map(|c| c.dataset.clone()),
        chunks: chunks.as_ref().map(|c| c.declared),
        chunks_stored: chunks.as_ref().and_then(|c| c.stored),
    })
}

/// The description printed.
#[derive(Serialize)]
struct StoreInfo {
    path: String,
    dims: [u64; 3],
    dtype: String,
    spacing: [f64; 3],
    origin: [f64; 3],
    /// Unit of the spacing and origin (an OME-Zarr name); absent when the store has none.
    #[serde(skip_serializing_if = "Option::is_none")]
    unit: Option<String>,
    /// The anatomical direction each axis points to, as three letters (`RAS`); absent when the store has none.
    #[serde(skip_serializing_if = "Option::is_none")]
    orientation: Option<String>,
    brick_size: u64,
    /// The bricks' codec when not zstd (`{"name": "wavelet", "max_error": E}`).
    #[serde(skip_serializing_if = "Option::is_none")]
    brick_codec: Option<BrickCodec>,
    value_range: [f64; 2],
    /// `[percent, value]` pairs; absent for stores that do not keep them.
    #[serde(skip_serializing_if = "Option::is_none")]
    value_percentiles: Option<Vec<[f64; 2]>>,
    bytes_on_disk: u64,
    /// A 4-D/5-D image's axes before z, y, x (time, channel), each with its extent and the index read.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    leading_axes: Vec<LeadingAxisInfo>,
    /// The chosen channel's OME-Zarr `omero` display settings.
    #[serde(skip_serializing_if = "Option::is_none")]
    omero: Option<OmeroInfo>,
    levels: Vec<LevelInfo>,
}

#[derive(Serialize)]
struct LeadingAxisInfo {
    name: String,
    kind: &'static str,
    extent: u64,
    index: u64,
}

#[derive(Serialize)]
struct OmeroInfo {
    #[serde(skip_serializing_if = "Option::is_none")]
    label: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    color: Option<[f32; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    window: Option<[f64; 2]>,
}

/// Runs `voxstream info`.
pub fn run(args: &InfoArgs) -> Result<()> {
    check_store_path(&args.store, "info")?;
    let cache_bytes = voxstream_store::store_reader::DEFAULT_CACHE_BYTES;
    let planes = PlaneChoice { channel: args.channel, time: args.time };
    let reader = open_store(&args.store, cache_bytes, args.value_range, planes, &args.remote.access(), false)?;
    warn_about_leftovers(&args.store);
    let layout = reader.layout();
    let attributes = reader.attributes();
    let levels = (0..layout.levels())
        .map(|level| if reader.is_native() { Ok(native_level(&reader, level)) } else { foreign_level(&reader, level) })
        .collect::<Result<Vec<_>>>()?;
    let info = StoreInfo {
        // The store as the reader shows it: a remote store's URL without credentials.
        path: reader.path().display().to_string(),
        dims: attributes.dims,
        dtype: attributes.dtype.clone(),
        spacing: attributes.spacing,
        origin: attributes.origin,
        unit: reader.info().unit.map(|u| u.name().to_string()),
        orientation: reader.info().orientation.map(|o| o.code()),
        brick_size: attributes.brick_size,
        brick_codec: attributes.brick_codec,
        value_range: attributes.value_range,
        value_percentiles: attributes.value_percentiles.clone(),
        bytes_on_disk: reader.bytes_on_disk(),
        leading_axes: reader
            .image_planes()
            .axes
            .iter()
            .map(|a| LeadingAxisInfo { name: a.name.clone(), kind: a.kind.name(), extent: a.extent, index: a.index })
            .collect(),
        omero: reader.image_planes().omero.as_ref().map(|o| OmeroInfo {
            label: o.label.clone(),
            color: o.color,
            window: o.window,
        }),
        levels,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
        return Ok(());
    }
    println!("store        {}", info.path);
    println!("dimensions   {} x {} x {}", info.dims[0], info.dims[1], info.dims[2]);
    println!("type         {}", info.dtype);
    let unit = info.unit.as_ref().map(|u| format!(" {u}")).unwrap_or_default();
    println!("spacing      {} {} {}{unit}", info.spacing[0], info.spacing[1], info.spacing[2]);
    println!("origin       {} {} {}{unit}", info.origin[0], info.origin[1], info.origin[2]);
    if let Some(orientation) = reader.info().orientation {
        println!("orientation  {orientation}");
    }
    println!("value range  {} to {}", shown_value(info.value_range[0]), shown_value(info.value_range[1]));
    if let Some(percentiles) = &info.value_percentiles {
        let text: Vec<String> = percentiles.iter().map(|[p, v]| format!("{p}%: {}", shown_value(*v))).collect();
        println!("percentiles  {}", text.join(", "));
    }
    if let Some(planes) = planes_description(reader.image_planes()) {
        println!("showing      {planes}");
    }
    if let Some(omero) = &info.omero {
        let mut parts = Vec::new();
        if let Some(label) = &omero.label {
            parts.push(format!("\"{label}\""));
        }
        if let Some([r, g, b]) = omero.color {
            parts.push(format!(
                "colour #{:02X}{:02X}{:02X}",
                (r * 255.0).round() as u8,
                (g * 255.0).round() as u8,
                (b * 255.0).round() as u8
            ));
        }
        if let Some([start, end]) = omero.window {
            parts.push(format!("window {start} to {end} (the default transfer function's)"));
        }
        println!("omero        {}", parts.join(", "));
    }
    let codec = match info.brick_codec {
        None | Some(BrickCodec::Zstd) => String::new(),
        Some(BrickCodec::Wavelet { max_error }) if max_error > 0.0 => {
            format!(", wavelet-coded: every sample within {max_error} of the imported value")
        }
        Some(BrickCodec::Wavelet { .. }) => ", wavelet-coded, lossless".into(),
    };
    println!("brick        {}^3{codec}", info.brick_size);
    match reader.remote() {
        Some(remote) => {
            let counts = remote.counts();
            println!(
                "remote       {} requests, {:.2} MiB fetched to open it",
                counts.requests,
                counts.bytes as f64 / 1048576.0
            );
        }
        None => println!("on disk      {:.2} MiB", info.bytes_on_disk as f64 / 1048576.0),
    }
    if reader.is_native() {
        println!("level  dimensions          bricks   stored  constant  empty");
        for l in &info.levels {
            let count = |v: Option<u64>| v.unwrap_or(0);
            println!(
                "{:>5}  {:>6}x{:>6}x{:>6}  {:>7}  {:>7}  {:>8}  {:>5}",
                l.level,
                l.dims[0],
                l.dims[1],
                l.dims[2],
                l.bricks,
                count(l.stored),
                count(l.constant),
                count(l.empty)
            );
        }
    } else {
        println!("level  dimensions          bricks  dataset          chunks   stored");
        for l in &info.levels {
            let (dataset, chunks, stored) = match (&l.dataset, l.chunks, l.chunks_stored) {
                // A remote HTTP store cannot be listed: its stored chunks are unknown.
                (Some(d), Some(c), s) => (d.clone(), c.to_string(), s.map_or("?".into(), |s| s.to_string())),
                _ => ("(averaged)".into(), "-".into(), "-".into()),
            };
            println!(
                "{:>5}  {:>6}x{:>6}x{:>6}  {:>7}  {:<14}  {:>7}  {:>7}",
                l.level, l.dims[0], l.dims[1], l.dims[2], l.bricks, dataset, chunks, stored
            );
        }
    }
    Ok(())
}
