//! The out-of-core producer against the in-memory one: the same bricks within a budget, the mass at every level,
//! adaptive smoothing, attributes, isolated and wide kernels, and the settings' errors.

use super::*;
use crate::particles::ParticleSet;
use crate::{ParticleProducer, RawParticles};
use voxstream_core::NodeContent;
use voxstream_core::{NodeKey, Produced, Producer};

/// A ball with a denser core, in file units around (10, 20, 30) with radius 5.
fn cloud(count: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut state = seed;
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..count)
        .map(|_| loop {
            let p = [next() * 2.0 - 1.0, next() * 2.0 - 1.0, next() * 2.0 - 1.0];
            let r2: f64 = p.iter().map(|v| v * v).sum();
            if r2 <= 1.0 && (r2 < 0.2 || next() < 0.5) {
                return [10.0 + 5.0 * p[0], 20.0 + 5.0 * p[1], 30.0 + 5.0 * p[2]];
            }
        })
        .collect()
}

fn out_of_core(memory_bytes: u64) -> OutOfCoreSettings {
    OutOfCoreSettings { memory_bytes, spill_directory: std::env::temp_dir() }
}

/// The largest difference between the two producers' fields over the non-empty nodes of `level` (every
/// `stride`-th), relative to the in-memory value range, and the number of nodes compared.
fn largest_difference(
    memory: &ParticleProducer,
    streamed: &SuperbrickParticleProducer,
    level: u32,
    stride: u64,
) -> (f64, usize) {
    let shape = memory.shape();
    assert_eq!(shape, streamed.shape());
    let per_axis = shape.nodes_per_axis(level);
    let (mut a, mut b) = (vec![0u16; shape.voxels_per_brick()], vec![0u16; shape.voxels_per_brick()]);
    let (mut worst, mut compared) = (0.0f64, 0);
    for index in (0..per_axis.pow(3)).step_by(stride as usize) {
        let key = NodeKey { level, ijk: [index % per_axis, index / per_axis % per_axis, index / per_axis / per_axis] };
        let (oracle_a, oracle_b) = (memory.oracle(key), streamed.oracle(key));
        if oracle_a.is_some() && oracle_b.is_some() {
            continue;
        }
        let pa = memory.produce(key, &mut a).unwrap();
        let pb = streamed.produce(key, &mut b).unwrap();
        if pa.content == NodeContent::Brick || pb.content == NodeContent::Brick {
            compared += 1;
            let value = |v: &[u16], i: usize, p: &Produced, [lower, upper]: [f64; 2]| {
                let unit = match p.content {
                    NodeContent::Brick => f64::from(v[i]) / 65535.0,
                    NodeContent::Constant(c) => f64::from(c),
                    NodeContent::Empty => 0.0,
                };
                lower + unit * (upper - lower)
            };
            let [lower, upper] = memory.value_range();
            for i in 0..a.len() {
                let da = value(&a, i, &pa, memory.value_range());
                let db = value(&b, i, &pb, streamed.value_range());
                worst = worst.max((da - db).abs() / (upper - lower));
            }
        }
    }
    (worst, compared)
}

#[test]
fn out_of_core_bricks_equal_the_in_memory_ones_within_a_budget() {
    let positions = cloud(400_000, 5);
    let count = positions.len();
    let masses: Vec<f32> = (0..count).map(|i| 0.5 + (i % 4) as f32 * 0.25).collect();
    let set =
        ParticleSet::new(RawParticles { smoothing: vec![0.6; count], masses, positions, ..RawParticles::default() })
            .unwrap();
    let settings = ParticleTreeSettings { resolution: Some(256), ..ParticleTreeSettings::default() };
    let memory = ParticleProducer::new(&set, settings).unwrap();
    let streamed = SuperbrickParticleProducer::new(&set, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
    let statistics = streamed.statistics();
    assert_eq!(statistics.particles, count as u64);
    assert!(statistics.superbricks_per_axis >= 4, "{statistics:?}");
    // The coarse levels' aggregates fit a quarter of the budget while built (before, the level above the
    // superbricks' was held whole whatever the budget: 2 GiB for 20 million points in 64 MiB).
    let aggregate_bytes = statistics.coarse_particles * BYTES_PER_AGGREGATE;
    assert!(aggregate_bytes <= MIN_MEMORY_BYTES / AGGREGATE_SHARE, "{aggregate_bytes} bytes: {statistics:?}");
    assert!(statistics.coarse_levels_held < statistics.superbrick_level, "{statistics:?}");
    assert!((streamed.total_mass() / memory.total_mass() - 1.0).abs() < 1e-9);
    // Every particle probed in both (one support class): the same peak, the same scale.
    assert!((streamed.density_scale() / memory.density_scale() - 1.0).abs() < 1e-9);
    assert!((streamed.typical_density() / memory.typical_density() - 1.0).abs() < 0.012);
    // At and below the superbricks' level, the same sums of the same kernels (up to the order of the sum and
    // 16-bit quantisation).
    let finest = memory.shape().max_level;
    for (level, stride) in [(statistics.superbrick_level, 1), (finest, 37)] {
        let (worst, compared) = largest_difference(&memory, &streamed, level, stride);
        assert!(compared > 20, "level {level}: {compared} bricks");
        assert!(worst <= 1.0 / 65535.0, "level {level}: {worst}");
    }
    // Coarser levels come from aggregated particles (the coarsest) or the superbricks: close, not equal (1.1% of the
    // scale at most, measured).
    for level in 0..statistics.superbrick_level {
        let (worst, compared) = largest_difference(&memory, &streamed, level, 1);
        assert!(compared > 0);
        assert!(worst < 0.02, "level {level}: {worst} of the density scale");
    }
    // Only part of the set was ever in memory.
    let statistics = streamed.statistics();
    assert!(statistics.loads > 0);
    assert!(
        statistics.peak_cached_particles <= statistics.budget_particles + statistics.largest_superbrick,
        "{statistics:?}"
    );
    assert!(statistics.peak_cached_particles < count as u64 / 2, "{statistics:?}");
}

#[test]
fn out_of_core_density_integrates_to_the_total_mass_at_every_level() {
    let positions = cloud(60_000, 9);
    let set =
        ParticleSet::new(RawParticles { smoothing: vec![0.4; positions.len()], positions, ..RawParticles::default() })
            .unwrap();
    let settings = ParticleTreeSettings { resolution: Some(128), ..ParticleTreeSettings::default() };
    let producer = SuperbrickParticleProducer::new(&set, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
    assert!(producer.statistics().superbrick_level >= 1, "{:?}", producer.statistics());
    let shape = producer.shape();
    let m = shape.brick_size as usize;
    let b = m + 2;
    let mut voxels = vec![0u16; shape.voxels_per_brick()];
    for level in 0..=shape.max_level {
        let per_axis = shape.nodes_per_axis(level);
        let mut sum = 0.0;
        for index in 0..per_axis.pow(3) {
            let key =
                NodeKey { level, ijk: [index % per_axis, index / per_axis % per_axis, index / per_axis / per_axis] };
            if producer.oracle(key).is_some() {
                continue;
            }
            if producer.produce(key, &mut voxels).unwrap().content != NodeContent::Brick {
                continue;
            }
            for k in 1..=m {
                for j in 1..=m {
                    for i in 1..=m {
                        sum += f64::from(voxels[(k * b + j) * b + i]) / 65535.0;
                    }
                }
            }
        }
        let integral = sum * producer.density_scale() * shape.voxel_size(level).powi(3);
        let total = producer.total_mass();
        assert!((integral / total - 1.0).abs() < 0.01, "level {level}: {integral} vs {total}");
    }
}

#[test]
fn adaptive_smoothing_per_superbrick_matches_the_whole_set() {
    // No smoothing lengths in the file: the k-d trees per superbrick give each particle the h the whole set's
    // tree gives it (up to the cap's median, taken from a histogram).
    let set = ParticleSet::new(RawParticles { positions: cloud(150_000, 21), ..RawParticles::default() }).unwrap();
    let settings = ParticleTreeSettings { resolution: Some(256), ..ParticleTreeSettings::default() };
    let memory = ParticleProducer::new(&set, settings).unwrap();
    let streamed = SuperbrickParticleProducer::new(&set, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
    assert!(streamed.statistics().superbricks_per_axis >= 4, "{:?}", streamed.statistics());
    assert!((streamed.margin() / memory.margin() - 1.0).abs() < 0.02, "{} {}", streamed.margin(), memory.margin());
    let level = memory.shape().max_level;
    let (worst, compared) = largest_difference(&memory, &streamed, level, 53);
    assert!(compared > 20);
    assert!(worst < 0.01, "{worst}");
}

#[test]
fn an_attribute_out_of_core_equals_the_in_memory_one() {
    // A temperature rising along x: the SPH interpolant with weights mⱼ/ρⱼ·Aⱼ, ρⱼ probed at every particle.
    let positions = cloud(20_000, 13);
    let values: Vec<f32> = positions.iter().map(|p| (p[0] - 10.0) as f32 * 3.0 + 1.0).collect();
    let set = ParticleSet::new(RawParticles {
        smoothing: vec![0.6; positions.len()],
        masses: (0..positions.len()).map(|i| 1.0 + (i % 2) as f32).collect(),
        positions,
        values,
        value_name: "temperature".into(),
    })
    .unwrap();
    let settings = ParticleTreeSettings { resolution: Some(128), attribute: true, ..ParticleTreeSettings::default() };
    let memory = ParticleProducer::new(&set, settings).unwrap();
    let streamed = SuperbrickParticleProducer::new(&set, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
    let statistics = streamed.statistics();
    assert!(statistics.superbricks_per_axis >= 4, "{statistics:?}");
    let ([a0, a1], [b0, b1]) = (memory.value_range(), streamed.value_range());
    assert!(a0 < -10.0 && a1 > 10.0, "the range covers the temperatures: {a0} {a1}");
    assert!((a0 - b0).abs() < 1e-4 * (a1 - a0) && (a1 - b1).abs() < 1e-4 * (a1 - a0), "{a0} {a1} / {b0} {b1}");
    // Empty space is the voxel value of 0 in both.
    let far = NodeKey { level: 1, ijk: [0, 0, 0] };
    assert_eq!(memory.oracle(far).is_some(), streamed.oracle(far).is_some());
    for level in statistics.superbrick_level..=memory.shape().max_level {
        let stride = if level == statistics.superbrick_level { 1 } else { 7 };
        let (worst, compared) = largest_difference(&memory, &streamed, level, stride);
        assert!(compared > 10, "level {level}: {compared}");
        assert!(worst <= 2.0 / 65535.0, "level {level}: {worst}");
    }
    for level in 0..statistics.superbrick_level {
        let (worst, _) = largest_difference(&memory, &streamed, level, 1);
        assert!(worst < 0.02, "level {level}: {worst}");
    }
}

#[test]
fn isolated_and_widely_smoothed_particles_match_the_in_memory_producer() {
    // An isolated trio (fewer than 8 neighbours anywhere near: in memory their h hits the cap, and must out of
    // core too), and one particle whose kernel spans the cube (it must not make the whole set one superbrick).
    let mut positions = cloud(40_000, 17);
    positions.extend([[40.0, 20.0, 30.0], [40.01, 20.0, 30.0], [40.0, 20.01, 30.0]]);
    let adaptive = ParticleSet::new(RawParticles { positions: positions.clone(), ..RawParticles::default() }).unwrap();
    let settings = ParticleTreeSettings { resolution: Some(64), ..ParticleTreeSettings::default() };
    let memory = ParticleProducer::new(&adaptive, settings).unwrap();
    let streamed = SuperbrickParticleProducer::new(&adaptive, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
    assert!(streamed.statistics().superbricks_per_axis >= 4, "{:?}", streamed.statistics());
    for level in streamed.statistics().superbrick_level..=memory.shape().max_level {
        let (worst, compared) = largest_difference(&memory, &streamed, level, 1);
        assert!(compared > 10);
        assert!(worst < 0.01, "adaptive, level {level}: {worst}");
    }
    let mut smoothing = vec![0.5f32; positions.len()];
    smoothing[7] = 40.0;
    let wide = ParticleSet::new(RawParticles { positions, smoothing, ..RawParticles::default() }).unwrap();
    let memory = ParticleProducer::new(&wide, settings).unwrap();
    let streamed = SuperbrickParticleProducer::new(&wide, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
    assert!(streamed.statistics().superbricks_per_axis >= 4, "{:?}", streamed.statistics());
    for level in streamed.statistics().superbrick_level..=memory.shape().max_level {
        let (worst, compared) = largest_difference(&memory, &streamed, level, 1);
        assert!(compared > 10);
        assert!(worst <= 1.0 / 65535.0, "one wide kernel, level {level}: {worst}");
    }
}

#[test]
fn bad_settings_are_named() {
    let set = ParticleSet::new(RawParticles { positions: cloud(10, 1), ..RawParticles::default() }).unwrap();
    let small = SuperbrickParticleProducer::new(&set, ParticleTreeSettings::default(), &out_of_core(1 << 20));
    assert!(small.unwrap_err().to_string().contains("give at least 8 MiB"));
    let attribute = ParticleTreeSettings { attribute: true, ..ParticleTreeSettings::default() };
    let error = SuperbrickParticleProducer::new(&set, attribute, &out_of_core(MIN_MEMORY_BYTES)).unwrap_err();
    assert!(error.to_string().contains("no scalar attribute"), "{error}");
    let missing =
        OutOfCoreSettings { memory_bytes: MIN_MEMORY_BYTES, spill_directory: "/nonexistent/voxstream-spill".into() };
    let error = SuperbrickParticleProducer::new(&set, ParticleTreeSettings::default(), &missing).unwrap_err();
    assert!(error.to_string().contains("/nonexistent/voxstream-spill"), "{error}");
}

#[test]
fn a_cluster_finer_than_a_voxel_merges_out_of_core_too() {
    // As in memory (`particle_producer`'s test): 20,000 points within 5·10⁻⁵ of the origin and one 100 away. Every
    // point was spilled and the probe of their superbrick was quadratic; within a 64th of the finest voxel the
    // settings allow they are a few records of the same mass.
    let mut state = 11u64;
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut positions: Vec<[f64; 3]> = (0..20_000).map(|_| [next() * 5e-5, next() * 5e-5, next() * 5e-5]).collect();
    positions.push([100.0; 3]);
    let set = ParticleSet::new(RawParticles { positions, ..RawParticles::default() }).unwrap();
    let settings = ParticleTreeSettings::default();
    let producer = SuperbrickParticleProducer::new(&set, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
    let statistics = producer.statistics();
    assert_eq!(statistics.particles, 20_001);
    assert!(statistics.spill_bytes <= 9 * 24, "{statistics:?}");
    assert!((producer.total_mass() - 20_001.0).abs() < 1e-6);
}

/// Points jittered by `spread` (file units) about `centre`, and a generator's state.
fn jittered(count: usize, centre: [f64; 3], spread: f64, seed: u64) -> Vec<[f64; 3]> {
    let mut state = seed;
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..count).map(|_| centre.map(|c| c + next() * spread)).collect()
}

#[test]
fn a_dense_cluster_merges_while_it_is_binned_within_the_budget() {
    // Issue 41: binning loaded each superbrick whole before merging its close particles, so a region holding much of
    // a file went past --particle-memory while binning (10⁷ clustered points: 877 MB at 64 MiB). Here 300,000
    // points within 5·10⁻⁵ of one place (one superbrick) and one point far away, in 8 MiB (131,072 particles).
    let mut positions = jittered(300_000, [0.0; 3], 5e-5, 3);
    positions.push([100.0; 3]);
    for attribute in [false, true] {
        let values: Vec<f32> = (0..positions.len()).map(|i| (i % 5) as f32).collect();
        let set = ParticleSet::new(RawParticles {
            positions: positions.clone(),
            values: if attribute { values } else { Vec::new() },
            value_name: if attribute { "v".into() } else { String::new() },
            ..RawParticles::default()
        })
        .unwrap();
        let settings = ParticleTreeSettings { attribute, ..ParticleTreeSettings::default() };
        let producer = SuperbrickParticleProducer::new(&set, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
        let statistics = producer.statistics();
        assert_eq!(statistics.particles, 300_001);
        // Never more than a sliver of the budget read at once, and a handful of records kept (the attribute's
        // merge too: it kept every particle before).
        assert!(statistics.largest_read <= statistics.budget_particles / 8, "{attribute}: {statistics:?}");
        assert!(statistics.spilled_particles <= 20, "{attribute}: {statistics:?}");
        assert!((producer.total_mass() - 300_001.0).abs() < 1e-3 * 300_001.0, "{}", producer.total_mass());
        // The range the in-memory producer finds (the attribute's: its values, 0 to 4 evenly, interpolate to about
        // their mean at the cluster).
        let memory = ParticleProducer::new(&set, settings).unwrap();
        let ([a0, a1], [b0, b1]) = (memory.value_range(), producer.value_range());
        assert!((a0 - b0).abs() <= 1e-3 * (a1 - a0) && (a1 / b1 - 1.0).abs() < 0.01, "{a0} {a1} / {b0} {b1}");
        if attribute {
            assert!((a1 - 2.0).abs() < 0.1, "{a1}");
        }
    }
}

#[test]
fn copies_merged_while_binned_keep_the_in_memory_smoothing_and_density() {
    // 100,000 copies of a point inside a cloud, no smoothing lengths: binned, the copies are one record standing
    // for 100,000 particles, and the adaptive rule must count them (a k-d tree over the copies themselves took over
    // five minutes for a million): with each record counted once, its kernel would reach its 8 cloud neighbours
    // instead of the in-memory producer's 1e-6, and the density there would differ by orders of magnitude.
    let mut positions = cloud(20_000, 23);
    positions.extend(std::iter::repeat_n([10.5, 20.5, 30.5], 100_000));
    let set = ParticleSet::new(RawParticles { positions, ..RawParticles::default() }).unwrap();
    let settings = ParticleTreeSettings { resolution: Some(64), ..ParticleTreeSettings::default() };
    let memory = ParticleProducer::new(&set, settings).unwrap();
    let streamed = SuperbrickParticleProducer::new(&set, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
    let statistics = streamed.statistics();
    assert!(statistics.superbricks_per_axis >= 4, "{statistics:?}");
    assert!(statistics.largest_read < 20_000, "the copies were read whole: {statistics:?}");
    assert!((streamed.margin() / memory.margin() - 1.0).abs() < 0.02, "{} {}", streamed.margin(), memory.margin());
    assert!((streamed.value_range()[1] / memory.value_range()[1] - 1.0).abs() < 0.02);
    for level in statistics.superbrick_level..=memory.shape().max_level {
        let (worst, compared) = largest_difference(&memory, &streamed, level, 1);
        assert!(compared > 10, "level {level}: {compared}");
        assert!(worst < 0.01, "level {level}: {worst}");
    }
}

#[test]
fn a_region_denser_than_the_budget_is_refused_naming_the_memory_it_needs() {
    // 200,000 distinct points (far apart at the merging scale) within a thousandth of the set's width: one
    // superbrick of them cannot be held in 8 MiB (131,072 particles) however it is binned.
    let mut positions = jittered(200_000, [50.05, 50.05, 50.05], 0.1, 9);
    positions.extend([[0.0; 3], [100.0; 3]]);
    let set = ParticleSet::new(RawParticles { positions, ..RawParticles::default() }).unwrap();
    let error = SuperbrickParticleProducer::new(&set, ParticleTreeSettings::default(), &out_of_core(MIN_MEMORY_BYTES))
        .unwrap_err()
        .to_string();
    // (A few dozen of them fall in one merging cell.)
    let held: u64 = error.split(' ').next().and_then(|n| n.parse().ok()).unwrap_or(0);
    assert!(held > 199_000 && error.contains("particles (after merging") && error.contains("lie in one superbrick"));
    // 200,000 at 64 bytes, twice: 24.4 MiB, rounded up.
    assert!(error.contains("give --particle-memory 25 or more"), "{error}");
    let enough = SuperbrickParticleProducer::new(&set, ParticleTreeSettings::default(), &out_of_core(25 << 20));
    assert!(enough.is_ok(), "{:?}", enough.err());
}
