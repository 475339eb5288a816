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
