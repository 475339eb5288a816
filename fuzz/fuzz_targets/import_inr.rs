//! The .inr and .inr.gz importers: the first byte picks one (even: .inr, odd: .inr.gz), the rest is the file, imported into a
//! scratch store.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Some((&selector, file)) = data.split_first() {
        voxstream_fuzz::import_bytes(if selector % 2 == 0 { "inr" } else { "inr.gz" }, file, None);
    }
});
