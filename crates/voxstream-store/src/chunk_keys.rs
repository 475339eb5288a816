//! Which chunks of a foreign array exist on disk, found by listing its folder (never by walking the declared chunk
//! grid, which metadata can make astronomically large), and the check that the array's declared chunk-key separator
//! matches how its chunk files are laid out.
//!
//! A Zarr v2 array declaring `"dimension_separator": "."` over chunk files laid out as `0/0/0` (or the reverse, and
//! the same for Zarr v3's `chunk_key_encoding`) would read as nothing but fill value: an empty image. When none of
//! the array's files is a chunk key under the declared separator but some are under the other one, the array is
//! refused, naming both.

use std::path::Path;

use serde_json::Value;

/// How an array names its chunks: an optional leading component (`c` for Zarr v3's default encoding), then the
/// chunk indices, joined by the separator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct KeyEncoding {
    pub prefix: Option<&'static str>,
    pub separator: char,
}

impl KeyEncoding {
    /// The encoding an array's metadata (zarrs' serialisation of its `zarr.json` or `.zarray`) declares.
    pub fn of(metadata: &Value) -> KeyEncoding {
        let separator_in = |value: Option<&Value>, default: char| match value.and_then(Value::as_str) {
            Some(".") => '.',
            Some("/") => '/',
            _ => default,
        };
        if let Some(encoding) = metadata.get("chunk_key_encoding") {
            let separator = encoding.get("configuration").and_then(|c| c.get("separator"));
            if encoding.get("name").and_then(Value::as_str) == Some("v2") {
                return KeyEncoding { prefix: None, separator: separator_in(separator, '.') };
            }
            return KeyEncoding { prefix: Some("c"), separator: separator_in(separator, '/') };
        }
        KeyEncoding { prefix: None, separator: separator_in(metadata.get("dimension_separator"), '.') }
    }

    /// The same encoding with the other separator.
    pub fn other(self) -> KeyEncoding {
        KeyEncoding { separator: if self.separator == '.' { '/' } else { '.' }, ..self }
    }

    /// The chunk indices `key` (a path relative to the array's folder, components joined by `/`) names, if it is a
    /// chunk key of `dimensions` indices in this encoding.
    pub fn decode(self, key: &str, dimensions: usize) -> Option<Vec<u64>> {
        let mut rest = key;
        if let Some(prefix) = self.prefix {
            rest = rest.strip_prefix(prefix)?.strip_prefix(self.separator)?;
        }
        let parts: Vec<&str> = rest.split(self.separator).collect();
        if parts.len() != dimensions || (self.separator == '.' && rest.contains('/')) {
            return None;
        }
        parts.iter().map(|p| if p.bytes().all(|b| b.is_ascii_digit()) { p.parse().ok() } else { None }).collect()
    }

    fn describe(self) -> String {
        let sep = self.separator;
        match self.prefix {
            Some(prefix) => format!("'{sep}' (keys like {prefix}{sep}0{sep}0{sep}0)"),
            None => format!("'{sep}' (keys like 0{sep}0{sep}0)"),
        }
    }
}

/// Every regular file below `folder` (depth at most `max_depth`), as paths relative to it joined by `/`; hidden
/// files and the Zarr metadata files are left out. Symbolic links are not followed.
fn files_below(folder: &Path, max_depth: usize) -> Vec<String> {
    let mut found = Vec::new();
    let mut pending = vec![(folder.to_path_buf(), String::new(), 0usize)];
    while let Some((dir, relative, depth)) = pending.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') || name == "zarr.json" {
                continue;
            }
            let key = if relative.is_empty() { name.clone() } else { format!("{relative}/{name}") };
            match entry.file_type() {
                Ok(t) if t.is_dir() && depth < max_depth => pending.push((entry.path(), key, depth + 1)),
                Ok(t) if t.is_file() => found.push(key),
                _ => {}
            }
        }
    }
    found
}

/// The indices of the chunks of the array in `folder` (its metadata `metadata`, `dimensions` axes) that exist on
/// disk, or a one-line refusal when none is named as declared while some are named with the other separator.
pub(crate) fn stored_chunks(folder: &Path, metadata: &Value, dimensions: usize) -> Result<Vec<Vec<u64>>, String> {
    chunks_named(&files_below(folder, dimensions + 1), metadata, dimensions)
}

/// Most keys listed below one remote array (beyond it, every chunk of the grid is taken as stored).
const MAX_LISTED_KEYS: usize = 1 << 20;

/// Where an array's chunks are looked for.
pub(crate) enum ChunkSource<'a> {
    /// The store's folder on disk.
    Folder(&'a Path),
    /// A remote store (listed where the service lists: object stores yes, plain HTTP no).
    Remote(&'a voxstream_remote::RemoteStore),
}

/// The stored chunks of the array `name` (as [`stored_chunks`]), or `None` where they cannot be listed (a remote
/// HTTP store, or more than [`MAX_LISTED_KEYS`]): then every chunk of the grid is to be taken as stored.
pub(crate) fn stored_chunks_in(
    source: &ChunkSource,
    name: &str,
    metadata: &Value,
    dimensions: usize,
) -> Result<Option<Vec<Vec<u64>>>, String> {
    match source {
        ChunkSource::Folder(store) => {
            stored_chunks(&store.join(name.trim_start_matches('/')), metadata, dimensions).map(Some)
        }
        ChunkSource::Remote(remote) => {
            let Some(keys) = remote.list(name, MAX_LISTED_KEYS).map_err(|e| e.to_string())? else {
                return Ok(None);
            };
            let files: Vec<String> = keys
                .into_iter()
                .filter(|key| {
                    let file = key.rsplit('/').next().unwrap_or(key);
                    !file.starts_with('.') && file != "zarr.json"
                })
                .collect();
            chunks_named(&files, metadata, dimensions).map(Some)
        }
    }
}

/// The chunk indices that `files` (paths relative to an array's folder) name under the array's declared key
/// encoding, or a one-line refusal when none does while some follow the other separator.
fn chunks_named(files: &[String], metadata: &Value, dimensions: usize) -> Result<Vec<Vec<u64>>, String> {
    let declared = KeyEncoding::of(metadata);
    let decode_all = |encoding: KeyEncoding| -> Vec<Vec<u64>> {
        files.iter().filter_map(|key| encoding.decode(key, dimensions)).collect()
    };
    let chunks = decode_all(declared);
    if chunks.is_empty() {
        let other = declared.other();
        if let Some(example) = files.iter().find(|key| other.decode(key, dimensions).is_some()) {
            return Err(format!(
                "declares chunk keys separated by {}, but its chunk files use {} (e.g. {example}): it would read as \
                 empty; fix the separator in its metadata (dimension_separator or chunk_key_encoding)",
                declared.describe(),
                other.describe()
            ));
        }
    }
    Ok(chunks)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encodings_decode_their_own_keys_only() {
        let v2_dot = KeyEncoding::of(&serde_json::json!({"zarr_format": 2, "dimension_separator": "."}));
        let v2_slash = KeyEncoding::of(&serde_json::json!({"zarr_format": 2, "dimension_separator": "/"}));
        let v3 = KeyEncoding::of(&serde_json::json!({"chunk_key_encoding": {"name": "default"}}));
        assert_eq!(v2_dot.decode("1.2.3", 3), Some(vec![1, 2, 3]));
        assert_eq!(v2_dot.decode("1/2/3", 3), None);
        assert_eq!(v2_slash.decode("1/2/3", 3), Some(vec![1, 2, 3]));
        assert_eq!(v2_slash.decode("1.2.3", 3), None);
        assert_eq!(v3.decode("c/0/4/5", 3), Some(vec![0, 4, 5]));
        assert_eq!(v3.decode("c/0/4", 3), None);
        assert_eq!(v3.decode("c/0/x/5", 3), None);
        assert_eq!(v2_dot.other(), v2_slash);
    }
}
