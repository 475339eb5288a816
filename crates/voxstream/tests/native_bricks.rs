//! 8-bit volumes in 8-bit bricks (issue "a ray caster faster than VTK's", item 2): a `u8` store keeps one byte per
//! voxel in the brick pool, half the 16-bit pool's memory, and renders the same image within a stated tolerance
//! (each byte's value differs from its 16-bit quantisation by at most half a 16-bit step).

mod common;

use std::path::Path;

use common::{stderr, voxstream};

fn scratch(name: &str) -> std::path::PathBuf {
    common::scratch("native-bricks", name)
}

/// A 72×64×56 u8 NRRD: a textured ball in a box of `air` (0, or above 0 so that the value range starts there).
fn write_ball(path: &Path, air: u8) {
    common::write_nrrd(path, [72, 64, 56], "1 1 1.2", |i, j, k| {
        let d = (((i as f64 - 36.0) / 27.0).powi(2)
            + ((j as f64 - 32.0) / 24.0).powi(2)
            + ((k as f64 - 28.0) / 21.0).powi(2))
        .sqrt();
        let texture = ((i * 7 + j * 13 + k * 29) % 23) as f64;
        if d < 1.0 {
            (air as f64 + 180.0 * (1.0 - d * d) + texture).min(255.0) as u8
        } else {
            air
        }
    });
}

fn read_png(path: &Path) -> Vec<u8> {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buffer).unwrap();
    buffer.truncate(info.buffer_size());
    buffer
}

fn stats(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Peak signal-to-noise ratio of two 8-bit images, and their largest difference.
fn compare(a: &[u8], b: &[u8]) -> (f64, u8) {
    assert_eq!(a.len(), b.len());
    let squared: f64 = a.iter().zip(b).map(|(&x, &y)| (x as f64 - y as f64).powi(2)).sum::<f64>() / a.len() as f64;
    let largest = a.iter().zip(b).map(|(&x, &y)| x.abs_diff(y)).max().unwrap_or(0);
    (10.0 * (255.0f64.powi(2) / squared.max(1e-12)).log10(), largest)
}

/// Renders `store` with `--brick-bits auto` and `16`; returns both images and both stats.
fn render_both(dir: &Path, store: &str, look: &[&str]) -> [(Vec<u8>, serde_json::Value); 2] {
    ["auto", "16"].map(|bits| {
        let (out, json) = (format!("{store}-{bits}.png"), format!("{store}-{bits}.json"));
        let mut args =
            vec!["render", store, "--width", "96", "--height", "96", "--out", &out, "--stats", &json, "--quiet"];
        args.extend_from_slice(&["--brick-bits", bits]);
        args.extend_from_slice(look);
        let output = voxstream(&args, dir);
        assert!(output.status.success(), "{}", stderr(&output));
        (read_png(&dir.join(&out)), stats(&dir.join(&json)))
    })
}

#[test]
fn u8_stores_render_from_8_bit_bricks_in_half_the_memory() {
    let dir = scratch("u8");
    for (name, air) in [("zero", 0u8), ("offset", 17)] {
        write_ball(&dir.join(format!("{name}.nrrd")), air);
        let store = format!("{name}.zarr");
        let nrrd = format!("{name}.nrrd");
        let output = voxstream(&["import", &nrrd, "--out", &store, "--brick-size", "16", "--quiet"], &dir);
        assert!(output.status.success(), "{}", stderr(&output));

        // Volume rendering: the same bricks, half the bytes, and the same image within a stated tolerance.
        let [(narrow, narrow_stats), (wide, wide_stats)] = render_both(&dir, &store, &[]);
        assert_eq!(narrow_stats["converged"], true);
        assert_eq!(narrow_stats["bricks_resident"], wide_stats["bricks_resident"], "{name}");
        let (narrow_bytes, wide_bytes) = (
            narrow_stats["resident_bytes_peak"].as_f64().unwrap(),
            wide_stats["resident_bytes_peak"].as_f64().unwrap(),
        );
        // Per brick: 18³ voxels of 1 byte instead of 2, plus the same bookkeeping; nodes are the same.
        assert!(narrow_bytes < 0.6 * wide_bytes, "{name}: {narrow_bytes} bytes resident, 16-bit {wide_bytes}");
        // Air stays exactly 0 in 8-bit bricks, so empty space is skipped as before: the same samples.
        assert_eq!(narrow_stats["samples"], wide_stats["samples"], "{name}");
        let (psnr, largest) = compare(&narrow, &wide);
        assert!(psnr >= 50.0 && largest <= 3, "{name}: {psnr:.1} dB, largest difference {largest}");

        // Isosurfaces read the same bricks (corners scaled to 16-bit units).
        let iso = (air as f64 + 90.0).to_string();
        let [(narrow, _), (wide, _)] = render_both(&dir, &store, &["--iso", &iso]);
        let (psnr, _) = compare(&narrow, &wide);
        assert!(psnr >= 40.0, "{name} isosurface: {psnr:.1} dB");
        assert!(narrow.iter().any(|&v| v > 0), "{name}: the isosurface image is empty");
    }
}

#[test]
fn u16_stores_keep_16_bit_bricks_whatever_the_flag() {
    let dir = scratch("u16");
    // The same ball as 16-bit samples: `auto` must leave it in 16-bit bricks, the same bytes as `16`.
    let (nx, ny, nz) = (40usize, 36usize, 32usize);
    let mut bytes =
        format!("NRRD0004\ntype: ushort\ndimension: 3\nsizes: {nx} {ny} {nz}\nencoding: raw\nendian: little\n\n")
            .into_bytes();
    for i in 0..nx * ny * nz {
        let v = ((i % nx) * 900 + (i / nx % ny) * 40) as u16;
        bytes.extend(v.to_le_bytes());
    }
    std::fs::write(dir.join("ramp.nrrd"), bytes).unwrap();
    let output = voxstream(&["import", "ramp.nrrd", "--out", "ramp.zarr", "--brick-size", "16", "--quiet"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    let [(auto, auto_stats), (wide, wide_stats)] = render_both(&dir, "ramp.zarr", &[]);
    assert_eq!(auto, wide);
    assert_eq!(auto_stats["resident_bytes_peak"], wide_stats["resident_bytes_peak"]);
}

#[test]
fn u8_bricks_give_the_same_bytes_with_and_without_gathered_corners() {
    use std::sync::Arc;
    use voxstream::render_command::{default_store_transfer_function, store_camera, store_placement};
    use voxstream_core::VoxelFormat;
    use voxstream_engine::{LoopLimits, Mode, Session};
    use voxstream_render::{InstructionSet, RenderSettings};
    use voxstream_store::{StoreProducer, StoreReader};

    // The ray loop reads 8-bit bricks' corners with AVX2 gathers where the CPU has AVX2 (the detected instruction
    // set), through slices in the baseline build: the same bytes. Bricks of 16³ so that many lanes share a pool
    // whose last brick's last cells need the slices.
    let dir = scratch("u8-gathers");
    write_ball(&dir.join("ball.nrrd"), 0);
    let output = voxstream(&["import", "ball.nrrd", "--out", "ball.zarr", "--brick-size", "16", "--quiet"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    let reader = Arc::new(StoreReader::open(&dir.join("ball.zarr")).expect("store"));
    let transfer_function = default_store_transfer_function(reader.attributes().typical_range()).expect("function");
    println!("this CPU: {}, gathers: {}", InstructionSet::detected(), InstructionSet::Detect.gathers());
    let render = |instruction_set: InstructionSet, format: Option<VoxelFormat>| {
        let settings = RenderSettings {
            width: 96,
            height: 96,
            placement: store_placement(&reader),
            instruction_set,
            ..RenderSettings::default()
        };
        let producer = StoreProducer::new(reader.clone()).expect("producer").with_voxel_format(format);
        let range = reader.attributes().value_range;
        let mut session =
            Session::with_value_range(producer, &transfer_function, settings, 64 << 20, LoopLimits::default(), range)
                .expect("session");
        let frame = session.render(&store_camera(reader.info(), 96, 96), Mode::Converged).expect("render");
        assert!(frame.is_converged());
        (frame.image, frame.samples, session.peak_resident_bytes())
    };
    let (gathered, gathered_samples, narrow_bytes) = render(InstructionSet::Detect, None);
    let (sliced, sliced_samples, _) = render(InstructionSet::Baseline, None);
    let covered = gathered.pixels.iter().filter(|p| p[3] > 0.01).count();
    assert!(covered > 800, "the ball covers {covered} pixels only");
    assert_eq!(gathered_samples, sliced_samples);
    assert!(gathered.pixels == sliced.pixels, "gathered and sliced corners give different images");
    // The bricks were 8-bit ones: a 16-bit pool of the same bricks takes much more memory.
    let (_, _, wide_bytes) = render(InstructionSet::Detect, Some(VoxelFormat::Wide));
    assert!((narrow_bytes as f64) < 0.6 * wide_bytes as f64, "{narrow_bytes} bytes, 16-bit {wide_bytes}");
}
