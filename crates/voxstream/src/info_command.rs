//! `voxstream info`: what a store holds.

use anyhow::Result;
use serde::Serialize;

use crate::cli::InfoArgs;
use crate::source_path::{check_store_path, warn_about_leftovers};
use crate::store_open::open_store;

/// Bricks of one level.
#[derive(Serialize)]
struct LevelInfo {
    level: usize,
    dims: [u64; 3],
    bricks: u64,
    stored: u64,
    constant: u64,
    empty: u64,
}

/// The description printed.
#[derive(Serialize)]
struct StoreInfo {
    path: String,
    dims: [u64; 3],
    dtype: String,
    spacing: [f64; 3],
    origin: [f64; 3],
    brick_size: u64,
    value_range: [f64; 2],
    /// `[percent, value]` pairs; absent for stores that do not keep them.
    #[serde(skip_serializing_if = "Option::is_none")]
    value_percentiles: Option<Vec<[f64; 2]>>,
    bytes_on_disk: u64,
    levels: Vec<LevelInfo>,
}

/// Runs `voxstream info`.
pub fn run(args: &InfoArgs) -> Result<()> {
    check_store_path(&args.store, "info")?;
    let reader = open_store(&args.store, voxstream_store::store_reader::DEFAULT_CACHE_BYTES, args.value_range, false)?;
    warn_about_leftovers(&args.store);
    let layout = reader.layout();
    let attributes = reader.attributes();
    let levels = (0..layout.levels())
        .map(|level| {
            let b = layout.bricks(level);
            let (mut stored, mut constant, mut empty) = (0, 0, 0);
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
            LevelInfo { level, dims: layout.level_dims[level], bricks: b.iter().product(), stored, constant, empty }
        })
        .collect();
    let info = StoreInfo {
        path: args.store.display().to_string(),
        dims: attributes.dims,
        dtype: attributes.dtype.clone(),
        spacing: attributes.spacing,
        origin: attributes.origin,
        brick_size: attributes.brick_size,
        value_range: attributes.value_range,
        value_percentiles: attributes.value_percentiles.clone(),
        bytes_on_disk: reader.bytes_on_disk(),
        levels,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
        return Ok(());
    }
    println!("store        {}", info.path);
    println!("dimensions   {} x {} x {}", info.dims[0], info.dims[1], info.dims[2]);
    println!("type         {}", info.dtype);
    println!("spacing      {} {} {}", info.spacing[0], info.spacing[1], info.spacing[2]);
    println!("origin       {} {} {}", info.origin[0], info.origin[1], info.origin[2]);
    println!("value range  {} to {}", info.value_range[0], info.value_range[1]);
    if let Some(percentiles) = &info.value_percentiles {
        let text: Vec<String> = percentiles.iter().map(|[p, v]| format!("{p}%: {v}")).collect();
        println!("percentiles  {}", text.join(", "));
    }
    println!("brick        {}^3", info.brick_size);
    println!("on disk      {:.2} MiB", info.bytes_on_disk as f64 / 1048576.0);
    println!("level  dimensions          bricks   stored  constant  empty");
    for l in &info.levels {
        println!(
            "{:>5}  {:>6}x{:>6}x{:>6}  {:>7}  {:>7}  {:>8}  {:>5}",
            l.level, l.dims[0], l.dims[1], l.dims[2], l.bricks, l.stored, l.constant, l.empty
        );
    }
    Ok(())
}
