//! Regression corpus for metadata that could drive unbounded work (issue 41 items 3 and 9): foreign OME-Zarr images
//! declaring vast shapes with no chunks, pyramids holding only level 0, JSON inputs over the 4 MiB cap, and level
//! arrays whose metadata was edited so that they no longer decode.
//!
//! The stores are written here by hand (Zarr v3 and v2 metadata, uncompressed `bytes` chunks), so each test builds in
//! milliseconds. Every case runs the binary in a child killed past [`TIME_BOUND`] (the test then fails): a case that
//! would run for hours cannot pass, and none is asserted as a speed limit.

mod common;

use common::import_ball;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{json, Value};

/// A case still running after this long is unbounded work: it is killed and the test fails.
const TIME_BOUND: Duration = Duration::from_secs(60);

/// What one run of the binary did.
struct Run {
    code: i32,
    stdout: String,
    stderr: String,
}

/// Runs `voxstream args` in `dir`, killing it (and failing) past [`TIME_BOUND`].
fn run(args: &[&str], dir: &Path) -> Run {
    let mut child = Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run voxstream");
    // Drain the pipes on threads so that a chatty child never blocks on a full pipe.
    let mut stdout = child.stdout.take().unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let out = std::thread::spawn(move || std::io::read_to_string(&mut stdout).unwrap_or_default());
    let err = std::thread::spawn(move || std::io::read_to_string(&mut stderr).unwrap_or_default());
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        if start.elapsed() > TIME_BOUND {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?} still running after {TIME_BOUND:?}: killed (work not bounded by what exists)");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let (stdout, stderr) = (out.join().unwrap(), err.join().unwrap());
    assert!(!stderr.contains("panicked"), "{args:?} panicked: {stderr}");
    Run { code: status.code().unwrap_or(-1), stdout, stderr }
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-hostile-metadata-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write_json(path: &Path, value: &Value) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, serde_json::to_string_pretty(value).unwrap()).unwrap();
}

/// A Zarr v3 array's metadata: u8 samples of `shape` (z, y, x) in cubic chunks of `chunk`, stored raw.
fn array_v3(shape: [u64; 3], chunk: u64) -> Value {
    json!({
        "zarr_format": 3, "node_type": "array", "shape": shape, "data_type": "uint8",
        "chunk_grid": {"name": "regular", "configuration": {"chunk_shape": [chunk, chunk, chunk]}},
        "chunk_key_encoding": {"name": "default", "configuration": {"separator": "/"}},
        "fill_value": 0, "codecs": [{"name": "bytes"}], "attributes": {}
    })
}

/// Writes a foreign OME-Zarr 0.5 image at `dir/name` with one dataset per entry of `levels` (x, y, z edges), each
/// halving the one before, in chunks of `chunk`, none stored.
fn foreign_v3(dir: &Path, name: &str, levels: &[[u64; 3]], chunk: u64) -> PathBuf {
    let store = dir.join(name);
    let _ = std::fs::remove_dir_all(&store);
    let datasets: Vec<Value> = (0..levels.len())
        .map(|i| {
            let s = (1u64 << i) as f64;
            json!({"path": i.to_string(), "coordinateTransformations": [{"type": "scale", "scale": [s, s, s]}]})
        })
        .collect();
    for (i, [x, y, z]) in levels.iter().enumerate() {
        write_json(&store.join(format!("{i}/zarr.json")), &array_v3([*z, *y, *x], chunk));
    }
    let axes: Vec<Value> = ["z", "y", "x"].iter().map(|a| json!({"name": a, "type": "space"})).collect();
    write_json(
        &store.join("zarr.json"),
        &json!({"zarr_format": 3, "node_type": "group", "attributes": {"ome": {"version": "0.5",
            "multiscales": [{"axes": axes, "datasets": datasets}]}}}),
    );
    store
}

/// Stores chunk `zyx` (chunk-grid indices) of dataset `level` as `chunk`³ samples of `value`.
fn store_chunk(store: &Path, level: usize, zyx: [u64; 3], chunk: u64, value: u8) {
    let path = store.join(format!("{level}/c/{}/{}/{}", zyx[0], zyx[1], zyx[2]));
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, vec![value; chunk.pow(3) as usize]).unwrap();
}

/// A pyramid of `levels` levels halving `edge`.
fn cube_pyramid(edge: u64, levels: usize) -> Vec<[u64; 3]> {
    (0..levels).map(|i| [edge >> i; 3]).collect()
}

/// Asserts a one-line error, exit 1, holding every needle.
fn assert_refused(args: &[&str], dir: &Path, needles: &[&str]) {
    let out = run(args, dir);
    assert_eq!(out.code, 1, "{args:?}: exit {}: {}", out.code, out.stderr);
    assert_eq!(out.stderr.trim_end().lines().count(), 1, "{args:?}: not one line:\n{}", out.stderr);
    for needle in needles {
        assert!(out.stderr.contains(needle), "{args:?}: '{}' lacks '{needle}'", out.stderr.trim_end());
    }
}

fn render_args(store: &str) -> Vec<&str> {
    vec!["render", store, "--out", "x.png", "--width", "48", "--height", "48"]
}

#[test]
fn a_declared_2_20_cubed_image_with_no_chunks_is_listed_and_rendered_promptly() {
    let dir = scratch("vast");
    // Every level declared (16 datasets, 2^20 down to 32 per axis), no chunk stored: 3.5·10¹³ bricks at level 0.
    foreign_v3(&dir, "vast.zarr", &cube_pyramid(1 << 20, 16), 64);
    let info = run(&["info", "vast.zarr", "--json"], &dir);
    assert_eq!(info.code, 0, "{}", info.stderr);
    let info: Value = serde_json::from_str(&info.stdout).unwrap();
    let levels = info["levels"].as_array().unwrap();
    assert_eq!(levels.len(), 16);
    assert_eq!(levels[0]["bricks"], json!(1u64 << 45), "declared bricks are arithmetic, not a loop");
    assert_eq!(levels[0]["chunks"], json!(1u64 << 42));
    for level in levels {
        assert_eq!(level["chunks_stored"], json!(0), "{level}");
        assert!(level.get("stored").is_none(), "foreign stores have no per-brick record: {level}");
    }
    // It renders (nothing is stored: an empty picture, with the usual warning), exit 0.
    let out = run(&render_args("vast.zarr"), &dir);
    assert_eq!(out.code, 0, "{}", out.stderr);
    assert!(dir.join("x.png").exists());
    // The text form counts chunk files too, including one stored.
    let store = dir.join("vast.zarr");
    store_chunk(&store, 15, [0, 0, 0], 64, 9);
    let text = run(&["info", "vast.zarr"], &dir);
    assert_eq!(text.code, 0, "{}", text.stderr);
    let last = text.stdout.lines().last().unwrap().split_whitespace().collect::<Vec<_>>();
    assert_eq!(last[last.len() - 2..], ["1", "1"], "{}", text.stdout);
}

#[test]
fn a_pyramid_holding_only_a_large_level_0_is_refused_naming_the_fix() {
    let dir = scratch("level0");
    // 8192³ declared, one chunk stored (sparse): averaging its coarsest brick would read 5.5·10¹¹ samples.
    let store = foreign_v3(&dir, "sparse.zarr", &[[8192; 3]], 64);
    store_chunk(&store, 0, [64, 64, 64], 64, 200);
    // 2^20³ with only level 0 and no chunk at all.
    foreign_v3(&dir, "vast0.zarr", &[[1 << 20; 3]], 64);
    // 8192³ holding levels 0 and 1: the run of missing levels is named from 2.
    foreign_v3(&dir, "two.zarr", &cube_pyramid(8192, 2), 64);
    for (store, levels) in [("sparse.zarr", "levels 1 to 8"), ("vast0.zarr", "levels 1 to 15"), ("two.zarr", "2 to 8")]
    {
        for args in [render_args(store), vec!["info", store]] {
            assert_refused(&args, &dir, &[store, levels, "voxstream import", "multiscales"]);
        }
    }
    assert!(!dir.join("x.png").exists(), "a refused store rendered an image");
    // A missing level whose bricks average little is still synthesised: 128³ holding only level 0 renders.
    let small = foreign_v3(&dir, "small.zarr", &[[128; 3]], 64);
    store_chunk(&small, 0, [0, 0, 0], 64, 200);
    let out = run(&render_args("small.zarr"), &dir);
    assert_eq!(out.code, 0, "{}", out.stderr);
}

/// Writes a foreign OME-Zarr 0.4 (Zarr v2) image of one 64³ u8 dataset at `dir/name`, its one chunk stored.
fn foreign_v2(dir: &Path, name: &str) -> PathBuf {
    let store = dir.join(name);
    let _ = std::fs::remove_dir_all(&store);
    write_json(&store.join(".zgroup"), &json!({"zarr_format": 2}));
    let axes: Vec<Value> = ["z", "y", "x"].iter().map(|a| json!({"name": a, "type": "space"})).collect();
    write_json(
        &store.join(".zattrs"),
        &json!({"multiscales": [{"version": "0.4", "axes": axes, "datasets": [{"path": "0",
            "coordinateTransformations": [{"type": "scale", "scale": [1.0, 1.0, 1.0]}]}]}]}),
    );
    write_json(
        &store.join("0/.zarray"),
        &json!({"zarr_format": 2, "shape": [64, 64, 64], "chunks": [64, 64, 64], "dtype": "|u1",
            "compressor": null, "fill_value": 0, "order": "C", "filters": null, "dimension_separator": "/"}),
    );
    std::fs::create_dir_all(store.join("0/0/0")).unwrap();
    std::fs::write(store.join("0/0/0/0"), vec![100u8; 64 * 64 * 64]).unwrap();
    store
}

/// Pads the JSON file at `path` with trailing spaces (still valid JSON) to one byte over the 4 MiB cap.
fn pad_over_cap(path: &Path) {
    let mut text = std::fs::read(path).unwrap();
    text.resize((4 << 20) + 1, b' ');
    std::fs::write(path, text).unwrap();
}

#[test]
fn json_inputs_over_the_cap_are_refused_naming_the_file_and_the_cap() {
    let dir = scratch("json");
    // Each store opens and renders as written.
    foreign_v3(&dir, "v3.zarr", &cube_pyramid(64, 2), 64);
    foreign_v2(&dir, "v2.zarr");
    for store in ["v3.zarr", "v2.zarr"] {
        assert_eq!(run(&["info", store], &dir).code, 0, "{store}");
    }
    // Store metadata one byte over the cap, for every file zarrs reads: refused before zarrs reads it.
    let cases =
        [("v3.zarr", "zarr.json"), ("v3.zarr", "1/zarr.json"), ("v2.zarr", ".zattrs"), ("v2.zarr", "0/.zarray")];
    for (index, (base, file)) in cases.into_iter().enumerate() {
        let name = format!("big{index}.zarr");
        match base {
            "v3.zarr" => foreign_v3(&dir, &name, &cube_pyramid(64, 2), 64),
            _ => foreign_v2(&dir, &name),
        };
        pad_over_cap(&dir.join(&name).join(file));
        for args in [render_args(&name), vec!["info", &name]] {
            assert_refused(&args, &dir, &[&format!("{name}/{file}"), "4 MiB", "cap"]);
        }
    }
    // A FIFO in place of zarr.json would block zarrs forever: refused as not a regular file.
    let fifo = foreign_v3(&dir, "fifo.zarr", &cube_pyramid(64, 2), 64);
    std::fs::remove_file(fifo.join("1/zarr.json")).unwrap();
    let made = Command::new("mkfifo").arg(fifo.join("1/zarr.json")).status().expect("mkfifo");
    assert!(made.success(), "mkfifo failed");
    assert_refused(&["info", "fifo.zarr"], &dir, &["fifo.zarr/1/zarr.json", "not a regular file"]);
    // A transfer function and a camera path over the cap (a valid one, padded).
    std::fs::write(dir.join("tf.json"), r#"{"points": [[0, 0, 0, 0, 0], [100, 1, 1, 1, 0.5]]}"#).unwrap();
    let mut with_tf = render_args("v2.zarr");
    with_tf.extend(["--tf", "tf.json"]);
    assert_eq!(run(&with_tf, &dir).code, 0, "the transfer function as written renders");
    pad_over_cap(&dir.join("tf.json"));
    assert_refused(&with_tf, &dir, &["tf.json", "transfer function", "4 MiB"]);
    std::fs::write(dir.join("path.json"), r#"[{"eye": [3, 3, 3], "target": [0, 0, 0], "up": [0, 0, 1], "fov": 40}]"#)
        .unwrap();
    pad_over_cap(&dir.join("path.json"));
    let mut with_path = render_args("v2.zarr");
    with_path.extend(["--path", "path.json"]);
    assert_refused(&with_path, &dir, &["path.json", "camera path", "4 MiB"]);
    // 25 MB of padded files: not left in the temporary folder on every run.
    std::fs::remove_dir_all(&dir).unwrap();
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

/// Copies `dir/base.zarr` to `dir/name` and edits the metadata of its level `level`.
fn edited_level(dir: &Path, name: &str, level: usize, edit: &dyn Fn(&mut Value)) {
    copy_dir(&dir.join("base.zarr"), &dir.join(name));
    let path = dir.join(name).join(format!("{level}/zarr.json"));
    let mut metadata: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut metadata);
    std::fs::write(&path, metadata.to_string()).unwrap();
}

#[test]
fn info_refuses_level_arrays_that_do_not_decode_with_renders_message() {
    let dir = scratch("levels");
    import_ball(&dir, "base.zarr");
    type Edit = fn(&mut Value);
    let edits: [(&str, Edit, &str); 5] = [
        ("dtype", |m| m["data_type"] = json!("uint8"), "holds uint8"),
        (
            "endian",
            |m| m["codecs"][0]["configuration"]["codecs"][0]["configuration"]["endian"] = json!("big"),
            "min/max",
        ),
        (
            "codec",
            |m| m["codecs"][0]["configuration"]["codecs"][1] = json!({"name": "gzip", "configuration": {"level": 5}}),
            "gzip",
        ),
        ("inner", |m| m["codecs"][0]["configuration"]["chunk_shape"] = json!([8, 8, 8]), "does not decode"),
        ("outer", |m| m["chunk_grid"]["configuration"]["chunk_shape"] = json!([32, 128, 128]), "does not decode"),
    ];
    for (what, edit, needle) in edits {
        for level in [0, 1, 2] {
            let name = format!("{what}{level}.zarr");
            edited_level(&dir, &name, level, &edit);
            let level_name = if what == "dtype" { format!("'{level}'") } else { format!("level {level}") };
            let info = run(&["info", &name], &dir);
            let render = run(&render_args(&name), &dir);
            for (out, command) in [(&info, "info"), (&render, "render")] {
                assert_eq!(out.code, 1, "{name}: {command} exit {}: {}", out.code, out.stderr);
                let line = out.stderr.trim_end();
                assert_eq!(line.lines().count(), 1, "{name}: {command}: not one line:\n{line}");
                for n in [&name, &level_name, needle, "import the volume again"] {
                    assert!(line.contains(n), "{name}: {command}: '{line}' lacks '{n}'");
                }
            }
            assert_eq!(info.stderr, render.stderr, "{name}: info and render differ");
        }
    }
    assert!(!dir.join("x.png").exists(), "a refused store rendered an image");
    // Unedited, it opens; with one damaged shard it still opens (the brick is reported when rendered, exit 3); with
    // every shard of level 0 damaged, the level decodes nowhere and is refused like an edit.
    assert_eq!(run(&["info", "base.zarr"], &dir).code, 0);
    let shards = ["0/c/0/0/0", "0/c/1/0/0"];
    copy_dir(&dir.join("base.zarr"), &dir.join("one.zarr"));
    std::fs::write(dir.join("one.zarr").join(shards[1]), b"not a shard").unwrap();
    assert_eq!(run(&["info", "one.zarr"], &dir).code, 0);
    copy_dir(&dir.join("base.zarr"), &dir.join("all.zarr"));
    for shard in shards {
        std::fs::write(dir.join("all.zarr").join(shard), b"not a shard").unwrap();
    }
    assert_refused(&["info", "all.zarr"], &dir, &["all.zarr", "level 0 does not decode"]);
    // A foreign image whose coarse dataset holds another sample type than level 0: refused by both, naming it.
    let store = foreign_v3(&dir, "mixed.zarr", &cube_pyramid(64, 2), 64);
    let path = store.join("1/zarr.json");
    let mut metadata: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    metadata["data_type"] = json!("float32");
    std::fs::write(&path, metadata.to_string()).unwrap();
    for args in [render_args("mixed.zarr"), vec!["info", "mixed.zarr"]] {
        assert_refused(&args, &dir, &["mixed.zarr", "'1' holds float32", "u8"]);
    }
}
