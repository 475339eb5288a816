//! "Did you mean …?": the closest of some names to a mistyped one, for built-in scene names and for the files and
//! folders beside a path that does not exist. One rule for all, so a typo gets the same help wherever it is made.

use std::path::{Path, PathBuf};

/// Most edits (Levenshtein distance) between a typed name and a suggestion.
const MAX_EDITS: usize = 2;

/// Most entries of a folder looked at for a suggestion (a huge folder is not listed in full for a hint).
const MAX_SIBLINGS: usize = 10_000;

/// The candidate closest to `typed`, when it is at most [`MAX_EDITS`] edits away (and not `typed` itself).
pub fn closest_name<'a>(typed: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    candidates
        .into_iter()
        .filter(|name| *name != typed)
        .map(|name| (strsim::levenshtein(name, typed), name))
        .filter(|(edits, _)| *edits <= MAX_EDITS)
        .min()
        .map(|(_, name)| name)
}

/// The existing entry beside the missing `path` whose name is closest to its name, as a path to show: a folder when
/// `want_folder`, else a file. `None` when `path`'s folder cannot be listed or nothing is near.
pub fn closest_sibling(path: &Path, want_folder: bool) -> Option<PathBuf> {
    let typed = path.file_name()?.to_str()?;
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
    let entries = std::fs::read_dir(parent.unwrap_or(Path::new("."))).ok()?;
    let names: Vec<String> = entries
        .take(MAX_SIBLINGS)
        .filter_map(|entry| entry.ok())
        .filter(|entry| entry.path().is_dir() == want_folder)
        .filter_map(|entry| entry.file_name().into_string().ok())
        .collect();
    let name = closest_name(typed, names.iter().map(String::as_str))?;
    Some(parent.map_or_else(|| PathBuf::from(name), |p| p.join(name)))
}

/// " (did you mean `X`?)" for a missing `path` with a near sibling, else "".
pub fn sibling_hint(path: &Path, want_folder: bool) -> String {
    closest_sibling(path, want_folder).map_or_else(String::new, |p| format!(" (did you mean `{}`?)", p.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_names_are_suggested_and_far_ones_are_not() {
        let names = ["sponge", "hypertexture", "shell"];
        assert_eq!(closest_name("spnge", names), Some("sponge"));
        assert_eq!(closest_name("shel", names), Some("shell"));
        assert_eq!(closest_name("cloud", names), None);
        assert_eq!(closest_name("sponge", names), None, "the name itself is no suggestion");
    }

    #[test]
    fn siblings_of_the_right_kind_are_suggested() {
        let dir = std::env::temp_dir().join(format!("voxstream-near-names-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("foot.zarr")).unwrap();
        std::fs::write(dir.join("bunny.ply"), b"").unwrap();
        assert_eq!(closest_sibling(&dir.join("fot.zarr"), true), Some(dir.join("foot.zarr")));
        assert_eq!(closest_sibling(&dir.join("fot.zarr"), false), None, "a folder is no file");
        assert_eq!(closest_sibling(&dir.join("buny.ply"), false), Some(dir.join("bunny.ply")));
        assert_eq!(sibling_hint(&dir.join("zzz.ply"), false), "");
        assert_eq!(closest_sibling(&dir.join("nosuch/fot.zarr"), true), None, "an unreadable folder gives none");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
