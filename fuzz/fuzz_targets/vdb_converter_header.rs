//! The first line the .vdb converter prints (its JSON header), from which the importer sizes the volume.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = voxstream_store::formats::vdb::parse_converter_header(std::path::Path::new("fuzz.vdb"), text);
    }
});
