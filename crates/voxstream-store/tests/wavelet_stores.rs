//! Compressed bricks (issue 47, items 2–4). Stores whose bricks are wavelet-coded read back through the same reader as
//! zstd stores, exactly when lossless, within the bound at every level when lossy, with per-brick min/max that hold
//! every decoded sample (so empty-space skipping never culls a brick whose decoded values reach a transfer
//! function); and the host cache of bricks as stored answers a brick the decoded cache let go.

use std::path::{Path, PathBuf};

use voxstream_store::volume::SamplesInMemory;
use voxstream_store::{import_volume, BrickCodec, DType, ImportOptions, StoreReader, VolumeInfo};

const DIMS: [u64; 3] = [70, 61, 45];

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-wavelet-stores-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A smooth field with a sharp-edged ball, noise, and an empty corner, as `dtype` holds it.
fn volume(dtype: DType) -> Vec<f32> {
    let mut seed = 7u64;
    let mut values = Vec::new();
    for z in 0..DIMS[2] {
        for y in 0..DIMS[1] {
            for x in 0..DIMS[0] {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let noise = (seed >> 40) as f32 / (1u64 << 24) as f32;
                let (fx, fy, fz) = (x as f32, y as f32, z as f32);
                let ball =
                    if (fx - 40.0).powi(2) + (fy - 30.0).powi(2) + (fz - 20.0).powi(2) < 200.0 { 0.5 } else { 0.0 };
                let v = if x < 20 && y < 20 { 0.0 } else { 0.3 + 0.2 * (fx * 0.1).sin() * (fy * 0.07).cos() + ball };
                let v = v + 0.02 * noise * (v > 0.0) as u8 as f32;
                values.push(match dtype {
                    DType::U8 => (v * 255.0).floor().min(255.0),
                    DType::U16 => (v * 60000.0).floor().min(65535.0),
                    DType::I16 => (v * 60000.0).floor().min(65535.0) - 32768.0,
                    DType::F32 => v * 3.0 - 1.0,
                });
            }
        }
    }
    values
}

fn import(dir: &Path, name: &str, dtype: DType, codec: BrickCodec) -> StoreReader {
    import_only(dir, name, dtype, codec);
    StoreReader::open(&dir.join(name)).unwrap()
}

fn import_only(dir: &Path, name: &str, dtype: DType, codec: BrickCodec) {
    let info = VolumeInfo { dims: DIMS, dtype, spacing: [1.0; 3], origin: [0.0; 3], unit: None, orientation: None };
    let mut source = SamplesInMemory::new(info, volume(dtype)).unwrap();
    let out = dir.join(name);
    let options = ImportOptions { brick_size: 16, shard_bricks: 2, codec, ..ImportOptions::default() };
    import_volume(&mut source, &out, &options, &mut |_, _| {}).unwrap();
}

/// Every level whole, as the reader assembles it.
fn levels(reader: &StoreReader) -> Vec<Vec<f32>> {
    (0..reader.layout().levels())
        .map(|level| reader.read_region(level, [0; 3], reader.layout().level_dims[level]).unwrap())
        .collect()
}

/// Asserts that every brick's stored `[min, max]` holds each of its decoded samples.
fn ranges_hold_samples(reader: &StoreReader, what: &str) {
    let layout = reader.layout();
    let b = layout.brick_size;
    for level in 0..layout.levels() {
        let dims = layout.level_dims[level];
        let samples = reader.read_region(level, [0; 3], dims).unwrap();
        let bricks = layout.bricks(level);
        for bz in 0..bricks[2] {
            for by in 0..bricks[1] {
                for bx in 0..bricks[0] {
                    let range = reader.brick_range(level, [bx, by, bz]).unwrap();
                    for z in bz * b..((bz + 1) * b).min(dims[2]) {
                        for y in by * b..((by + 1) * b).min(dims[1]) {
                            for x in bx * b..((bx + 1) * b).min(dims[0]) {
                                let v = samples[((z * dims[1] + y) * dims[0] + x) as usize];
                                assert!(
                                    range[0] <= v && v <= range[1],
                                    "{what}: level {level} brick {:?}: {v} outside {range:?}",
                                    [bx, by, bz]
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}

fn stored_bytes(dir: &Path) -> u64 {
    let mut total = 0;
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if path.components().any(|c| c.as_os_str() == "c") {
                total += entry.metadata().unwrap().len();
            }
        }
    }
    total
}

#[test]
fn lossless_wavelet_stores_read_as_their_zstd_twins_at_every_level() {
    let dir = scratch("lossless");
    for dtype in [DType::U8, DType::U16, DType::I16, DType::F32] {
        let zstd = import(&dir, &format!("{dtype:?}-zstd"), dtype, BrickCodec::Zstd);
        let wavelet = import(&dir, &format!("{dtype:?}-wavelet"), dtype, BrickCodec::Wavelet { max_error: 0.0 });
        let (want, got) = (levels(&zstd), levels(&wavelet));
        for (level, (w, g)) in want.iter().zip(&got).enumerate() {
            assert!(w.iter().zip(g).all(|(a, b)| a.to_bits() == b.to_bits()), "{dtype:?} level {level}");
        }
        assert_eq!(wavelet.attributes().brick_codec, Some(BrickCodec::Wavelet { max_error: 0.0 }));
        assert_eq!(zstd.attributes().brick_codec, None, "zstd stores keep the attributes they always had");
        ranges_hold_samples(&wavelet, &format!("{dtype:?} lossless"));
        if dtype != DType::F32 {
            // Lossless f32 falls back to byte-shuffled zstd: no smaller, but not larger either by much.
            let (a, b) = (
                stored_bytes(&dir.join(format!("{dtype:?}-zstd"))),
                stored_bytes(&dir.join(format!("{dtype:?}-wavelet"))),
            );
            assert!(b < a, "{dtype:?}: wavelet {b} bytes against zstd {a}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn lossy_wavelet_stores_hold_their_bound_and_their_brick_ranges_hold_the_decoded_samples() {
    let dir = scratch("lossy");
    for (dtype, bound) in [(DType::U8, 2.0), (DType::U16, 40.0), (DType::I16, 7.5), (DType::F32, 0.01)] {
        let zstd = import(&dir, &format!("{dtype:?}-zstd"), dtype, BrickCodec::Zstd);
        let lossy = import(&dir, &format!("{dtype:?}-lossy"), dtype, BrickCodec::Wavelet { max_error: bound });
        let (want, got) = (levels(&zstd), levels(&lossy));
        let mut changed = 0usize;
        for (level, (w, g)) in want.iter().zip(&got).enumerate() {
            for (a, b) in w.iter().zip(g) {
                assert!((a - b).abs() as f64 <= bound * (1.0 + 1e-6), "{dtype:?} level {level}: {a} decoded as {b}");
                changed += (a != b) as usize;
            }
        }
        assert!(changed > 0, "{dtype:?}: a bound of {bound} changed no sample");
        ranges_hold_samples(&lossy, &format!("{dtype:?} max error {bound}"));
        let (a, b) =
            (stored_bytes(&dir.join(format!("{dtype:?}-zstd"))), stored_bytes(&dir.join(format!("{dtype:?}-lossy"))));
        assert!(b < a, "{dtype:?}: lossy {b} bytes against zstd {a}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bricks_the_decoded_cache_let_go_are_decoded_again_from_the_compressed_cache() {
    let dir = scratch("host-caches");
    for codec in [BrickCodec::Zstd, BrickCodec::Wavelet { max_error: 0.0 }] {
        let name = format!("{codec:?}");
        import_only(&dir, &name, DType::U16, codec);
        // 16³ bricks of u16 are 8 KiB decoded (kept in the store's type): an 800 KiB host cache holds 50 of level
        // 0's 60 decoded, and keeps 400 KiB of bricks as stored (about 5.7 KiB each, noisy u16), which holds them
        // all.
        let reader = StoreReader::open_with_cache(&dir.join(&name), 800 << 10).unwrap();
        let caches = reader.host_caches();
        assert_eq!(caches.decoded_bytes, 50 * 16 * 16 * 16 * 2, "{name}");
        let compressed = caches.compressed.expect("a native store has a compressed-brick cache");
        assert_eq!(compressed.capacity_bytes, 400 << 10, "{name}");
        let dims = reader.layout().level_dims[0];
        let first = reader.read_region(0, [0; 3], dims).unwrap();
        let after_first = reader.host_caches().compressed.unwrap();
        let second = reader.read_region(0, [0; 3], dims).unwrap();
        let after_second = reader.host_caches().compressed.unwrap();
        assert!(first == second, "{name}: the same samples from either cache");
        let stored = after_first.bricks_held;
        assert!(stored > 40, "{name}: {after_first:?}");
        assert!(after_first.held_bytes <= after_first.capacity_bytes, "{name}: {after_first:?}");
        // The second pass finds as stored the bricks the decoded cache let go: in scan order, LRU keeps none of the
        // ones it wants first, so most of them.
        assert!(after_second.hits - after_first.hits >= stored / 2, "{name}: {after_first:?} then {after_second:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
