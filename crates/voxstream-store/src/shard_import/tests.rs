//! The distributed import against the single-process one: every file of the store byte for byte, whatever order
//! the tasks run in; and what crosses a process boundary checked.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::*;
use crate::import::import_volume;
use crate::volume::SamplesInMemory;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-shard-import-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn info(dims: [u64; 3], dtype: DType) -> VolumeInfo {
    VolumeInfo { dims, dtype, spacing: [1.0, 0.5, 2.0], origin: [3.0, 0.0, -1.0], unit: None, orientation: None }
}

/// A volume with empty corners, smooth parts and noise (so bricks are empty, uniform and varied).
fn volume(dims: [u64; 3], dtype: DType) -> Vec<f32> {
    let mut values = Vec::new();
    let mut seed = 12345u64;
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let noise = (seed >> 40) as f32 / (1u64 << 24) as f32;
                let v = if x + y < 12 { 0.0 } else { ((x * 3 + y * 5 + z * 7) % 200) as f32 + 40.0 * noise };
                values.push(match dtype {
                    _ if v == 0.0 => 0.0,
                    DType::U8 => v.min(255.0).floor(),
                    DType::U16 => (v * 250.0).floor(),
                    DType::I16 => (v * 100.0).floor() - 9000.0,
                    DType::F32 => v * 0.37 - 20.0,
                });
            }
        }
    }
    values
}

/// Runs every task in this process, in the order `order` gives each level's shards, as a cluster would.
fn import_by_shards(
    values: &[f32],
    info: &VolumeInfo,
    out: &Path,
    options: &ImportOptions,
    reverse: bool,
) -> Result<ImportReport, StoreError> {
    let import = ShardImport::begin(info.clone(), out, options)?;
    let spec = ShardSpec::from_json(&import.spec().to_json())?;
    let layout = import.layout().clone();
    let mut halves: HashMap<(usize, [u64; 3]), Vec<f32>> = HashMap::new();
    let mut summaries = Vec::new();
    for level in 0..layout.levels() {
        let grid = spec.shards(&layout, level);
        let mut shards: Vec<[u64; 3]> =
            (0..grid[2]).flat_map(|z| (0..grid[1]).flat_map(move |y| (0..grid[0]).map(move |x| [x, y, z]))).collect();
        if reverse {
            shards.reverse();
        }
        for shard in shards {
            let input = if level == 0 {
                let (o, e) = spec.region(&layout, 0, shard)?;
                let mut samples = Vec::new();
                for z in o[2]..o[2] + e[2] {
                    for y in o[1]..o[1] + e[1] {
                        let row = ((z * info.dims[1] + y) * info.dims[0]) as usize;
                        samples.extend_from_slice(&values[row + o[0] as usize..row + (o[0] + e[0]) as usize]);
                    }
                }
                ShardInput::Samples(samples)
            } else {
                let mut children = spec.children(&layout, level, shard);
                if reverse {
                    children.reverse();
                }
                ShardInput::Pieces(children.into_iter().map(|c| (c, halves.remove(&(level - 1, c)).unwrap())).collect())
            };
            let output = spec.write_shard(level, shard, input)?;
            halves.insert((level, shard), output.coarse);
            summaries.push(output.summary);
        }
    }
    if reverse {
        summaries.reverse();
    }
    import.finish(summaries)
}

/// Every file under `root`, by relative path.
fn files(root: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut found = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                found.push((path.strip_prefix(root).unwrap().to_path_buf(), std::fs::read(&path).unwrap()));
            }
        }
    }
    found.sort();
    found
}

/// Asserts that the stores `a` and `b` hold the same files with the same bytes.
fn same_files(a: &Path, b: &Path, what: &str) {
    let (want, have) = (files(a), files(b));
    assert_eq!(
        have.iter().map(|f| &f.0).collect::<Vec<_>>(),
        want.iter().map(|f| &f.0).collect::<Vec<_>>(),
        "{what}: the stores' files"
    );
    for ((path, bytes), (_, wanted)) in have.iter().zip(&want) {
        let first = bytes.iter().zip(wanted).position(|(x, y)| x != y);
        assert!(
            bytes == wanted,
            "{what}: {} differs ({} bytes against {}, first at {first:?})",
            path.display(),
            bytes.len(),
            wanted.len()
        );
    }
}

fn single(values: &[f32], info: &VolumeInfo, out: &Path, options: &ImportOptions) -> ImportReport {
    let mut source = SamplesInMemory::new(info.clone(), values.to_vec()).unwrap();
    import_volume(&mut source, out, options, &mut |_, _| {}).unwrap()
}

#[test]
fn shard_tasks_in_any_order_write_the_single_process_store_byte_for_byte() {
    let dir = scratch("identical");
    // Odd dims everywhere; 4-sample bricks and 2×2 bricks a shard: 5 levels, several shards on each.
    let dims = [37, 45, 29];
    let codecs = [BrickCodec::Zstd, BrickCodec::Wavelet { max_error: 0.0 }, BrickCodec::Wavelet { max_error: 2.5 }];
    for (dtype, codec) in
        [DType::U8, DType::U16, DType::I16, DType::F32].into_iter().flat_map(|dtype| codecs.map(|codec| (dtype, codec)))
    {
        let options = ImportOptions { brick_size: 4, shard_bricks: 2, codec, ..ImportOptions::default() };
        let dtype_name = format!("{dtype:?} {codec:?}");
        let values = volume(dims, dtype);
        let info = info(dims, dtype);
        // The same store name in two folders: the name is written into the OME metadata.
        let (a, b, c) =
            (dir.join("one").join("store"), dir.join("tasks").join("store"), dir.join("back").join("store"));
        for folder in [&a, &b, &c] {
            std::fs::create_dir_all(folder.parent().unwrap()).unwrap();
        }
        let expected = single(&values, &info, &a, &options);
        assert!(expected.levels >= 4, "{expected:?}");
        assert!(expected.bricks_empty[0] > 0 && expected.bricks_written[0] > 0, "{expected:?}");
        let got = import_by_shards(&values, &info, &b, &options, false).unwrap();
        assert_eq!(got, expected, "{dtype_name}");
        let backwards = import_by_shards(&values, &info, &c, &options, true).unwrap();
        assert_eq!(backwards, expected, "{dtype_name}");
        assert!(files(&a).len() > 20, "{} files", files(&a).len());
        same_files(&a, &b, &dtype_name);
        same_files(&a, &c, &format!("{dtype_name}, tasks backwards"));
        for folder in [&a, &b, &c] {
            std::fs::remove_dir_all(folder).unwrap();
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn non_finite_samples_are_replaced_or_named_by_their_place_in_the_volume() {
    let dir = scratch("non-finite");
    let dims = [20, 18, 11];
    let mut values = volume(dims, DType::F32);
    let at = |x: u64, y: u64, z: u64| ((z * dims[1] + y) * dims[0] + x) as usize;
    values[at(13, 9, 6)] = f32::NAN;
    values[at(2, 17, 10)] = f32::INFINITY;
    let info = info(dims, DType::F32);
    let options = ImportOptions { brick_size: 4, shard_bricks: 2, nan_as: Some(-1.0), ..ImportOptions::default() };
    let (a, b) = (dir.join("a").join("s"), dir.join("b").join("s"));
    std::fs::create_dir_all(dir.join("a")).unwrap();
    std::fs::create_dir_all(dir.join("b")).unwrap();
    let expected = single(&values, &info, &a, &options);
    assert_eq!(import_by_shards(&values, &info, &b, &options, false).unwrap(), expected);
    same_files(&a, &b, "nan_as");

    let strict = ImportOptions { nan_as: None, overwrite: true, ..options };
    let error = import_by_shards(&values, &info, &b, &strict, false).unwrap_err();
    assert!(
        matches!(error, StoreError::NonFinite { position, .. } if position == [13, 9, 6] || position == [2, 17, 10]),
        "{error}"
    );
    assert!(b.join("zarr.json").exists(), "the store in place is kept");
    assert!(!partial_path(&b).exists(), "the partial store is removed");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn forged_specs_pieces_and_summaries_are_refused_with_a_reason() {
    let dir = scratch("forged");
    let dims = [20, 18, 11];
    let info = info(dims, DType::U8);
    let options = ImportOptions { brick_size: 4, shard_bricks: 2, ..ImportOptions::default() };
    let out = dir.join("s");
    let import = ShardImport::begin(info.clone(), &out, &options).unwrap();
    let spec = import.spec().clone();
    let layout = import.layout().clone();
    let text = spec.to_json();
    for (from, to) in
        [("\"brick_size\":4", "\"brick_size\":5"), ("\"u8\"", "\"u9\""), ("\"shard_bricks\":2", "\"shard_bricks\":0")]
    {
        assert!(ShardSpec::from_json(&text.replace(from, to)).is_err(), "{to}");
    }
    assert!(ShardSpec::from_json("{").unwrap_err().to_string().contains("not a shard spec"));
    assert!(spec
        .write_shard(0, [9, 0, 0], ShardInput::Samples(vec![0.0; 4]))
        .unwrap_err()
        .to_string()
        .contains("outside"));
    let short = spec.write_shard(0, [0, 0, 0], ShardInput::Samples(vec![0.0; 4])).unwrap_err();
    assert!(short.to_string().contains("8×8×4 samples, 4 were given"), "{short}");
    let children = spec.children(&layout, 1, [0, 0, 0]);
    assert_eq!(children.len(), 8);
    let wrong = spec.write_shard(1, [0, 0, 0], ShardInput::Pieces(vec![(children[0], vec![0.0; 3])])).unwrap_err();
    let foreign = spec.write_shard(1, [0, 0, 0], ShardInput::Pieces(vec![([2, 0, 0], vec![0.0; 32])])).unwrap_err();
    assert!(foreign.to_string().contains("is not a child of"), "{foreign}");
    assert!(wrong.to_string().contains("hold 3 samples"), "{wrong}");
    let lacking = spec.write_shard(1, [0, 0, 0], ShardInput::Pieces(vec![(children[0], vec![0.0; 32])])).unwrap_err();
    assert!(lacking.to_string().contains("lacks the halves"), "{lacking}");
    let level_zero = spec.write_shard(0, [0, 0, 0], ShardInput::Pieces(Vec::new())).unwrap_err();
    assert!(level_zero.to_string().contains("read from the source"), "{level_zero}");
    // A summary list missing shards: refused, and the partial store removed with the import.
    let error = import.finish(Vec::new()).unwrap_err();
    assert!(error.to_string().contains("were not reported"), "{error}");
    assert!(!out.exists() && !partial_path(&out).exists());
    // A task still running after the abort writes nothing, and makes no new partial store.
    let late = spec.write_shard(0, [0, 0, 0], ShardInput::Samples(vec![1.0; 8 * 8 * 4])).unwrap_err();
    assert!(late.to_string().contains("is gone from the partial store"), "{late}");
    assert!(!partial_path(&out).exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_object_store_url_is_refused_before_anything_is_written() {
    // The tasks write files into `out`: a URL would be a local folder named `s3:`, believed to be in the bucket.
    let dims = [8, 8, 8];
    for url in ["s3://scans/volume.zarr", "gs://scans/volume.zarr", "https://example.org/volume.zarr"] {
        let error = ShardImport::begin(info(dims, DType::U8), Path::new(url), &ImportOptions::default())
            .err()
            .unwrap_or_else(|| panic!("{url}: a distributed import into a URL began"));
        let message = error.to_string();
        assert!(message.contains("folder every worker sees") && message.contains(url), "{message}");
    }
    for folder in ["s3:", "gs:", "https:"] {
        assert!(!Path::new(folder).exists(), "a local folder {folder} was written");
    }
    // Credentials in a URL are not repeated.
    let error = ShardImport::begin(
        info(dims, DType::U8),
        Path::new("https://user:hunter2@h/v.zarr"),
        &ImportOptions::default(),
    )
    .err()
    .expect("a URL with credentials began");
    assert!(!error.to_string().contains("hunter2"), "{error}");
}
