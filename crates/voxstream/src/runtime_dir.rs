//! `XDG_RUNTIME_DIR` for `--backend gpu`: no more `XDG_RUNTIME_DIR is invalid or not set in the environment`.
//!
//! That line is libwayland-client's, not voxstream's and not an error: Mesa's Vulkan device-selection layer
//! (`VK_LAYER_MESA_device_select`, an implicit layer that every Mesa Vulkan driver installs and the loader always
//! loads) calls `wl_display_connect` to find the Wayland compositor's GPU whenever the application enables the
//! Wayland surface extension, which wgpu does even without a window; libwayland prints the line when
//! `XDG_RUNTIME_DIR` is unset or not an absolute path (it looks for the compositor's socket there), once per
//! enumeration of the adapters, so twice per run. Without a compositor the layer picks the adapter it would have
//! picked anyway.
//!
//! Where the variable is unset or not absolute, [`prepare_for_vulkan`] points it at an empty directory made for the
//! process (mode 0700, removed when the run ends), before anything opens Vulkan: libwayland looks for a socket
//! there, finds none, and says nothing. A desktop session's valid `XDG_RUNTIME_DIR` is left alone. The other ways
//! were worse: filtering stderr needs a pipe in front of it for the whole run (and hides what else Mesa says);
//! `NODEVICE_SELECT=1` silences the layer by turning it off, which changes the adapter picked on machines with
//! several GPUs.
//!
//! The variable is set from `main` before any thread starts (setting the environment while other threads read it
//! is undefined behaviour in C), and only for the commands that open a GPU.

use std::ffi::OsStr;
use std::os::unix::fs::DirBuilderExt;
use std::path::{Path, PathBuf};

/// The variable libwayland reads.
pub const VARIABLE: &str = "XDG_RUNTIME_DIR";

/// Whether `value` (the variable's, `None` when unset) makes libwayland complain: unset, empty or not an absolute
/// path (libwayland's own test). An absolute path that does not exist is left alone: libwayland only fails to find
/// a socket there, silently.
pub fn needs_private_runtime_dir(value: Option<&OsStr>) -> bool {
    value.is_none_or(|v| !Path::new(v).is_absolute())
}

/// A directory made for this process and named in `XDG_RUNTIME_DIR`; removed (if still empty) when dropped.
#[derive(Debug)]
pub struct PrivateRuntimeDir {
    path: PathBuf,
}

impl PrivateRuntimeDir {
    /// The directory.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for PrivateRuntimeDir {
    fn drop(&mut self) {
        // `remove_dir`, not `remove_dir_all`: only what this process made, and only if nothing was put in it.
        let _ = std::fs::remove_dir(&self.path);
    }
}

/// Makes an empty directory only this user can enter, under `parent`, named after this process; a name taken
/// (a crashed run's leftover, or anything else, a symbolic link included: `mkdir` never follows one) is skipped.
pub fn make_private_dir(parent: &Path) -> std::io::Result<PathBuf> {
    let mut last_error = None;
    for attempt in 0..16 {
        let path = parent.join(format!("voxstream-runtime-{}-{attempt}", std::process::id()));
        match std::fs::DirBuilder::new().mode(0o700).create(&path) {
            Ok(()) => return Ok(path),
            Err(error) if error.kind() == std::io::ErrorKind::AlreadyExists => last_error = Some(error),
            Err(error) => return Err(error),
        }
    }
    Err(last_error.unwrap_or_else(|| std::io::Error::other("no free name")))
}

/// Points `XDG_RUNTIME_DIR` at a private directory where it is unset or invalid ([`needs_private_runtime_dir`]);
/// keep what it returns until the run ends. Call it from `main` before any thread starts. `None` where the variable
/// was fine, or where no directory could be made (then libwayland's line is printed, as before: harmless).
pub fn prepare_for_vulkan() -> Option<PrivateRuntimeDir> {
    if !needs_private_runtime_dir(std::env::var_os(VARIABLE).as_deref()) {
        return None;
    }
    let path = make_private_dir(&std::env::temp_dir()).ok()?;
    // Edition 2021: safe to call; sound here because `main` calls it before starting any thread.
    std::env::set_var(VARIABLE, &path);
    Some(PrivateRuntimeDir { path })
}

#[cfg(test)]
mod tests {
    use std::os::unix::fs::PermissionsExt;

    use super::*;

    #[test]
    fn only_an_unset_or_relative_runtime_dir_is_replaced() {
        assert!(needs_private_runtime_dir(None));
        assert!(needs_private_runtime_dir(Some(OsStr::new(""))));
        assert!(needs_private_runtime_dir(Some(OsStr::new("run/user/1000"))));
        assert!(needs_private_runtime_dir(Some(OsStr::new("~/runtime"))));
        assert!(!needs_private_runtime_dir(Some(OsStr::new("/run/user/1000"))));
        assert!(!needs_private_runtime_dir(Some(OsStr::new("/nonexistent/but/absolute"))));
    }

    #[test]
    fn the_private_dir_is_new_empty_and_the_users_alone() {
        let parent = std::env::temp_dir().join(format!("voxstream-runtime-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&parent);
        std::fs::create_dir_all(&parent).unwrap();
        // A leftover of the same name is not reused.
        let taken = parent.join(format!("voxstream-runtime-{}-0", std::process::id()));
        std::fs::create_dir(&taken).unwrap();
        std::fs::write(taken.join("wayland-0"), b"").unwrap();
        let path = make_private_dir(&parent).unwrap();
        assert_ne!(path, taken);
        assert_eq!(std::fs::metadata(&path).unwrap().permissions().mode() & 0o777, 0o700);
        assert_eq!(std::fs::read_dir(&path).unwrap().count(), 0);
        drop(PrivateRuntimeDir { path: path.clone() });
        assert!(!path.exists(), "removed with its guard");
        assert!(taken.join("wayland-0").exists(), "what it did not make is left alone");
        std::fs::remove_dir_all(&parent).unwrap();
    }
}
