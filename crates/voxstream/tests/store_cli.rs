//! The store through the command line: import with progress, info, render, and a corrupt brick at render time.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn voxstream(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_voxstream")).args(args).current_dir(dir).output().expect("run voxstream")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-store-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A 96×80×72 u16 NRRD: a soft ball in an empty box.
fn write_ball(path: &Path) {
    common::write_nrrd(path, [96, 80, 72], "0.5 0.5 0.6", |i, j, k| {
        let d = (((i as f64 - 48.0) / 30.0).powi(2)
            + ((j as f64 - 40.0) / 28.0).powi(2)
            + ((k as f64 - 36.0) / 25.0).powi(2))
        .sqrt();
        if d < 1.0 {
            (4000.0 * (1.0 - d * d)) as u16 + 100
        } else {
            0
        }
    });
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

#[test]
fn import_info_render_and_survive_a_corrupt_brick() {
    let dir = scratch("flow");
    write_ball(&dir.join("ball.nrrd"));
    let output = voxstream(&["import", "ball.nrrd", "--out", "ball.zarr", "--brick-size", "16"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));

    let output = voxstream(&["info", "ball.zarr", "--json"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    let info: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(info["dims"], serde_json::json!([96, 80, 72]));
    assert_eq!(info["dtype"], "u16");
    assert_eq!(info["value_range"][1].as_f64().unwrap(), 4100.0);
    let level0 = &info["levels"][0];
    assert_eq!(level0["bricks"], 6 * 5 * 5);
    assert!(level0["empty"].as_u64().unwrap() > 0 && level0["stored"].as_u64().unwrap() > 0);
    assert!(info["bytes_on_disk"].as_u64().unwrap() > 0);

    let output = voxstream(
        &["render", "ball.zarr", "--width", "64", "--height", "64", "--out", "a.png", "--stats", "a.json"],
        &dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(!stderr(&output).contains("warning"), "{}", stderr(&output));
    let stats: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("a.json")).unwrap()).unwrap();
    assert_eq!(stats["converged"], true);
    assert!(stats["bricks_produced"].as_u64().unwrap() > 0);

    // Corrupt every shard of level 0 but the first: the render completes, each failed brick is reported once (as a
    // warning), coarser levels stand in, and the exit code (3) says the image is incomplete. (With every shard of
    // the level corrupt, the level decodes nowhere and the store is refused at open, as `info` refuses it.)
    let mut corrupted = 0;
    for entry in walk(&dir.join("ball.zarr/0")) {
        if entry.file_name().is_some_and(|n| n != "zarr.json") && !entry.ends_with("c/0/0/0") {
            std::fs::write(&entry, b"not a shard").unwrap();
            corrupted += 1;
        }
    }
    assert!(corrupted > 0);
    let output = voxstream(
        &[
            "render",
            "ball.zarr",
            "--width",
            "64",
            "--height",
            "64",
            "--out",
            "b.png",
            "--stats",
            "b.json",
            "--lod-bias",
            "3",
        ],
        &dir,
    );
    let text = stderr(&output);
    assert_eq!(output.status.code(), Some(3), "{text}");
    assert!(text.contains("warning") && text.contains("ball.zarr"), "{text}");
    assert!(!text.contains("panicked"), "{text}");
    let stats: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("b.json")).unwrap()).unwrap();
    let failures = stats["producer_failures"].as_u64().unwrap();
    assert!(failures > 0);
    // Reported once each: no more failures than level-0 bricks.
    assert!(failures <= 6 * 5 * 5, "{failures} failures for at most 150 bricks");
    assert!(dir.join("b.png").exists());
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        if path.is_dir() {
            out.extend(walk(&path));
        } else {
            out.push(path);
        }
    }
    out
}

#[test]
fn bad_stores_and_inputs_fail_with_one_line() {
    let dir = scratch("bad");
    write_ball(&dir.join("ball.nrrd"));
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["render", "missing.zarr", "--out", "x.png"], "not found"),
        (vec!["info", "missing.zarr"], "not found"),
        (vec!["import", "missing.nrrd", "--out", "m.zarr"], "missing.nrrd"),
        (vec!["import", "ball.nrrd", "--out", "b.zarr", "--brick-size", "7"], "brick size"),
        (vec!["import", "ball.nrrd", "--out", "b.zarr", "--dims", "4,4,4"], "--dtype"),
        (vec!["import", "ball.nrrd", "--out", "b.zarr", "--dims", "4,4,4", "--dtype", "u64"], "--dtype"),
    ];
    for (args, needle) in cases {
        let output = voxstream(&args, &dir);
        let text = stderr(&output);
        assert!(!output.status.success(), "{args:?} succeeded");
        assert_eq!(text.trim_end().lines().count(), 1, "{args:?}: {text}");
        assert!(text.contains(needle), "{args:?}: '{text}' lacks '{needle}'");
    }
    // A store whose metadata is corrupt.
    let output = voxstream(&["import", "ball.nrrd", "--out", "c.zarr", "--quiet"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    std::fs::write(dir.join("c.zarr/zarr.json"), "{ broken").unwrap();
    let output = voxstream(&["render", "c.zarr", "--out", "x.png"], &dir);
    let text = stderr(&output);
    assert!(!output.status.success() && text.contains("zarr.json"), "{text}");
    assert_eq!(text.trim_end().lines().count(), 1, "{text}");
}

#[test]
fn store_renders_are_deterministic_with_background_prefetch() {
    // Interactive frames with a small per-frame bound hand many deferred bricks to the background prefetch; the
    // images must not depend on it, nor on the number of threads.
    let dir = scratch("determinism");
    write_ball(&dir.join("ball.nrrd"));
    let output = voxstream(&["import", "ball.nrrd", "--out", "ball.zarr", "--brick-size", "8", "--quiet"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    let mut images = Vec::new();
    for (i, threads) in ["1", "2", "2"].iter().enumerate() {
        let out = format!("f{i}.png");
        let output = Command::new(env!("CARGO_BIN_EXE_voxstream"))
            .args([
                "render",
                "ball.zarr",
                "--mode",
                "interactive",
                "--frames",
                "6",
                "--requests-per-frame",
                "20",
                "--width",
                "48",
                "--height",
                "48",
                "--out",
                &out,
            ])
            .env("RAYON_NUM_THREADS", threads)
            .current_dir(&dir)
            .output()
            .unwrap();
        assert!(output.status.success(), "{}", stderr(&output));
        images.push(std::fs::read(dir.join(&out)).unwrap());
    }
    assert!(images.windows(2).all(|w| w[0] == w[1]), "store renders differ between runs");
}

/// PSNR of `b` against `a` (8-bit samples).
fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let mse = a.iter().zip(b).map(|(x, y)| (*x as f64 - *y as f64).powi(2)).sum::<f64>() / a.len() as f64;
    10.0 * (255.0f64.powi(2) / mse.max(1e-12)).log10()
}

#[test]
fn wavelet_coded_stores_import_say_so_and_render_like_zstd_stores() {
    let dir = scratch("wavelet");
    write_ball(&dir.join("ball.nrrd"));
    let stores = [
        ("zstd.zarr", vec!["--codec", "zstd"]),
        ("exact.zarr", vec!["--codec", "wavelet"]),
        ("lossy.zarr", vec!["--codec", "wavelet", "--max-error", "20"]),
    ];
    for (store, flags) in &stores {
        let mut args = vec!["import", "ball.nrrd", "--out", store, "--brick-size", "16"];
        args.extend(flags);
        let output = voxstream(&args, &dir);
        assert!(output.status.success(), "{store}: {}", stderr(&output));
        if *store == "lossy.zarr" {
            assert!(stderr(&output).contains("every sample within 20 of its value"), "{}", stderr(&output));
        }
        let output = voxstream(&["info", store, "--json"], &dir);
        assert!(output.status.success(), "{}", stderr(&output));
        let info: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
        let expected = match *store {
            "zstd.zarr" => serde_json::Value::Null,
            "exact.zarr" => serde_json::json!({"name": "wavelet", "max_error": 0.0}),
            _ => serde_json::json!({"name": "wavelet", "max_error": 20.0}),
        };
        assert_eq!(info["brick_codec"], expected, "{store}");
        let png = store.replace(".zarr", ".png");
        let output = voxstream(&["render", store, "--width", "96", "--height", "96", "--out", &png], &dir);
        assert!(output.status.success(), "{store}: {}", stderr(&output));
        assert!(!stderr(&output).contains("warning"), "{store}: {}", stderr(&output));
    }
    let level0 = |store: &str| {
        let mut files = walk(&dir.join(store).join("0"));
        files.retain(|f| f.file_name().is_some_and(|n| n != "zarr.json"));
        files.iter().map(|f| std::fs::metadata(f).unwrap().len()).sum::<u64>()
    };
    let (zstd, exact, lossy) = (level0("zstd.zarr"), level0("exact.zarr"), level0("lossy.zarr"));
    assert!(exact < zstd && lossy < exact, "level 0 bytes: zstd {zstd}, wavelet {exact}, ±20 {lossy}");
    let (_, _, want) = common::read_png(&dir.join("zstd.png"));
    let (_, _, same) = common::read_png(&dir.join("exact.png"));
    assert!(want == same, "a lossless wavelet store renders the zstd store's image");
    let (_, _, near) = common::read_png(&dir.join("lossy.png"));
    let db = psnr(&want, &near);
    assert!(db > 40.0 && db.is_finite(), "±20 in 0..4100 renders at {db:.1} dB against the exact store");

    for (flags, expected) in [
        (vec!["--max-error", "3"], "applies to the wavelet codec; zstd is lossless"),
        (vec!["--codec", "wavelet", "--max-error", "-1"], "finite number ≥ 0"),
    ] {
        let mut args = vec!["import", "ball.nrrd", "--out", "bad.zarr"];
        args.extend(&flags);
        let output = voxstream(&args, &dir);
        let text = stderr(&output);
        assert!(!output.status.success() && !text.contains("panicked"), "{flags:?}: {text}");
        assert!(text.contains(expected) && text.lines().count() == 1, "{flags:?}: {text}");
        assert!(!dir.join("bad.zarr").exists());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_compressed_cache_takes_half_the_host_cache_or_a_budget_of_its_own() {
    let dir = scratch("host-caches");
    write_ball(&dir.join("ball.nrrd"));
    let output = voxstream(&["import", "ball.nrrd", "--out", "ball.zarr", "--brick-size", "16"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    let caches = |flags: &[&str], name: &str| {
        let mut args = vec!["render", "ball.zarr", "--width", "64", "--height", "64", "--out", "c.png"];
        args.extend(["--budget-mb", "64", "--stats", name]);
        args.extend(flags);
        let output = voxstream(&args, &dir);
        assert!(output.status.success(), "{flags:?}: {}", stderr(&output));
        let stats: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join(name)).unwrap()).unwrap();
        let host = &stats["host_caches"];
        let compressed = &host["compressed"];
        assert!(compressed["held_bytes"].as_u64().unwrap() > 0, "{host}");
        assert!(compressed["held_bytes"].as_u64() <= compressed["capacity_bytes"].as_u64(), "{host}");
        (host["decoded_bytes"].as_u64().unwrap(), compressed["capacity_bytes"].as_u64().unwrap())
    };
    let (decoded, compressed) = caches(&[], "half.json");
    // Half of the store's share each (the decoded half rounded down to whole 16³ u16 bricks of 8 KiB).
    assert!(compressed > 1 << 20 && decoded <= compressed && compressed - decoded < 8192, "{decoded} {compressed}");
    let (own_decoded, own_compressed) = caches(&["--compressed-cache-mb", "3"], "own.json");
    assert_eq!(own_compressed, 3 << 20);
    assert!(own_decoded >= 2 * decoded, "the whole share decoded: {own_decoded} against {decoded}");
    std::fs::remove_dir_all(&dir).unwrap();
}
