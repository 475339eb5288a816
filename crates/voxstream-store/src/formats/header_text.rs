//! Small helpers for the text headers of NRRD, MetaImage and INR.

use std::path::Path;

use crate::error::StoreError;

/// Parses `count` whitespace- or comma-separated numbers from `value`, naming `key` in errors.
pub fn numbers<T: std::str::FromStr>(path: &Path, key: &str, value: &str, count: usize) -> Result<Vec<T>, StoreError> {
    let parts: Vec<&str> = value
        .split(|c: char| c.is_whitespace() || c == ',' || c == '(' || c == ')')
        .filter(|s| !s.is_empty())
        .collect();
    if parts.len() < count {
        return Err(StoreError::format(path, format!("'{key}' needs {count} numbers, got '{value}'")));
    }
    parts[..count]
        .iter()
        .map(|p| p.parse::<T>().map_err(|_| StoreError::format(path, format!("'{key}': '{p}' is not a number"))))
        .collect()
}

/// Three numbers as an array.
pub fn three<T: std::str::FromStr + Copy>(path: &Path, key: &str, value: &str) -> Result<[T; 3], StoreError> {
    let v = numbers::<T>(path, key, value, 3)?;
    Ok([v[0], v[1], v[2]])
}

/// The longest text header read (NRRD, MetaImage): real ones are a few hundred bytes; a file with no line breaks
/// must not be read whole as one "line".
pub const MAX_HEADER_BYTES: u64 = 1 << 20;

/// Reads the next header line into `line` (cleared first) and adds its length to `header_bytes`; a header longer
/// than [`MAX_HEADER_BYTES`] is an error. Returns the bytes read (0 at the end of the file).
pub fn read_line(
    path: &Path,
    reader: &mut impl std::io::BufRead,
    line: &mut String,
    header_bytes: &mut u64,
) -> Result<usize, StoreError> {
    use std::io::{BufRead, Read};
    line.clear();
    let allowed = MAX_HEADER_BYTES.saturating_sub(*header_bytes);
    let read = reader
        .take(allowed + 1)
        .read_line(line)
        .map_err(|e| StoreError::format(path, format!("unreadable header: {e}")))?;
    *header_bytes += read as u64;
    if *header_bytes > MAX_HEADER_BYTES {
        return Err(StoreError::format(
            path,
            format!("header longer than {MAX_HEADER_BYTES} bytes: not a text header, or no blank line ends it"),
        ));
    }
    Ok(read)
}
