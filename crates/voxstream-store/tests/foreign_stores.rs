//! Foreign (not voxstream-written) OME-Zarr images read right and read once (issues 41 item 8, 42 items 2 and 4):
//! the value range comes from level 0, chunks larger than a brick are read once, and metadata that would be read
//! wrongly (axes x, y, z; a scale of strings; a chunk-key separator that does not match the files) is refused.
//!
//! The images are written here by hand as Zarr v2 (gzip-compressed `<u2` chunks, C order), as other tools write
//! them (compressed chunks are decoded whole, so a brick cannot read just its part of one).

use std::path::{Path, PathBuf};

use std::io::Write;

use serde_json::{json, Value};
use voxstream_store::foreign::ForeignOptions;
use voxstream_store::image_planes::{LeadingKind, PlaneChoice};
use voxstream_store::StoreReader;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-foreign-stores-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// One level: its samples (x fastest) and dims (x, y, z).
struct Level {
    samples: Vec<u16>,
    dims: [u64; 3],
}

impl Level {
    fn filled(dims: [u64; 3], value: impl Fn(u64, u64, u64) -> u16) -> Level {
        let mut samples = Vec::new();
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    samples.push(value(x, y, z));
                }
            }
        }
        Level { samples, dims }
    }
}

/// How the image is written.
struct Layout {
    /// Chunk edge (x, y, z).
    chunk: [u64; 3],
    /// The separator `.zarray` declares.
    declared_separator: &'static str,
    /// The separator the chunk files are laid out with.
    file_separator: &'static str,
    /// `multiscales[0].axes`, if any.
    axes: Option<Value>,
    /// `scale` of every dataset's transform.
    scale: Value,
}

impl Default for Layout {
    fn default() -> Layout {
        Layout {
            chunk: [64; 3],
            declared_separator: "/",
            file_separator: "/",
            axes: Some(json!([
                {"name": "z", "type": "space", "unit": "micrometer"},
                {"name": "y", "type": "space", "unit": "micrometer"},
                {"name": "x", "type": "space", "unit": "micrometer"}
            ])),
            scale: json!([1.0, 1.0, 1.0]),
        }
    }
}

/// Writes an OME-Zarr 0.4 image (Zarr v2) of `levels` at `store`; returns the bytes of its chunk files.
fn write_v2(store: &Path, levels: &[Level], layout: &Layout) -> u64 {
    write_v2_planes(store, &[levels], &[], layout, None)
}

/// Writes an OME-Zarr 0.4 image (Zarr v2) with leading axes of extents `leading` (chunks of one sample along them):
/// `planes[p]` is the pyramid of the `p`-th combination of leading indices (the last leading axis fastest), and
/// `omero` goes into the attributes where given; returns the bytes of its chunk files.
fn write_v2_planes(store: &Path, planes: &[&[Level]], leading: &[u64], layout: &Layout, omero: Option<Value>) -> u64 {
    let levels = planes[0];
    std::fs::create_dir_all(store).unwrap();
    std::fs::write(store.join(".zgroup"), r#"{"zarr_format": 2}"#).unwrap();
    let datasets: Vec<Value> = (0..levels.len())
        .map(|i| {
            let factor = (1u64 << i) as f64;
            let scale: Vec<Value> = layout
                .scale
                .as_array()
                .unwrap()
                .iter()
                .map(|s| s.as_f64().map_or(s.clone(), |v| json!(v * factor)))
                .collect();
            json!({"path": i.to_string(), "coordinateTransformations": [{"type": "scale", "scale": scale}]})
        })
        .collect();
    let mut multiscale = json!({"version": "0.4", "name": "test", "datasets": datasets});
    if let Some(axes) = &layout.axes {
        multiscale["axes"] = axes.clone();
    }
    let mut zattrs = json!({"multiscales": [multiscale]});
    if let Some(omero) = omero {
        zattrs["omero"] = omero;
    }
    std::fs::write(store.join(".zattrs"), zattrs.to_string()).unwrap();
    let c = layout.chunk;
    let mut chunk_bytes = 0;
    for (i, level) in levels.iter().enumerate() {
        let dir = store.join(i.to_string());
        std::fs::create_dir_all(&dir).unwrap();
        let [nx, ny, nz] = level.dims;
        let shape: Vec<u64> = leading.iter().copied().chain([nz, ny, nx]).collect();
        let chunks: Vec<u64> = leading.iter().map(|_| 1).chain([c[2], c[1], c[0]]).collect();
        let zarray = json!({
            "zarr_format": 2, "shape": shape, "chunks": chunks, "dtype": "<u2",
            "compressor": {"id": "gzip", "level": 1}, "fill_value": 0, "order": "C", "filters": null,
            "dimension_separator": layout.declared_separator
        });
        std::fs::write(dir.join(".zarray"), zarray.to_string()).unwrap();
        for (p, plane) in planes.iter().enumerate() {
            let level = &plane[i];
            // The plane's leading indices as chunk-key components.
            let mut prefix = String::new();
            let mut rest = p as u64;
            for (a, &extent) in leading.iter().enumerate().rev() {
                let sep = layout.file_separator;
                prefix = format!("{}{sep}{prefix}", rest % extent);
                rest /= extent;
                let _ = a;
            }
            for cz in 0..nz.div_ceil(c[2]) {
                for cy in 0..ny.div_ceil(c[1]) {
                    for cx in 0..nx.div_ceil(c[0]) {
                        let mut bytes = Vec::new();
                        for z in cz * c[2]..(cz + 1) * c[2] {
                            for y in cy * c[1]..(cy + 1) * c[1] {
                                for x in cx * c[0]..(cx + 1) * c[0] {
                                    let v = if x < nx && y < ny && z < nz {
                                        level.samples[((z * ny + y) * nx + x) as usize]
                                    } else {
                                        0
                                    };
                                    bytes.extend_from_slice(&v.to_le_bytes());
                                }
                            }
                        }
                        let sep = layout.file_separator;
                        let key = format!("{prefix}{cz}{sep}{cy}{sep}{cx}");
                        let path = dir.join(&key);
                        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
                        let mut gzip = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
                        gzip.write_all(&bytes).unwrap();
                        let bytes = gzip.finish().unwrap();
                        chunk_bytes += bytes.len() as u64;
                        std::fs::write(path, bytes).unwrap();
                    }
                }
            }
        }
    }
    chunk_bytes
}

/// A 2×2×2 mean pyramid of `level0` down to one 32³ brick, as other tools write it.
fn pyramid(level0: Level) -> Vec<Level> {
    let mut levels = vec![level0];
    while levels.last().unwrap().dims.iter().any(|&d| d > 32) {
        let finer = levels.last().unwrap();
        let [fx, fy, _] = finer.dims;
        let dims = finer.dims.map(|d| d.div_ceil(2));
        let level = Level::filled(dims, |x, y, z| {
            let mut sum = 0u32;
            for (dx, dy, dz) in [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1)]
            {
                sum += finer.samples[(((2 * z + dz) * fy + 2 * y + dy) * fx + 2 * x + dx) as usize] as u32;
            }
            (sum / 8) as u16
        });
        levels.push(level);
    }
    levels
}

/// Bytes of the files under `dir`.
fn walk_bytes(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| if e.path().is_dir() { walk_bytes(&e.path()) } else { e.metadata().unwrap().len() })
        .sum()
}

fn open_error(store: &Path) -> String {
    match StoreReader::open(store) {
        Ok(_) => panic!("{} opened, expected a refusal", store.display()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_bright_outlier_only_at_level_zero_keeps_its_value() {
    let dir = scratch("outlier");
    // A stent-like scan: 100 everywhere, one strut voxel at 2000; the coarse levels average it away (to 100 + 1900/8
    // at level 1, and less above), so the coarsest level says nothing of it.
    let mut levels =
        pyramid(Level::filled([128, 128, 128], |x, y, z| if [x, y, z] == [70, 61, 52] { 2000 } else { 100 }));
    let coarsest = levels.last_mut().unwrap();
    coarsest.samples.iter_mut().for_each(|v| *v = 100);
    write_v2(&dir.join("stent.zarr"), &levels, &Layout::default());
    let reader = StoreReader::open(&dir.join("stent.zarr")).unwrap();
    assert_eq!(reader.attributes().value_range, [100.0, 2000.0]);
    assert_eq!(reader.read_region(0, [70, 61, 52], [1, 1, 1]).unwrap(), [2000.0]);
    assert_eq!(reader.clipped_samples(), 0);

    // A range given by the caller is used as is (level 0 not scanned), and the samples beyond it are counted.
    let options = ForeignOptions { value_range: Some([0.0, 1000.0]), ..Default::default() };
    let narrow = StoreReader::open_with_options(&dir.join("stent.zarr"), 64 << 20, &options).unwrap();
    assert_eq!(narrow.attributes().value_range, [0.0, 1000.0]);
    // Level 0 was not scanned: besides the metadata, only the probe's one central brick per level was read (one of
    // level 0's eight chunks), far less than level 0's chunks.
    let level0_bytes: u64 = walk_bytes(&dir.join("stent.zarr/0"));
    assert!(narrow.storage_bytes_read() < level0_bytes / 2, "level 0 was scanned although the range was given");
    narrow.read_region(0, [64, 32, 32], [32, 32, 32]).unwrap();
    assert_eq!(narrow.clipped_samples(), 1);
}

#[test]
fn a_level_0_beyond_the_scan_bound_gives_the_range_of_the_finest_level_within_it() {
    let dir = scratch("bound");
    // Level 0 (128³, 8 chunks of 64³) ramps 0..=254 along x, plus one bright voxel; level 1 (64³, one chunk) holds
    // 2x2x2 means, in which the bright voxel is diluted to a few hundred.
    let levels =
        pyramid(Level::filled([128, 128, 128], |x, y, z| if [x, y, z] == [3, 5, 7] { 3000 } else { 2 * x as u16 }));
    write_v2(&dir.join("big.zarr"), &levels, &Layout::default());
    let whole = StoreReader::open(&dir.join("big.zarr")).unwrap();
    assert_eq!((whole.attributes().value_range, whole.value_range_level()), ([0.0, 3000.0], 0));

    // A bound below level 0's 8 · 64³ stored samples, above level 1's 64³: level 1 is scanned, and only it.
    let options = ForeignOptions { max_scan_samples: Some(64 * 64 * 64), ..Default::default() };
    let bounded = StoreReader::open_with_options(&dir.join("big.zarr"), 64 << 20, &options).unwrap();
    assert_eq!(bounded.value_range_level(), 1);
    let [lo, hi] = bounded.attributes().value_range;
    let level1 = &levels[1].samples;
    let (want_lo, want_hi) = (*level1.iter().min().unwrap() as f64, *level1.iter().max().unwrap() as f64);
    assert_eq!([lo, hi], [want_lo, want_hi]);
    assert!(hi < 3000.0, "level 1 averages the bright voxel away");
    // Level 0's bright voxel is then clipped, and counted.
    bounded.read_region(0, [0, 0, 0], [32, 32, 32]).unwrap();
    assert!(bounded.clipped_samples() >= 1);

    // A bound below every level: the coarsest stored level is scanned.
    let options = ForeignOptions { max_scan_samples: Some(1), ..Default::default() };
    let tiny = StoreReader::open_with_options(&dir.join("big.zarr"), 64 << 20, &options).unwrap();
    assert_eq!(tiny.value_range_level(), levels.len() - 1);
}

#[test]
fn unwritten_chunks_bring_the_fill_value_into_the_range() {
    let dir = scratch("sparse");
    let levels = pyramid(Level::filled([128, 64, 64], |_, _, _| 500));
    write_v2(&dir.join("sparse.zarr"), &levels, &Layout::default());
    std::fs::remove_file(dir.join("sparse.zarr/0/0/0/1")).unwrap();
    let reader = StoreReader::open(&dir.join("sparse.zarr")).unwrap();
    assert_eq!(reader.attributes().value_range, [0.0, 500.0]);
}

#[test]
fn chunks_larger_than_bricks_are_read_once() {
    let dir = scratch("once");
    let levels = pyramid(Level::filled([192, 128, 128], |x, y, z| ((x * 7 + y * 3 + z) % 1000) as u16));
    let chunk_bytes = write_v2(&dir.join("chunks64.zarr"), &levels, &Layout::default());
    let reader = StoreReader::open(&dir.join("chunks64.zarr")).unwrap();
    // Every brick of every level, with the one-voxel border the producer reads, in z, y, x order.
    let layout = reader.layout().clone();
    for level in 0..layout.levels() {
        let dims = layout.level_dims[level];
        let bricks = layout.bricks(level);
        for z in 0..bricks[2] {
            for y in 0..bricks[1] {
                for x in 0..bricks[0] {
                    let ijk = [x, y, z];
                    let lower = [0, 1, 2].map(|a| (ijk[a] * 32).saturating_sub(1));
                    let upper = [0, 1, 2].map(|a| ((ijk[a] + 1) * 32 + 1).min(dims[a]));
                    let size = [0, 1, 2].map(|a| upper[a] - lower[a]);
                    let samples = reader.read_region(level, lower, size).unwrap();
                    if level == 0 {
                        assert_eq!(samples[0], ((lower[0] * 7 + lower[1] * 3 + lower[2]) % 1000) as f32);
                    }
                }
            }
        }
    }
    let read = reader.storage_bytes_read();
    assert!(
        read as f64 <= 1.2 * chunk_bytes as f64,
        "read {read} bytes (value range scan and every brick) for {chunk_bytes} bytes of chunks on disk"
    );
}

#[test]
fn axes_other_than_z_y_x_are_refused() {
    let dir = scratch("axes");
    let levels = pyramid(Level::filled([64, 48, 40], |x, _, _| x as u16));
    let layout = Layout {
        axes: Some(json!([{"name": "x", "type": "space"}, {"name": "y", "type": "space"},
                                          {"name": "z", "type": "space"}])),
        ..Layout::default()
    };
    write_v2(&dir.join("xyz.zarr"), &levels, &layout);
    let message = open_error(&dir.join("xyz.zarr"));
    assert!(message.contains("[x, y, z]") && message.contains("z, y, x"), "{message}");
    // The same image with its axes listed z, y, x opens with x along the 64 samples.
    write_v2(&dir.join("zyx.zarr"), &levels, &Layout::default());
    assert_eq!(StoreReader::open(&dir.join("zyx.zarr")).unwrap().info().dims, [64, 48, 40]);
}

#[test]
fn a_scale_that_is_not_numbers_is_refused() {
    let dir = scratch("scale");
    let levels = pyramid(Level::filled([64, 64, 64], |_, _, _| 1));
    write_v2(&dir.join("strings.zarr"), &levels, &Layout { scale: json!(["a", "b", "c"]), ..Layout::default() });
    let message = open_error(&dir.join("strings.zarr"));
    assert!(message.contains("scale") && message.contains("\"a\"") && message.contains("3 numbers"), "{message}");
    write_v2(&dir.join("short.zarr"), &levels, &Layout { scale: json!([2.0, 1.0]), ..Layout::default() });
    assert!(open_error(&dir.join("short.zarr")).contains("scale"));
    write_v2(&dir.join("good.zarr"), &levels, &Layout { scale: json!([3.0, 2.0, 0.5]), ..Layout::default() });
    assert_eq!(StoreReader::open(&dir.join("good.zarr")).unwrap().info().spacing, [0.5, 2.0, 3.0]);
}

#[test]
fn a_separator_that_does_not_match_the_files_is_refused() {
    let dir = scratch("separator");
    let levels = pyramid(Level::filled([64, 64, 64], |_, _, _| 7));
    let dot_over_slash = Layout { declared_separator: ".", file_separator: "/", ..Layout::default() };
    write_v2(&dir.join("dot.zarr"), &levels, &dot_over_slash);
    let message = open_error(&dir.join("dot.zarr"));
    assert!(message.contains("'.'") && message.contains("'/'") && message.contains("separator"), "{message}");
    let slash_over_dot = Layout { declared_separator: "/", file_separator: ".", ..Layout::default() };
    write_v2(&dir.join("slash.zarr"), &levels, &slash_over_dot);
    assert!(open_error(&dir.join("slash.zarr")).contains("separator"));
    // Declared as laid out, both read the image.
    for (name, separator) in [("dots.zarr", "."), ("slashes.zarr", "/")] {
        let layout = Layout { declared_separator: separator, file_separator: separator, ..Layout::default() };
        write_v2(&dir.join(name), &levels, &layout);
        let reader = StoreReader::open(&dir.join(name)).unwrap();
        assert_eq!(reader.read_region(0, [10, 20, 30], [1, 1, 1]).unwrap(), [7.0]);
    }
}

#[test]
fn a_dataset_path_leaving_the_store_is_refused() {
    let dir = scratch("escape");
    let levels = pyramid(Level::filled([64, 64, 64], |_, _, _| 7));
    write_v2(&dir.join("inner/image.zarr"), &levels, &Layout::default());
    let attributes = dir.join("inner/image.zarr/.zattrs");
    let text = std::fs::read_to_string(&attributes).unwrap().replace(r#""path":"0""#, r#""path":"../image.zarr/0""#);
    std::fs::write(&attributes, text).unwrap();
    let message = open_error(&dir.join("inner/image.zarr"));
    assert!(message.contains("leaves the store"), "{message}");
}

/// Issue 42 item 5: a 5-D image's other channels and time points could not be reached, and channel 0 was read
/// silently. `planes` chooses them (`--channel`, `--time`); the reader says which it reads, the value range is the
/// chosen volume's, and the chosen channel's `omero` metadata is read.
#[test]
fn channels_and_time_points_of_a_five_dimensional_image_are_chosen() {
    let dir = scratch("planes");
    let store = dir.join("cells.ome.zarr");
    // Two time points of three channels: the plane (t, c) holds 1000·t + 100·c + x at every sample.
    let pyramids: Vec<Vec<Level>> = (0..6u16)
        .map(|p| pyramid(Level::filled([40, 36, 32], move |x, _, _| 1000 * (p / 3) + 100 * (p % 3) + x as u16)))
        .collect();
    let planes: Vec<&[Level]> = pyramids.iter().map(|p| p.as_slice()).collect();
    let layout = Layout {
        axes: Some(json!([{"name": "t", "type": "time"}, {"name": "c", "type": "channel"}, "z", "y", "x"])),
        scale: json!([1.0, 1.0, 0.5, 0.5, 0.5]),
        chunk: [16; 3],
        ..Layout::default()
    };
    let omero = json!({"channels": [
        {"label": "DAPI", "color": "0000FF", "window": {"start": 0, "end": 50}},
        {"label": "GFP", "color": "00FF00", "window": {"start": 1110, "end": 1130}},
        {"label": "RFP", "color": "FF0000"}]});
    write_v2_planes(&store, &planes, &[2, 3], &layout, Some(omero));
    let open = |channel: Option<u64>, time: Option<u64>| {
        let options = ForeignOptions { planes: PlaneChoice { channel, time }, ..Default::default() };
        StoreReader::open_with_options(&store, 64 << 20, &options)
    };
    let reader = open(Some(1), Some(1)).unwrap();
    assert_eq!(reader.read_region(0, [7, 3, 2], [1, 1, 1]).unwrap(), [1107.0]);
    assert_eq!(reader.info().spacing, [0.5; 3]);
    assert_eq!(reader.attributes().value_range, [1100.0, 1139.0], "the chosen plane's range");
    let planes = reader.image_planes();
    let (time, channel) = (planes.axis(LeadingKind::Time).unwrap(), planes.axis(LeadingKind::Channel).unwrap());
    assert_eq!((time.extent, time.index, channel.extent, channel.index), (2, 1, 3, 1));
    let omero = planes.omero.as_ref().unwrap();
    assert_eq!(
        (omero.label.as_deref(), omero.color, omero.window),
        (Some("GFP"), Some([0.0, 1.0, 0.0]), Some([1110.0, 1130.0]))
    );
    // Coarser levels read the same plane.
    let coarse = reader.read_region(1, [0, 0, 0], [1, 1, 1]).unwrap()[0];
    assert!((1100.0..1102.0).contains(&coarse), "{coarse}");
    // By default the first of each, said in `image_planes`.
    let reader = open(None, None).unwrap();
    assert_eq!(reader.read_region(0, [7, 3, 2], [1, 1, 1]).unwrap(), [7.0]);
    assert_eq!(reader.image_planes().axis(LeadingKind::Channel).unwrap().index, 0);
    // Beyond the image, or an axis it does not have: one line naming what there is.
    let error = open(Some(3), None).err().unwrap().to_string();
    assert!(error.contains("--channel 3: the image has 3 channels (0 to 2)"), "{error}");
    let error = open(None, Some(2)).err().unwrap().to_string();
    assert!(error.contains("--time 2: the image has 2 time points (0 to 1)"), "{error}");
    let flat = dir.join("flat.ome.zarr");
    write_v2(&flat, &pyramid(Level::filled([40, 36, 32], |x, _, _| x as u16)), &Layout::default());
    let options = ForeignOptions { planes: PlaneChoice { channel: Some(1), time: None }, ..Default::default() };
    let error = StoreReader::open_with_options(&flat, 64 << 20, &options).err().unwrap().to_string();
    assert!(error.contains("--channel: the image has no channel axis (its axes: z, y, x)"), "{error}");
    std::fs::remove_dir_all(&dir).ok();
}
