//! Bounds for the ray caster's cost per sample, measured on the machine the benchmark runs on: straight rays marched
//! through one cache-resident brick, a trilinear sample every half voxel, and nothing else (no tree, no transfer
//! function, no compositing). `voxstream bench` reports the ray caster's nanoseconds per sample and core next to them,
//! so that the gap is read on one machine in one run rather than across machines and days.
//!
//! - [`scalar_trilinear_ns_per_sample`]: a plain scalar loop, one ray at a time. The number of steps of each chord is
//!   computed before its loop, and the eight corners are read through one slice, so the loop holds one bounds check
//!   per sample and no other test.
//! - [`lanes_trilinear_ns_per_sample`]: eight rays in lock-step through the renderer's own lane sampler
//!   ([`voxstream_render::sampler::values_across`], the one its lanes take their samples with: positions, cells and
//!   weights as SIMD, the corners read by AVX2 gathers where the CPU has them), compiled for the instruction set the
//!   ray loop uses. What SIMD across rays can give the trilinear part of a sample on this CPU.
//!
//! Both are measured on bricks of either voxel width (`u16`: comparable with earlier figures; `u8`: the 8-bit scans
//! and the sponge are stored as bytes).

use std::hint::black_box;
use std::time::{Duration, Instant};

use voxstream_core::{Dequantize, Voxel};
use voxstream_render::gathered_corners::CornerGather;
use voxstream_render::sampler::{values_across, LANES};
use voxstream_render::InstructionSet;

/// Brick edge including its one-voxel border, as the brick pool stores a 32³ brick.
const EDGE: usize = 34;
/// March step, in voxels (the ray caster's default `--step`).
const STEP: f32 = 0.5;

/// Nanoseconds per trilinear sample on one core with voxels of type `V`, measured for about `duration`.
pub fn scalar_trilinear_ns_per_sample<V: BoundVoxel>(duration: Duration) -> f64 {
    let brick = brick::<V>();
    let mut random = xorshift();
    let (mut samples, mut sum) = (0u64, 0.0f32);
    let start = Instant::now();
    while start.elapsed() < duration {
        for _ in 0..256 {
            // Steps before the chord leaves the brick, computed once: the loop itself tests nothing.
            let Chord { start: mut p, advance, steps } = random_chord(&mut random);
            for _ in 0..steps {
                sum += trilinear(&brick, p);
                p = [p[0] + advance[0], p[1] + advance[1], p[2] + advance[2]];
            }
            samples += steps as u64;
        }
    }
    black_box(sum);
    start.elapsed().as_secs_f64() * 1e9 / samples.max(1) as f64
}

/// Nanoseconds per trilinear sample on one core with eight rays in lock-step (see the module docs), measured for
/// about `duration` on the instruction set `instruction_set` selects: each lane marches a chord of the brick of its
/// own and takes a new one when it ends, and the lanes step together in bursts that last until the first lane's
/// chord ends (the renderer's lanes refill the same way). Each chord costs what it costs the scalar loop to set up.
pub fn lanes_trilinear_ns_per_sample<V: BoundVoxel>(duration: Duration, instruction_set: InstructionSet) -> f64 {
    let gather = CornerGather::new(instruction_set.gathers());
    instruction_set.arch().dispatch(LanesBound::<V> { duration, gather, voxel: std::marker::PhantomData })
}

/// [`lanes_trilinear_ns_per_sample`]'s loop, compiled for each instruction set by `pulp` (as the renderer's tile loop).
struct LanesBound<V> {
    duration: Duration,
    gather: CornerGather,
    voxel: std::marker::PhantomData<V>,
}

impl<V: BoundVoxel> pulp::WithSimd for LanesBound<V> {
    type Output = f64;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> f64 {
        let brick = brick::<V>();
        let mut random = xorshift();
        let mut next_chord = || random_chord(&mut random);
        let mut lanes = Lanes::new();
        let (mut samples, mut sum) = (0u64, 0.0f32);
        let start_time = Instant::now();
        while start_time.elapsed() < self.duration {
            let (taken, total) = lanes.march(&brick, &mut next_chord, 64, V::DEQUANTIZE, self.gather);
            samples += taken;
            sum += total;
        }
        black_box(sum);
        start_time.elapsed().as_secs_f64() * 1e9 / samples.max(1) as f64
    }
}

/// One chord of the bound's brick: where it starts, its step, and how many steps it takes inside.
#[derive(Clone, Copy, Debug)]
struct Chord {
    start: [f32; 3],
    advance: [f32; 3],
    steps: u32,
}

/// A chord from a random interior point in a random direction, until it leaves the brick.
fn random_chord(random: &mut impl FnMut() -> f32) -> Chord {
    let limit = (EDGE - 1) as f32;
    let start = [random() * limit, random() * limit, random() * limit];
    let d = normalised([random() - 0.5, random() - 0.5, random() - 0.5]);
    let advance = d.map(|c| c * STEP);
    // A direction too short to normalise would stay put: a few brick edges at most.
    Chord { start, advance, steps: chord_steps(start, advance, limit).min(4 * EDGE as u32) }
}

/// Eight lanes, each on its own chord (positions `start + k·delta`, as the renderer's lanes hold them).
struct Lanes {
    start: [[f32; LANES]; 3],
    delta: [[f32; LANES]; 3],
    k: [f32; LANES],
    /// Steps left on each lane's chord.
    left: [u32; LANES],
}

impl Lanes {
    fn new() -> Lanes {
        Lanes { start: [[0.0; LANES]; 3], delta: [[0.0; LANES]; 3], k: [0.0; LANES], left: [0; LANES] }
    }

    /// `bursts` bursts: lanes whose chord has ended take new ones from `next_chord` (which must give chords with
    /// steps now and then), then all eight step together until the first chord ends. Returns the samples taken and
    /// their sum.
    #[inline(always)]
    fn march<V: Voxel>(
        &mut self,
        brick: &[V],
        next_chord: &mut impl FnMut() -> Chord,
        bursts: usize,
        dq: Dequantize,
        gather: CornerGather,
    ) -> (u64, f32) {
        let bases = [0u32; LANES];
        let (mut samples, mut sum) = (0u64, 0.0f32);
        for _ in 0..bursts {
            for lane in 0..LANES {
                while self.left[lane] == 0 {
                    let chord = next_chord();
                    for a in 0..3 {
                        self.start[a][lane] = chord.start[a];
                        self.delta[a][lane] = chord.advance[a];
                    }
                    self.k[lane] = 0.0;
                    self.left[lane] = chord.steps;
                }
            }
            let burst = self.left.iter().copied().min().unwrap_or(0);
            for _ in 0..burst {
                let values = values_across(brick, EDGE, &bases, &self.start, &self.delta, &self.k, dq, gather);
                sum += values.iter().sum::<f32>();
                for k in &mut self.k {
                    *k += 1.0;
                }
            }
            for left in &mut self.left {
                *left -= burst;
            }
            samples += u64::from(burst) * LANES as u64;
        }
        (samples, sum)
    }
}

/// A small xorshift generator of `[0, 1)` floats (the bounds need no statistical quality, only no pattern the
/// branch predictor or the prefetcher could learn).
fn xorshift() -> impl FnMut() -> f32 {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Steps of `advance` from `p` before the chord leaves `[0, limit]³`.
fn chord_steps(p: [f32; 3], advance: [f32; 3], limit: f32) -> u32 {
    (0..3)
        .map(|a| {
            let room = if advance[a] > 0.0 { limit - p[a] } else { p[a] };
            if advance[a] == 0.0 {
                u32::MAX
            } else {
                ((room / advance[a].abs()).ceil() as u32).saturating_sub(1)
            }
        })
        .min()
        .unwrap_or(0)
}

/// A voxel type the bounds can be measured on: the pool's two.
pub trait BoundVoxel: Voxel {
    /// The voxel holding the low bits of `bits`.
    fn from_low_bits(bits: u32) -> Self;
    /// How the renderer turns the interpolated stored value into the normalised one.
    const DEQUANTIZE: Dequantize;
}

impl BoundVoxel for u16 {
    fn from_low_bits(bits: u32) -> u16 {
        bits as u16
    }
    const DEQUANTIZE: Dequantize = Dequantize { scale: 1.0 / 65535.0, offset: 0.0 };
}

impl BoundVoxel for u8 {
    fn from_low_bits(bits: u32) -> u8 {
        bits as u8
    }
    const DEQUANTIZE: Dequantize = Dequantize { scale: 1.0 / 255.0, offset: 0.0 };
}

/// A brick of pseudo-random voxels (no pattern a predictor could learn).
fn brick<V: BoundVoxel>() -> Vec<V> {
    (0..EDGE * EDGE * EDGE).map(|i| V::from_low_bits((i as u32).wrapping_mul(2_654_435_761))).collect()
}

fn normalised(v: [f32; 3]) -> [f32; 3] {
    let length = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-6);
    v.map(|c| c / length)
}

/// The trilinear interpolation of `brick` at `p` (voxel units, inside `[0, EDGE − 1)³`): the eight corners are read
/// through one slice, so one bounds check per sample remains.
#[inline]
fn trilinear<V: Voxel>(brick: &[V], p: [f32; 3]) -> f32 {
    const ROW: usize = EDGE;
    const SLAB: usize = EDGE * EDGE;
    let cell = p.map(|c| c.floor());
    let f = [p[0] - cell[0], p[1] - cell[1], p[2] - cell[2]];
    let [x, y, z] = cell.map(|c| c as usize);
    let base = (z * EDGE + y) * EDGE + x;
    let corners = &brick[base..base + SLAB + ROW + 2];
    let at = |offset: usize| corners[offset].stored();
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let x00 = lerp(at(0), at(1), f[0]);
    let x10 = lerp(at(ROW), at(ROW + 1), f[0]);
    let x01 = lerp(at(SLAB), at(SLAB + 1), f[0]);
    let x11 = lerp(at(SLAB + ROW), at(SLAB + ROW + 1), f[0]);
    lerp(lerp(x00, x10, f[1]), lerp(x01, x11, f[1]), f[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trilinear_interpolates_the_corners_and_a_linear_field() {
        let linear: Vec<u16> = (0..EDGE * EDGE * EDGE)
            .map(|i| (i % EDGE + 2 * (i / EDGE % EDGE) + 3 * (i / EDGE / EDGE)) as u16)
            .collect();
        assert_eq!(trilinear(&linear, [2.0, 3.0, 4.0]), 2.0 + 6.0 + 12.0);
        let value = trilinear(&linear, [2.25, 3.5, 4.75]);
        assert!((value - (2.25 + 7.0 + 14.25)).abs() < 1e-4, "{value}");
    }

    #[test]
    fn the_lanes_take_the_scalar_loops_samples() {
        lanes_take_the_scalar_loops_samples::<u16>();
        lanes_take_the_scalar_loops_samples::<u8>();
    }

    /// The timed loop of the lanes bound ([`Lanes::march`], with the gathers where the CPU has them) takes the same
    /// samples as the scalar loop: on chords of equal length, every burst ends with all eight chords, and the sum of
    /// its samples is the sum of the scalar loop's over the same chords.
    fn lanes_take_the_scalar_loops_samples<V: BoundVoxel>() {
        const STEPS: u32 = 12;
        const BURSTS: usize = 5;
        let brick = brick::<V>();
        let mut random = xorshift();
        // Chords of STEPS steps that stay inside: starts at least STEPS half-voxels from every face.
        let margin = STEPS as f32 * STEP + 1.0;
        let room = (EDGE - 1) as f32 - 2.0 * margin;
        let chords: Vec<Chord> = (0..BURSTS * LANES)
            .map(|_| {
                let start = [0, 1, 2].map(|_| margin + random() * room);
                let d = normalised([random() - 0.5, random() - 0.5, random() - 0.5]);
                Chord { start, advance: d.map(|c| c * STEP), steps: STEPS }
            })
            .collect();
        let mut expected = 0.0f64;
        for chord in &chords {
            let mut p = chord.start;
            for _ in 0..chord.steps {
                expected += f64::from(trilinear(&brick, p) * V::DEQUANTIZE.scale);
                p = [0, 1, 2].map(|a| p[a] + chord.advance[a]);
            }
        }
        let mut given = chords.iter().copied();
        let mut next_chord = || given.next().expect("the lanes asked for more chords than they take");
        let gather = CornerGather::new(InstructionSet::Detect.gathers());
        let (samples, sum) = Lanes::new().march(&brick, &mut next_chord, BURSTS, V::DEQUANTIZE, gather);
        assert_eq!(samples, (BURSTS * LANES) as u64 * u64::from(STEPS));
        let relative = (f64::from(sum) - expected).abs() / expected;
        assert!(relative < 1e-4, "lanes sum {sum} against the scalar loop's {expected}");
        assert!(given.next().is_none(), "every chord was marched");
    }
}
