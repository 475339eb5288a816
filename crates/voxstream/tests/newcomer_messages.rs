//! The newcomer's smaller frictions (issue 42 item 13), through the binary: an `import` command suggested for a
//! volume file that works as printed, "did you mean" for store and mesh paths, a store's level named as such, a
//! transfer function over a sliver of the data warned about, and I/O errors without "(os error N)".

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn voxstream(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_voxstream")).args(args).current_dir(dir).output().expect("run voxstream")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-newcomer-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Side of the test volume.
const SIDE: u16 = 16;

/// A 16³ little-endian `u16` ramp from 0 to 3400, as raw samples.
fn ramp_samples() -> Vec<u8> {
    let count = u32::from(SIDE).pow(3);
    (0..count).flat_map(|n| ((n * 3400 / (count - 1)) as u16).to_le_bytes()).collect()
}

/// The `voxstream import …` command between "run `" and "` first" of an error message, as arguments (after
/// `import`'s placeholders are filled in as a user would).
fn suggested_import(message: &str) -> Vec<String> {
    let start = message.find("run `voxstream ").unwrap_or_else(|| panic!("no command in: {message}")) + 15;
    let end = start + message[start..].find('`').unwrap();
    let command =
        message[start..end].replace("X,Y,Z", &format!("{SIDE},{SIDE},{SIDE}")).replace("u8|u16|i16|f32", "u16");
    command.split_whitespace().map(str::to_string).collect()
}

/// Imports the ramp as `ramp.zarr` in `dir`.
fn import_ramp(dir: &Path) {
    std::fs::write(dir.join("ramp.raw"), ramp_samples()).unwrap();
    let dims = format!("{SIDE},{SIDE},{SIDE}");
    let args = ["import", "ramp.raw", "--dims", &dims, "--dtype", "u16", "--out", "ramp.zarr", "--quiet"];
    let output = voxstream(&args, dir);
    assert!(output.status.success(), "{}", stderr(&output));
}

#[test]
fn a_raw_file_gets_an_import_command_that_works() {
    let dir = scratch("raw");
    std::fs::create_dir_all(dir.join("data")).unwrap();
    std::fs::write(dir.join("data/scan.raw"), ramp_samples()).unwrap();
    for command in ["render", "info"] {
        let output = voxstream(&[command, "data/scan.raw"], &dir);
        assert_eq!(output.status.code(), Some(1));
        assert_eq!(
            stderr(&output).trim_end(),
            format!(
                "error: data/scan.raw holds raw samples, not a store: run `voxstream import data/scan.raw --dims X,Y,Z \
                 --dtype u8|u16|i16|f32 --out scan.zarr` first (X,Y,Z: its dimensions; pick one --dtype), then \
                 `voxstream {command} scan.zarr`"
            )
        );
    }
    let message = stderr(&voxstream(&["info", "data/scan.raw"], &dir));
    let args = suggested_import(&message);
    let output = voxstream(&args.iter().map(String::as_str).collect::<Vec<_>>(), &dir);
    assert!(output.status.success(), "{args:?}: {}", stderr(&output));
    assert!(dir.join("scan.zarr").is_dir(), "the store is written into the current folder");
    assert!(!dir.join("data/scan.zarr").exists(), "not beside the input");
    assert!(voxstream(&["info", "scan.zarr"], &dir).status.success());
}

#[test]
fn a_volume_file_gets_an_import_command_into_the_current_folder() {
    let dir = scratch("nrrd");
    std::fs::create_dir_all(dir.join("data")).unwrap();
    let header =
        format!("NRRD0004\ntype: ushort\ndimension: 3\nsizes: {SIDE} {SIDE} {SIDE}\nencoding: raw\nendian: little\n\n");
    std::fs::write(dir.join("data/ramp.nrrd"), [header.into_bytes(), ramp_samples()].concat()).unwrap();
    let message = stderr(&voxstream(&["render", "data/ramp.nrrd"], &dir));
    assert!(message.contains("run `voxstream import data/ramp.nrrd --out ramp.zarr` first"), "{message}");
    let args = suggested_import(&message);
    let output = voxstream(&args.iter().map(String::as_str).collect::<Vec<_>>(), &dir);
    assert!(output.status.success(), "{args:?}: {}", stderr(&output));
    assert!(dir.join("ramp.zarr").is_dir());
}

#[test]
fn a_folder_of_tiff_slices_gets_an_import_command() {
    let dir = scratch("tiff");
    std::fs::create_dir_all(dir.join("data/slices")).unwrap();
    std::fs::write(dir.join("data/slices/z000.tif"), b"II*\0").unwrap();
    let output = voxstream(&["info", "data/slices"], &dir);
    assert_eq!(output.status.code(), Some(1));
    assert_eq!(
        stderr(&output).trim_end(),
        "error: data/slices is a folder of TIFF slices, not a store: run `voxstream import data/slices --out \
         slices.zarr` first, then `voxstream info slices.zarr`"
    );
}

#[test]
fn dicom_folders_and_files_get_an_import_command() {
    let dir = scratch("dicom");
    // A PACS export: a study folder, a series folder, files named without extension but marked as DICOM.
    std::fs::create_dir_all(dir.join("study/SE0001")).unwrap();
    let marked = [vec![0u8; 128], b"DICM".to_vec(), vec![0u8; 64]].concat();
    std::fs::write(dir.join("study/SE0001/IM0001"), &marked).unwrap();
    let output = voxstream(&["render", "study"], &dir);
    assert_eq!(output.status.code(), Some(1));
    assert_eq!(
        stderr(&output).trim_end(),
        "error: study is a folder of DICOM files, not a store: run `voxstream import study --out study.zarr` first \
         (one series per folder), then `voxstream render study.zarr`"
    );
    let output = voxstream(&["info", "study/SE0001/IM0001"], &dir);
    assert_eq!(output.status.code(), Some(1));
    assert_eq!(
        stderr(&output).trim_end(),
        "error: study/SE0001/IM0001 is a volume file, not a store: run `voxstream import study/SE0001/IM0001 --out \
         IM0001.zarr` first, then `voxstream info IM0001.zarr`"
    );
}

#[test]
fn store_and_mesh_typos_get_the_near_name() {
    let dir = scratch("typos");
    import_ramp(&dir);
    std::fs::write(dir.join("bunny.ply"), b"").unwrap();
    let output = voxstream(&["info", "rmp.zarr"], &dir);
    assert_eq!(output.status.code(), Some(1));
    assert_eq!(
        stderr(&output).trim_end(),
        "error: store rmp.zarr not found (did you mean `ramp.zarr`?): expected a folder made by `voxstream import` \
         (check the path)"
    );
    let output = voxstream(&["render", "buny.ply"], &dir);
    assert_eq!(output.status.code(), Some(1));
    assert_eq!(
        stderr(&output).trim_end(),
        "error: mesh or particle file buny.ply not found (did you mean `bunny.ply`?) (check the path)"
    );
    let message = stderr(&voxstream(&["import", "buny.ply", "--out", "b.zarr"], &dir));
    assert!(message.contains("(did you mean `bunny.ply`?)"), "{message}");
    // A volume file to import, misspelled.
    std::fs::write(dir.join("t1.nii"), b"").unwrap();
    let output = voxstream(&["import", "t1.ni", "--out", "t.zarr"], &dir);
    assert_eq!(output.status.code(), Some(1));
    assert_eq!(stderr(&output).trim_end(), "error: t1.ni: not found (did you mean `t1.nii`?)");
    let message = stderr(&voxstream(&["info", "elsewhere.zarr"], &dir));
    assert!(!message.contains("did you mean"), "nothing near: {message}");
}

#[test]
fn a_level_of_a_store_names_its_store() {
    let dir = scratch("level");
    import_ramp(&dir);
    for command in ["render", "info"] {
        let output = voxstream(&[command, "ramp.zarr/0"], &dir);
        assert_eq!(output.status.code(), Some(1));
        assert_eq!(
            stderr(&output).trim_end(),
            format!(
                "error: ramp.zarr/0 is level 0 of the store ramp.zarr: pass the store's folder instead (`voxstream \
                 {command} ramp.zarr`)"
            )
        );
    }
    let message = stderr(&voxstream(&["info", "ramp.zarr/0/zarr.json"], &dir));
    assert!(message.contains("is a file inside the store ramp.zarr"), "{message}");
}

#[test]
fn a_transfer_function_over_a_sliver_of_the_data_warns() {
    let dir = scratch("sliver");
    import_ramp(&dir);
    // Written for 8-bit data: 0 to 255 of the ramp's 0 to 3400.
    std::fs::write(dir.join("tf.json"), r#"{"points": [[0, 1,1,1,0], [128, 1,0.5,0,0.5], [255, 1,1,1,1]]}"#).unwrap();
    let args = ["render", "ramp.zarr", "--tf", "tf.json", "--width", "32", "--height", "32", "--out", "a.png"];
    let output = voxstream(&args, &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    let message = stderr(&output);
    assert!(message.contains("the transfer function's values span 0 to 255, only "), "{message}");
    assert!(message.contains("of the data's typical values"), "{message}");
    std::fs::write(dir.join("wide.json"), r#"{"points": [[0, 1,1,1,0], [3400, 1,1,1,1]]}"#).unwrap();
    let args = ["render", "ramp.zarr", "--tf", "wide.json", "--width", "32", "--height", "32", "--out", "b.png"];
    let message = stderr(&voxstream(&args, &dir));
    assert!(!message.contains("transfer function's values span"), "{message}");
}

#[test]
fn io_errors_have_no_os_error_numbers() {
    let dir = scratch("io");
    let output = voxstream(&["render", "--tf", "missing.json", "--out", "x.png"], &dir);
    assert_eq!(output.status.code(), Some(1));
    assert_eq!(stderr(&output).trim_end(), "error: cannot read transfer function missing.json: not found");
    let output = voxstream(&["render", "--camera", "missing/cam.json", "--out", "x.png"], &dir);
    let message = stderr(&output);
    assert!(message.contains("cannot read camera missing/cam.json: not found"), "{message}");
    assert!(!message.contains("os error"), "{message}");
}
