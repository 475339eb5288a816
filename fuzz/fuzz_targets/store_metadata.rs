//! A store's root `zarr.json` (voxstream's attributes, or a foreign OME-Zarr's multiscales), opened as `voxstream
//! info` and `render` open a store: parsed and validated, with no level arrays present.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let store = voxstream_fuzz::scratch().join("metadata.zarr");
    if std::fs::create_dir_all(&store).is_err() || std::fs::write(store.join("zarr.json"), data).is_err() {
        return;
    }
    let _ = voxstream_store::StoreReader::open(&store);
});
