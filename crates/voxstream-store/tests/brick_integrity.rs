//! Bricks that prove themselves (issue 41, items 1, 2, 5 and 6): a store's shards edited byte by byte (a forged
//! index entry with its CRC32C recomputed, a decompression bomb in place of a brick, a single-bit flip, a FIFO in
//! place of a shard) must read as an error naming the problem, never an abort, a hang, a huge allocation or silently
//! wrong samples; stores written before bricks carried checksums stay readable.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use voxstream_store::formats::{open_volume, Endian, RawLayout};
use voxstream_store::{import_volume, DType, ImportOptions, StoreReader, VolumeInfo};

/// 32×32×16 u16 samples: bricks of 8, two by two bricks per shard (four bricks, an index of 4 × 16 + 4 bytes).
const DIMS: [u64; 3] = [32, 32, 16];
const BRICK: u64 = 8;
const BRICKS_PER_SHARD: usize = 4;
/// Level 0's first shard: bricks (0..2, 0..2, 0) of z row 0.
const SHARD: &str = "0/c/0/0/0";

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-bricks-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Noisy samples in 100..1100 (so that zstd keeps literals, where a flipped bit changes a sample silently).
fn samples() -> Vec<u16> {
    let mut state = 0x9e37_79b9_u32;
    (0..DIMS.iter().product::<u64>())
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            100 + (state % 1000) as u16
        })
        .collect()
}

/// Imports [`samples`] into `dir/NAME`.
fn import(dir: &Path, name: &str, brick_checksums: bool) -> PathBuf {
    let raw = dir.join("volume.raw");
    let bytes: Vec<u8> = samples().iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(&raw, bytes).unwrap();
    let info = VolumeInfo {
        dims: DIMS,
        dtype: DType::U16,
        spacing: [1.0; 3],
        origin: [0.0; 3],
        unit: None,
        orientation: None,
    };
    let layout = RawLayout { info, file_type: None, endian: Endian::Little, header_bytes: 0 };
    let mut source = open_volume(&raw, Some(&layout)).unwrap();
    let store = dir.join(name);
    let options = ImportOptions { brick_size: BRICK, shard_bricks: 2, brick_checksums, ..ImportOptions::default() };
    import_volume(source.as_mut(), &store, &options, &mut |_, _| {}).unwrap();
    store
}

/// CRC32C (Castagnoli), as the Zarr `crc32c` codec and the shard index use it.
fn crc32c(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &byte in bytes {
        crc ^= byte as u32;
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0x82f6_3b78 } else { crc >> 1 };
        }
    }
    !crc
}

/// A shard file: its bytes and its index of (offset, length) per brick (at the end, with its CRC32C).
struct Shard {
    bytes: Vec<u8>,
    index: Vec<(u64, u64)>,
}

impl Shard {
    fn read(path: &Path) -> Shard {
        let bytes = std::fs::read(path).unwrap();
        let index_start = bytes.len() - BRICKS_PER_SHARD * 16 - 4;
        let word = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
        let index =
            (0..BRICKS_PER_SHARD).map(|i| (word(index_start + 16 * i), word(index_start + 16 * i + 8))).collect();
        let stored = u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().unwrap());
        assert_eq!(stored, crc32c(&bytes[index_start..bytes.len() - 4]), "the test reads the index wrongly");
        Shard { bytes: bytes[..index_start].to_vec(), index }
    }

    /// Writes the shard back with its index and a recomputed index CRC32C (as a forger would).
    fn write(&self, path: &Path) {
        let mut out = self.bytes.clone();
        let index: Vec<u8> =
            self.index.iter().flat_map(|(o, n)| o.to_le_bytes().into_iter().chain(n.to_le_bytes())).collect();
        out.extend(&index);
        out.extend(crc32c(&index).to_le_bytes());
        std::fs::write(path, out).unwrap();
    }

    /// The stored bytes of brick `i` (its zstd frame and CRC32C).
    fn brick(&self, i: usize) -> &[u8] {
        let (offset, length) = self.index[i];
        &self.bytes[offset as usize..(offset + length) as usize]
    }
}

/// Level 0's samples of brick `(bx, by, 0)`.
fn read_brick(reader: &StoreReader, bx: u64, by: u64) -> Result<Vec<f32>, String> {
    reader.read_region(0, [bx * BRICK, by * BRICK, 0], [BRICK; 3]).map_err(|e| e.to_string())
}

#[test]
fn a_single_bit_flip_that_zstd_and_the_min_max_miss_is_caught_by_the_crc32c() {
    let dir = scratch("flip");
    let store = import(&dir, "flip.zarr", true);
    let path = store.join(SHARD);
    let mut shard = Shard::read(&path);
    let stored = shard.brick(0).to_vec();
    let (frame, crc) = stored.split_at(stored.len() - 4);
    assert_eq!(u32::from_le_bytes(crc.try_into().unwrap()), crc32c(frame), "each brick ends in its CRC32C");
    // A flip that a reader without the checksum takes for good data: the frame still decodes to a brick of the
    // same size and the same min/max (which the reader checks), but other samples.
    let decode = |frame: &[u8]| zstd::decode_all(frame).ok();
    let range = |bytes: &[u8]| {
        let v: Vec<u16> = bytes.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
        (v.iter().min().copied(), v.iter().max().copied())
    };
    let original = decode(frame).unwrap();
    let silent = (0..frame.len() * 8).find(|&bit| {
        let mut flipped = frame.to_vec();
        flipped[bit / 8] ^= 1 << (bit % 8);
        decode(&flipped).is_some_and(|d| d.len() == original.len() && d != original && range(&d) == range(&original))
    });
    let bit = silent.expect("no flip of this brick passes zstd and the min/max: the test lost its subject");
    let offset = shard.index[0].0 as usize;
    shard.bytes[offset + bit / 8] ^= 1 << (bit % 8);
    shard.write(&path);

    let reader = StoreReader::open(&store).unwrap();
    let error = read_brick(&reader, 0, 0).unwrap_err();
    assert!(error.contains("CRC32C does not match") && error.contains("level 0"), "{error}");
    // The shard's other bricks are intact.
    let neighbour = read_brick(&reader, 1, 0).unwrap();
    let expected: Vec<f32> = (0..BRICK)
        .flat_map(|z| (0..BRICK).flat_map(move |y| (BRICK..2 * BRICK).map(move |x| (x, y, z))))
        .map(|(x, y, z)| samples()[((z * DIMS[1] + y) * DIMS[0] + x) as usize] as f32)
        .collect();
    assert_eq!(neighbour, expected);
}

#[test]
fn stores_written_without_brick_checksums_stay_readable() {
    let dir = scratch("old");
    let expected: Vec<f32> = samples().iter().map(|&v| v as f32).collect();
    for (name, brick_checksums) in [("old.zarr", false), ("new.zarr", true)] {
        let store = import(&dir, name, brick_checksums);
        let metadata = std::fs::read_to_string(store.join("0/zarr.json")).unwrap();
        assert!(metadata.contains("crc32c\""), "{name}: the index always carries its CRC32C");
        let codecs = metadata.matches("\"crc32c\"").count();
        assert_eq!(codecs, if brick_checksums { 2 } else { 1 }, "{name}: {metadata}");
        let reader = StoreReader::open(&store).unwrap();
        assert_eq!(reader.read_region(0, [0; 3], DIMS).unwrap(), expected, "{name}");
    }
}

#[test]
fn forged_shard_index_entries_are_errors_before_any_allocation() {
    let dir = scratch("forged");
    let store = import(&dir, "forged.zarr", true);
    let path = store.join(SHARD);
    let original = Shard::read(&path);
    // A brick of 2^62 bytes (the allocation that aborted every reader), one that wraps past u64::MAX, and one that
    // lies within the file but is longer than any brick can be encoded (8³ u16: a 1 KiB frame at most, plus slack).
    let file_bytes = original.bytes.len() as u64;
    let forgeries = [
        (8, 1u64 << 62, "past the end of the file"),
        (u64::MAX - 2, 16, "past the end of the file"),
        (0, file_bytes, "more than the"),
    ];
    for (offset, length, needle) in forgeries {
        let mut shard = Shard { bytes: original.bytes.clone(), index: original.index.clone() };
        shard.index[0] = (offset, length);
        shard.write(&path);
        let reader = StoreReader::open(&store).unwrap();
        let error = read_brick(&reader, 0, 0).unwrap_err();
        assert!(error.contains(needle) && error.contains(SHARD), "{offset}+{length}: {error}");
        assert!(read_brick(&reader, 1, 0).is_ok(), "{offset}+{length}: the other bricks read");
    }
}

/// A zstd frame of `bytes` zeros, written in pieces (the test never holds the inflated brick either).
fn zstd_bomb(bytes: usize) -> Vec<u8> {
    let mut encoder = zstd::stream::write::Encoder::new(Vec::new(), 1).unwrap();
    let zeros = vec![0u8; 1 << 20];
    for _ in 0..bytes / zeros.len() {
        encoder.write_all(&zeros).unwrap();
    }
    encoder.finish().unwrap()
}

#[test]
fn a_brick_that_inflates_past_its_size_stops_at_it() {
    let dir = scratch("bomb");
    let store = import(&dir, "bomb.zarr", true);
    let path = store.join(SHARD);
    let mut shard = Shard::read(&path);
    // 16 MiB of zeros where the brick holds 1 KiB, with a valid CRC32C (a checksum proves integrity, not intent),
    // small enough on disk to pass as a brick's bytes (at most a 1 KiB zstd frame and slack).
    let mut bomb = zstd_bomb(16 << 20);
    bomb.extend(crc32c(&bomb).to_le_bytes());
    assert!(bomb.len() < 1024, "the bomb is {} bytes on disk, more than a brick can be", bomb.len());
    shard.index[0] = (shard.bytes.len() as u64, bomb.len() as u64);
    shard.bytes.extend(&bomb);
    shard.write(&path);
    let reader = StoreReader::open(&store).unwrap();
    let error = read_brick(&reader, 0, 0).unwrap_err();
    assert!(error.contains("inflates past the 1024 bytes"), "{error}");
}

#[test]
fn foreign_zarr_v2_chunks_that_inflate_past_their_size_stop_at_it() {
    let dir = scratch("foreign-bomb");
    let bomb = zstd_bomb(64 << 20);
    let mut gzip_bomb = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    let zeros = vec![0u8; 1 << 20];
    for _ in 0..64 {
        gzip_bomb.write_all(&zeros).unwrap();
    }
    let gzip_bomb = gzip_bomb.finish().unwrap();
    for (compressor, chunk) in [(r#"{"id": "zstd", "level": 1}"#, bomb), (r#"{"id": "gzip", "level": 1}"#, gzip_bomb)] {
        let store = dir.join(format!("{}.zarr", if compressor.contains("zstd") { "zstd" } else { "gzip" }));
        std::fs::create_dir_all(store.join("0")).unwrap();
        std::fs::write(store.join(".zgroup"), r#"{"zarr_format": 2}"#).unwrap();
        let attributes = r#"{"multiscales": [{"version": "0.4", "datasets": [{"path": "0"}]}]}"#;
        std::fs::write(store.join(".zattrs"), attributes).unwrap();
        let array = format!(
            r#"{{"zarr_format": 2, "shape": [32, 32, 32], "chunks": [32, 32, 32], "dtype": "<u2",
                "compressor": {compressor}, "fill_value": 0, "order": "C", "filters": null}}"#
        );
        std::fs::write(store.join("0/.zarray"), array).unwrap();
        std::fs::write(store.join("0/0.0.0"), chunk).unwrap();
        // Opening reads the coarsest dataset for the value range: the chunk of 64 KiB inflating to 64 MiB.
        let error = StoreReader::open(&store).err().map(|e| e.to_string()).expect("a bomb opened as a store");
        assert!(error.contains("inflates past the 65536 bytes"), "{compressor}: {error}");
    }
}

#[test]
fn a_fifo_in_place_of_a_shard_is_refused_not_waited_on() {
    let dir = scratch("fifo");
    let store = import(&dir, "fifo.zarr", true);
    let path = store.join(SHARD);
    std::fs::remove_file(&path).unwrap();
    let made = std::process::Command::new("mkfifo").arg(&path).status().expect("mkfifo");
    assert!(made.success(), "mkfifo failed");
    let reader = StoreReader::open(&store).unwrap();
    // Opening a FIFO for reading waits for a writer: read on a thread, so that a regression fails the test rather
    // than hanging it (the bound is a hang guard, generous beyond any read of four bricks).
    let (sender, receiver) = mpsc::channel();
    std::thread::spawn(move || sender.send(read_brick(&reader, 0, 0)));
    let result = receiver.recv_timeout(Duration::from_secs(60)).expect("the read blocked on the FIFO");
    let error = result.unwrap_err();
    assert!(error.contains("not a regular file") && error.contains(SHARD), "{error}");
}
