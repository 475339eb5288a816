//! Regression corpus for hostile stores and render flags (issue 9): stores made by importing a small volume, then
//! edited (zarr.json attributes, deleted shards, deleted or truncated min/max arrays), and flags asking for more
//! memory than the machine or the budget holds.
//!
//! Every case runs the binary under a time bound (killed and failed past [`TIME_BOUND`]; never asserted as a speed
//! limit) and measures its peak resident set size (GNU time's `%M`, else `VmHWM` polled), asserted under
//! [`MEMORY_BOUND`].
//! An invalid store gives one line naming the store and the field, exit 1; a brick the store says exists but cannot
//! be read gives warnings, the image, and exit 3.

mod common;

use common::import_ball;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A case still running after this long is a hang: it is killed and the test fails.
const TIME_BOUND: Duration = Duration::from_secs(120);

/// Peak resident set size allowed to any case (the small store renders with the default 256 MiB budget, of which
/// little is touched; an error must come before any large allocation).
const MEMORY_BOUND: u64 = 320 << 20;

/// What one run of the binary did.
struct Run {
    code: i32,
    stderr: String,
    peak_rss_bytes: u64,
}

/// GNU time, which reports the peak RSS of the command it runs (`%M`, KiB).
const GNU_TIME: &str = "/usr/bin/time";

/// Runs `voxstream args` in `dir`, killing it past [`TIME_BOUND`]. Peak RSS comes from GNU time where installed,
/// else from polling `VmHWM` in `/proc/<pid>/status` (a lower bound between polls, but never skipped).
fn run(args: &[&str], dir: &Path) -> Run {
    let tag = format!("{}-{:?}", std::process::id(), std::thread::current().id()).replace(['(', ')'], "");
    let stderr_path = dir.join(format!(".stderr-{tag}"));
    let rss_path = dir.join(format!(".rss-{tag}"));
    let binary = env!("CARGO_BIN_EXE_voxstream");
    let has_time = Path::new(GNU_TIME).exists();
    let mut command = if has_time {
        let mut c = Command::new(GNU_TIME);
        c.arg("-f").arg("%M").arg("-o").arg(&rss_path).arg(binary);
        c
    } else {
        Command::new(binary)
    };
    let mut child = command
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&stderr_path).unwrap())
        .spawn()
        .expect("run voxstream");
    let start = Instant::now();
    let mut polled_hwm_kib = 0u64;
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        // The process whose memory counts: the binary itself (GNU time's child, or our own).
        let target = if has_time { children_of(child.id()).first().copied() } else { Some(child.id()) };
        if let Some(kib) = target.and_then(vm_hwm_kib) {
            polled_hwm_kib = polled_hwm_kib.max(kib);
        }
        if start.elapsed() > TIME_BOUND {
            if let Some(pid) = target.filter(|_| has_time) {
                let _ = Command::new("kill").arg("-KILL").arg(pid.to_string()).status();
            }
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?} hung: killed after {TIME_BOUND:?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let stderr = std::fs::read_to_string(&stderr_path).unwrap_or_default();
    let _ = std::fs::remove_file(&stderr_path);
    let time_kib = if has_time {
        let text = std::fs::read_to_string(&rss_path).expect("GNU time wrote no report");
        let _ = std::fs::remove_file(&rss_path);
        // The last line is %M (a line before it names a fatal signal, if any).
        Some(text.lines().last().and_then(|l| l.trim().parse::<u64>().ok()).expect("GNU time's %M"))
    } else {
        None
    };
    let peak_rss_bytes = time_kib.unwrap_or(0).max(polled_hwm_kib) * 1024;
    assert!(peak_rss_bytes > 0, "{args:?}: peak memory not measured");
    let code = status.code().unwrap_or(-1);
    Run { code, stderr, peak_rss_bytes }
}

/// Child processes of `pid` (Linux).
fn children_of(pid: u32) -> Vec<u32> {
    std::fs::read_to_string(format!("/proc/{pid}/task/{pid}/children"))
        .map(|t| t.split_whitespace().filter_map(|p| p.parse().ok()).collect())
        .unwrap_or_default()
}

/// `VmHWM` of `pid` in KiB.
fn vm_hwm_kib(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status.lines().find(|l| l.starts_with("VmHWM:"))?.split_whitespace().nth(1)?.parse().ok()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-hostile-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Rewrites `attributes.voxstream.FIELD` of the store's root zarr.json as raw JSON text.
fn set_attribute(store: &Path, field: &str, json: &str) {
    let path = store.join("zarr.json");
    let mut root: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    root["attributes"]["voxstream"][field] = serde_json::from_str(json).unwrap();
    std::fs::write(&path, serde_json::to_string_pretty(&root).unwrap()).unwrap();
}

/// Asserts the common properties, then returns the run.
fn checked(args: &[&str], dir: &Path) -> Run {
    let out = run(args, dir);
    assert!(!out.stderr.contains("panicked"), "{args:?} panicked: {}", out.stderr);
    assert!(out.peak_rss_bytes <= MEMORY_BOUND, "{args:?}: peak RSS {} MiB over the bound", out.peak_rss_bytes >> 20);
    out
}

/// Asserts a one-line error (exit 1) containing every needle, for `render` and `info`.
fn assert_refused(dir: &Path, store: &str, needles: &[&str]) {
    for args in [vec!["render", store, "--out", "x.png", "--width", "32", "--height", "32"], vec!["info", store]] {
        let out = checked(&args, dir);
        assert_eq!(out.code, 1, "{args:?}: exit {}, {}", out.code, out.stderr);
        assert_eq!(out.stderr.trim_end().lines().count(), 1, "{args:?}: not one line:\n{}", out.stderr);
        for needle in needles.iter().chain([&store]) {
            assert!(out.stderr.contains(needle), "{args:?}: '{}' lacks '{needle}'", out.stderr.trim_end());
        }
    }
    assert!(!dir.join("x.png").exists(), "a refused store rendered an image");
}

#[test]
fn corrupt_store_metadata_is_one_line_naming_the_field() {
    let dir = scratch("metadata");
    import_ball(&dir, "base.zarr");
    let cases: &[(&str, &str, &[&str])] = &[
        ("brick_size", "0", &["brick_size"]),
        ("brick_size", "7", &["brick_size"]),
        ("levels", "1", &["levels"]),
        ("levels", "40", &["levels"]),
        ("value_range", "[3050, 0]", &["value_range", "reversed"]),
        ("value_range", "[-1e308, 1e308]", &["value_range"]),
        ("value_range", "[0, 9000]", &["value_range", "min/max"]),
        ("format_version", "99", &["format_version", "newer voxstream"]),
        ("spacing", "[null, 1, 1]", &["spacing"]),
        ("spacing", "[0, 1, 1]", &["spacing"]),
        ("origin", "\"ORIGIN\"", &["zarr.json"]),
        ("dims", "[1099511627776, 40, 36]", &["dims"]),
        ("dims", "[1048576, 1048576, 1048576]", &["levels"]),
        ("dtype", "\"u64\"", &["dtype"]),
    ];
    for (index, (field, value, needles)) in cases.iter().enumerate() {
        let name = format!("s{index}.zarr");
        copy_dir(&dir.join("base.zarr"), &dir.join(&name));
        set_attribute(&dir.join(&name), field, value);
        if value.contains("ORIGIN") {
            // Beyond f64: JSON can write it, no parser reads it as a finite number.
            let path = dir.join(&name).join("zarr.json");
            let text = std::fs::read_to_string(&path).unwrap().replace("\"ORIGIN\"", "[1e400, 0, 0]");
            std::fs::write(&path, text).unwrap();
        }
        assert_refused(&dir, &name, needles);
    }
    // brick_size 0 with levels 1 (the combination that used to loop in PyramidLayout::new, growing memory).
    copy_dir(&dir.join("base.zarr"), &dir.join("zero.zarr"));
    set_attribute(&dir.join("zero.zarr"), "brick_size", "0");
    set_attribute(&dir.join("zero.zarr"), "levels", "1");
    assert_refused(&dir, "zero.zarr", &["brick_size"]);
    // Huge dims with the matching level count: refused by the level arrays' shapes, nothing sized from the dims.
    copy_dir(&dir.join("base.zarr"), &dir.join("huge.zarr"));
    set_attribute(&dir.join("huge.zarr"), "dims", "[1048576, 1048576, 1048576]");
    set_attribute(&dir.join("huge.zarr"), "levels", "17");
    assert_refused(&dir, "huge.zarr", &["level 0 has shape"]);
    // A level array declaring shards of 2^60 samples (decoding one would allocate that): refused at open.
    copy_dir(&dir.join("base.zarr"), &dir.join("shards.zarr"));
    let level_path = dir.join("shards.zarr/0/zarr.json");
    let mut level: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&level_path).unwrap()).unwrap();
    level["chunk_grid"]["configuration"]["chunk_shape"] = serde_json::json!([1 << 20, 1 << 20, 1 << 20]);
    std::fs::write(&level_path, level.to_string()).unwrap();
    assert_refused(&dir, "shards.zarr", &["0/zarr.json chunk_shape"]);
}

/// Turns a copy of a native store into a foreign OME-Zarr image (drops `attributes.voxstream`), then edits it.
fn foreign_copy(dir: &Path, name: &str, edit: impl Fn(&mut serde_json::Value, &mut serde_json::Value)) {
    copy_dir(&dir.join("base.zarr"), &dir.join(name));
    let root_path = dir.join(name).join("zarr.json");
    let level_path = dir.join(name).join("0/zarr.json");
    let mut root: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&root_path).unwrap()).unwrap();
    let mut level: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&level_path).unwrap()).unwrap();
    root["attributes"].as_object_mut().unwrap().remove("voxstream");
    edit(&mut root, &mut level);
    std::fs::write(&root_path, serde_json::to_string_pretty(&root).unwrap()).unwrap();
    std::fs::write(&level_path, serde_json::to_string_pretty(&level).unwrap()).unwrap();
}

#[test]
fn foreign_ome_zarr_metadata_is_checked_before_it_sizes_anything() {
    let dir = scratch("foreign");
    import_ball(&dir, "base.zarr");
    // Unedited, the OME metadata alone renders.
    foreign_copy(&dir, "plain.zarr", |_, _| {});
    let out = checked(&["render", "plain.zarr", "--out", "p.png", "--width", "32", "--height", "32"], &dir);
    assert_eq!(out.code, 0, "{}", out.stderr);
    foreign_copy(&dir, "scale.zarr", |root, _| {
        root["attributes"]["ome"]["multiscales"][0]["datasets"][0]["coordinateTransformations"][0]["scale"] =
            serde_json::json!([1.0, 1.0, 0.0]);
    });
    assert_refused(&dir, "scale.zarr", &["spacing"]);
    foreign_copy(&dir, "chunks.zarr", |_, level| {
        level["codecs"][0]["configuration"]["chunk_shape"] = serde_json::json!([4096, 4096, 4096]);
    });
    assert_refused(&dir, "chunks.zarr", &[]);
}

/// Foreign images take their value range from level 0 (issue 42 item 2); `--value-range` replaces it, and samples
/// beyond it are clipped with a warning; the flag is refused where it cannot apply.
#[test]
fn foreign_value_range_comes_from_level_zero_or_the_flag() {
    let dir = scratch("foreign-range");
    import_ball(&dir, "base.zarr");
    foreign_copy(&dir, "plain.zarr", |_, _| {});
    let info = Command::new(env!("CARGO_BIN_EXE_voxstream")).args(["info", "plain.zarr"]).current_dir(&dir).output();
    let info = String::from_utf8_lossy(&info.unwrap().stdout).into_owned();
    assert!(info.contains("value range  0 to 3050"), "{info}");
    let render = ["render", "plain.zarr", "--out", "p.png", "--width", "32", "--height", "32"];
    let narrow = checked(&[&render[..], &["--value-range", "0,1000"]].concat(), &dir);
    assert_eq!(narrow.code, 0, "{}", narrow.stderr);
    assert!(narrow.stderr.contains("were clipped") && narrow.stderr.contains("--value-range"), "{}", narrow.stderr);
    let wide = checked(&[&render[..], &["--value-range", "0,4000"]].concat(), &dir);
    assert!(!wide.stderr.contains("clipped"), "{}", wide.stderr);
    let reversed = checked(&[&render[..], &["--value-range", "1000,0"]].concat(), &dir);
    assert!(reversed.code != 0 && reversed.stderr.contains("LO must be below HI"), "{}", reversed.stderr);
    let beyond = checked(&["info", "plain.zarr", "--value-range", "0,70000"], &dir);
    assert_eq!(beyond.code, 1, "{}", beyond.stderr);
    assert!(beyond.stderr.contains("u16 samples hold"), "{}", beyond.stderr);
    let native = checked(&["info", "base.zarr", "--value-range", "0,1000"], &dir);
    assert_eq!(native.code, 1, "{}", native.stderr);
    assert_eq!(native.stderr.trim_end().lines().count(), 1, "{}", native.stderr);
    assert!(native.stderr.contains("voxstream store"), "{}", native.stderr);
}

#[test]
fn missing_or_truncated_min_max_is_a_store_error_not_empty_space() {
    let dir = scratch("minmax");
    import_ball(&dir, "base.zarr");
    // The chunk of a level deleted, truncated, or the whole array gone.
    copy_dir(&dir.join("base.zarr"), &dir.join("deleted.zarr"));
    std::fs::remove_file(dir.join("deleted.zarr/voxstream_minmax/1/c/0/0/0/0")).unwrap();
    assert_refused(&dir, "deleted.zarr", &["min/max of level 1", "missing"]);

    copy_dir(&dir.join("base.zarr"), &dir.join("truncated.zarr"));
    let chunk = dir.join("truncated.zarr/voxstream_minmax/0/c/0/0/0/0");
    let bytes = std::fs::read(&chunk).unwrap();
    std::fs::write(&chunk, &bytes[..bytes.len() / 2]).unwrap();
    assert_refused(&dir, "truncated.zarr", &["min/max of level 0", "truncated"]);

    copy_dir(&dir.join("base.zarr"), &dir.join("gone.zarr"));
    std::fs::remove_dir_all(dir.join("gone.zarr/voxstream_minmax/2")).unwrap();
    assert_refused(&dir, "gone.zarr", &["min/max of level 2"]);
}

#[test]
fn unreadable_bricks_warn_count_and_exit_3() {
    let dir = scratch("bricks");
    import_ball(&dir, "base.zarr");
    let level0 = |store: &str| dir.join(store).join("0/c/1/0/0");
    // A missing shard (level 0, the middle row of z: inside the ball), a truncated one, a corrupt one.
    type Damage = fn(&Path);
    let edits: [(&str, Damage); 3] = [
        ("missing.zarr", |p| std::fs::remove_file(p).unwrap()),
        ("truncated.zarr", |p| {
            let bytes = std::fs::read(p).unwrap();
            std::fs::write(p, &bytes[..bytes.len() / 3]).unwrap();
        }),
        ("corrupt.zarr", |p| {
            let mut bytes = std::fs::read(p).unwrap();
            let middle = bytes.len() / 2;
            bytes[middle..middle + 64].iter_mut().for_each(|b| *b = !*b);
            std::fs::write(p, bytes).unwrap();
        }),
    ];
    for (store, edit) in edits {
        copy_dir(&dir.join("base.zarr"), &dir.join(store));
        assert!(level0(store).exists(), "the test store lacks the shard it damages");
        edit(&level0(store));
        let png = format!("{store}.png");
        let stats = format!("{store}.json");
        let args =
            ["render", store, "--out", &png, "--stats", &stats, "--width", "64", "--height", "64", "--lod-bias", "3"];
        let out = checked(&args, &dir);
        assert_eq!(out.code, 3, "{store}: exit {}: {}", out.code, out.stderr);
        let warnings = out.stderr.lines().filter(|l| l.starts_with("warning:")).count();
        assert!(warnings > 0, "{store}: no warning: {}", out.stderr);
        assert!(out.stderr.contains("incomplete"), "{store}: {}", out.stderr);
        let stats: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join(&stats)).unwrap()).unwrap();
        let failures = stats["producer_failures"].as_u64().unwrap();
        assert!(failures > 0, "{store}: producer_failures 0");
        assert!(dir.join(&png).exists(), "{store}: no image");
    }
    // The undamaged store: exit 0, no warning.
    let out = checked(
        &["render", "base.zarr", "--out", "ok.png", "--width", "64", "--height", "64", "--lod-bias", "3"],
        &dir,
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(!out.stderr.contains("warning"), "{}", out.stderr);
}

#[test]
fn budgets_and_image_sizes_beyond_memory_are_refused_before_allocating() {
    let dir = scratch("budget");
    let physical_mb = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| t.lines().find(|l| l.starts_with("MemTotal:"))?.split_whitespace().nth(1)?.parse::<u64>().ok())
        .map(|kib| kib / 1024)
        .expect("MemTotal in /proc/meminfo");
    let out = checked(&["render", "--budget-mb", "1048576", "--out", "x.png", "--width", "32", "--height", "32"], &dir);
    if physical_mb < 1048576 {
        assert_eq!(out.code, 1, "{}", out.stderr);
        assert!(out.stderr.contains("machine's memory") && out.stderr.contains("--budget-mb"), "{}", out.stderr);
        assert_eq!(out.stderr.trim_end().lines().count(), 1, "{}", out.stderr);
    }
    let cases: &[(&[&str], &str)] = &[
        (&["render", "--width", "16384", "--height", "16384", "--out", "x.png"], "--width/--height"),
        (&["render", "--width", "4000000000", "--height", "2", "--out", "x.png"], "--width"),
        (&["render", "--width", "100000", "--height", "100000", "--budget-mb", "1000", "--out", "x.png"], "--width"),
        (&["bench", "--size", "16384", "--scenes", "shell", "--budget-mb", "64"], "--size"),
        (&["bench", "--budget-mb", "1048576", "--scenes", "shell", "--size", "32"], "--budget-mb"),
    ];
    for (args, needle) in cases {
        let out = checked(args, &dir);
        assert!(out.code == 1 || out.code == 2, "{args:?}: exit {}: {}", out.code, out.stderr);
        assert_eq!(out.stderr.trim_end().lines().count(), 1, "{args:?}: {}", out.stderr);
        assert!(out.stderr.contains(needle), "{args:?}: '{}' lacks '{needle}'", out.stderr.trim_end());
    }
    assert!(!dir.join("x.png").exists());
}

#[test]
fn overwrite_swaps_stores_and_an_interrupted_swap_is_named_then_cleaned() {
    let dir = scratch("overwrite");
    import_ball(&dir, "ball.zarr");
    let out =
        checked(&["import", "ball.nrrd", "--out", "ball.zarr", "--brick-size", "16", "--overwrite", "--quiet"], &dir);
    assert_eq!(out.code, 0, "{}", out.stderr);
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("ball.zarr."))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // Killed between the two renames: the old store aside, the new one still partial.
    std::fs::rename(dir.join("ball.zarr"), dir.join("ball.zarr.old-4242")).unwrap();
    for args in [vec!["info", "ball.zarr"], vec!["render", "ball.zarr", "--out", "x.png"]] {
        let out = checked(&args, &dir);
        assert_eq!(out.code, 1, "{}", out.stderr);
        assert!(out.stderr.contains("ball.zarr.old-4242"), "{args:?}: {}", out.stderr);
        assert_eq!(out.stderr.trim_end().lines().count(), 1, "{}", out.stderr);
    }
    // The next import puts a store in place and removes the aside folder.
    let out = checked(&["import", "ball.nrrd", "--out", "ball.zarr", "--brick-size", "16", "--quiet"], &dir);
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(!dir.join("ball.zarr.old-4242").exists());
    assert_eq!(checked(&["info", "ball.zarr"], &dir).code, 0);
}

#[test]
fn concurrent_renders_to_one_output_never_share_a_temporary_file() {
    let dir = scratch("concurrent");
    let args = ["render", "shell", "--width", "96", "--height", "96", "--out", "same.png", "--stats", "same.json"];
    let children: Vec<_> = (0..4)
        .map(|_| {
            Command::new(env!("CARGO_BIN_EXE_voxstream"))
                .args(args)
                .current_dir(&dir)
                .stderr(Stdio::piped())
                .spawn()
                .expect("run voxstream")
        })
        .collect();
    for child in children {
        let output = child.wait_with_output().unwrap();
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    }
    let png = std::fs::read(dir.join("same.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(dir.join("same.json")).unwrap()).unwrap();
    let names: Vec<_> = std::fs::read_dir(&dir).unwrap().flatten().map(|e| e.file_name()).collect();
    assert_eq!(names.len(), 2, "temporary files left: {names:?}");
}

/// CRC32C (Castagnoli), as the shard index and the bricks' `crc32c` codec use it.
fn crc32c(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &byte in bytes {
        crc ^= byte as u32;
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0x82f6_3b78 } else { crc >> 1 };
        }
    }
    !crc
}

/// Rewrites the shard at `path` (64 bricks, index at the end): `edit` gets the bytes before the index and the
/// index's (offset, length) of each brick (`u64::MAX` twice: absent); the index's CRC32C is recomputed, as a forger
/// would.
fn edit_shard(path: &Path, edit: impl Fn(&mut Vec<u8>, &mut [(u64, u64)])) {
    const BRICKS: usize = 64;
    let bytes = std::fs::read(path).unwrap();
    let start = bytes.len() - BRICKS * 16 - 4;
    assert_eq!(
        u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().unwrap()),
        crc32c(&bytes[start..bytes.len() - 4])
    );
    let word = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
    let mut index: Vec<(u64, u64)> = (0..BRICKS).map(|i| (word(start + 16 * i), word(start + 16 * i + 8))).collect();
    let mut data = bytes[..start].to_vec();
    edit(&mut data, &mut index);
    let encoded: Vec<u8> = index.iter().flat_map(|(o, n)| o.to_le_bytes().into_iter().chain(n.to_le_bytes())).collect();
    data.extend(&encoded);
    data.extend(crc32c(&encoded).to_le_bytes());
    std::fs::write(path, data).unwrap();
}

/// Renders `store` and asserts an incomplete image (exit 3) whose warnings hold `needle`.
fn assert_bricks_fail(dir: &Path, store: &str, needle: &str) {
    let png = format!("{store}.png");
    let args = ["render", store, "--out", &png, "--width", "64", "--height", "64", "--lod-bias", "3"];
    let out = checked(&args, dir);
    assert_eq!(out.code, 3, "{store}: exit {}: {}", out.code, out.stderr);
    assert!(out.stderr.lines().any(|l| l.starts_with("warning:") && l.contains(needle)), "{store}: {}", out.stderr);
    assert!(dir.join(&png).exists(), "{store}: no image");
}

#[test]
fn forged_shard_indexes_bombs_fifos_and_flipped_bits_are_failed_bricks() {
    let dir = scratch("shards");
    import_ball(&dir, "base.zarr");
    let shard = |store: &str| dir.join(store).join("0/c/1/0/0");
    let present = |index: &[(u64, u64)]| index.iter().filter(|e| **e != (u64::MAX, u64::MAX)).count();

    // Every brick of a shard inside the ball claims 2^62 bytes (zarrs allocated that, and aborted).
    copy_dir(&dir.join("base.zarr"), &dir.join("forged.zarr"));
    edit_shard(&shard("forged.zarr"), |_, index| {
        assert!(present(index) > 0, "the shard holds no brick to forge");
        index.iter_mut().filter(|e| **e != (u64::MAX, u64::MAX)).for_each(|e| e.1 = 1 << 62);
    });
    assert_bricks_fail(&dir, "forged.zarr", "past the end of the file");
    // Read whole into memory, the first failed brick is the error: one line, exit 1.
    let in_memory = ["render", "forged.zarr", "--in-memory", "--out", "m.png", "--width", "32", "--height", "32"];
    let out = checked(&in_memory, &dir);
    assert_eq!(out.code, 1, "--in-memory: exit {}: {}", out.code, out.stderr);
    assert_eq!(out.stderr.trim_end().lines().count(), 1, "--in-memory: not one line:\n{}", out.stderr);
    assert!(out.stderr.contains("past the end of the file"), "{}", out.stderr);
    // A foreign (OME-Zarr) copy of the forged store: the same check, without voxstream's brick bound.
    foreign_copy(&dir, "forged-foreign.zarr", |_, _| {});
    edit_shard(&shard("forged-foreign.zarr"), |_, index| {
        index.iter_mut().filter(|e| **e != (u64::MAX, u64::MAX)).for_each(|e| e.1 = 1 << 62);
    });
    assert_bricks_fail(&dir, "forged-foreign.zarr", "past the end of the file");

    // Every brick of the shard points at one zstd frame that inflates to 256 MiB (8 KiB on disk, a brick's size),
    // with a valid CRC32C: decoding stops at the brick's 8 KiB.
    copy_dir(&dir.join("base.zarr"), &dir.join("bomb.zarr"));
    edit_shard(&shard("bomb.zarr"), |data, index| {
        let mut encoder = zstd::stream::write::Encoder::new(Vec::new(), 1).unwrap();
        let zeros = vec![0u8; 1 << 20];
        for _ in 0..256 {
            std::io::Write::write_all(&mut encoder, &zeros).unwrap();
        }
        let mut bomb = encoder.finish().unwrap();
        bomb.extend(crc32c(&bomb).to_le_bytes());
        let at = data.len() as u64;
        data.extend(&bomb);
        index.iter_mut().filter(|e| **e != (u64::MAX, u64::MAX)).for_each(|e| *e = (at, bomb.len() as u64));
    });
    assert_bricks_fail(&dir, "bomb.zarr", "inflates past the 8192 bytes");

    // One flipped bit in the first brick's compressed bytes: its CRC32C no longer matches.
    copy_dir(&dir.join("base.zarr"), &dir.join("flip.zarr"));
    edit_shard(&shard("flip.zarr"), |data, index| {
        let &(offset, length) = index.iter().find(|e| **e != (u64::MAX, u64::MAX)).unwrap();
        data[(offset + length / 2) as usize] ^= 0x10;
    });
    let png = "flip.png";
    let args = ["render", "flip.zarr", "--out", png, "--width", "64", "--height", "64", "--lod-bias", "3"];
    let out = checked(&args, &dir);
    // The flipped brick fails wherever the render reads it; whether the view reads it depends on the view, so the
    // store is also read whole, which reads every brick.
    assert!(out.code == 0 || out.code == 3, "exit {}: {}", out.code, out.stderr);
    let whole = ["render", "flip.zarr", "--in-memory", "--out", "w.png", "--width", "32", "--height", "32"];
    let out = checked(&whole, &dir);
    assert_eq!(out.code, 1, "exit {}: {}", out.code, out.stderr);
    assert!(out.stderr.contains("CRC32C does not match"), "{}", out.stderr);

    // A FIFO in place of the shard: refused before it is opened (opening it would wait for a writer forever).
    copy_dir(&dir.join("base.zarr"), &dir.join("fifo.zarr"));
    std::fs::remove_file(shard("fifo.zarr")).unwrap();
    assert!(Command::new("mkfifo").arg(shard("fifo.zarr")).status().expect("mkfifo").success());
    assert_bricks_fail(&dir, "fifo.zarr", "not a regular file");
}

/// Blosc (lz4, no shuffle) of `bytes`, as numcodecs writes a Zarr v2 chunk.
fn blosc(bytes: Vec<u8>) -> Vec<u8> {
    use zarrs::array::codec::api::{Codec, CodecOptions};
    let metadata: zarrs::metadata::v3::MetadataV3 = serde_json::from_str(
        r#"{"name": "blosc", "configuration": {"cname": "lz4", "clevel": 5, "shuffle": "noshuffle", "blocksize": 0}}"#,
    )
    .unwrap();
    let Codec::BytesToBytes(codec) = Codec::from_metadata(&metadata).unwrap() else { panic!("blosc") };
    codec.encode(std::borrow::Cow::Owned(bytes), &CodecOptions::default()).unwrap().into_owned()
}

#[test]
fn a_blosc_bomb_in_another_tools_store_is_a_failed_brick_within_memory() {
    // A Zarr v2 OME-Zarr image (as zarr-python writes it) of 64³ bytes in eight 32³ blosc chunks; one chunk is 512
    // MiB of zeros in about 2 MB of blosc, whose header declares it. zarrs allocated and filled that much.
    let dir = scratch("blosc");
    let store = dir.join("blosc.zarr");
    let write_json = |path: &Path, value: serde_json::Value| {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, value.to_string()).unwrap();
    };
    write_json(&store.join(".zgroup"), serde_json::json!({"zarr_format": 2}));
    let axes: Vec<serde_json::Value> =
        ["z", "y", "x"].iter().map(|a| serde_json::json!({"name": a, "type": "space"})).collect();
    write_json(
        &store.join(".zattrs"),
        serde_json::json!({"multiscales": [{"version": "0.4", "axes": axes, "datasets": [{"path": "0",
            "coordinateTransformations": [{"type": "scale", "scale": [1.0, 1.0, 1.0]}]}]}]}),
    );
    write_json(
        &store.join("0/.zarray"),
        serde_json::json!({"zarr_format": 2, "shape": [64, 64, 64], "chunks": [32, 32, 32], "dtype": "|u1",
            "compressor": {"id": "blosc", "cname": "lz4", "clevel": 5, "shuffle": 0, "blocksize": 0},
            "fill_value": 0, "order": "C", "filters": null, "dimension_separator": "/"}),
    );
    let good = blosc(vec![100u8; 32 * 32 * 32]);
    for chunk in 0..8 {
        let path = store.join(format!("0/{}/{}/{}", chunk >> 2, (chunk >> 1) & 1, chunk & 1));
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, if chunk == 7 { blosc(vec![0u8; 512 << 20]) } else { good.clone() }).unwrap();
    }
    // The level's probe at open reads that chunk: the store is refused in one line, within the memory bound.
    let out = checked(&["render", "blosc.zarr", "--out", "b.png", "--width", "64", "--height", "64"], &dir);
    assert_eq!(out.code, 1, "exit {}: {}", out.code, out.stderr);
    assert_eq!(out.stderr.trim_end().lines().count(), 1, "not one line:\n{}", out.stderr);
    assert!(out.stderr.contains("declares 536870912 bytes, past the 32768 bytes"), "{}", out.stderr);
    // Without the bomb the store renders (the blosc chunks decode through the strict decoder).
    std::fs::write(store.join("0/1/1/1"), &good).unwrap();
    let out = checked(&["render", "blosc.zarr", "--out", "b.png", "--width", "64", "--height", "64"], &dir);
    assert_eq!(out.code, 0, "exit {}: {}", out.code, out.stderr);
}

fn copy_dir(from: &Path, to: &Path) {
    let _ = std::fs::remove_dir_all(to);
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap().flatten() {
        let target = to.join(entry.file_name());
        if entry.path().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}
