//! The Python package (`crates/voxstream-python`) builds as a wheel, installs into the project's virtual environment
//! and passes its pytest suite: `scripts/python-tests.sh`, run here so that the README's test command covers
//! Python too. The suite compares Python's images with this build's `voxstream` binary byte for byte, checks that
//! the arrays own Rust's buffers, that the GIL is released while rendering and that Ctrl-C stops a render within
//! half a second.
//!
//! The wheel builds into this build's `target/` (maturin runs cargo in the same workspace and environment), so only
//! the module itself and the few crates whose features differ for it are compiled again.

use std::process::Command;

mod common;

#[test]
fn the_python_package_builds_installs_and_passes_pytest() {
    let root = common::repository_root();
    // This test binary is target/<profile>/deps/python_package-…: its build's target folder is three levels up.
    let exe = std::env::current_exe().expect("test binary path");
    let target = exe.ancestors().nth(3).expect("target folder").to_path_buf();
    let output = Command::new("bash")
        .arg("scripts/python-tests.sh")
        .current_dir(&root)
        .env("CARGO_TARGET_DIR", &target)
        .env("VOXSTREAM_BIN", env!("CARGO_BIN_EXE_voxstream"))
        .output()
        .expect("bash runs");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    println!("{stdout}");
    if !output.status.success() {
        // Long linker and build logs get cut in the middle by CI's summaries: the lines that say why come first,
        // with the disk space left (a cold CI build once ran out of it while linking the module).
        let why: Vec<&str> = stderr
            .lines()
            .filter(|l| {
                let l = l.to_ascii_lowercase();
                l.contains("error") || l.contains("no space") || l.contains("ld:") || l.contains("killed")
            })
            .map(|l| if l.len() > 300 { &l[..l.floor_char_boundary(300)] } else { l })
            .take(20)
            .collect();
        let space = Command::new("df").arg("-h").arg(&target).output().map(|o| o.stdout).unwrap_or_default();
        panic!(
            "scripts/python-tests.sh failed:\n{}\n\ndisk space at {}:\n{}\nfull output:\n{stdout}\n{stderr}",
            why.join("\n"),
            target.display(),
            String::from_utf8_lossy(&space)
        );
    }
    let summary = stdout.lines().rev().find(|l| l.contains(" passed")).unwrap_or_default();
    assert!(
        !summary.contains("failed") && !summary.contains("error") && !summary.contains("skipped"),
        "pytest: {summary}"
    );
    let passed: u32 = summary.trim_start_matches('=').trim().split(' ').next().unwrap_or("0").parse().unwrap_or(0);
    assert!(passed >= 15, "pytest ran only {passed} tests: {summary}");
}
