//! What the SOURCE of `render` and the STORE of `info` name, and the message when it is not a store: "not found"
//! (with the nearest folder beside it suggested), "this is a volume file: import it first" (with an `import` command
//! that works: `--dims`/`--dtype` placeholders for raw files, the store written to the current folder), "a level of
//! the store …", "a built-in scene, not a store", or an unknown name with the closest scene suggested. Both commands
//! go through here, so the same mistake gets the same message.

use std::io::Read;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Result};
use voxstream_geometry::formats::is_geometry_file_name;
use voxstream_store::formats::dicom::has_dicom_extension;
use voxstream_store::formats::dicom_header::has_dicom_magic;
use voxstream_store::import::{aside_paths, partial_path};
use voxstream_store::store_lock::leftover_aside_paths;

use crate::near_names::{closest_name, sibling_hint};
use crate::scenes::SCENE_NAMES;

/// File-name endings of the volume formats `voxstream import` reads.
const VOLUME_FILE_ENDINGS: [&str; 20] = [
    ".nrrd", ".nhdr", ".nii", ".nii.gz", ".mha", ".mhd", ".inr", ".inr.gz", ".vti", ".npy", ".npz", ".tif", ".tiff",
    ".vdb", ".raw", ".den", ".img", ".dcm", ".dicom", ".ima",
];

/// File-name endings of raw sample files: `voxstream import` reads them only with `--dims` and `--dtype`.
const RAW_FILE_ENDINGS: [&str; 3] = [".raw", ".den", ".img"];

/// How many folders up a path is looked at for the store it lies in.
const MAX_STORE_DEPTH: usize = 8;

/// Most entries of a folder looked at for TIFF slices.
const MAX_LISTED_ENTRIES: usize = 10_000;

/// Most bytes of a `zarr.json` or `.zattrs` read to tell whether its folder is a store.
const MAX_METADATA_BYTES: u64 = 1 << 20;

/// Checks that `path` can be a store (a folder, or an interrupted import's `.partial` folder or `--overwrite`'s aside
/// folder, which the store reader then reports as such), or explains what it is instead. `command` is `render` or
/// `info`.
pub fn check_store_path(path: &Path, command: &str) -> Result<()> {
    // A URL names a remote store: the store reader opens and checks it.
    if voxstream_store::remote::is_remote(&path.to_string_lossy()) {
        return Ok(());
    }
    let shown = path.display();
    if path.is_dir() && !is_store(path) {
        if let Some(store) = enclosing_store(path) {
            let what = match path.file_name().and_then(|n| n.to_str()).filter(|n| n.parse::<u32>().is_ok()) {
                Some(level) if path.parent() == Some(store.as_path()) => format!("level {level} of"),
                _ => "a folder inside".to_string(),
            };
            bail!(
                "{shown} is {what} the store {}: pass the store's folder instead (`voxstream {command} {}`)",
                store.display(),
                shell_word(&store.display().to_string())
            );
        }
        if holds_tiff_slices(path) {
            let (input, store) = (shell_word(&shown.to_string()), suggested_store_name(path));
            bail!(
                "{shown} is a folder of TIFF slices, not a store: run `voxstream import {input} --out {store}` first, \
                 then `voxstream {command} {store}`"
            );
        }
        if holds_dicom_files(path) {
            let (input, store) = (shell_word(&shown.to_string()), suggested_store_name(path));
            bail!(
                "{shown} is a folder of DICOM files, not a store: run `voxstream import {input} --out {store}` first \
                 (one series per folder), then `voxstream {command} {store}`"
            );
        }
    }
    if path.is_dir() || partial_path(path).is_dir() || !aside_paths(path).is_empty() {
        return Ok(());
    }
    let lower = path.to_string_lossy().to_lowercase();
    if path.is_file() {
        if let Some(store) = enclosing_store(path) {
            bail!(
                "{shown} is a file inside the store {}: pass the store's folder instead (`voxstream {command} {}`)",
                store.display(),
                shell_word(&store.display().to_string())
            );
        }
        if path.file_name().is_some_and(|name| name == "zarr.json" || name == ".zattrs" || name == ".zgroup") {
            let folder = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
            bail!(
                "{shown} is a file inside a store: pass the store's folder instead (`voxstream {command} {}`)",
                folder.display()
            );
        }
        let input = shell_word(&shown.to_string());
        let store = suggested_store_name(path);
        if RAW_FILE_ENDINGS.iter().any(|ending| lower.ends_with(ending)) {
            bail!(
                "{shown} holds raw samples, not a store: run `voxstream import {input} --dims X,Y,Z --dtype \
                 u8|u16|i16|f32 --out {store}` first (X,Y,Z: its dimensions; pick one --dtype), then `voxstream \
                 {command} {store}`"
            );
        }
        if VOLUME_FILE_ENDINGS.iter().any(|ending| lower.ends_with(ending)) || has_dicom_magic(path) {
            bail!(
                "{shown} is a volume file, not a store: run `voxstream import {input} --out {store}` first, then \
                 `voxstream {command} {store}`"
            );
        }
        if is_geometry_file_name(path) {
            bail!(
                "{shown} is a mesh or particle file (by its name), not a store: `voxstream render {input}` draws it, or \
                 `voxstream import {input} --out {store}` bakes it into a store"
            );
        }
        bail!(
            "{shown} is a file, not a store folder: `voxstream {command}` reads a store made by `voxstream import` (if \
             it holds raw samples: `voxstream import {input} --dims X,Y,Z --dtype u8|u16|i16|f32 --out {store}`)"
        );
    }
    if SCENE_NAMES.contains(&lower.as_str()) {
        bail!("{shown} is a built-in scene, not a store: `voxstream info` describes stores made by `voxstream import`");
    }
    let looks_like_a_path = lower.contains('/') || lower.contains('.') || lower.contains('\\');
    if command == "render" && !looks_like_a_path {
        let hint = closest_name(&lower, SCENE_NAMES).map_or_else(String::new, |n| format!(" (did you mean `{n}`?)"));
        bail!(
            "unknown source '{shown}'{hint}: expected a built-in scene ({}) or a store folder made by `voxstream import`",
            SCENE_NAMES.join(", ")
        );
    }
    let hint = sibling_hint(path, true);
    bail!("store {shown} not found{hint}: expected a folder made by `voxstream import` (check the path)")
}

/// Prints one warning line per folder `STORE.old-<pid>` left beside the store `path` (complete, just opened) by an
/// interrupted `import --overwrite`. Only named: `info` and `render` read and take no lock, and deleting a folder
/// the user did not name is the import's job (it holds the lock, so it knows no other import is swapping).
pub fn warn_about_leftovers(path: &Path) {
    if voxstream_store::remote::is_remote(&path.to_string_lossy()) {
        return;
    }
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

/// The error for a mesh or particle file that does not exist, with the nearest file beside it suggested.
pub fn missing_geometry_file(path: &Path) -> anyhow::Error {
    let hint = sibling_hint(path, false);
    anyhow!("mesh or particle file {} not found{hint} (check the path)", path.display())
}

/// Whether `folder` holds the root metadata of a multiscale store (voxstream's or another tool's OME-Zarr).
fn is_store(folder: &Path) -> bool {
    ["zarr.json", ".zattrs"].iter().any(|name| {
        let Ok(file) = std::fs::File::open(folder.join(name)) else { return false };
        let mut text = String::new();
        file.take(MAX_METADATA_BYTES).read_to_string(&mut text).is_ok() && text.contains("\"multiscales\"")
    })
}

/// Whether `folder` holds `.tif`/`.tiff` files and no Zarr metadata (among its first entries).
/// `true` when `folder` (not a store) holds DICOM files, or its subfolders do (a PACS export's study folder).
fn holds_dicom_files(folder: &Path) -> bool {
    let has_metadata = ["zarr.json", ".zattrs", ".zgroup"].iter().any(|name| folder.join(name).exists());
    let Ok(entries) = std::fs::read_dir(folder) else { return false };
    let is_dicom = |path: &Path| path.is_file() && (has_dicom_extension(path) || has_dicom_magic(path));
    !has_metadata
        && entries.take(MAX_LISTED_ENTRIES).filter_map(|entry| entry.ok()).any(|entry| {
            let path = entry.path();
            is_dicom(&path)
                || path.is_dir()
                    && std::fs::read_dir(&path).is_ok_and(|inner| inner.take(16).flatten().any(|e| is_dicom(&e.path())))
        })
}

fn holds_tiff_slices(folder: &Path) -> bool {
    let has_metadata = ["zarr.json", ".zattrs", ".zgroup"].iter().any(|name| folder.join(name).exists());
    let Ok(entries) = std::fs::read_dir(folder) else { return false };
    !has_metadata
        && entries.take(MAX_LISTED_ENTRIES).filter_map(|entry| entry.ok()).any(|entry| {
            let name = entry.file_name().to_string_lossy().to_lowercase();
            name.ends_with(".tif") || name.ends_with(".tiff")
        })
}

/// The store that `path` lies inside (not `path` itself), if any within [`MAX_STORE_DEPTH`] folders up.
fn enclosing_store(path: &Path) -> Option<PathBuf> {
    path.ancestors()
        .skip(1)
        .take(MAX_STORE_DEPTH)
        .map(|folder| if folder.as_os_str().is_empty() { Path::new(".") } else { folder })
        .find(|folder| is_store(folder))
        .map(Path::to_path_buf)
}

/// `text` as one shell word: unchanged when it holds only safe characters, else in single quotes.
fn shell_word(text: &str) -> String {
    let safe = |c: char| c.is_ascii_alphanumeric() || "._-/+,=:@%".contains(c);
    if !text.is_empty() && text.chars().all(safe) {
        text.to_string()
    } else {
        format!("'{}'", text.replace('\'', "'\\''"))
    }
}

/// `data/scan.nii.gz` → `scan.zarr`, in the current folder (the input's may be read-only).
fn suggested_store_name(input: &Path) -> String {
    let name = input.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let lower = name.to_lowercase();
    let ending = VOLUME_FILE_ENDINGS.iter().filter(|e| lower.ends_with(*e)).max_by_key(|e| e.len());
    let stem = match ending {
        Some(ending) if name.len() > ending.len() => &name[..name.len() - ending.len()],
        _ => name.rsplit_once('.').map_or(name.as_str(), |(stem, _)| stem).trim_start_matches('.'),
    };
    shell_word(&format!("{}.zarr", if stem.is_empty() { "volume" } else { stem }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn store_names_are_suggested_in_the_current_folder() {
        assert_eq!(suggested_store_name(Path::new("/read/only/scan.nii.gz")), "scan.zarr");
        assert_eq!(suggested_store_name(Path::new("vol.npy")), "vol.zarr");
        assert_eq!(suggested_store_name(Path::new("data/bunny.ply")), "bunny.zarr");
        assert_eq!(suggested_store_name(Path::new("my scan.raw")), "'my scan.zarr'");
        assert_eq!(suggested_store_name(Path::new(".raw")), "volume.zarr");
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
