//! Raw files: the first 8 bytes are the layout the command line would give (x, y, z as u16, then the type, then
//! the header bytes to skip), the rest is the file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxstream_store::formats::{Endian, RawLayout};
use voxstream_store::{DType, VolumeInfo};

fuzz_target!(|data: &[u8]| {
    if data.len() < 8 {
        return;
    }
    let dim = |i: usize| u16::from_le_bytes([data[i], data[i + 1]]) as u64;
    let dtype = [DType::U8, DType::U16, DType::I16, DType::F32][(data[6] % 4) as usize];
    let layout = RawLayout {
        info: VolumeInfo {
            dims: [dim(0), dim(2), dim(4)],
            dtype,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            unit: None,
            orientation: None,
        },
        file_type: None,
        endian: if data[6] & 4 == 0 { Endian::Little } else { Endian::Big },
        header_bytes: data[7] as u64,
    };
    voxstream_fuzz::import_bytes("raw", &data[8..], Some(&layout));
});
