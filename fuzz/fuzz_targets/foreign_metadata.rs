//! A foreign OME-Zarr image's metadata (Zarr v3 or v2: the group's multiscales and two datasets' array metadata,
//! see `voxstream_fuzz::foreign_files`), opened as `voxstream info` and `render` open it: every dataset's shape,
//! chunks, data type and codecs checked, a brick of each level read, and the stored chunks counted.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| voxstream_fuzz::open_foreign_bytes(data));
