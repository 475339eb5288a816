//! The .npy and .npz importers: the first byte picks one (even: .npy, odd: .npz), the rest is the file, imported into a
//! scratch store.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Some((&selector, file)) = data.split_first() {
        voxstream_fuzz::import_bytes(if selector % 2 == 0 { "npy" } else { "npz" }, file, None);
    }
});
