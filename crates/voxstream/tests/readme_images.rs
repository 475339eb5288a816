//! The README's pictures are what the build renders: every `voxstream … --out docs/images/NAME.png` command in
//! README.md is run (after the `voxstream import`, `synth-rgbd` and `fuse` commands writing to `/tmp/` it depends
//! on), and its image is compared with the committed one. `scripts/make-readme-images.sh` regenerates them (this
//! test with `VOXSTREAM_UPDATE_README_IMAGES=1`).
//!
//! The commands that read `data/real/` need `scripts/fetch-real-data.sh`; with `VOXSTREAM_SKIP_REAL_DATA=1` and no
//! data they are skipped (and said to be).

use std::path::Path;
use std::process::Command;

mod common;

use common::repository_root;

/// Largest difference of a channel (of 255) that counts as equal: the PNGs are 8-bit, and a different libm may
/// round a sample differently.
const CHANNEL_TOLERANCE: u8 = 2;
/// Fraction of pixels that may differ by more than the tolerance.
const MAX_DIFFERING_FRACTION: f64 = 0.001;

/// The `voxstream` commands of README.md, in order, from code blocks (continuation lines joined) and from backticks.
fn readme_commands(readme: &str) -> Vec<String> {
    let mut commands = Vec::new();
    let mut in_block = false;
    let mut pending = String::new();
    for line in readme.lines() {
        if line.trim_start().starts_with("```") {
            in_block = !in_block;
            continue;
        }
        if in_block {
            let text = line.trim();
            let (text, continued) = match text.strip_suffix('\\') {
                Some(head) => (head.trim_end(), true),
                None => (text, false),
            };
            pending.push_str(text);
            pending.push(' ');
            if !continued {
                commands.push(std::mem::take(&mut pending));
            }
        } else {
            commands.extend(line.split('`').skip(1).step_by(2).map(String::from));
        }
    }
    commands
        .into_iter()
        .map(|c| c.trim().trim_start_matches("./target/release/").to_string())
        .filter(|c| {
            ["voxstream import ", "voxstream render ", "voxstream synth-rgbd ", "voxstream fuse "]
                .iter()
                .any(|start| c.starts_with(start))
        })
        .collect()
}

/// Decoded 8-bit RGB pixels and size.
fn decode(path: &Path) -> (Vec<u8>, u32, u32) {
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    ));
    let mut reader = decoder.read_info().unwrap();
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buffer).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
    buffer.truncate(info.buffer_size());
    (buffer, info.width, info.height)
}

#[test]
fn readme_pictures_match_what_the_build_renders() {
    let root = repository_root();
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let commands = readme_commands(&readme);
    let update = std::env::var_os("VOXSTREAM_UPDATE_README_IMAGES").is_some();
    let have_data = root.join("data/real/mni152_t1.nii.gz").exists();
    let skip_data = !have_data && std::env::var_os("VOXSTREAM_SKIP_REAL_DATA").is_some();
    assert!(
        have_data || skip_data,
        "real data missing: run scripts/fetch-real-data.sh (or set VOXSTREAM_SKIP_REAL_DATA=1)"
    );

    let work = std::env::temp_dir().join(format!("voxstream-readme-images-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&work);
    std::fs::create_dir_all(&work).unwrap();
    let work_text = work.display().to_string();
    let mut pictures = Vec::new();
    let mut failures = Vec::new();
    for command in &commands {
        let is_picture = command.starts_with("voxstream render ") && command.contains("--out docs/images/");
        // Imports, and the synthetic RGB-D sequence and fused store a picture of depth fusion is rendered from.
        let is_store_import = ["voxstream import ", "voxstream synth-rgbd ", "voxstream fuse "]
            .iter()
            .any(|start| command.starts_with(start))
            && command.contains("--out /tmp/");
        if !is_picture && !is_store_import {
            continue;
        }
        let needs_data = command.contains("data/real/") || command.contains("/tmp/");
        if needs_data && skip_data {
            println!("skipped (no real data): {command}");
            continue;
        }
        // Stores and images go to a scratch folder; everything else is read from the repository.
        let concrete = command
            .replace("/tmp/", "{work}/")
            .replace("--out docs/images/", "--out {work}/")
            .replace("{work}", &work_text);
        let words: Vec<&str> = concrete.split_whitespace().collect();
        let output = Command::new(env!("CARGO_BIN_EXE_voxstream"))
            .args(&words[1..])
            .arg("--quiet")
            .current_dir(&root)
            .output()
            .unwrap();
        assert!(output.status.success(), "`{command}` failed:\n{}", String::from_utf8_lossy(&output.stderr));
        if !is_picture {
            continue;
        }
        let name = command.split("--out docs/images/").nth(1).unwrap().split_whitespace().next().unwrap().to_string();
        let rendered = work.join(&name);
        let committed = root.join("docs/images").join(&name);
        pictures.push(name.clone());
        if update {
            std::fs::copy(&rendered, &committed).unwrap();
            println!("updated docs/images/{name}");
            continue;
        }
        let (new, width, height) = decode(&rendered);
        let (old, old_width, old_height) = decode(&committed);
        if (width, height) != (old_width, old_height) {
            failures.push(format!("{name}: {old_width}x{old_height} committed, {width}x{height} rendered"));
            continue;
        }
        let differing = new
            .chunks_exact(3)
            .zip(old.chunks_exact(3))
            .filter(|(a, b)| a.iter().zip(b.iter()).any(|(x, y)| x.abs_diff(*y) > CHANNEL_TOLERANCE))
            .count();
        let fraction = differing as f64 / (width * height) as f64;
        println!("{name}: {:.3}% of pixels differ", fraction * 100.0);
        if fraction > MAX_DIFFERING_FRACTION {
            failures.push(format!("{name}: {:.2}% of pixels differ from what `{command}` renders", fraction * 100.0));
        }
    }
    // Every picture the README shows has its command there.
    for line in readme.lines() {
        for reference in line.split("](docs/images/").skip(1) {
            let name = reference.split(')').next().unwrap();
            let skipped = skip_data && !pictures.iter().any(|p| p == name);
            assert!(
                pictures.iter().any(|p| p == name) || skipped && !name.starts_with("sponge"),
                "README.md shows docs/images/{name} without a `voxstream render … --out docs/images/{name}` command"
            );
        }
    }
    assert!(pictures.len() >= 4, "README.md names only {} picture commands", pictures.len());
    let _ = std::fs::remove_dir_all(&work);
    assert!(
        failures.is_empty(),
        "README pictures out of date (run scripts/make-readme-images.sh):\n{}",
        failures.join("\n")
    );
}

#[test]
fn readme_commands_are_found() {
    let commands = readme_commands(
        "text `voxstream render a --out docs/images/a.png` more\n```sh\n./target/release/voxstream render b \\\n    --out docs/images/b.png\nvoxstream import x --out /tmp/x.zarr\n```\n",
    );
    assert_eq!(
        commands,
        [
            "voxstream render a --out docs/images/a.png",
            "voxstream render b --out docs/images/b.png",
            "voxstream import x --out /tmp/x.zarr"
        ]
    );
}
