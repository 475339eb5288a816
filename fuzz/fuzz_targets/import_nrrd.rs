//! The .nrrd importer: header and data path, through a real import into a scratch store.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| voxstream_fuzz::import_bytes("nrrd", data, None));
