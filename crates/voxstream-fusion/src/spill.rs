//! World chunks streamed to disk and back (seed 004 §8.6): a chunk far from the camera is written as one file and
//! dropped from memory; it is read back when a frame touches it again.
//!
//! A chunk file is `VXFC`, a format version, the chunk key, the brick count, then per brick its key, error, integrated
//! flag, sign and confidence bits, colour blocks and surface offset blocks, and a CRC-32 of everything before it. The
//! files are the fusion's own scratch space, but they are read back as untrusted input all the same: counts are checked
//! against the file's length before anything is allocated, keys must lie in the chunk, and a checksum mismatch is an
//! error, never a wrong brick. The thesis compresses colour pages with RLE + Huffman here; these files are not
//! compressed (bits are 128 bytes per brick; colours go as they are).

use std::io::Write;
use std::path::{Path, PathBuf};

use glam::IVec3;

use crate::brick::{BinaryBrick, Bits, ColourBlock, OffsetBlock};
use crate::brick_map::{chunk_of, CHUNK_BRICKS};
use crate::FusionError;

const MAGIC: &[u8; 4] = b"VXFC";
const VERSION: u32 = 2;
/// Key, error, flag, two bit sets, colour and offset block counts.
const BRICK_HEADER: usize = 12 + 4 + 1 + 128 + 2;
const COLOUR_BLOCK: usize = 1 + 64;

/// The file of chunk `chunk` in `dir`.
pub fn chunk_path(dir: &Path, chunk: IVec3) -> PathBuf {
    dir.join(format!("chunk_{}_{}_{}.vxfc", chunk.x, chunk.y, chunk.z))
}

fn file_error(path: &Path, message: impl std::fmt::Display) -> FusionError {
    FusionError::File { path: path.to_path_buf(), message: message.to_string() }
}

/// Writes `bricks` (all of chunk `chunk`) to its file, replacing an older one; written to a temporary name and
/// renamed, so a crash never leaves half a chunk under the real name.
pub fn write_chunk(dir: &Path, chunk: IVec3, bricks: &[(IVec3, BinaryBrick)]) -> Result<(), FusionError> {
    let mut bytes = Vec::with_capacity(28 + bricks.len() * (BRICK_HEADER + 2 * COLOUR_BLOCK));
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&VERSION.to_le_bytes());
    for c in chunk.to_array() {
        bytes.extend_from_slice(&c.to_le_bytes());
    }
    bytes.extend_from_slice(&(bricks.len() as u32).to_le_bytes());
    for (key, brick) in bricks {
        debug_assert_eq!(chunk_of(*key), chunk);
        for c in key.to_array() {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
        bytes.extend_from_slice(&brick.error.to_le_bytes());
        bytes.push(u8::from(brick.integrated));
        for bits in [&brick.inside, &brick.confident] {
            for w in bits.0 {
                bytes.extend_from_slice(&w.to_le_bytes());
            }
        }
        bytes.push(brick.colours.len() as u8);
        for block in &brick.colours {
            bytes.push(block.block);
            for c in block.rgb565 {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
        bytes.push(brick.offsets.len() as u8);
        for block in &brick.offsets {
            bytes.push(block.block);
            bytes.extend(block.offset.map(|o| o as u8));
            bytes.extend(block.weight);
        }
    }
    let crc = crc32fast::hash(&bytes);
    bytes.extend_from_slice(&crc.to_le_bytes());
    let path = chunk_path(dir, chunk);
    let temporary = path.with_extension("vxfc.partial");
    let mut file = std::fs::File::create(&temporary).map_err(|e| file_error(&temporary, e))?;
    file.write_all(&bytes).map_err(|e| file_error(&temporary, e))?;
    drop(file);
    std::fs::rename(&temporary, &path).map_err(|e| file_error(&path, e))
}

/// A little-endian reader over a chunk file's bytes that reports a short file instead of panicking.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
    path: &'a Path,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], FusionError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| file_error(self.path, "the chunk file is cut short"))?;
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }
    fn u8(&mut self) -> Result<u8, FusionError> {
        Ok(self.take(1)?[0])
    }
    fn u16(&mut self) -> Result<u16, FusionError> {
        Ok(u16::from_le_bytes(self.take(2)?.try_into().expect("2 bytes")))
    }
    fn u32(&mut self) -> Result<u32, FusionError> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().expect("4 bytes")))
    }
    fn i32(&mut self) -> Result<i32, FusionError> {
        Ok(i32::from_le_bytes(self.take(4)?.try_into().expect("4 bytes")))
    }
    fn u64(&mut self) -> Result<u64, FusionError> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into().expect("8 bytes")))
    }
    fn key(&mut self) -> Result<IVec3, FusionError> {
        Ok(IVec3::new(self.i32()?, self.i32()?, self.i32()?))
    }
}

/// Reads chunk `chunk`'s bricks back, verifying the file's checksum and structure.
pub fn read_chunk(dir: &Path, chunk: IVec3) -> Result<Vec<(IVec3, BinaryBrick)>, FusionError> {
    let path = chunk_path(dir, chunk);
    let bytes = std::fs::read(&path).map_err(|e| file_error(&path, format!("a streamed-out chunk is gone: {e}")))?;
    decode_chunk(&bytes, chunk, &path)
}

/// Decodes a chunk file's bytes (see [`read_chunk`]).
pub fn decode_chunk(bytes: &[u8], chunk: IVec3, path: &Path) -> Result<Vec<(IVec3, BinaryBrick)>, FusionError> {
    if bytes.len() < 28 {
        return Err(file_error(path, "not a chunk file: too short"));
    }
    let (body, crc) = bytes.split_at(bytes.len() - 4);
    if crc32fast::hash(body).to_le_bytes() != crc {
        return Err(file_error(path, "the chunk file's checksum does not match: it was damaged on disk"));
    }
    let mut r = Reader { bytes: body, at: 0, path };
    if r.take(4)? != MAGIC || r.u32()? != VERSION {
        return Err(file_error(path, "not a chunk file of this version"));
    }
    if r.key()? != chunk {
        return Err(file_error(path, format!("the file holds another chunk than {chunk}")));
    }
    let count = r.u32()? as usize;
    if count > (CHUNK_BRICKS as usize).pow(3) || count.saturating_mul(BRICK_HEADER) > body.len() {
        return Err(file_error(path, format!("the file claims {count} bricks, more than it can hold")));
    }
    let mut bricks = Vec::with_capacity(count);
    for _ in 0..count {
        let key = r.key()?;
        if chunk_of(key) != chunk {
            return Err(file_error(path, format!("brick {key} does not lie in chunk {chunk}")));
        }
        let error = f32::from_le_bytes(r.take(4)?.try_into().expect("4 bytes"));
        let integrated = r.u8()? != 0;
        let mut inside = Bits::default();
        let mut confident = Bits::default();
        for bits in [&mut inside, &mut confident] {
            for w in bits.0.iter_mut() {
                *w = r.u64()?;
            }
        }
        let blocks = r.u8()? as usize;
        if blocks > 16 {
            return Err(file_error(path, format!("brick {key} claims {blocks} colour blocks, more than 16")));
        }
        let mut colours = Vec::with_capacity(blocks);
        for _ in 0..blocks {
            let block = r.u8()?;
            let mut rgb565 = [0u16; 32];
            for c in rgb565.iter_mut() {
                *c = r.u16()?;
            }
            if block >= 16 || colours.last().is_some_and(|b: &ColourBlock| b.block >= block) {
                return Err(file_error(path, format!("brick {key}'s colour blocks are out of order")));
            }
            colours.push(ColourBlock { block, rgb565 });
        }
        let blocks = r.u8()? as usize;
        if blocks > 16 {
            return Err(file_error(path, format!("brick {key} claims {blocks} offset blocks, more than 16")));
        }
        let mut offsets = Vec::with_capacity(blocks);
        for _ in 0..blocks {
            let block = r.u8()?;
            let raw = r.take(32)?;
            let offset: [i8; 32] = std::array::from_fn(|i| raw[i] as i8);
            let weight: [u8; 32] = r.take(32)?.try_into().expect("32 bytes");
            if block >= 16 || offsets.last().is_some_and(|b: &OffsetBlock| b.block >= block) {
                return Err(file_error(path, format!("brick {key}'s offset blocks are out of order")));
            }
            offsets.push(OffsetBlock { block, offset, weight });
        }
        bricks.push((key, BinaryBrick { inside, confident, error, integrated, colours, offsets }));
    }
    if r.at != body.len() {
        return Err(file_error(path, "the chunk file has bytes after its last brick"));
    }
    Ok(bricks)
}

/// Deletes chunk `chunk`'s file (after it was read back); a failure only leaves a stale file, which the next
/// write of the chunk replaces.
pub fn remove_chunk(dir: &Path, chunk: IVec3) {
    let _ = std::fs::remove_file(chunk_path(dir, chunk));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<(IVec3, BinaryBrick)> {
        let mut a = BinaryBrick { error: 0.004, integrated: true, ..BinaryBrick::default() };
        a.inside.set(17, true);
        a.confident.set(17, true);
        a.set_colour(1, 2, 3, [200, 100, 50]);
        a.set_colour(7, 7, 7, [10, 20, 30]);
        a.set_offset(7, 7, 7, -0.25, 30.0);
        a.set_offset(0, 0, 0, 0.5, 3.0);
        let b = BinaryBrick::default();
        vec![(IVec3::new(-32, 5, 31), a), (IVec3::new(-1, 0, 0), b)]
    }

    #[test]
    fn chunks_round_trip() {
        let dir = std::env::temp_dir().join(format!("voxstream-spill-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let chunk = IVec3::new(-1, 0, 0);
        write_chunk(&dir, chunk, &sample()).unwrap();
        assert_eq!(read_chunk(&dir, chunk).unwrap(), sample());
        remove_chunk(&dir, chunk);
        assert!(matches!(read_chunk(&dir, chunk), Err(FusionError::File { .. })));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn damaged_or_forged_chunks_are_errors() {
        let dir = std::env::temp_dir().join(format!("voxstream-spill-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let chunk = IVec3::new(-1, 0, 0);
        write_chunk(&dir, chunk, &sample()).unwrap();
        let good = std::fs::read(chunk_path(&dir, chunk)).unwrap();
        let path = Path::new("x.vxfc");
        // Every single-byte flip is caught (by the checksum or the structure), never decoded into bricks.
        for at in 0..good.len() {
            let mut bad = good.clone();
            bad[at] ^= 0x10;
            assert!(decode_chunk(&bad, chunk, path).is_err(), "flip at {at}");
        }
        // Truncations too.
        for len in [0, 10, 27, good.len() - 1] {
            assert!(decode_chunk(&good[..len], chunk, path).is_err(), "cut at {len}");
        }
        // A forged count with a valid checksum is refused before allocating.
        let mut forged = good[..good.len() - 4].to_vec();
        forged[20..24].copy_from_slice(&u32::MAX.to_le_bytes());
        let crc = crc32fast::hash(&forged);
        forged.extend_from_slice(&crc.to_le_bytes());
        let message = decode_chunk(&forged, chunk, path).unwrap_err().to_string();
        assert!(message.contains("claims"), "{message}");
        // Another chunk's file under this chunk's name.
        assert!(decode_chunk(&good, IVec3::ZERO, path).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
