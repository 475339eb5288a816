//! Decoding one binary or appended `DataArray` to its bytes: the header, base64, and zlib blocks.
//!
//! Each function is given the bytes the array must decode to (`expected`, from what the reader knows of the array:
//! its extent or its point count, its components and type) and checks every size against them, with checked
//! arithmetic, before it allocates or inflates anything.

use std::io::Read;

use base64::Engine;

use crate::encoding::Encoding;

/// Why an array could not be decoded: one line naming the problem (the reader adds the file and the array).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ArrayError(pub String);

impl From<&str> for ArrayError {
    fn from(message: &str) -> ArrayError {
        ArrayError(message.to_string())
    }
}

impl From<String> for ArrayError {
    fn from(message: String) -> ArrayError {
        ArrayError(message)
    }
}

/// What a reader bounds its arrays by, and how its messages name where the expected size comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Bounds {
    /// What fixes the expected size, for messages ("the extent", "the point count").
    pub needed_by: &'static str,
    /// The most a compressed array may inflate, times its compressed bytes ([`crate::DEFLATE_MAX_RATIO`]).
    pub deflate_max_ratio: u64,
}

/// The header integer at byte `at` of `bytes`.
fn read_uint(bytes: &[u8], at: usize, e: Encoding) -> Result<u64, ArrayError> {
    let size = e.header_size();
    let b = at.checked_add(size).and_then(|end| bytes.get(at..end)).ok_or("truncated block header")?;
    let mut v = [0u8; 8];
    if e.big_endian {
        v[8 - size..].copy_from_slice(b);
        Ok(u64::from_be_bytes(v))
    } else {
        v[..size].copy_from_slice(b);
        Ok(u64::from_le_bytes(v))
    }
}

/// An uncompressed array: a byte count, then the bytes; the count must be `expected`.
fn uncompressed(all: &[u8], e: Encoding, expected: usize, bounds: &Bounds) -> Result<Vec<u8>, ArrayError> {
    let n = read_uint(all, 0, e)?;
    if n != expected as u64 {
        return Err(format!("the array's header says {n} bytes, {} needs {expected}", bounds.needed_by).into());
    }
    let hsize = e.header_size();
    hsize.checked_add(expected).and_then(|end| all.get(hsize..end)).map(<[u8]>::to_vec).ok_or_else(|| {
        format!("truncated data: {} bytes of the {expected} announced", all.len().saturating_sub(hsize)).into()
    })
}

fn base64_decode(text: &[u8]) -> Result<Vec<u8>, ArrayError> {
    base64::engine::general_purpose::STANDARD.decode(text).map_err(|e| format!("bad base64: {e}").into())
}

/// Characters of base64 that encode `bytes` bytes (padded).
fn base64_len(bytes: usize) -> Option<usize> {
    bytes.div_ceil(3).checked_mul(4)
}

/// Inline or appended base64, of exactly one array (what follows it in appended data is not decoded). Uncompressed,
/// the header and the data are one base64 run (as VTK writes them) or two (as some writers do: the header's run is
/// then padded); compressed, the block header and the blocks are two runs.
pub fn decode_base64_array(text: &[u8], e: Encoding, expected: usize, bounds: &Bounds) -> Result<Vec<u8>, ArrayError> {
    let hsize = e.header_size();
    let first_chars = 4 * hsize.div_ceil(3);
    let first_text = text.get(..first_chars).ok_or("truncated header")?;
    let too_long = || ArrayError::from("the array is longer than the file");
    if !e.compressed {
        let all = if first_text.contains(&b'=') {
            let mut all = base64_decode(first_text)?;
            if all.len() > hsize {
                // One padded run holding the header and a few bytes of data (an array of one or two bytes).
                return uncompressed(&all, e, expected, bounds);
            }
            let data_chars = base64_len(expected).ok_or_else(too_long)?;
            let data = first_chars.checked_add(data_chars).and_then(|end| text.get(first_chars..end));
            all.extend(base64_decode(data.ok_or("truncated data")?)?);
            all
        } else {
            let chars = hsize.checked_add(expected).and_then(base64_len).ok_or_else(too_long)?;
            base64_decode(text.get(..chars).ok_or("truncated data")?)?
        };
        return uncompressed(&all, e, expected, bounds);
    }
    let blocks = read_uint(&base64_decode(first_text)?, 0, e)?;
    let header_len = block_header_len(blocks, hsize, text.len())?;
    let header_chars = base64_len(header_len).ok_or_else(too_long)?;
    let header = base64_decode(text.get(..header_chars).ok_or("truncated header")?)?;
    let compressed = compressed_len(&header, blocks, e)?;
    let data_chars = base64_len(compressed).ok_or_else(too_long)?;
    let data = header_chars.checked_add(data_chars).and_then(|end| text.get(header_chars..end));
    let data = base64_decode(data.ok_or("truncated compressed data")?)?;
    inflate_blocks(&header, &data, blocks, e, expected, bounds)
}

/// Appended raw bytes of one array (and whatever follows it).
pub fn decode_raw_array(bytes: &[u8], e: Encoding, expected: usize, bounds: &Bounds) -> Result<Vec<u8>, ArrayError> {
    if !e.compressed {
        return uncompressed(bytes, e, expected, bounds);
    }
    let blocks = read_uint(bytes, 0, e)?;
    let header_len = block_header_len(blocks, e.header_size(), bytes.len())?;
    let (header, data) = bytes.split_at_checked(header_len).ok_or("truncated header")?;
    inflate_blocks(header, data, blocks, e, expected, bounds)
}

/// Bytes of a `[blocks, block size, last block size, compressed sizes…]` header, which must fit in `available`.
fn block_header_len(blocks: u64, hsize: usize, available: usize) -> Result<usize, ArrayError> {
    blocks
        .checked_add(3)
        .and_then(|n| n.checked_mul(hsize as u64))
        .filter(|&n| n <= available as u64)
        .map(|n| n as usize)
        .ok_or_else(|| format!("{blocks} compressed blocks announced, more than the data can hold").into())
}

/// The byte offset of block `block`'s compressed size in a block header.
fn size_entry(block: u64, hsize: usize) -> Result<usize, ArrayError> {
    let at = usize::try_from(block).ok().and_then(|b| b.checked_add(3)?.checked_mul(hsize));
    Ok(at.ok_or("truncated block header")?)
}

/// The sum of the compressed block sizes of a block header.
fn compressed_len(header: &[u8], blocks: u64, e: Encoding) -> Result<usize, ArrayError> {
    let mut total = 0u64;
    for block in 0..blocks {
        let size = read_uint(header, size_entry(block, e.header_size())?, e)?;
        total = total.checked_add(size).ok_or("compressed block sizes overflow")?;
    }
    Ok(usize::try_from(total).map_err(|_| "compressed block sizes overflow")?)
}

/// zlib blocks after the `[blocks, block size, last block size, compressed sizes…]` header. The sizes must add up to
/// the `expected` bytes before anything is inflated, and each block must inflate to exactly its size.
fn inflate_blocks(
    header: &[u8],
    data: &[u8],
    blocks: u64,
    e: Encoding,
    expected: usize,
    bounds: &Bounds,
) -> Result<Vec<u8>, ArrayError> {
    let hsize = e.header_size();
    let block_size = read_uint(header, hsize, e)?;
    let last_size = match read_uint(header, 2 * hsize, e)? {
        0 => block_size,
        n => n,
    };
    let total = match blocks {
        0 => Some(0),
        n => block_size.checked_mul(n - 1).and_then(|t| t.checked_add(last_size)),
    };
    let needed_by = bounds.needed_by;
    if last_size > block_size || total != Some(expected as u64) {
        return Err(format!(
            "the compression header ({blocks} blocks of {block_size} bytes, the last {last_size}) does not add up to \
             the {expected} bytes {needed_by} needs"
        )
        .into());
    }
    let ratio = bounds.deflate_max_ratio;
    if expected as u64 > (data.len() as u64).saturating_mul(ratio) {
        return Err(format!(
            "{} compressed bytes cannot inflate to the {expected} bytes {needed_by} needs (deflate expands at most \
             {ratio}:1)",
            data.len()
        )
        .into());
    }
    let mut out = Vec::with_capacity(expected);
    let mut at = 0usize;
    for block in 0..blocks {
        let size = read_uint(header, size_entry(block, hsize)?, e)?;
        let chunk = usize::try_from(size)
            .ok()
            .and_then(|size| data.get(at..at.checked_add(size)?))
            .ok_or_else(|| format!("compressed block {block} ({size} bytes) runs past the end of the data"))?;
        let want = if block + 1 == blocks { last_size } else { block_size };
        let before = out.len();
        // One byte more than announced is enough to tell a block that inflates too far.
        flate2::read::ZlibDecoder::new(chunk)
            .take(want.saturating_add(1))
            .read_to_end(&mut out)
            .map_err(|e| format!("corrupt zlib block {block}: {e}"))?;
        let got = (out.len() - before) as u64;
        if got != want {
            let got = if got > want { format!("more than {want}") } else { got.to_string() };
            return Err(format!("zlib block {block} inflates to {got} bytes, its header says {want}").into());
        }
        at += chunk.len();
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use super::*;
    use crate::DEFLATE_MAX_RATIO;

    const BOUNDS: Bounds = Bounds { needed_by: "the test", deflate_max_ratio: DEFLATE_MAX_RATIO };

    fn b64(bytes: &[u8]) -> Vec<u8> {
        base64::engine::general_purpose::STANDARD.encode(bytes).into_bytes()
    }

    fn zlib(bytes: &[u8]) -> Vec<u8> {
        let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        e.write_all(bytes).unwrap();
        e.finish().unwrap()
    }

    /// Header integers in `e`'s width and byte order.
    fn header(values: &[u64], e: Encoding) -> Vec<u8> {
        let mut out = Vec::new();
        for &v in values {
            match (e.header_u64, e.big_endian) {
                (true, false) => out.extend(v.to_le_bytes()),
                (true, true) => out.extend(v.to_be_bytes()),
                (false, false) => out.extend((v as u32).to_le_bytes()),
                (false, true) => out.extend((v as u32).to_be_bytes()),
            }
        }
        out
    }

    /// `data` as zlib blocks of `block` bytes: the block header and the blocks.
    fn blocked(data: &[u8], block: usize, e: Encoding) -> (Vec<u8>, Vec<u8>) {
        let blocks: Vec<Vec<u8>> = data.chunks(block).map(zlib).collect();
        let last = data.len() - (blocks.len() - 1) * block;
        let mut entries = vec![blocks.len() as u64, block as u64, if last == block { 0 } else { last as u64 }];
        entries.extend(blocks.iter().map(|b| b.len() as u64));
        (header(&entries, e), blocks.concat())
    }

    fn data() -> Vec<u8> {
        (0..1000u32).flat_map(|i| (i * 7).to_le_bytes()).collect()
    }

    #[test]
    fn a_base64_array_round_trips_in_one_run_or_two() {
        let data = data();
        for e in [Encoding::default(), Encoding { big_endian: true, header_u64: true, compressed: false }] {
            let count = header(&[data.len() as u64], e);
            let one_run = b64(&[count.clone(), data.clone()].concat());
            let two_runs = [b64(&count), b64(&data)].concat();
            for text in [one_run, two_runs] {
                // What follows the array (another array's base64) is not decoded.
                let text = [text, b"QUJD".to_vec()].concat();
                assert_eq!(decode_base64_array(&text, e, data.len(), &BOUNDS).unwrap(), data);
            }
            let raw = [count, data.clone()].concat();
            assert_eq!(decode_raw_array(&raw, e, data.len(), &BOUNDS).unwrap(), data);
            let wrong = decode_raw_array(&raw, e, data.len() + 1, &BOUNDS).unwrap_err();
            assert_eq!(wrong.to_string(), "the array's header says 4000 bytes, the test needs 4001");
        }
    }

    /// Arrays of one or two bytes: in one run, the header's padded characters hold data too (a 1×1×1 volume of
    /// bytes); in two, the header's run is padded alone. Both read.
    #[test]
    fn tiny_arrays_read_in_one_run_or_two() {
        for e in [Encoding::default(), Encoding { big_endian: false, header_u64: true, compressed: false }] {
            for data in [vec![7u8], vec![7u8, 9]] {
                let count = header(&[data.len() as u64], e);
                let one_run = b64(&[count.clone(), data.clone()].concat());
                let two_runs = [b64(&count), b64(&data)].concat();
                for text in [one_run, two_runs] {
                    let decoded = decode_base64_array(&text, e, data.len(), &BOUNDS);
                    assert_eq!(decoded.unwrap(), data, "{}", String::from_utf8_lossy(&text));
                }
            }
        }
    }

    #[test]
    fn a_zlib_blocked_array_round_trips_raw_and_base64() {
        let data = data();
        for header_u64 in [false, true] {
            let e = Encoding { header_u64, compressed: true, ..Encoding::default() };
            for block in [data.len(), 1024, 999] {
                let (head, blocks) = blocked(&data, block, e);
                let raw = [head.clone(), blocks.clone()].concat();
                assert_eq!(decode_raw_array(&raw, e, data.len(), &BOUNDS).unwrap(), data);
                let text = [b64(&head), b64(&blocks)].concat();
                assert_eq!(decode_base64_array(&text, e, data.len(), &BOUNDS).unwrap(), data);
            }
        }
    }

    #[test]
    fn a_truncated_block_header_is_an_error() {
        let data = data();
        let e = Encoding { compressed: true, ..Encoding::default() };
        let (head, blocks) = blocked(&data, 1024, e);
        for cut in 0..head.len() {
            let error = decode_raw_array(&head[..cut], e, data.len(), &BOUNDS).unwrap_err().to_string();
            assert!(
                error.contains("truncated block header") || error.contains("more than the data can hold"),
                "{cut}: {error}"
            );
        }
        // Every cut of the blocks too.
        let raw = [head, blocks].concat();
        for cut in 0..raw.len() {
            assert!(decode_raw_array(&raw[..cut], e, data.len(), &BOUNDS).is_err(), "{cut}");
        }
        // A block count whose header would not fit in memory, let alone the data.
        let huge = header(&[u64::MAX, 4, 4], Encoding { header_u64: true, ..e });
        let error = decode_raw_array(&huge, Encoding { header_u64: true, ..e }, 4, &BOUNDS).unwrap_err();
        assert_eq!(error.to_string(), format!("{} compressed blocks announced, more than the data can hold", u64::MAX));
    }

    #[test]
    fn a_block_claiming_more_than_the_bound_is_an_error() {
        // A consistent header announcing 12 MB from 10 compressed bytes is refused before inflating.
        let e = Encoding { compressed: true, ..Encoding::default() };
        let bomb = [header(&[1, 12_000_000, 0, 10], e), vec![0x78, 0x9c, 0, 0, 0, 0, 0, 0, 0, 0]].concat();
        assert_eq!(
            decode_raw_array(&bomb, e, 12_000_000, &BOUNDS).unwrap_err().to_string(),
            "10 compressed bytes cannot inflate to the 12000000 bytes the test needs (deflate expands at most 1032:1)"
        );
        // A block inflating past its announced size.
        let data = data();
        let block = zlib(&data);
        let lying = [header(&[1, 100, 0, block.len() as u64], e), block].concat();
        assert_eq!(
            decode_raw_array(&lying, e, 100, &BOUNDS).unwrap_err().to_string(),
            "zlib block 0 inflates to more than 100 bytes, its header says 100"
        );
        // Sizes that do not add up to what is expected.
        let error = decode_raw_array(&lying, e, 101, &BOUNDS).unwrap_err().to_string();
        assert!(error.contains("does not add up to the 101 bytes the test needs"), "{error}");
    }
}
