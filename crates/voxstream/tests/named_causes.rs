//! Messages that name the real cause, and `render` and `view` agreeing (issue 41, items 10 and 12): a store whose
//! spacing or origin is 1e308 is refused by `info` and `render` naming the store's field (not "invalid flags" or
//! "invalid camera"); `--eye` far away or a hair from the target names the flag and the distance (not "up is
//! parallel"); flags for particle files are refused with a store; a viewer script's `iso` meets `render --iso`'s
//! check; `view` exits 3 on unreadable bricks as `render` does.

mod common;

use std::path::Path;
use std::process::Output;

use common::{import_ball, scratch, stderr, voxstream};

/// Rewrites `attributes.voxstream.FIELD` of the store's root zarr.json.
fn set_attribute(store: &Path, field: &str, value: serde_json::Value) {
    let path = store.join("zarr.json");
    let mut root: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    root["attributes"]["voxstream"][field] = value;
    std::fs::write(&path, serde_json::to_string_pretty(&root).unwrap()).unwrap();
}

/// Asserts exit 1 with one line on stderr containing every needle and none of `blamed`; returns the line.
fn refused(out: &Output, needles: &[&str], blamed: &[&str]) -> String {
    let text = stderr(out);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert_eq!(text.trim_end().lines().count(), 1, "not one line:\n{text}");
    for needle in needles {
        assert!(text.contains(needle), "'{}' lacks '{needle}'", text.trim_end());
    }
    for wrong in blamed {
        assert!(!text.contains(wrong), "'{}' blames '{wrong}'", text.trim_end());
    }
    text
}

const SMALL: [&str; 5] = ["--width", "32", "--height", "32", "--quiet"];

#[test]
fn a_store_placed_beyond_f32_is_refused_naming_its_field() {
    let dir = scratch("named-causes", "extent");
    import_ball(&dir, "base.zarr");
    for (name, field, value) in [
        ("spacing.zarr", "spacing", serde_json::json!([1e308, 1.0, 1.0])),
        ("origin.zarr", "origin", serde_json::json!([0.0, 1e308, 0.0])),
        ("far.zarr", "spacing", serde_json::json!([1.0, 1.0, 1e35])),
    ] {
        let copy = std::process::Command::new("cp").arg("-r").arg("base.zarr").arg(name).current_dir(&dir).status();
        assert!(copy.expect("cp runs").success());
        set_attribute(&dir.join(name), field, value);
        let blamed = ["invalid flags", "invalid camera", "parallel"];
        refused(&voxstream(&["info", name], &dir), &[name, field, "rescale the units"], &blamed);
        let args = [&["render", name, "--out", "x.png"][..], &SMALL[..]].concat();
        refused(&voxstream(&args, &dir), &[name, field, "rescale the units"], &blamed);
        assert!(!dir.join("x.png").exists());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_bad_eye_names_the_flag_and_the_distance() {
    let dir = scratch("named-causes", "eye");
    let far = [&["render", "sponge", "--eye", "1e308,0,0", "--out", "x.png"][..], &SMALL[..]].concat();
    refused(&voxstream(&far, &dir), &["--eye 1e308,0,0", "lies beyond"], &["parallel"]);
    let close = [
        &["render", "sponge", "--eye", "0.5,0.5,0.5000000001", "--target", "0.5,0.5,0.5", "--out", "x.png"][..],
        &SMALL[..],
    ]
    .concat();
    refused(&voxstream(&close, &dir), &["--eye 0.5,0.5,0.5000000001", "--target", "too close"], &["parallel"]);
    // A real parallel up still says so, with the vectors.
    let parallel =
        [&["render", "sponge", "--eye", "0.5,3,0.5", "--target", "0.5,0.5,0.5", "--out", "x.png"][..], &SMALL[..]]
            .concat();
    refused(&voxstream(&parallel, &dir), &["parallel", "sponge's default view"], &[]);
    assert!(!dir.join("x.png").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn particle_flags_with_a_store_or_scene_are_refused_not_ignored() {
    let dir = scratch("named-causes", "particle-flags");
    import_ball(&dir, "ball.zarr");
    for source in ["ball.zarr", "sponge"] {
        for (flag, value) in [("--smoothing-scale", "2"), ("--particle-memory", "64")] {
            let args = [&["render", source, flag, value, "--out", "x.png"][..], &SMALL[..]].concat();
            refused(&voxstream(&args, &dir), &[flag, "applies to particle files", source], &[]);
        }
    }
    assert!(!dir.join("x.png").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_script_isovalue_outside_the_data_is_refused_as_render_refuses_it() {
    let dir = scratch("named-causes", "script-iso");
    import_ball(&dir, "ball.zarr");
    std::fs::write(dir.join("s.txt"), "wait-final\niso 500\niso 1e30\nquit\n").unwrap();
    // No display needed: the script is checked against the data before any window.
    let view = std::process::Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["view", "ball.zarr", "--script", "s.txt"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .current_dir(&dir)
        .output()
        .unwrap();
    let line = refused(&view, &["s.txt line 3: iso 1e30 lies outside the data's values"], &["no display"]);
    let render =
        voxstream(&[&["render", "ball.zarr", "--iso", "1e30", "--out", "x.png"][..], &SMALL[..]].concat(), &dir);
    let render_line = refused(&render, &["--iso 1e30 lies outside the data's values"], &[]);
    // The same check: the same words after the name of where the value came from.
    let reason = |l: &str| l.split("1e30").nth(1).unwrap_or("").to_string();
    assert_eq!(reason(&line), reason(&render_line));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `view` on a store with corrupt level-0 bricks exits 3 as `render` does (under Xvfb).
#[test]
fn view_exits_three_on_unreadable_bricks_as_render_does() {
    let has_xvfb =
        std::process::Command::new("sh").args(["-c", "command -v xvfb-run"]).output().is_ok_and(|o| o.status.success());
    assert!(has_xvfb, "xvfb-run is needed (Debian: apt-get install xvfb xauth libgl1-mesa-dri)");
    let dir = scratch("named-causes", "view-exit");
    import_ball(&dir, "ball.zarr");
    // Every other brick of level 0's shard gets a flipped byte (its CRC-32C then fails): a level none of whose
    // bricks reads is refused at open (`level_probe`), so some are left whole, as damage usually leaves them.
    let level: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("ball.zarr/0/zarr.json")).unwrap()).unwrap();
    let edges = |shape: &serde_json::Value| -> Vec<u64> {
        shape.as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect()
    };
    let shard = edges(&level["chunk_grid"]["configuration"]["chunk_shape"]);
    let brick = edges(&level["codecs"][0]["configuration"]["chunk_shape"]);
    let bricks_per_shard = (0..3).map(|a| (shard[a] / brick[a]) as usize).product::<usize>();
    let mut corrupted = 0;
    for entry in walk(&dir.join("ball.zarr/0")) {
        if entry.file_name().is_some_and(|n| n != "zarr.json") {
            let mut bytes = std::fs::read(&entry).unwrap();
            // The index at the end: one entry of (offset, length), u64 little-endian, per brick of the shard, then
            // its CRC-32C.
            let index_start = bytes.len() - (bricks_per_shard * 16 + 4);
            let entries: Vec<(u64, u64)> = bytes[index_start..bytes.len() - 4]
                .chunks_exact(16)
                .map(|e| {
                    (u64::from_le_bytes(e[..8].try_into().unwrap()), u64::from_le_bytes(e[8..].try_into().unwrap()))
                })
                .filter(|&(offset, _)| offset != u64::MAX)
                .collect();
            for (offset, length) in entries.into_iter().skip(1).step_by(2) {
                bytes[(offset + length / 2) as usize] ^= 0xff;
                corrupted += 1;
            }
            std::fs::write(&entry, bytes).unwrap();
        }
    }
    assert!(corrupted > 0);
    let render = voxstream(&[&["render", "ball.zarr", "--out", "x.png"][..], &SMALL[..]].concat(), &dir);
    assert_eq!(render.status.code(), Some(3), "{}", stderr(&render));
    std::fs::write(dir.join("s.txt"), "wait-final 600\nquit\n").unwrap();
    let viewer = env!("CARGO_BIN_EXE_voxstream");
    let view = std::process::Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1280x900x24", viewer, "view", "ball.zarr", "--width", "64", "--height", "64"])
        .args(["--script", "s.txt", "--stats", "stats.json"])
        .current_dir(&dir)
        .output()
        .expect("run xvfb-run");
    let text = stderr(&view);
    assert_eq!(view.status.code(), Some(3), "{text}");
    assert!(text.contains("warning") && text.contains("ball.zarr"), "{text}");
    assert!(text.contains("the image is incomplete"), "{text}");
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("stats.json")).unwrap()).unwrap();
    assert!(stats["producer_failures"].as_u64().unwrap() > 0, "{stats}");
    // The window's status line says so too.
    let status = stats["status_line"].as_str().unwrap_or_default();
    assert!(status.contains("failed (coarser data stands in)"), "status line: {status}");
    std::fs::remove_dir_all(&dir).unwrap();
}

fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files.extend(walk(&path));
        } else {
            files.push(path);
        }
    }
    files
}
