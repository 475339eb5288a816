//! The wavelet brick codec (issue 47): arbitrary bytes decoded as u8, u16 and f32 bricks (never a panic, only a
//! `DecodeError`), and, differentially, small bricks made from the input encoded losslessly and within an error bound
//! and decoded again: lossless is exact, lossy within its bound, and the header's min/max are the decoded brick's.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxstream_wavelet::{decode, encode, Entropy, Mode, Options};

fuzz_target!(|data: &[u8]| {
    let Some((&selector, rest)) = data.split_first() else { return };
    if selector % 2 == 0 {
        let _ = decode::<u8>(rest);
        let _ = decode::<u16>(rest);
        let _ = decode::<f32>(rest);
        return;
    }
    // A brick of at most 12³ 16-bit samples from the rest of the input.
    let Some((&shape, samples)) = rest.split_first() else { return };
    let dims = [1 + (shape & 3) as usize * 3, 1 + ((shape >> 2) & 3) as usize * 3, 1 + ((shape >> 4) & 3) as usize * 3];
    let count = dims[0] * dims[1] * dims[2];
    let brick: Vec<u16> = (0..count)
        .map(|i| {
            let j = 2 * i % samples.len().max(1);
            u16::from_le_bytes([samples.get(j).copied().unwrap_or(0), samples.get(j + 1).copied().unwrap_or(0)])
        })
        .collect();
    let entropy = if selector & 2 == 0 { Entropy::Rans } else { Entropy::ZstdPlanes };
    let levels = (selector >> 2) % 4;
    for mode in [Mode::Lossless, Mode::MaxError(f64::from(selector >> 4))] {
        let options = Options { mode, levels, entropy, ..Options::default() };
        let encoded = encode(&brick, dims, &options).expect("a valid brick encodes");
        let (header, back) = decode::<u16>(&encoded).expect("an encoded brick decodes");
        let bound = match mode {
            Mode::MaxError(e) => e,
            _ => 0.0,
        };
        for (a, b) in brick.iter().zip(&back) {
            assert!(f64::from(a.abs_diff(*b)) <= bound, "{a} decoded as {b} beyond {bound} ({mode:?})");
        }
        let (min, max) = back.iter().fold((u16::MAX, 0), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        assert_eq!((header.min, header.max), (f64::from(min), f64::from(max)), "header min/max");
    }
});
