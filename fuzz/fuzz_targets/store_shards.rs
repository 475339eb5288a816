//! A native store's shard, edited by the input (the whole file, its index with the index CRC-32C recomputed, or one
//! brick's bytes with the brick's CRC-32C recomputed), then read whole as `render --in-memory` reads a store: forged
//! index entries, decompression bombs and corrupt frames must be errors, never an abort, a hang or a huge allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    voxstream_fuzz::read_shard_input(data);
});
