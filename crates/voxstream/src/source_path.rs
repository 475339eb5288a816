//! What the SOURCE of `render` and the STORE of `info` name, and the message when it is not a store: "not found",
//! "this is a volume file: import it first", "a built-in scene, not a store", or an unknown name with the closest
//! scene suggested. Both commands go through here, so the same mistake gets the same message.

use std::path::Path;

use anyhow::{bail, Result};
use voxstream_store::import::{aside_paths, partial_path};
use voxstream_store::store_lock::leftover_aside_paths;

use crate::scenes::SCENE_NAMES;

/// File-name endings of the volume formats `voxstream import` reads.
const VOLUME_FILE_ENDINGS: [&str; 17] = [
    ".nrrd", ".nhdr", ".nii", ".nii.gz", ".mha", ".mhd", ".inr", ".inr.gz", ".vti", ".npy", ".npz", ".tif", ".tiff",
    ".vdb", ".raw", ".den", ".img",
];

/// Checks that `path` can be a store (a folder, or an interrupted import's `.partial` folder or `--overwrite`'s aside
/// folder, which the store reader then reports as such), or explains what it is instead. `command` is `render` or
/// `info`.
pub fn check_store_path(path: &Path, command: &str) -> Result<()> {
    let shown = path.display();
    if path.is_dir() || partial_path(path).is_dir() || !aside_paths(path).is_empty() {
        return Ok(());
    }
    let lower = path.to_string_lossy().to_lowercase();
    if path.is_file() {
        if path.file_name().is_some_and(|name| name == "zarr.json" || name == ".zattrs" || name == ".zgroup") {
            let folder = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
            bail!(
                "{shown} is a file inside a store: pass the store's folder instead (`voxstream {command} {}`)",
                folder.display()
            );
        }
        if VOLUME_FILE_ENDINGS.iter().any(|ending| lower.ends_with(ending)) {
            let store = suggested_store_name(path);
            bail!(
                "{shown} is a volume file, not a store: run `voxstream import {shown} --out {store}` first, then \
                 `voxstream {command} {store}`"
            );
        }
        bail!("{shown} is a file, not a store folder: `voxstream {command}` reads a store made by `voxstream import`");
    }
    if SCENE_NAMES.contains(&lower.as_str()) {
        bail!("{shown} is a built-in scene, not a store: `voxstream info` describes stores made by `voxstream import`");
    }
    let looks_like_a_path = lower.contains('/') || lower.contains('.') || lower.contains('\\');
    if command == "render" && !looks_like_a_path {
        let closest = SCENE_NAMES.iter().min_by_key(|name| strsim::levenshtein(name, &lower)).copied();
        let hint = match closest {
            Some(name) if strsim::levenshtein(name, &lower) <= 2 => format!(" (did you mean `{name}`?)"),
            _ => String::new(),
        };
        bail!(
            "unknown source '{shown}'{hint}: expected a built-in scene ({}) or a store folder made by `voxstream import`",
            SCENE_NAMES.join(", ")
        );
    }
    bail!("store {shown} not found: expected a folder made by `voxstream import` (check the path)")
}

/// Prints one warning line per folder `STORE.old-<pid>` left beside the store `path` (complete, just opened) by an
/// interrupted `import --overwrite`. Only named: `info` and `render` read and take no lock, and deleting a folder
/// the user did not name is the import's job (it holds the lock, so it knows no other import is swapping).
pub fn warn_about_leftovers(path: &Path) {
    for aside in leftover_aside_paths(path) {
        eprintln!(
            "warning: {} is left over from an interrupted `voxstream import --overwrite` ({} is complete): delete it \
             (`rm -r {}`), or the next import of {} will",
            aside.display(),
            path.display(),
            aside.display(),
            path.display()
        );
    }
}

/// `scan.nii.gz` → `scan.zarr`, next to the input.
fn suggested_store_name(input: &Path) -> String {
    let name = input.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let lower = name.to_lowercase();
    let ending = VOLUME_FILE_ENDINGS.iter().filter(|e| lower.ends_with(*e)).max_by_key(|e| e.len());
    let stem = match ending {
        Some(ending) if name.len() > ending.len() => &name[..name.len() - ending.len()],
        _ => name.as_str(),
    };
    input.with_file_name(format!("{stem}.zarr")).display().to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn store_names_are_suggested_next_to_the_input() {
        assert_eq!(suggested_store_name(Path::new("data/scan.nii.gz")), "data/scan.zarr");
        assert_eq!(suggested_store_name(Path::new("vol.npy")), "vol.zarr");
    }

    #[test]
    fn mistakes_are_explained() {
        let message = |text: &str, command: &str| check_store_path(Path::new(text), command).unwrap_err().to_string();
        assert_eq!(
            message("spnge", "render"),
            "unknown source 'spnge' (did you mean `sponge`?): expected a built-in scene (sponge, hypertexture, shell) \
             or a store folder made by `voxstream import`"
        );
        assert_eq!(
            message("nosuch.zarr", "render"),
            "store nosuch.zarr not found: expected a folder made by `voxstream import` (check the path)"
        );
        assert_eq!(message("nosuch.zarr", "info"), message("nosuch.zarr", "render"));
        assert!(message("sponge", "info").contains("is a built-in scene, not a store"));
    }
}
