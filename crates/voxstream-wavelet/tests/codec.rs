//! Round trips, the max-error guarantee, header min/max, and hostile input (property tests marked `prop_`).

use proptest::prelude::*;
use voxstream_wavelet::{decode, encode, Codec, DecodeError, Entropy, Kind, Mode, Options, Sample};
use voxstream_wavelet::{header_len, DType};

fn lossless() -> Options {
    Options::default()
}

fn with(mode: Mode) -> Options {
    Options { mode, ..Options::default() }
}

/// A smooth field with a little structure: a blob plus ramps.
fn smooth(dims: [usize; 3], amp: f64) -> Vec<f64> {
    let mut v = Vec::new();
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let (fx, fy, fz) = (x as f64 / 7.0, y as f64 / 5.0, z as f64 / 9.0);
                v.push(amp * (0.5 + 0.25 * (fx.sin() * fy.cos()) + 0.2 * (fz * 0.7).sin()));
            }
        }
    }
    v
}

fn rng_vec(n: usize, seed: u64, max: u64) -> Vec<u64> {
    let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s % (max + 1)
        })
        .collect()
}

fn check_lossless<T: Sample>(v: &[T], dims: [usize; 3]) {
    for entropy in [Entropy::Rans, Entropy::ZstdPlanes, Entropy::Smallest] {
        for levels in 0..=3 {
            let enc = encode(v, dims, &Options { levels, entropy, ..lossless() }).unwrap();
            let (h, back) = decode::<T>(&enc).unwrap();
            assert!(v.iter().zip(&back).all(|(a, b)| a.same(*b)), "dims {dims:?} levels {levels} {entropy:?}");
            check_range(&h, &back);
        }
    }
}

fn check_range<T: Sample>(h: &voxstream_wavelet::Header, back: &[T]) {
    let lo = back.iter().map(|x| x.to_f64()).fold(f64::INFINITY, f64::min);
    let hi = back.iter().map(|x| x.to_f64()).fold(f64::NEG_INFINITY, f64::max);
    assert_eq!((h.min, h.max), (lo, hi));
}

fn max_err<T: Sample>(a: &[T], b: &[T]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x.to_f64() - y.to_f64()).abs()).fold(0.0, f64::max)
}

#[test]
fn lossless_u8_u16_random_smooth_constant_odd_dims() {
    for dims in [[1, 1, 1], [32, 32, 32], [34, 34, 34], [7, 3, 5], [1, 17, 2], [33, 1, 1]] {
        let n = dims.iter().product();
        check_lossless(&rng_vec(n, 1, 255).iter().map(|&x| x as u8).collect::<Vec<_>>(), dims);
        check_lossless(&rng_vec(n, 2, 65535).iter().map(|&x| x as u16).collect::<Vec<_>>(), dims);
        check_lossless(&smooth(dims, 60000.0).iter().map(|&x| x as u16).collect::<Vec<_>>(), dims);
        check_lossless(&smooth(dims, 250.0).iter().map(|&x| x as u8).collect::<Vec<_>>(), dims);
        check_lossless(&vec![77u16; n], dims);
        check_lossless(&smooth(dims, 1e3).iter().map(|&x| x as f32).collect::<Vec<_>>(), dims);
    }
}

#[test]
fn constant_bricks_are_a_bare_header() {
    let enc = encode(&vec![5u8; 32 * 32 * 32], [32, 32, 32], &lossless()).unwrap();
    assert_eq!(enc.len(), header_len(DType::U8));
    let (h, back) = decode::<u8>(&enc).unwrap();
    assert_eq!((h.kind, h.min, h.max), (Kind::Constant, 5.0, 5.0));
    assert!(back.iter().all(|&x| x == 5));
}

#[test]
fn lossless_compresses_smooth_data() {
    let dims = [32, 32, 32];
    let v: Vec<u16> = smooth(dims, 4000.0).iter().map(|&x| x as u16).collect();
    let enc = encode(&v, dims, &lossless()).unwrap();
    assert!(enc.len() < v.len() * 2 / 4, "{} bytes", enc.len());
}

#[test]
fn non_finite_floats_round_trip_bit_exactly() {
    let v = [1.0f32, f32::NAN, f32::INFINITY, -0.0, 3.5, f32::NEG_INFINITY, 0.0, 2.0];
    let enc = encode(&v, [2, 2, 2], &with(Mode::MaxError(0.5))).unwrap();
    let (h, back) = decode::<f32>(&enc).unwrap();
    assert_eq!(h.kind, Kind::Raw);
    assert!(v.iter().zip(&back).all(|(a, b)| a.to_bits() == b.to_bits()));
}

#[test]
fn lossy_is_smaller_and_within_bound_on_a_smooth_f32_brick() {
    let dims = [32, 32, 32];
    let v: Vec<f32> = smooth(dims, 1.0).iter().map(|&x| x as f32).collect();
    let mut prev = usize::MAX;
    for e in [1e-5, 1e-4, 1e-3, 1e-2] {
        let enc = encode(&v, dims, &with(Mode::MaxError(e))).unwrap();
        let (h, back) = decode::<f32>(&enc).unwrap();
        assert!(max_err(&v, &back) <= e);
        check_range(&h, &back);
        assert!(enc.len() < prev, "coarser bounds must not grow the brick");
        prev = enc.len();
    }
}

#[test]
fn target_psnr_is_met_on_noisy_data() {
    let dims = [32, 32, 32];
    let v: Vec<f32> =
        smooth(dims, 100.0).iter().zip(rng_vec(32768, 9, 1000)).map(|(&x, r)| (x + r as f64 / 100.0) as f32).collect();
    let (lo, hi) = v.iter().fold((f32::MAX, f32::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    let peak = (hi - lo) as f64;
    let enc = encode(&v, dims, &with(Mode::TargetPsnr { db: 50.0, peak })).unwrap();
    let back = decode::<f32>(&enc).unwrap().1;
    let mse = v.iter().zip(&back).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>() / v.len() as f64;
    let psnr = 10.0 * (peak * peak / mse).log10();
    assert!(psnr >= 49.5, "psnr {psnr}");
}

#[test]
fn corrupted_bricks_are_refused() {
    let dims = [16, 16, 16];
    let v: Vec<u16> = smooth(dims, 3000.0).iter().map(|&x| x as u16).collect();
    let enc = encode(&v, dims, &lossless()).unwrap();
    assert_eq!(decode::<u8>(&enc).unwrap_err(), DecodeError::WrongType { stored: DType::U16, asked: DType::U8 });
    assert!(matches!(decode::<u16>(&enc[..enc.len() - 1]), Err(DecodeError::Payload(_))));
    assert_eq!(decode::<u16>(&enc[..10]).unwrap_err(), DecodeError::Truncated);
    let mut m = enc.clone();
    m[0] = b'X';
    assert_eq!(decode::<u16>(&m).unwrap_err(), DecodeError::Magic);
    let mut m = enc.clone();
    m[5] = 0; // dim x = 0 (high byte is 0 for 16)
    assert!(matches!(decode::<u16>(&m), Err(DecodeError::Header(_))));
    // Flipping payload bytes is caught (by the rANS end state, the tables, or the min/max check) in most positions
    // (not in raw extra bits that keep the range: the codec has no checksum, the store's chunks do); none may panic.
    let mut caught = 0;
    for i in header_len(DType::U16)..enc.len() {
        let mut m = enc.clone();
        m[i] ^= 0x5a;
        caught += decode::<u16>(&m).is_err() as usize;
    }
    assert!(
        caught * 4 >= (enc.len() - header_len(DType::U16)) * 3,
        "{caught} of {}",
        enc.len() - header_len(DType::U16)
    );
    let mut out = vec![0u16; 10];
    assert!(matches!(Codec::default().decode_into(&enc, &mut out), Err(DecodeError::WrongLength { .. })));
}

fn dims_strategy() -> impl Strategy<Value = [usize; 3]> {
    [1usize..=20, 1usize..=20, 1usize..=20].prop_map(|d| d)
}

/// Random, smooth and noisy-smooth bricks of u16 values.
fn brick_u16() -> impl Strategy<Value = ([usize; 3], Vec<u16>)> {
    (dims_strategy(), 0u8..3, any::<u64>(), 1u64..65535).prop_map(|(dims, kind, seed, amp)| {
        let n = dims.iter().product();
        let noise = rng_vec(n, seed, amp);
        let s = smooth(dims, amp as f64);
        let v = (0..n)
            .map(|i| match kind {
                0 => noise[i] as u16,
                1 => s[i] as u16,
                _ => (s[i] * 0.9 + noise[i] as f64 * 0.1) as u16,
            })
            .collect();
        (dims, v)
    })
}

fn brick_f32() -> impl Strategy<Value = ([usize; 3], Vec<f32>)> {
    (dims_strategy(), 0u8..3, any::<u64>(), -1e4f64..1e4, 1e-3f64..1e4).prop_map(|(dims, kind, seed, base, amp)| {
        let n = dims.iter().product();
        let noise = rng_vec(n, seed, 1 << 20);
        let s = smooth(dims, amp);
        let v = (0..n)
            .map(|i| {
                let r = noise[i] as f64 / (1u64 << 20) as f64 * amp;
                (base
                    + match kind {
                        0 => r,
                        1 => s[i],
                        _ => s[i] + 0.05 * r,
                    }) as f32
            })
            .collect();
        (dims, v)
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 160, ..ProptestConfig::default() })]

    #[test]
    fn prop_lossless_u16_round_trips((dims, v) in brick_u16(), levels in 0u8..=3) {
        let enc = encode(&v, dims, &Options { levels, ..lossless() }).unwrap();
        let (h, back) = decode::<u16>(&enc).unwrap();
        prop_assert_eq!(&back, &v);
        check_range(&h, &back);
    }

    #[test]
    fn prop_lossy_u16_error_bounded((dims, v) in brick_u16(), e in 0.0f64..3000.0, levels in 0u8..=3) {
        let enc = encode(&v, dims, &Options { levels, mode: Mode::MaxError(e), ..lossless() }).unwrap();
        let (h, back) = decode::<u16>(&enc).unwrap();
        prop_assert!(max_err(&v, &back) <= e);
        check_range(&h, &back);
    }

    #[test]
    fn prop_lossy_f32_error_bounded((dims, v) in brick_f32(), e_exp in -7.0f64..3.0, levels in 0u8..=3) {
        let e = 10f64.powf(e_exp);
        let opts = Options { levels, mode: Mode::MaxError(e), entropy: Entropy::Smallest, ..lossless() };
        let enc = encode(&v, dims, &opts).unwrap();
        let (h, back) = decode::<f32>(&enc).unwrap();
        prop_assert!(max_err(&v, &back) <= e, "max err {} > {}", max_err(&v, &back), e);
        check_range(&h, &back);
    }

    #[test]
    fn prop_lossy_u8_error_bounded(dims in dims_strategy(), seed in any::<u64>(), e in 0.0f64..40.0) {
        let n = dims.iter().product();
        let v: Vec<u8> = rng_vec(n, seed, 255).iter().zip(smooth(dims, 200.0)).map(|(&r, s)| (s + r as f64 / 8.0) as u8).collect();
        let enc = encode(&v, dims, &with(Mode::MaxError(e))).unwrap();
        let (h, back) = decode::<u8>(&enc).unwrap();
        prop_assert!(max_err(&v, &back) <= e);
        check_range(&h, &back);
    }

    /// Fuzz-style: random bytes never panic.
    #[test]
    fn prop_random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = decode::<u8>(&bytes);
        let _ = decode::<u16>(&bytes);
        let _ = decode::<f32>(&bytes);
    }

    /// Fuzz-style: valid encodings with a few bytes mutated (header included) never panic, and whatever decodes
    /// still has the header's min/max.
    #[test]
    fn prop_mutated_encodings_never_panic((dims, v) in brick_u16(), e in 0.0f64..50.0,
        muts in proptest::collection::vec((any::<usize>(), any::<u8>()), 1..6)) {
        let mut enc = encode(&v, dims, &with(Mode::MaxError(e))).unwrap();
        for (at, x) in muts {
            let i = at % enc.len();
            enc[i] ^= x | 1;
        }
        if let Ok((h, back)) = decode::<u16>(&enc) {
            check_range(&h, &back);
        }
    }
}
