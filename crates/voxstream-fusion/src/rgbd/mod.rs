//! Sources of RGB-D frames: recorded sequences in the TUM RGB-D benchmark's layout, and synthetic sequences ray cast
//! from a mesh with a Kinect-like noise model, whose true surface is known (seed 004 §8.2 evaluates the fusion on
//! the benchmark's sequences and on synthetic data).
//!
//! - [`tum`]: reading and writing the benchmark's folders (Sturm et al., "A benchmark for the evaluation of RGB-D
//!   SLAM systems", IROS 2012).
//! - [`noise`]: the Kinect v1 depth noise of Nguyen, Izadi and Lovell 2012 ([NIL12] in §8.2).
//! - [`synth`]: orbits around a mesh standing on a floor, exact depth by ray casting, then the noise model.

pub mod noise;
pub mod synth;
pub mod tum;

pub use noise::NoiseModel;
pub use synth::{write_sequence, SyntheticSequence, SyntheticSettings};
pub use tum::{TumDataset, TumWriter};

/// A deterministic stream of 64 random bits for `(seed, index)`: splitmix64's finaliser over the mixed inputs, so
/// every pixel of every frame has its own stream and the result does not depend on the order of evaluation.
#[inline]
pub(crate) fn hash64(seed: u64, index: u64) -> u64 {
    let mut z = seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15).rotate_left(17);
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Splitmix64 from a seed: uniform numbers in (0, 1) and standard normal ones (Box–Muller).
#[derive(Clone, Debug)]
pub(crate) struct SplitMix {
    state: u64,
}

impl SplitMix {
    pub(crate) fn new(seed: u64, index: u64) -> SplitMix {
        SplitMix { state: hash64(seed, index) }
    }

    pub(crate) fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in the open interval (0, 1).
    pub(crate) fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller; one of the pair is used).
    pub(crate) fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}
