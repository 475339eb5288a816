//! The anatomical orientation (issue 42 item 7) through the real binary: a NIfTI's qform reaches the store, its OME
//! axes (OME-NGFF RFC-4) and `info`; the default view, the anatomical presets and the anatomical slices look at the
//! same side of the same head whichever way its file stores it; `--orientation` gives or replaces one; the presets
//! that need one say how to give it.

mod common;

use std::path::Path;

use common::{nifti_u8_header, read_png, scratch, stderr, voxstream};
use voxstream_store::StoreReader;

/// Samples per axis of the test head (even at every level, so that a flipped copy's levels are the same blocks).
const N: usize = 64;

/// A head-like volume in RAS index axes (x to the right, y to the front, z up): a ball, a nose at the front and a
/// little to the right, a ridge on top towards the back. No symmetry maps it onto itself.
fn head(i: usize, j: usize, k: usize) -> u8 {
    let at = |c: [f64; 3], r: f64| {
        let d = [i as f64 - c[0], j as f64 - c[1], k as f64 - c[2]];
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() < r
    };
    if at([36.0, 52.0, 30.0], 7.0) {
        250
    } else if at([30.0, 20.0, 50.0], 6.0) {
        180
    } else if at([32.0, 32.0, 30.0], 20.0) {
        90
    } else {
        0
    }
}

/// A NIfTI-1 of the head: `flip` stores it with x and y reversed (LPS index axes) and says so with a qform of 180°
/// about z; `qform` false writes no orientation at all.
fn write_nifti(path: &Path, flip: bool, qform: bool) {
    let mut h = nifti_u8_header([N; 3], [1.0; 4], 2); // millimetres
    if qform {
        h[252..254].copy_from_slice(&1i16.to_le_bytes());
        // Quaternion (b, c, d): none is the identity (RAS), d = 1 is 180° about z (x and y reversed).
        let d = if flip { 1.0f32 } else { 0.0 };
        h[264..268].copy_from_slice(&d.to_le_bytes());
    }
    for k in 0..N {
        for j in 0..N {
            for i in 0..N {
                h.push(if flip { head(N - 1 - i, N - 1 - j, k) } else { head(i, j, k) });
            }
        }
    }
    std::fs::write(path, h).unwrap();
}

fn run(dir: &Path, args: &[&str]) -> String {
    let output = voxstream(args, dir);
    assert!(output.status.success(), "{args:?}: {}", stderr(&output));
    String::from_utf8_lossy(&output.stdout).into_owned() + &stderr(&output)
}

/// The image `render` makes of `store` with `extra` flags.
fn render(dir: &Path, store: &str, extra: &[&str]) -> Vec<u8> {
    let out = format!("{store}-{}.png", extra.join("").replace(['=', '-', ' '], "_"));
    let mut args = vec!["render", store, "--width", "96", "--height", "96", "--out", &out, "--quiet"];
    args.extend_from_slice(extra);
    run(dir, &args);
    read_png(&dir.join(&out)).2
}

/// Mean and largest absolute difference of two images' bytes.
fn difference(a: &[u8], b: &[u8]) -> (f64, u8) {
    assert_eq!(a.len(), b.len());
    let diffs: Vec<u8> = a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).collect();
    (diffs.iter().map(|&d| d as f64).sum::<f64>() / diffs.len() as f64, diffs.into_iter().max().unwrap_or(0))
}

#[test]
fn one_head_stored_two_ways_is_seen_from_the_same_side() {
    let dir = scratch("orientation", "two-ways");
    write_nifti(&dir.join("ras.nii"), false, true);
    write_nifti(&dir.join("lps.nii"), true, true);
    for name in ["ras", "lps"] {
        let said = run(&dir, &["import", &format!("{name}.nii"), "--out", &format!("{name}.zarr")]);
        assert!(said.contains(&format!("u8, oriented {}", name.to_uppercase())), "{said}");
    }
    // The orientation reaches the store, its OME-Zarr axes (RFC-4) and `info`.
    let ras = StoreReader::open(&dir.join("ras.zarr")).unwrap();
    assert_eq!(ras.info().orientation.map(|o| o.code()).as_deref(), Some("RAS"));
    let zarr: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("lps.zarr/zarr.json")).unwrap()).unwrap();
    let axes = &zarr["attributes"]["ome"]["multiscales"][0]["axes"];
    let values: Vec<&str> = (0..3).map(|a| axes[a]["orientation"]["value"].as_str().unwrap()).collect();
    assert_eq!(values, ["inferior-to-superior", "anterior-to-posterior", "right-to-left"], "{axes}");
    assert!(axes.as_array().unwrap().iter().all(|a| a["orientation"]["type"] == "anatomical"), "{axes}");
    let text = run(&dir, &["info", "lps.zarr"]);
    assert!(
        text.contains("orientation  LPS (x right-to-left, y anterior-to-posterior, z inferior-to-superior)"),
        "{text}"
    );
    let json: serde_json::Value = serde_json::from_str(&run(&dir, &["info", "ras.zarr", "--json"])).unwrap();
    assert_eq!(json["orientation"], "RAS");

    // The same head from the same side: the default view, an anatomical preset, an axial slice. The flipped copy is
    // the head turned 180° about z, and so is its camera: the images agree up to the samples' rounding.
    for extra in [&[][..], &["--view", "anterior"], &["--view", "left"], &["--slice", "axial=40"]] {
        let (mean, largest) = difference(&render(&dir, "ras.zarr", extra), &render(&dir, "lps.zarr", extra));
        assert!(mean < 0.05 && largest <= 3, "{extra:?}: the two differ by {mean:.3} on average, {largest} at most");
    }
    // The default view looks at the face, from the patient's left and above, head up: in the RAS store's axes
    // from +y (the front), −x (the left), +z; in the LPS store's from −y, +x, +z.
    for (store, expected) in [("ras.zarr", [-0.55, 0.65, 0.52]), ("lps.zarr", [0.55, -0.65, 0.52])] {
        run(&dir, &["render", store, "--width", "32", "--height", "32", "--out", "c.png", "--stats", "c.json"]);
        let stats: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("c.json")).unwrap()).unwrap();
        let vector = |name: &str| -> Vec<f64> {
            stats["camera"][name].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect()
        };
        let (eye, target, up) = (vector("eye"), vector("target"), vector("up"));
        let towards: Vec<f64> = (0..3).map(|a| eye[a] - target[a]).collect();
        let length = towards.iter().map(|v| v * v).sum::<f64>().sqrt();
        let norm = expected.iter().map(|v: &f64| v * v).sum::<f64>().sqrt();
        for a in 0..3 {
            assert!((towards[a] / length - expected[a] / norm).abs() < 1e-9, "{store}: the eye towards {towards:?}");
        }
        assert_eq!(up, [0.0, 0.0, 1.0], "{store}: head up");
    }
    let default = render(&dir, "ras.zarr", &[]);

    // Without an orientation the index axes' convention holds (from −y, +z up): for this RAS head, the back. The
    // check above can fail.
    write_nifti(&dir.join("plain.nii"), false, false);
    run(&dir, &["import", "plain.nii", "--out", "plain.zarr", "--quiet"]);
    assert_eq!(StoreReader::open(&dir.join("plain.zarr")).unwrap().info().orientation, None);
    let (mean, _) = difference(&default, &render(&dir, "plain.zarr", &[]));
    assert!(mean > 1.0, "the unoriented head should be seen from elsewhere: {mean:.3}");
    // `--orientation` says what the file does not, and the picture is the oriented one.
    run(&dir, &["import", "plain.nii", "--out", "given.zarr", "--orientation", "ras", "--quiet"]);
    assert_eq!(default, render(&dir, "given.zarr", &[]));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn orientations_that_cannot_be_used_are_one_line_with_the_fix() {
    let dir = scratch("orientation", "refused");
    write_nifti(&dir.join("plain.nii"), false, false);
    for (args, expected) in [
        (&["import", "plain.nii", "--out", "a.zarr", "--orientation", "RAR"][..], "names one body axis twice"),
        (&["import", "plain.nii", "--out", "a.zarr", "--orientation", "up"][..], "give three letters"),
    ] {
        let output = voxstream(args, &dir);
        let err = stderr(&output);
        assert_eq!(output.status.code(), Some(1), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains("--orientation") && err.contains(expected), "{err}");
        assert!(!dir.join("a.zarr").exists(), "nothing written");
    }
    run(&dir, &["import", "plain.nii", "--out", "plain.zarr", "--quiet"]);
    let output = voxstream(&["render", "plain.zarr", "--view", "anterior", "--out", "x.png"], &dir);
    let err = stderr(&output);
    assert_eq!(output.status.code(), Some(1), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("does not say its anatomical orientation") && err.contains("--orientation RAS"), "{err}");
    assert!(!dir.join("x.png").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
