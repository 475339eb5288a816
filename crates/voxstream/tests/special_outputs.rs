//! Outputs over things that are not regular files (issue 42, item 1): `render --out /dev/null` run as root once
//! replaced the machine's `/dev/null` with a regular file, and a named pipe became a file. A FIFO (or character
//! device) gets the bytes written into it and stays what it was; a folder is refused before any work; a link to a
//! file stays a link. The tests make their FIFOs with `mkfifo` in a scratch folder and never touch system paths.

#![cfg(unix)]

mod common;

use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::thread::JoinHandle;

use common::{scratch, stderr, voxstream};

/// A FIFO at `dir/name`.
fn fifo(dir: &Path, name: &str) -> PathBuf {
    let path = dir.join(name);
    let made = std::process::Command::new("mkfifo").arg(&path).status().expect("mkfifo runs");
    assert!(made.success(), "mkfifo {}", path.display());
    path
}

/// A thread that reads everything written into the FIFO at `path`.
fn drain(path: &Path) -> JoinHandle<Vec<u8>> {
    let path = path.to_path_buf();
    std::thread::spawn(move || std::fs::read(path).expect("read the FIFO"))
}

/// Whether `path` is still a FIFO (checked before joining its reader: a reader whose FIFO was replaced would wait
/// forever).
fn is_fifo(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_fifo())
}

/// Joins a FIFO's reader. If the command never opened the FIFO, opening it for reading and writing (which never
/// waits on Linux) and closing it lets the reader see an empty stream instead of waiting forever.
fn collect(path: &Path, reader: JoinHandle<Vec<u8>>) -> Vec<u8> {
    drop(std::fs::OpenOptions::new().read(true).write(true).open(path));
    reader.join().expect("the reader")
}

const SMALL: [&str; 6] = ["render", "sponge", "--width", "48", "--height", "40"];

#[test]
fn a_fifo_as_out_gets_the_png_and_stays_a_fifo() {
    let dir = scratch("special-outputs", "fifo-out");
    let pipe = fifo(&dir, "frame.png");
    let reader = drain(&pipe);
    let output = voxstream(&[&SMALL[..], &["--out", "frame.png", "--quiet"]].concat(), &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(is_fifo(&pipe), "the FIFO was replaced by a regular file");
    let bytes = collect(&pipe, reader);
    assert_eq!(bytes.get(1..4), Some(&b"PNG"[..]), "{} bytes came through", bytes.len());
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let info = decoder.read_info().expect("a whole PNG came through");
    assert_eq!((info.info().width, info.info().height), (48, 40));
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "no temporary file is left");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_fifo_as_stats_gets_the_json_and_stays_a_fifo() {
    let dir = scratch("special-outputs", "fifo-stats");
    let pipe = fifo(&dir, "stats.json");
    let reader = drain(&pipe);
    let output = voxstream(&[&SMALL[..], &["--out", "f.png", "--stats", "stats.json", "--quiet"]].concat(), &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(is_fifo(&pipe), "the FIFO was replaced by a regular file");
    let stats: serde_json::Value = serde_json::from_slice(&collect(&pipe, reader)).expect("the stats as JSON");
    assert_eq!(stats["source"], "sponge");
    assert!(dir.join("f.png").is_file());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_folder_as_out_or_stats_is_refused_before_rendering() {
    let dir = scratch("special-outputs", "folder");
    std::fs::create_dir(dir.join("frames")).unwrap();
    for args in [["--out", "frames", "--stats", "s.json"], ["--out", "f.png", "--stats", "frames"]] {
        let output = voxstream(&[&SMALL[..], &args[..]].concat(), &dir);
        let message = stderr(&output);
        assert_eq!(output.status.code(), Some(1), "{message}");
        let flag = if args[1] == "frames" { "--out" } else { "--stats" };
        assert!(message.contains(&format!("{flag}: frames is a folder")), "{message}");
        assert_eq!(message.trim_end().lines().count(), 1, "{message}");
        // Refused before the render: nothing was written.
        assert!(!dir.join("s.json").exists() && !dir.join("f.png").exists());
    }
    assert_eq!(std::fs::read_dir(dir.join("frames")).unwrap().count(), 0);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_link_to_a_file_as_out_stays_a_link() {
    let dir = scratch("special-outputs", "link");
    std::fs::create_dir(dir.join("real")).unwrap();
    std::fs::write(dir.join("real/frame.png"), b"old").unwrap();
    std::os::unix::fs::symlink("real/frame.png", dir.join("frame.png")).unwrap();
    let output = voxstream(&[&SMALL[..], &["--out", "frame.png", "--quiet"]].concat(), &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(std::fs::symlink_metadata(dir.join("frame.png")).unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read(dir.join("real/frame.png")).unwrap().get(1..4), Some(&b"PNG"[..]));
    std::fs::remove_dir_all(&dir).unwrap();
}
