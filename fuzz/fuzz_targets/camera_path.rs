//! A camera-path JSON file (`--path`): parsed and every camera validated.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = voxstream::camera_path::parse_camera_path(text);
    }
});
