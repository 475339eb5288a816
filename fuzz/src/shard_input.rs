//! The `store_shards` fuzz target's driver: a small native store whose one level-0 shard the input edits (the whole
//! file, its index, or one brick's bytes, with the CRC-32Cs that guard them recomputed), then read whole. Shared by
//! the fuzz crate and the main workspace's fuzz regression test (included by path, so both run this very code).

use std::path::{Path, PathBuf};

use voxstream_store::formats::{open_volume, Endian, RawLayout};
use voxstream_store::{import_volume, DType, ImportOptions, VolumeInfo};

/// CRC-32C (Castagnoli), which the shard index and the bricks' `crc32c` codec end in.
pub fn crc32c(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &byte in bytes {
        crc ^= byte as u32;
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0x82f6_3b78 } else { crc >> 1 };
        }
    }
    !crc
}

/// Bricks in the template store's one level-0 shard (16×16×8 u16 samples, bricks of 8, 2×2 bricks per shard).
pub const SHARD_BRICKS: usize = 4;

/// The template store of the `store_shards` target (made in `dir` once per process) and its level-0 shard's bytes.
fn shard_template(dir: &Path) -> Option<&'static (PathBuf, Vec<u8>)> {
    static TEMPLATE: std::sync::OnceLock<Option<(PathBuf, Vec<u8>)>> = std::sync::OnceLock::new();
    TEMPLATE
        .get_or_init(|| {
            let raw = dir.join("shards.raw");
            let samples: Vec<u8> = (0..16 * 16 * 8u32).flat_map(|i| ((i * 37 % 1000) as u16).to_le_bytes()).collect();
            std::fs::write(&raw, samples).ok()?;
            let info = VolumeInfo {
                dims: [16, 16, 8],
                dtype: DType::U16,
                spacing: [1.0; 3],
                origin: [0.0; 3],
                unit: None,
                orientation: None,
            };
            let layout = RawLayout { info, file_type: None, endian: Endian::Little, header_bytes: 0 };
            let mut source = open_volume(&raw, Some(&layout)).ok()?;
            let store = dir.join("shards.zarr");
            let options = ImportOptions { brick_size: 8, shard_bricks: 2, overwrite: true, ..ImportOptions::default() };
            import_volume(source.as_mut(), &store, &options, &mut |_, _| {}).ok()?;
            let shard = std::fs::read(store.join("0/c/0/0/0")).ok()?;
            Some((store, shard))
        })
        .as_ref()
}

/// The template shard edited by a fuzz input: the first byte picks what the rest replaces, with the CRC-32Cs that
/// guard it recomputed so that the bytes reach the decoders: 0, the whole shard file; 1, the index's
/// `(offset, nbytes)` pairs; 2, brick 0's stored bytes (its zstd frame, then its CRC-32C).
pub fn edited_shard(template: &[u8], data: &[u8]) -> Vec<u8> {
    let index_len = SHARD_BRICKS * 16;
    let start = template.len() - index_len - 4;
    let (bricks, index) = (&template[..start], &template[start..start + index_len]);
    let with_index = |bricks: &[u8], index: &[u8]| {
        let mut out = bricks.to_vec();
        out.extend(index);
        out.extend(crc32c(index).to_le_bytes());
        out
    };
    match data.split_first() {
        Some((mode, rest)) if mode % 3 == 1 => {
            let mut forged = index.to_vec();
            forged.iter_mut().zip(rest).for_each(|(b, r)| *b = *r);
            with_index(bricks, &forged)
        }
        Some((mode, rest)) if mode % 3 == 2 => {
            let mut out = bricks.to_vec();
            let offset = out.len() as u64;
            out.extend(rest);
            out.extend(crc32c(rest).to_le_bytes());
            let mut entries = index.to_vec();
            entries[..8].copy_from_slice(&offset.to_le_bytes());
            entries[8..16].copy_from_slice(&(rest.len() as u64 + 4).to_le_bytes());
            with_index(&out, &entries)
        }
        Some((_, rest)) => rest.to_vec(),
        None => template.to_vec(),
    }
}

/// Writes the edited shard into the template store (made in `dir` on the first call) and reads level 0 whole, as
/// `render --in-memory` would. Returns whether the input reached the reader (the template store could be made).
pub fn read_shard_input(dir: &Path, data: &[u8]) -> bool {
    let Some((store, template)) = shard_template(dir) else { return false };
    if std::fs::write(store.join("0/c/0/0/0"), edited_shard(template, data)).is_err() {
        return false;
    }
    if let Ok(reader) = voxstream_store::StoreReader::open(store) {
        let _ = reader.read_region(0, [0; 3], [16, 16, 8]);
    }
    true
}
