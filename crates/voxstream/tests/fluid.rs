//! `voxstream render --fluid` end to end (issue 48, Reichl ch. 6): a real SPH run and generated point files drawn
//! as a fluid, time series, the stats it writes, and the flags it refuses.

mod common;

use std::path::Path;

use common::{real_data_dir, scratch, stderr, voxstream};

/// Writes `points` as a binary little-endian PLY of float x, y, z.
fn write_points(path: &Path, points: &[[f32; 3]]) {
    let mut ply = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
        points.len()
    )
    .into_bytes();
    for p in points {
        for c in p {
            ply.extend(c.to_le_bytes());
        }
    }
    std::fs::write(path, ply).expect("write the point file");
}

/// A block of water `n × n/2 × n` on a lattice of spacing `h`, its top at `height`, and `spray` lone droplets
/// above it.
fn pool(n: usize, h: f32, height_shift: f32, spray: usize) -> Vec<[f32; 3]> {
    let mut out = Vec::new();
    for k in 0..n {
        for j in 0..n / 2 {
            for i in 0..n {
                let wobble = ((i * 7 + j * 13 + k * 29) % 10) as f32 / 10.0 * 0.2 * h;
                out.push([i as f32 * h + wobble, j as f32 * h + height_shift, k as f32 * h + wobble]);
            }
        }
    }
    for d in 0..spray {
        let f = d as f32;
        out.push([(f * 3.7) % (n as f32 * h), n as f32 * h * 0.9 + (f * 1.3) % 5.0 * h, (f * 5.3) % (n as f32 * h)]);
    }
    out
}

fn stats(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("stats written")).expect("stats are JSON")
}

/// Fraction of the image's pixels that are not black.
fn covered(png: &Path) -> f64 {
    let decoder = png::Decoder::new(std::fs::File::open(png).expect("png written"));
    let mut reader = decoder.read_info().expect("a png");
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buffer).expect("a frame");
    let channels = info.color_type.samples();
    let pixels = buffer[..info.buffer_size()].chunks(channels).filter(|p| p[..3].iter().any(|&c| c > 8)).count();
    pixels as f64 / (info.width * info.height) as f64
}

#[test]
fn a_pool_with_spray_renders_as_a_fluid_and_reports_what_it_made() {
    let dir = scratch("fluid", "pool");
    write_points(&dir.join("pool.ply"), &pool(60, 0.05, 0.0, 300));
    let output = voxstream(
        &[
            "render",
            "pool.ply",
            "--fluid",
            "--out",
            "pool.png",
            "--stats",
            "pool.json",
            "--width",
            "160",
            "--height",
            "120",
        ],
        &dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
    let err = stderr(&output);
    assert!(err.contains("108300 particles as a fluid"), "{err}");
    let s = stats(&dir.join("pool.json"));
    assert_eq!(s["particles"], 108_300);
    // The default radius: 0.6 of the lattice's spacing.
    let radius = s["radius"].as_f64().unwrap();
    assert!((radius - 0.03).abs() < 0.004, "{radius}");
    let frame = &s["frames"][0];
    assert_eq!(frame["complete"], true);
    assert!(frame["bricks_made"].as_u64().unwrap() > 0);
    // Binning holds a few bytes per particle, not its 12-byte position.
    assert!(s["bins_bytes"].as_u64().unwrap() < 6 * 108_300, "{}", s["bins_bytes"]);
    let coverage = covered(&dir.join("pool.png"));
    assert!(coverage > 0.2 && coverage < 0.9, "{coverage}");
}

#[test]
fn a_time_series_is_a_pattern_or_a_folder_and_time_picks_a_step() {
    let dir = scratch("fluid", "series");
    std::fs::create_dir(dir.join("steps")).unwrap();
    for step in 0..3 {
        // The pool rises by 10 units a step: the bounds in the stats say which step was drawn.
        write_points(&dir.join(format!("steps/splash_{step:04}.ply")), &pool(20, 0.1, 10.0 * step as f32, 0));
    }
    for (source, time) in [("steps/splash_*.ply", "2"), ("steps", "1")] {
        let output = voxstream(
            &[
                "render", source, "--fluid", "--time", time, "--out", "t.png", "--stats", "t.json", "--width", "64",
                "--height", "48",
            ],
            &dir,
        );
        assert!(output.status.success(), "{source}: {}", stderr(&output));
        let s = stats(&dir.join("t.json"));
        let name = s["source"].as_str().unwrap().to_string();
        assert!(name.ends_with(&format!("splash_000{time}.ply")), "{name}");
        assert!(stderr(&output).contains(&format!("time step {time} of 0..2")), "{}", stderr(&output));
    }
    let output = voxstream(&["render", "steps/splash_*.ply", "--fluid", "--time", "3", "--out", "t.png"], &dir);
    assert!(!output.status.success());
    let err = stderr(&output);
    assert!(err.contains("--time 3") && err.contains("has 3 time steps (0 to 2)"), "{err}");
    let output = voxstream(&["render", "steps/nothing_*.ply", "--fluid", "--out", "t.png"], &dir);
    assert!(stderr(&output).contains("no particle files there"), "{}", stderr(&output));
}

#[test]
fn flags_that_do_not_apply_to_a_fluid_are_refused_with_the_fix() {
    let dir = scratch("fluid", "flags");
    write_points(&dir.join("p.ply"), &pool(10, 0.1, 0.0, 0));
    let refused = |args: &[&str], expected: &str| {
        let output = voxstream(args, &dir);
        assert!(!output.status.success(), "{args:?} succeeded");
        let err = stderr(&output);
        assert!(err.contains(expected), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
    };
    refused(
        &["render", "p.ply", "--fluid", "--iso", "0.5"],
        "--iso (the fluid's surface is its spheres) does not apply with --fluid",
    );
    refused(&["render", "p.ply", "--particle-radius", "0.1"], "--particle-radius applies to fluids: add --fluid");
    refused(&["render", "p.ply", "--fluid", "--particle-radius", "-1"], "--particle-radius -1 is out of range");
    refused(&["render", "p.ply", "--fluid", "--particle-radius", "1", "--fluid-cell", "0.1"], "more than 3 cells");
    refused(&["render", "p.ply", "--fluid", "--foam", "1.5"], "--foam 1.5 is out of range");
    refused(&["render", "p.ply", "--fluid", "--fluid-cell", "1e-9"], "give a larger --particle-radius or --fluid-cell");
    refused(&["view", "p.ply", "--fluid"], "view --fluid is not built yet");
    refused(&["render", "p.ply", "--fluid", "--width", "200000", "--height", "200000"], "--width/--height");
    let output = voxstream(&["render", "p.ply", "--fluid", "--smooth", "none", "--out", "none.png"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
}

#[test]
fn a_budget_too_small_for_the_view_is_said_and_the_image_still_written() {
    let dir = scratch("fluid", "budget");
    write_points(&dir.join("big.ply"), &pool(200, 0.01, 0.0, 0));
    let output = voxstream(
        &[
            "render",
            "big.ply",
            "--fluid",
            "--fluid-cell",
            "0.0025",
            "--budget-mb",
            "1",
            "--lod-bias",
            "6",
            "--out",
            "b.png",
            "--width",
            "96",
            "--height",
            "64",
        ],
        &dir,
    );
    assert!(!output.status.success());
    let err = stderr(&output);
    assert!(err.contains("incomplete") && err.contains("--budget-mb 1"), "{err}");
    assert!(dir.join("b.png").exists());
    // 46 MB of particles: not left in the temporary folder on every run.
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_file_too_large_to_bin_here_is_refused_before_it_is_read() {
    // A header announcing ten billion points and a sparse file as long as they would be: nothing is read.
    let dir = scratch("fluid", "huge");
    let count: u64 = 10_000_000_000;
    let header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {count}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    );
    let path = dir.join("huge.ply");
    std::fs::write(&path, &header).unwrap();
    let file = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    file.set_len(header.len() as u64 + 12 * count).unwrap();
    let output = voxstream(&["render", "huge.ply", "--fluid", "--out", "h.png"], &dir);
    assert!(!output.status.success());
    let err = stderr(&output);
    assert!(err.contains("10000000000 particles take about 74.5 GiB to bin"), "{err}");
    assert!(err.contains("thin the file"), "{err}");
    let _ = std::fs::remove_file(&path);
}

/// PySPH's dam break (a real SPH run, `scripts/fetch-real-data.sh`) drawn as a fluid: the water column fills
/// part of the view.
#[test]
fn a_real_sph_run_renders_as_a_fluid() {
    let Some(real) = real_data_dir() else { return };
    let dir = scratch("fluid", "dam");
    let file = real.join("dam_break_3d_fluid.vtu");
    let file = file.to_str().unwrap();
    let output = voxstream(
        &["render", file, "--fluid", "--out", "dam.png", "--stats", "dam.json", "--width", "160", "--height", "120"],
        &dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
    let s = stats(&dir.join("dam.json"));
    assert_eq!(s["particles"], 9360);
    assert_eq!(s["frames"][0]["complete"], true);
    // dx 0.04: the spacing estimate finds it, the radius is 0.6 of it.
    let radius = s["radius"].as_f64().unwrap();
    assert!((radius - 0.024).abs() < 0.004, "{radius}");
    let coverage = covered(&dir.join("dam.png"));
    assert!(coverage > 0.1, "{coverage}");
}
