//! Rate–distortion and decode speed of the brick codec on real volumes (issue 47's measurements).
//!
//! `cargo run --release -p voxstream-wavelet --example rate_distortion -- [DATA_DIR] [BRICK]`
//! (DATA_DIR defaults to `data/real`, BRICK to 32; timings are the best of `REPS` runs, default 9). Reads `mni152_t1.nii.gz` (NIfTI), `skull_2.9.inr` and
//! `liver.inr.gz` (INRIA), cuts each into BRICK³ bricks (edges padded by clamping), codes every brick, and prints per
//! dataset and configuration: bits per voxel of the volume, the ratio to zstd -3 of the raw bricks (what voxstream
//! stores today), PSNR over the dataset's value range and the max error (both over the volume's voxels only), and
//! single-thread decode throughput in decoded bytes per second against memcpy and zstd's decode.

use std::io::Read;
use std::time::Instant;

use voxstream_wavelet::{max_error_for_psnr, Codec, Entropy, Mode, Options, Sample};

struct Volume<T> {
    dims: [usize; 3],
    data: Vec<T>,
}

fn read_all(path: &str) -> Vec<u8> {
    let raw = std::fs::read(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    if path.ends_with(".gz") {
        let mut out = Vec::new();
        flate2::read::GzDecoder::new(&raw[..]).read_to_end(&mut out).expect("gunzip");
        out
    } else {
        raw
    }
}

/// NIfTI-1: dims at 40.., datatype at 70, vox_offset at 108. u8 (datatype 2) only, which is what MNI152 holds.
fn read_nifti_u8(path: &str) -> Volume<u8> {
    let b = read_all(path);
    let i16_at = |o: usize| i16::from_le_bytes([b[o], b[o + 1]]);
    let dims = [i16_at(42) as usize, i16_at(44) as usize, i16_at(46) as usize];
    assert_eq!(i16_at(70), 2, "expected uint8 NIfTI");
    let off = f32::from_le_bytes(b[108..112].try_into().unwrap()) as usize;
    let n = dims.iter().product::<usize>();
    Volume { dims, data: b[off..off + n].to_vec() }
}

/// INRIA .inr: a 256-byte text header (XDIM, YDIM, ZDIM, TYPE, PIXSIZE), then little-endian samples.
fn read_inr(path: &str) -> (Vec<u8>, [usize; 3], String) {
    let b = read_all(path);
    let head = String::from_utf8_lossy(&b[..256]).to_string();
    let field = |k: &str| {
        head.lines().find_map(|l| l.strip_prefix(&format!("{k}="))).unwrap_or_else(|| panic!("{k} missing")).to_string()
    };
    let dims = ["XDIM", "YDIM", "ZDIM"].map(|k| field(k).trim().parse::<usize>().expect("dim"));
    let ty = format!("{} {}", field("TYPE"), field("PIXSIZE"));
    (b[256..].to_vec(), dims, ty)
}

/// Cuts a volume into b³ bricks, padding edges by clamping.
fn bricks<T: Sample>(v: &Volume<T>, b: usize) -> Vec<Vec<T>> {
    let [nx, ny, nz] = v.dims;
    let mut out = Vec::new();
    for bz in (0..nz).step_by(b) {
        for by in (0..ny).step_by(b) {
            for bx in (0..nx).step_by(b) {
                let mut brick = Vec::with_capacity(b * b * b);
                for z in 0..b {
                    for y in 0..b {
                        for x in 0..b {
                            let (x, y, z) = ((bx + x).min(nx - 1), (by + y).min(ny - 1), (bz + z).min(nz - 1));
                            brick.push(v.data[(z * ny + y) * nx + x]);
                        }
                    }
                }
                out.push(brick);
            }
        }
    }
    out
}

/// Sum of squared errors and max error over the voxels inside the volume.
fn distortion<T: Sample>(v: &Volume<T>, b: usize, orig: &[Vec<T>], dec: &[Vec<T>]) -> (f64, f64) {
    let [nx, ny, nz] = v.dims;
    let (mut sse, mut max) = (0.0, 0.0f64);
    let mut k = 0;
    for bz in (0..nz).step_by(b) {
        for by in (0..ny).step_by(b) {
            for bx in (0..nx).step_by(b) {
                for z in 0..b.min(nz - bz) {
                    for y in 0..b.min(ny - by) {
                        for x in 0..b.min(nx - bx) {
                            let i = (z * b + y) * b + x;
                            let d = orig[k][i].to_f64() - dec[k][i].to_f64();
                            sse += d * d;
                            max = max.max(d.abs());
                        }
                    }
                }
                k += 1;
            }
        }
    }
    (sse, max)
}

fn as_bytes<T: Sample>(v: &[T]) -> Vec<u8> {
    let mut out = Vec::with_capacity(v.len() * T::SIZE);
    for &x in v {
        x.put(&mut out);
    }
    out
}

/// Best of `reps` timings of `f`, in seconds.
fn best_of(reps: usize, mut f: impl FnMut()) -> f64 {
    (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn run<T: Sample>(name: &str, v: &Volume<T>, b: usize, errors: &[f64]) {
    let nvox = v.data.len() as f64;
    let (lo, hi) =
        v.data.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, c), x| (a.min(x.to_f64()), c.max(x.to_f64())));
    let peak = hi - lo;
    let bricks = bricks(v, b);
    let decoded_bytes = (bricks.len() * b * b * b * T::SIZE) as f64;
    println!(
        "\n## {name}: {:?} {:?}, range {lo}..{hi}, {} bricks of {b}³ ({:.1} MB decoded)",
        v.dims,
        T::DTYPE,
        bricks.len(),
        decoded_bytes / 1e6
    );
    println!("| config | bits/voxel | × smaller than zstd | PSNR dB | max err | decode GB/s (1 thread) |");
    println!("|---|---|---|---|---|---|");
    let reps: usize = std::env::var("REPS").ok().and_then(|s| s.parse().ok()).unwrap_or(9);
    // memcpy bound.
    let raw: Vec<Vec<u8>> = bricks.iter().map(|br| as_bytes(br)).collect();
    let mut dst = vec![0u8; b * b * b * T::SIZE];
    let t_memcpy = best_of(reps, || {
        for r in &raw {
            dst.copy_from_slice(r);
            std::hint::black_box(&dst);
        }
    });
    println!("| memcpy | {} | | | | {:.2} |", T::SIZE * 8, decoded_bytes / t_memcpy / 1e9);
    // zstd -3 of raw bricks.
    let z: Vec<Vec<u8>> = raw.iter().map(|r| zstd::bulk::compress(r, 3).unwrap()).collect();
    let zbytes: usize = z.iter().map(Vec::len).sum();
    let mut dz = zstd::bulk::Decompressor::new().unwrap();
    let t_zstd = best_of(reps, || {
        for c in &z {
            let n = dz.decompress_to_buffer(c, &mut dst[..]).unwrap();
            std::hint::black_box(n);
        }
    });
    let bpv = |bytes: usize| bytes as f64 * 8.0 / nvox;
    println!("| zstd -3 raw bricks | {:.3} | 1.00 | ∞ | 0 | {:.2} |", bpv(zbytes), decoded_bytes / t_zstd / 1e9);

    let mut configs: Vec<(String, Options)> = Vec::new();
    for levels in 1..=3u8 {
        configs.push((format!("lossless, {levels} levels, rANS"), Options { levels, ..Options::default() }));
    }
    configs.push((
        "lossless, 2 levels, zstd planes".into(),
        Options { entropy: Entropy::ZstdPlanes, ..Options::default() },
    ));
    for &e in errors {
        configs.push((format!("max error {e:.4}, rANS"), Options { mode: Mode::MaxError(e), ..Options::default() }));
    }
    configs.push((
        format!("max error {:.4}, zstd planes", errors[1]),
        Options { mode: Mode::MaxError(errors[1]), entropy: Entropy::ZstdPlanes, ..Options::default() },
    ));
    configs.push((
        "target 50 dB, rANS".into(),
        Options { mode: Mode::TargetPsnr { db: 50.0, peak }, ..Options::default() },
    ));
    let mut codec = Codec::default();
    for (label, opts) in configs {
        let mut enc = Vec::new();
        let mut huff = 0usize;
        let mut rans_payload = 0usize;
        for br in &bricks {
            let e = codec.encode(br, [b; 3], &opts).unwrap();
            // The breakdown is that of the last wavelet brick; count it only for those.
            let h = voxstream_wavelet::Header::read(&e).unwrap();
            if h.kind == voxstream_wavelet::Kind::Wavelet && h.entropy == Entropy::Rans {
                let bd = codec.last_breakdown;
                huff += bd.huffman_estimate + bd.tables + bd.extra;
                rans_payload += bd.rans + bd.tables + bd.extra;
            }
            enc.push(e);
        }
        let bytes: usize = enc.iter().map(Vec::len).sum();
        let mut dec: Vec<Vec<T>> = vec![vec![T::default(); b * b * b]; bricks.len()];
        let t = best_of(reps, || {
            for (e, d) in enc.iter().zip(dec.iter_mut()) {
                codec.decode_into(e, d).unwrap();
            }
        });
        let (sse, max) = distortion(v, b, &bricks, &dec);
        let psnr = if sse == 0.0 { f64::INFINITY } else { 10.0 * (peak * peak / (sse / nvox)).log10() };
        let huff_note = if rans_payload > 0 && opts.entropy == Entropy::Rans {
            format!(" (Huffman instead of rANS: {:.3})", bpv(bytes - rans_payload + huff))
        } else {
            String::new()
        };
        println!(
            "| {label} | {:.3}{huff_note} | {:.2} | {:.2} | {max:.4} | {:.2} |",
            bpv(bytes),
            zbytes as f64 / bytes as f64,
            psnr,
            decoded_bytes / t / 1e9
        );
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let dir = args.get(1).cloned().unwrap_or_else(|| "data/real".into());
    let b: usize = args.get(2).map_or(32, |s| s.parse().expect("brick size"));
    let mni = read_nifti_u8(&format!("{dir}/mni152_t1.nii.gz"));
    run("mni152_t1", &mni, b, &[1.0, 2.0, 4.0]);

    let (bytes, dims, ty) = read_inr(&format!("{dir}/skull_2.9.inr"));
    assert_eq!(ty, "float 32 bits", "skull type");
    let data: Vec<f32> = bytes.chunks_exact(4).map(f32::get).collect();
    let skull = Volume { dims, data };
    let (lo, hi) = skull.data.iter().fold((f32::MAX, f32::MIN), |(a, c), &x| (a.min(x), c.max(x)));
    let peak = (hi - lo) as f64;
    run("skull_2", &skull, b, &[40.0, 50.0, 60.0].map(|db| max_error_for_psnr(db, peak)));

    let (bytes, dims, ty) = read_inr(&format!("{dir}/liver.inr.gz"));
    assert_eq!(ty, "unsigned fixed 8 bits", "liver type");
    let liver = Volume { dims, data: bytes[..dims.iter().product::<usize>()].to_vec() };
    run("liver", &liver, b, &[1.0, 2.0, 4.0]);
}
