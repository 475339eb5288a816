//! The spill file: each superbrick's particles as a run of fixed-size records, in unit-cube units, and the reads
//! of a superbrick and of the particles around it that the build and the bricks need.

use std::os::unix::fs::FileExt;

use glam::DVec3;

use super::SuperbrickParticleProducer;

/// Bytes of a particle in the spill file: unit-cube position, support, mass, weight (`f32` little-endian each).
pub(super) const RECORD_BYTES: usize = 24;

/// A particle as the spill file holds it: `[x, y, z, support, mass, weight]`, unit-cube units (support 0: not yet
/// known). The weight is what the particle adds times its kernel: its mass (density), or `mⱼ/ρⱼ·Aⱼ` (attribute; the
/// value `Aⱼ` until the probe knows `ρⱼ`).
pub(super) type Record = [f32; 6];

/// Where a record keeps its mass, and its weight.
pub(super) const MASS: usize = 4;
pub(super) const WEIGHT: usize = 5;

impl SuperbrickParticleProducer {
    /// The particles of superbrick `bin` as the spill file holds them (the adaptive cap applied).
    pub(super) fn read(&self, bin: usize) -> std::io::Result<Vec<Record>> {
        let (from, to) = (self.starts[bin], self.starts[bin + 1]);
        self.largest_read.fetch_max(to - from, std::sync::atomic::Ordering::Relaxed);
        let mut bytes = vec![0u8; ((to - from) as usize) * RECORD_BYTES];
        self.spill.read_exact_at(&mut bytes, from * RECORD_BYTES as u64)?;
        Ok(bytes
            .chunks_exact(RECORD_BYTES)
            .map(|r| {
                let mut record: Record =
                    [0, 4, 8, 12, 16, 20].map(|o| f32::from_le_bytes([r[o], r[o + 1], r[o + 2], r[o + 3]]));
                record[3] = record[3].min(self.support_cap);
                record
            })
            .collect())
    }

    /// Superbrick `bin`'s box (unit-cube units).
    fn superbrick_box(&self, bin: usize) -> (DVec3, DVec3) {
        let s = self.per_axis;
        let ijk = [bin as u64 % s, bin as u64 / s % s, bin as u64 / s / s];
        let width = 1.0 / s as f64;
        let lower = DVec3::from(ijk.map(|c| c as f64 * width));
        (lower, lower + DVec3::splat(width))
    }

    /// The particles of the superbricks around `bin` (not `bin` itself) within `reach` of its box.
    pub(super) fn neighbourhood(&self, bin: usize, reach: f64) -> std::io::Result<Vec<Record>> {
        let (lower, upper) = self.superbrick_box(bin);
        let (lower, upper) = (lower - DVec3::splat(reach), upper + DVec3::splat(reach));
        let mut records = Vec::new();
        for other in self.bins_overlapping(lower, upper) {
            if other == bin {
                continue;
            }
            records.extend(self.read(other)?.into_iter().filter(|r| {
                let p = DVec3::new(f64::from(r[0]), f64::from(r[1]), f64::from(r[2]));
                p.cmpge(lower).all() && p.cmple(upper).all()
            }));
        }
        Ok(records)
    }

    /// The particles of the other superbricks whose kernels reach superbrick `bin`'s box (as far as each particle's
    /// own support: a few wide kernels do not bring in their superbricks' narrow ones).
    pub(super) fn kernels_reaching(&self, bin: usize) -> std::io::Result<Vec<Record>> {
        let (lower, upper) = self.superbrick_box(bin);
        let reach = DVec3::splat(self.max_support);
        let mut records = Vec::new();
        for other in self.bins_overlapping(lower - reach, upper + reach) {
            if other == bin
                || self.starts[other] == self.starts[other + 1]
                || !self.extents[other].reaches(lower, upper, 0.0)
            {
                continue;
            }
            records.extend(self.read(other)?.into_iter().filter(|r| {
                let p = DVec3::new(f64::from(r[0]), f64::from(r[1]), f64::from(r[2]));
                (lower - p).max(p - upper).max(DVec3::ZERO).length() < f64::from(r[3])
            }));
        }
        Ok(records)
    }

    /// The superbricks overlapping the box `lower..upper`.
    pub(super) fn bins_overlapping(&self, lower: DVec3, upper: DVec3) -> Vec<usize> {
        let s = self.per_axis;
        let cell = |v: f64| ((v * s as f64).floor().max(0.0) as u64).min(s - 1);
        let (from, to) = ([0, 1, 2].map(|a| cell(lower[a])), [0, 1, 2].map(|a| cell(upper[a])));
        let mut bins = Vec::new();
        for z in from[2]..=to[2] {
            for y in from[1]..=to[1] {
                for x in from[0]..=to[0] {
                    bins.push(((z * s + y) * s + x) as usize);
                }
            }
        }
        bins
    }

    /// Writes `records` over the spill file's records from particle `first` on.
    pub(super) fn write(&self, first: u64, records: &[Record]) -> std::io::Result<()> {
        let mut bytes = Vec::new();
        encode(records.iter(), &mut bytes);
        self.spill.write_all_at(&bytes, first * RECORD_BYTES as u64)
    }
}

/// Records as the index's input: unit positions, supports, and the `column` (mass or weight) as the index's masses.
pub(super) fn index_input<'a>(
    records: impl Iterator<Item = &'a Record>,
    column: usize,
) -> (Vec<DVec3>, Vec<f64>, Vec<f32>) {
    let mut positions = Vec::new();
    let mut support = Vec::new();
    let mut masses = Vec::new();
    for r in records {
        positions.push(DVec3::new(f64::from(r[0]), f64::from(r[1]), f64::from(r[2])));
        support.push(f64::from(r[3]));
        masses.push(r[column]);
    }
    (positions, support, masses)
}

/// Records as the spill file's bytes.
pub(super) fn encode<'a>(records: impl Iterator<Item = &'a Record>, bytes: &mut Vec<u8>) {
    bytes.clear();
    for record in records {
        for v in record {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
}
