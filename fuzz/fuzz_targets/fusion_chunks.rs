//! The depth fusion's chunk files (issue 49, `voxstream-fusion` `spill.rs`): world chunks streamed to disk are read
//! back as untrusted input. Arbitrary bytes decode to an error or to bricks whose keys lie in the chunk asked for,
//! never a panic nor an allocation beyond what the file's length allows.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxstream_fusion::brick_map::chunk_of;
use voxstream_fusion::spill::decode_chunk;

fuzz_target!(|data: &[u8]| {
    let chunk = glam::IVec3::new(-1, 0, 2);
    if let Ok(bricks) = decode_chunk(data, chunk, std::path::Path::new("fuzz.vxfc")) {
        for (key, brick) in &bricks {
            assert_eq!(chunk_of(*key), chunk, "brick {key} decoded into another chunk");
            assert!(brick.colours.len() <= 16 && brick.offsets.len() <= 16);
        }
    }
});
