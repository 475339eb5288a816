//! The DICOM importer (one `.dcm` file: a slice or a multi-frame grid): dicom-rs's parser and decoders, the
//! series' geometry and the sample conversion, through a real import into a scratch store.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| voxstream_fuzz::import_bytes("dcm", data, None));
