//! A DICOM file's element lengths, checked against the bytes that hold them before dicom-rs reads the file.
//!
//! dicom-rs allocates, and zeroes, each value by the length its header declares: a 500-byte file declaring a 3.7 GB
//! element made the importer touch 3.6 GB before failing (found by the `import_dicom` fuzz target). This walk reads
//! only the element headers (explicit or implicit VR, little or big endian, sequences and items of defined or
//! undefined length, deflated data sets inflated on the way) and refuses any length that reaches past what holds it,
//! so that what dicom-rs then allocates is bounded by the file (a deflated data set: by deflate's largest expansion).

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

/// Deflate's largest expansion (a 258-byte match from 2 bits), as for `.npz` and `.vti`.
const MAX_INFLATE: u64 = 1032;

/// Nesting deeper than this is refused (a sequence in an item in a sequence …).
const MAX_DEPTH: usize = 32;

/// Value representations whose explicit-VR header has a 2-byte length; every other one (and an unknown one, read as
/// UN, as dicom-rs reads it) has 2 reserved bytes and a 4-byte length.
const SHORT_VRS: [&[u8; 2]; 21] = [
    b"AE", b"AS", b"AT", b"CS", b"DA", b"DS", b"DT", b"FL", b"FD", b"IS", b"LO", b"LT", b"PN", b"SH", b"SL", b"SS",
    b"ST", b"TM", b"UI", b"UL", b"US",
];

const UNDEFINED: u32 = 0xFFFF_FFFF;

/// A source whose values can be passed over: a file seeks (lengths are checked against its size before), an
/// inflating stream reads through.
trait Skip: Read {
    fn skip_bytes(&mut self, n: u64) -> std::io::Result<u64>;
}

impl Skip for BufReader<File> {
    fn skip_bytes(&mut self, n: u64) -> std::io::Result<u64> {
        self.seek_relative(i64::try_from(n).unwrap_or(i64::MAX)).map(|()| n)
    }
}

impl Skip for &[u8] {
    fn skip_bytes(&mut self, n: u64) -> std::io::Result<u64> {
        let n = (n as usize).min(self.len());
        *self = &self[n..];
        Ok(n as u64)
    }
}

impl<R: Read> Skip for flate2::read::DeflateDecoder<R> {
    fn skip_bytes(&mut self, n: u64) -> std::io::Result<u64> {
        std::io::copy(&mut self.take(n), &mut std::io::sink())
    }
}

struct Walk<R: Skip> {
    from: R,
    /// Bytes read so far.
    at: u64,
    /// The most bytes the source can hold.
    end: u64,
    explicit: bool,
    big: bool,
    /// An item tag was read by [`Walk::begins_with_item`] and its item is next.
    pending_item: bool,
}

impl<R: Skip> Walk<R> {
    fn bytes<const N: usize>(&mut self) -> Result<Option<[u8; N]>, String> {
        let mut b = [0u8; N];
        let mut filled = 0;
        while filled < N {
            match self.from.read(&mut b[filled..]) {
                Ok(0) if filled == 0 => return Ok(None),
                Ok(0) => return Err(format!("ends inside an element header at byte {}", self.at + filled as u64)),
                Ok(n) => filled += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e.to_string()),
            }
        }
        self.at += N as u64;
        Ok(Some(b))
    }

    fn u16(&self, b: [u8; 2]) -> u16 {
        if self.big {
            u16::from_be_bytes(b)
        } else {
            u16::from_le_bytes(b)
        }
    }

    fn u32(&self, b: [u8; 4]) -> u32 {
        if self.big {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        }
    }

    fn skip(&mut self, n: u64) -> Result<(), String> {
        let skipped = self.from.skip_bytes(n).map_err(|e| e.to_string())?;
        self.at += skipped;
        if skipped < n {
            return Err(format!("ends {} bytes into a value of {n}", skipped));
        }
        Ok(())
    }

    fn header<const N: usize>(&mut self) -> Result<[u8; N], String> {
        self.bytes::<N>()?.ok_or_else(|| format!("ends inside an element header at byte {}", self.at))
    }

    /// The bytes left before `limit` (a defined length's end) or the source's end.
    fn left(&self, limit: Option<u64>) -> u64 {
        limit.unwrap_or(self.end).min(self.end).saturating_sub(self.at)
    }

    /// A data set's elements until `limit` (a defined length's end), an item delimiter (an undefined-length item's
    /// end), or the source's end.
    fn elements(&mut self, limit: Option<u64>, depth: usize, meta: bool) -> Result<(), String> {
        if depth > MAX_DEPTH {
            return Err(format!("sequences nested deeper than {MAX_DEPTH}"));
        }
        loop {
            if limit.is_some_and(|l| self.at >= l) {
                return Ok(());
            }
            let Some(tag) = self.bytes::<4>()? else {
                return if depth > 0 { Err("ends inside a sequence".into()) } else { Ok(()) };
            };
            let (group, element) = (self.u16([tag[0], tag[1]]), self.u16([tag[2], tag[3]]));
            if group == 0xFFFE {
                self.header::<4>()?;
                return match element {
                    0xE00D if limit.is_none() && depth > 0 => Ok(()),
                    _ => Err(format!("unexpected (FFFE,{element:04X}) among a data set's elements")),
                };
            }
            if meta && group != 0x0002 {
                return Err(format!("({group:04X},{element:04X}) inside the file meta group"));
            }
            let (vr, length) = if self.explicit {
                let vr = self.header::<2>()?;
                if !SHORT_VRS.contains(&&vr) {
                    self.header::<2>()?;
                    let b = self.header::<4>()?;
                    (Some(vr), self.u32(b))
                } else {
                    let b = self.header::<2>()?;
                    (Some(vr), self.u16(b) as u32)
                }
            } else {
                let b = self.header::<4>()?;
                (None, self.u32(b))
            };
            let pixel_data = (group, element) == (0x7FE0, 0x0010);
            if length == UNDEFINED {
                match vr {
                    _ if pixel_data || matches!(vr, Some(v) if &v == b"OB" || &v == b"OW") => {
                        self.items(None, depth + 1, true)?
                    }
                    None => self.items(None, depth + 1, false)?,
                    Some(v) if &v == b"SQ" => self.items(None, depth + 1, false)?,
                    Some(_) => {
                        // Undefined-length UN (or a VR dicom-rs does not know, which it reads as UN) holds an
                        // implicit VR little endian sequence.
                        let (explicit, big) = (self.explicit, self.big);
                        (self.explicit, self.big) = (false, false);
                        let walked = self.items(None, depth + 1, false);
                        (self.explicit, self.big) = (explicit, big);
                        walked?
                    }
                }
                continue;
            }
            if length as u64 > self.left(limit) {
                return Err(format!(
                    "element ({group:04X},{element:04X}) declares {length} bytes, more than the {} left",
                    self.left(limit)
                ));
            }
            let end = self.at + length as u64;
            let is_sequence = match vr {
                Some(v) => &v == b"SQ",
                // Implicit VR: a value that begins with an item tag is a sequence.
                None => length >= 8 && !pixel_data && self.begins_with_item()?,
            };
            if is_sequence {
                self.items(Some(end), depth + 1, false)?;
            } else {
                self.skip(end - self.at)?;
            }
        }
    }

    /// Reads 4 bytes of a value ending at `end` and says whether they are an item tag; the bytes are consumed, so
    /// the caller's walk of the items (or the skip of the value) goes on from there: [`Walk::items`] is told.
    fn begins_with_item(&mut self) -> Result<bool, String> {
        let b = self.header::<4>()?;
        let is_item = (self.u16([b[0], b[1]]), self.u16([b[2], b[3]])) == (0xFFFE, 0xE000);
        if is_item {
            self.pending_item = true;
        }
        Ok(is_item)
    }

    /// A sequence's items (data sets) or encapsulated pixel data's fragments (bytes), until `limit` or, undefined,
    /// the sequence delimiter.
    fn items(&mut self, limit: Option<u64>, depth: usize, fragments: bool) -> Result<(), String> {
        if depth > MAX_DEPTH {
            return Err(format!("sequences nested deeper than {MAX_DEPTH}"));
        }
        loop {
            if limit.is_some_and(|l| self.at >= l) {
                return Ok(());
            }
            let element = if std::mem::take(&mut self.pending_item) {
                0xE000
            } else {
                let tag = self.header::<4>()?;
                let (group, element) = (self.u16([tag[0], tag[1]]), self.u16([tag[2], tag[3]]));
                if group != 0xFFFE {
                    return Err(format!("({group:04X},{element:04X}) where an item was expected"));
                }
                element
            };
            let b = self.header::<4>()?;
            let length = self.u32(b);
            match element {
                0xE0DD if limit.is_none() => return Ok(()),
                0xE000 if length == UNDEFINED && !fragments => self.elements(None, depth + 1, false)?,
                0xE000 if length as u64 <= self.left(limit) => {
                    let end = self.at + length as u64;
                    if fragments {
                        self.skip(length as u64)?;
                    } else {
                        self.elements(Some(end), depth + 1, false)?;
                    }
                }
                0xE000 => {
                    return Err(format!("an item declares {length} bytes, more than the {} left", self.left(limit)))
                }
                other => return Err(format!("unexpected (FFFE,{other:04X}) in a sequence")),
            }
        }
    }
}

/// Checks every element length of the DICOM file `path` against the bytes that hold it; the reason when one reaches
/// past them (or the file's structure cannot be walked).
pub fn check_element_lengths(path: &Path) -> Result<(), String> {
    let file = File::open(path).map_err(|e| e.to_string())?;
    let file_len = file.metadata().map_err(|e| e.to_string())?.len();
    let mut reader = BufReader::new(file);
    let mut head = [0u8; 132];
    reader.read_exact(&mut head).map_err(|_| "shorter than DICOM's 128-byte preamble and DICM mark".to_string())?;
    // The file meta group: explicit VR little endian, its length given by its first element.
    let mut first = [0u8; 12];
    reader.read_exact(&mut first).map_err(|_| "no file meta group".to_string())?;
    if first[..8] != [2, 0, 0, 0, b'U', b'L', 4, 0] {
        return Err("the file meta group does not begin with its group length (0002,0000)".into());
    }
    let group_length = u32::from_le_bytes([first[8], first[9], first[10], first[11]]) as u64;
    let meta_end = 144 + group_length;
    if meta_end > file_len {
        return Err(format!("the file meta group declares {group_length} bytes, more than the file holds"));
    }
    let mut meta_bytes = vec![0u8; group_length as usize];
    reader.read_exact(&mut meta_bytes).map_err(|e| e.to_string())?;
    let mut inner =
        Walk { from: meta_bytes.as_slice(), at: 0, end: group_length, explicit: true, big: false, pending_item: false };
    inner.elements(Some(group_length), 0, true)?;
    let syntax = transfer_syntax(&meta_bytes).unwrap_or_default();
    let rest = file_len - meta_end;
    let (explicit, big, deflated) = match syntax.as_str() {
        "1.2.840.10008.1.2" => (false, false, false),
        "1.2.840.10008.1.2.2" => (true, true, false),
        "1.2.840.10008.1.2.1.99" => (true, false, true),
        _ => (true, false, false),
    };
    if deflated {
        let inflated = flate2::read::DeflateDecoder::new(reader);
        let end = rest.saturating_mul(MAX_INFLATE);
        Walk { from: inflated, at: 0, end, explicit, big, pending_item: false }.elements(None, 0, false)
    } else {
        Walk { from: reader, at: 0, end: rest, explicit, big, pending_item: false }.elements(None, 0, false)
    }
}

/// The Transfer Syntax UID (0002,0010) of a file meta group's bytes (explicit VR little endian).
fn transfer_syntax(meta: &[u8]) -> Option<String> {
    let mut at = 0;
    while at + 8 <= meta.len() {
        let (group, element) =
            (u16::from_le_bytes([meta[at], meta[at + 1]]), u16::from_le_bytes([meta[at + 2], meta[at + 3]]));
        let vr = &meta[at + 4..at + 6];
        let (length, header) = if !SHORT_VRS.iter().any(|v| v.as_slice() == vr) {
            let b = meta.get(at + 8..at + 12)?;
            (u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize, 12)
        } else {
            (u16::from_le_bytes([meta[at + 6], meta[at + 7]]) as usize, 8)
        };
        let value = meta.get(at + header..at + header + length)?;
        if (group, element) == (0x0002, 0x0010) {
            return Some(String::from_utf8_lossy(value).trim_end_matches(['\0', ' ']).to_string());
        }
        at += header + length;
    }
    None
}
