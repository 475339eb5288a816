//! README.md's main command, exactly as written in its "Quick start", works in a clean checkout: it builds and
//! renders the default scene to `frame.png`. (It once stopped with "could not determine which binary to run" when a
//! second binary joined the workspace, and nothing noticed; `.ci/run` also runs it from CI's clean clone.)
//!
//! The checkout is a copy of the files git tracks, in the system's temporary folder: outside this repository, so
//! that cargo reads the checkout's `.cargo/config.toml` alone (inside it, cargo would also merge this repository's
//! copy and append the same `rustflags` twice, which changes every crate's hash and rebuilds all ~300 of them). It
//! builds into the `target/` folder of the build running this test, in the same environment: cargo names a workspace's crates by their paths relative to the
//! workspace, and the copies keep their files' modification times, so it finds the working tree's build fresh for
//! the checkout and compiles nothing, unless the checkout differs (a file the build needs that git does not track is
//! missing there, and the build fails, as it would in a fresh clone). In CI this takes seconds; it once rebuilt every
//! dependency into a second target folder, and failed there.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

use common::repository_root;

/// The first `cargo run` line of README.md's "Quick start" code block, without its comment.
fn main_command(readme: &str) -> String {
    let section = readme.split("## Quick start").nth(1).expect("README.md has a Quick start section");
    let block = section.split("```sh").nth(1).expect("the Quick start has a sh block").split("```").next().unwrap();
    let line = block.lines().find(|l| l.trim_start().starts_with("cargo run")).expect("a `cargo run` line");
    line.split('#').next().unwrap().trim().to_string()
}

/// The files git tracks, copied to `checkout`.
fn clean_checkout(root: &Path, checkout: &Path) {
    let listed = Command::new("git").args(["ls-files", "-z"]).current_dir(root).output().expect("git");
    assert!(listed.status.success(), "git ls-files failed: {}", String::from_utf8_lossy(&listed.stderr));
    let mut copied = 0;
    for name in listed.stdout.split(|&b| b == 0).filter(|n| !n.is_empty()) {
        let relative = Path::new(std::str::from_utf8(name).unwrap());
        let source = root.join(relative);
        if !source.is_file() {
            continue; // deleted in the working tree, not yet committed
        }
        let destination = checkout.join(relative);
        std::fs::create_dir_all(destination.parent().unwrap()).unwrap();
        std::fs::copy(&source, &destination).unwrap();
        // Keep the modification time, so that cargo finds the previous run's build of this checkout fresh.
        let modified = std::fs::metadata(&source).and_then(|m| m.modified()).unwrap();
        std::fs::File::options().write(true).open(&destination).and_then(|f| f.set_modified(modified)).unwrap();
        copied += 1;
    }
    assert!(copied > 20, "only {copied} tracked files");
}

/// The last `lines` lines of `text` (a failed build's error is at its end).
fn tail(text: &str, lines: usize) -> String {
    let all: Vec<&str> = text.lines().collect();
    all[all.len().saturating_sub(lines)..].join("\n")
}

#[test]
fn readme_main_command_renders_the_default_scene_in_a_clean_checkout() {
    let root = repository_root();
    let command = main_command(&std::fs::read_to_string(root.join("README.md")).unwrap());
    assert!(command.starts_with("cargo run"), "{command}");

    // This test binary is target/<profile>/deps/quick_start-…: its build's target folder is three levels up.
    let exe = std::env::current_exe().expect("test binary path");
    let target = exe.ancestors().nth(3).expect("target folder").to_path_buf();
    // Earlier versions of this test built into target/quick-start, a second copy of every dependency.
    let _ = std::fs::remove_dir_all(target.join("quick-start"));
    // A folder of this process's own, removed however the test ends.
    let checkout = TempFolder(std::env::temp_dir().join(format!("voxstream-quick-start-{}", std::process::id())));
    let _ = std::fs::remove_dir_all(&checkout.0);
    clean_checkout(&root, &checkout.0);
    // The environment of this build (RUSTFLAGS included), so that cargo finds its artifacts fresh.
    let output = Command::new("bash")
        .args(["-c", &command])
        .current_dir(&checkout.0)
        .env("CARGO_TARGET_DIR", &target)
        .output()
        .expect("bash");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "`{command}` failed in a clean checkout; its last lines:\n{}", tail(&stderr, 40));
    assert!(stderr.contains("wrote frame.png (512x512, complete"), "no summary line:\n{}", tail(&stderr, 40));
    let bytes = std::fs::read(checkout.0.join("frame.png")).expect("frame.png written");
    let reader = png::Decoder::new(std::io::Cursor::new(bytes)).read_info().unwrap();
    assert_eq!((reader.info().width, reader.info().height), (512, 512));
}

/// A folder removed when dropped (also when the test panics).
struct TempFolder(PathBuf);

impl Drop for TempFolder {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
