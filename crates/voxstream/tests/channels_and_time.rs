//! Issue 42 item 5: 4-D and 5-D OME-Zarr images (time, channel, z, y, x), as microscopes and napari users have them.
//! Their other channels and time points could not be reached, and channel 0 was drawn without a word. `--channel`
//! and `--time` choose the volume (`render`, `view`, `info`, Python's `open`), the run says which it draws, `info`
//! lists them with the chosen channel's `omero` display settings, and the default transfer function follows those.
//!
//! The images are written by zarr-python (`data/venv`, made by `scripts/fetch-real-data.sh`), as other tools write
//! them.

mod common;

use std::path::Path;
use std::process::Command;

use common::{data_folder, read_png, scratch, stderr, voxstream};

/// Writes `cells.ome.zarr` (OME-Zarr 0.4, t = 2, c = 3, 40 × 36 × 32 voxels, a pyramid of two levels, `omero`
/// channels) and `plane.ome.zarr` (the 3-D volume of t = 1, c = 1 alone) in `dir`. Plane (t, c) is a ball whose
/// brightness is 1000 + 500·t + 200·c at its centre.
fn write_images(dir: &Path) {
    let script = r#"
import sys, numpy as np, zarr
out = sys.argv[1]
z, y, x = np.mgrid[0:32, 0:36, 0:40].astype(np.float64)
r = np.sqrt(((x - 20) / 14) ** 2 + ((y - 18) / 12) ** 2 + ((z - 16) / 11) ** 2)
ball = np.clip(1 - r, 0, None)
data = np.zeros((2, 3, 32, 36, 40), np.uint16)
for t in range(2):
    for c in range(3):
        data[t, c] = (ball * (1000 + 500 * t + 200 * c)).astype(np.uint16)
def write(path, array, axes, omero=None):
    group = zarr.open_group(path, mode="w", zarr_format=2)
    levels = [array, array[..., ::2, ::2, ::2]]
    n = array.ndim
    for i, a in enumerate(levels):
        chunks = (1,) * (n - 3) + (16, 16, 16)
        group.create_array(str(i), shape=a.shape, chunks=chunks, dtype=a.dtype)[:] = a
    datasets = [{"path": str(i), "coordinateTransformations": [{"type": "scale", "scale": [1.0] * (n - 3) + [2.0 ** i] * 3}]}
                for i in range(2)]
    group.attrs["multiscales"] = [{"version": "0.4", "axes": axes, "datasets": datasets}]
    if omero:
        group.attrs["omero"] = omero
space = [{"name": n, "type": "space", "unit": "micrometer"} for n in "zyx"]
omero = {"channels": [
    {"label": "DAPI", "color": "0000FF", "window": {"start": 0, "end": 1000}},
    {"label": "GFP", "color": "00FF00", "window": {"start": 100, "end": 1700}},
    {"label": "RFP", "color": "FF0000", "window": {"start": 0, "end": 2000}}]}
write(out + "/cells.ome.zarr", data, [{"name": "t", "type": "time"}, {"name": "c", "type": "channel"}] + space, omero)
write(out + "/plane.ome.zarr", data[1, 1], space)
"#;
    let python = data_folder().join("venv/bin/python");
    let status = Command::new(&python).args(["-c", script, &dir.display().to_string()]).status().unwrap_or_else(|e| {
        panic!("{}: {e} (run scripts/fetch-real-data.sh: it installs zarr into data/venv)", python.display())
    });
    assert!(status.success(), "writing the OME-Zarr images failed");
}

fn render(dir: &Path, args: &[&str], out: &str) -> (std::process::Output, Vec<u8>) {
    let mut all = vec!["render"];
    all.extend_from_slice(args);
    all.extend(["--width", "64", "--height", "64", "--out", out]);
    let output = voxstream(&all, dir);
    let pixels = if output.status.success() { read_png(&dir.join(out)).2 } else { Vec::new() };
    (output, pixels)
}

#[test]
fn channels_and_time_points_are_chosen_listed_and_drawn() {
    let dir = scratch("channels_and_time", "planes");
    write_images(&dir);
    std::fs::write(dir.join("tf.json"), r#"{"points": [[0, 0, 0, 0, 0], [1800, 1, 1, 1, 0.5]]}"#).unwrap();
    // The chosen plane draws as the same volume stored alone, byte for byte.
    let tf = ["--tf", "tf.json"];
    let (output, chosen) =
        render(&dir, &[&["cells.ome.zarr", "--channel", "1", "--time", "1"][..], &tf].concat(), "chosen.png");
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(stderr(&output).contains("channel 1 of 3 (\"GFP\"), time point 1 of 2"), "{}", stderr(&output));
    let (output, alone) = render(&dir, &[&["plane.ome.zarr"][..], &tf].concat(), "alone.png");
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(chosen == alone, "channel 1 at time 1 does not draw as that volume stored alone");
    // Another plane draws differently, and the default (0, 0) is said, with the flags that choose others.
    let (output, first) = render(&dir, &[&["cells.ome.zarr"][..], &tf].concat(), "first.png");
    assert!(output.status.success(), "{}", stderr(&output));
    let said = stderr(&output);
    assert!(
        said.contains("channel 0 of 3 (\"DAPI\"), time point 0 of 2 (the others: --channel C, --time T)"),
        "{said}"
    );
    assert!(first != chosen, "channel 0 draws as channel 1");
    // The default transfer function is the channel's omero window in its colour: GFP draws green only.
    let (output, green) = render(&dir, &["cells.ome.zarr", "--channel", "1"], "green.png");
    assert!(output.status.success(), "{}", stderr(&output));
    let (red, green_sum, blue) = green
        .chunks_exact(3)
        .fold((0u64, 0u64, 0u64), |(r, g, b), p| (r + u64::from(p[0]), g + u64::from(p[1]), b + u64::from(p[2])));
    assert!(green_sum > 1000 && red == 0 && blue == 0, "GFP's colour: {red} {green_sum} {blue}");
    // `info` lists them and the omero settings, in text and JSON.
    let output = voxstream(&["info", "cells.ome.zarr", "--channel", "2"], &dir);
    let text = String::from_utf8_lossy(&output.stdout).to_string();
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(text.contains("showing      channel 2 of 3 (\"RFP\"), time point 0 of 2"), "{text}");
    assert!(text.contains("omero        \"RFP\", colour #FF0000, window 0 to 2000"), "{text}");
    let output = voxstream(&["info", "cells.ome.zarr", "--json"], &dir);
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(json["leading_axes"][1]["kind"], "channel");
    assert_eq!(json["leading_axes"][1]["extent"], 3);
    assert_eq!(json["omero"]["label"], "DAPI");
    // What does not exist: one line each, nothing written.
    for (args, needle) in [
        (&["cells.ome.zarr", "--channel", "3"][..], "--channel 3: the image has 3 channels (0 to 2)"),
        (&["cells.ome.zarr", "--time", "2"][..], "--time 2: the image has 2 time points (0 to 1)"),
        (&["plane.ome.zarr", "--channel", "1"][..], "--channel: the image has no channel axis (its axes: z, y, x)"),
        (&["sponge", "--time", "1"][..], "--channel and --time apply to 4-D and 5-D OME-Zarr images"),
    ] {
        let (output, _) = render(&dir, args, "refused.png");
        let text = stderr(&output);
        assert!(!output.status.success(), "{args:?}: {text}");
        assert_eq!(text.trim_end().lines().count(), 1, "{args:?}: {text}");
        assert!(text.contains(needle), "{args:?}: {text}");
        assert!(!dir.join("refused.png").exists());
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Other tools' images (zarr-python, as the walk-through wrote them): one bright outlier does not stretch the default
/// transfer function over an empty image (the open-time scan keeps the samples' percentiles), the scan's bytes are
/// counted in `--stats` apart from rendering's, and OME-NGFF RFC-4's anatomical orientation is read.
#[test]
fn an_outlier_an_orientation_and_the_opening_scan_of_other_tools_images() {
    let dir = scratch("channels_and_time", "outlier");
    let script = r#"
import sys, numpy as np, zarr
out = sys.argv[1]
z, y, x = np.mgrid[0:48, 0:48, 0:48].astype(np.float64)
r = np.sqrt((x - 24) ** 2 + (y - 24) ** 2 + (z - 24) ** 2) / 18
data = np.where(r < 1, 1000 + 2000 * (1 - r), 0).astype(np.uint16)
data[20:26, 20:26, 20:26] = 60000
def write(path, axes):
    group = zarr.open_group(path, mode="w", zarr_format=2)
    for i, a in enumerate([data, data[::2, ::2, ::2]]):
        group.create_array(str(i), shape=a.shape, chunks=(16, 16, 16), dtype=a.dtype)[:] = a
    datasets = [{"path": str(i), "coordinateTransformations": [{"type": "scale", "scale": [2.0 ** i] * 3}]}
                for i in range(2)]
    group.attrs["multiscales"] = [{"version": "0.4", "axes": axes, "datasets": datasets}]
write(out + "/outlier.ome.zarr", [{"name": n, "type": "space"} for n in "zyx"])
values = {"z": "superior-to-inferior", "y": "anterior-to-posterior", "x": "left-to-right"}
write(out + "/oriented.ome.zarr",
      [{"name": n, "type": "space", "orientation": {"type": "anatomical", "value": values[n]}} for n in "zyx"])
"#;
    let python = data_folder().join("venv/bin/python");
    let status = Command::new(&python).args(["-c", script, &dir.display().to_string()]).status().unwrap();
    assert!(status.success(), "writing the OME-Zarr images failed");
    let (output, pixels) = render(&dir, &["outlier.ome.zarr", "--stats", "s.json"], "outlier.png");
    assert!(output.status.success(), "{}", stderr(&output));
    let lit = pixels.chunks_exact(3).filter(|p| p.iter().any(|&v| v > 8)).count();
    assert!(lit > 300, "the ball shows under the default transfer function: {lit} pixels lit");
    assert!(!stderr(&output).contains("the image is empty"), "{}", stderr(&output));
    let info = String::from_utf8_lossy(&voxstream(&["info", "outlier.ome.zarr"], &dir).stdout).to_string();
    assert!(info.contains("value range  0 to 60000") && info.contains("99.5%:"), "{info}");
    // The open-time scan read level 0's chunks (48³ u16, ~220 kB raw); with --value-range it is not made.
    let stats = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(name)).unwrap()).unwrap()
    };
    let scanned = stats("s.json")["file_bytes_read_opening"].as_u64().unwrap();
    let (output, _) = render(&dir, &["outlier.ome.zarr", "--value-range", "0,60000", "--stats", "v.json"], "v.png");
    assert!(output.status.success(), "{}", stderr(&output));
    let given = stats("v.json")["file_bytes_read_opening"].as_u64().unwrap();
    assert!(scanned > given + 20_000, "opening read {scanned} bytes with the scan, {given} without");
    // RFC-4: x left-to-right (R), y anterior-to-posterior (P), z superior-to-inferior (I).
    let output = voxstream(&["info", "oriented.ome.zarr", "--json"], &dir);
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(json["orientation"], "RPI", "{json}");
    std::fs::remove_dir_all(&dir).ok();
}
