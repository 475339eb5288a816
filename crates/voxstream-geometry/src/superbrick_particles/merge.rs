//! Merging particles closer than the finest voxels tell apart, out of core: the in-memory producer's rule (particles
//! within one cell a 64th of the finest voxel wide, with kernels within a sixteenth of an octave, become one particle
//! of their summed mass at their centre of mass; Reichl, seed 004, ch. 5 aggregates particles the same way for coarse
//! levels) applied twice:
//!
//! - **While binning**, to the *dense* superbricks (those the file puts more than [`DENSE_SHARE`]`⁻¹` of the memory
//!   budget's particles in): their records go through a map of cells ([`SpillMerger`]) bounded to a share of the
//!   budget, flushed to the spill file when full. A cluster of 10⁷ points in one place (or 10⁸ copies of one point)
//!   is a handful of records before any superbrick is loaded whole: binning a superbrick no longer loads what the
//!   file happened to put in it (10⁷ clustered points took 877 MB with `--particle-memory 64`). Where smoothing
//!   lengths are not known yet, the cell alone is the key and the merged record counts the particles it stands for
//!   (its support slot holds minus that count until the adaptive smoothing lengths replace it: the rule counts
//!   neighbours with their multiplicities, [`crate::neighbour_spacing`]).
//! - **After the smoothing lengths**, to every superbrick as it is sorted ([`merge_records`]), as in memory.
//!
//! With a scalar attribute the weight slot holds the value: merged particles carry their values' mass-weighted mean,
//! so that their contribution `M/ρ·Ā = Σ mⱼ·Aⱼ/ρ` is exactly the copies' (who share one density).

use std::collections::HashMap;
use std::os::unix::fs::FileExt;

use glam::DVec3;

use super::spill::{encode, Record, MASS, RECORD_BYTES, WEIGHT};

/// A superbrick holding more than a `1/DENSE_SHARE` of the budget's particles is merged while it is binned.
pub(super) const DENSE_SHARE: u64 = 8;

/// Bytes a cell of [`SpillMerger`]'s map takes (key, sums, the map's own overhead), counted at its most.
pub(super) const BYTES_PER_MERGED_CELL: u64 = 128;

/// How particles merge: the cell's width (unit-cube units) and whether the weight slot holds an attribute's value.
#[derive(Clone, Copy, Debug)]
pub(super) struct Merging {
    pub cell: f64,
    pub attribute: bool,
}

impl Merging {
    /// A record's cell of `self.cell` and, where its support is known (not a count), its sixteenth of an octave.
    fn key(&self, r: &Record) -> [i64; 4] {
        let c = [0, 1, 2].map(|a| (f64::from(r[a]) / self.cell).floor() as i64);
        let class = if r[3] < 0.0 { i64::MIN } else { (f64::from(r[3]).log2() * 16.0).floor() as i64 };
        [c[0], c[1], c[2], class]
    }
}

/// The particles a record stands for: minus its support slot before the smoothing lengths are known, else one.
pub(super) fn multiplicity(r: &Record) -> u64 {
    if r[3] < 0.0 {
        (-r[3]) as u64
    } else {
        1
    }
}

/// The sums a merged record is made from.
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    mass: f64,
    /// Density: the weights (masses) summed; attribute: the values weighted by mass.
    weight: f64,
    /// The mean's weights: masses, massless particles counting a little so that a cell of them has a position.
    sum_w: f64,
    position: DVec3,
    reach: f64,
    /// Particles counted where supports are not known yet.
    count: f64,
}

impl Sums {
    fn add(&mut self, r: &Record, attribute: bool) {
        let w = f64::from(r[MASS]).max(1e-30);
        self.mass += f64::from(r[MASS]);
        self.weight += if attribute { w * f64::from(r[WEIGHT]) } else { f64::from(r[WEIGHT]) };
        self.sum_w += w;
        self.position += DVec3::new(f64::from(r[0]), f64::from(r[1]), f64::from(r[2])) * w;
        if r[3] < 0.0 {
            self.count -= f64::from(r[3]);
        } else {
            self.reach += f64::from(r[3]) * w;
        }
    }

    fn record(&self, attribute: bool) -> Record {
        let p = (self.position / self.sum_w).as_vec3();
        let support = if self.count > 0.0 { -self.count } else { self.reach / self.sum_w };
        let weight = if attribute { self.weight / self.sum_w } else { self.weight };
        [p.x, p.y, p.z, support as f32, self.mass as f32, weight as f32]
    }
}

/// A superbrick's records with those of one key merged (see the module). Returned as given where nothing merges.
pub(super) fn merge_records(records: Vec<Record>, merging: Merging) -> Vec<Record> {
    let mut order: Vec<u32> = (0..records.len() as u32).collect();
    order.sort_unstable_by_key(|&i| merging.key(&records[i as usize]));
    let key = |n: usize| merging.key(&records[order[n] as usize]);
    if (1..order.len()).all(|n| key(n - 1) != key(n)) {
        return records;
    }
    let mut merged = Vec::new();
    let mut sums = Sums::default();
    for n in 0..order.len() {
        sums.add(&records[order[n] as usize], merging.attribute);
        if n + 1 == order.len() || key(n + 1) != key(n) {
            merged.push(sums.record(merging.attribute));
            sums = Sums::default();
        }
    }
    merged
}

/// The dense superbricks' records merged as the spill pass meets them: a map of at most `capacity` cells, written to
/// each superbrick's run when full and at the end.
pub(super) struct SpillMerger {
    merging: Merging,
    capacity: usize,
    cells: HashMap<(u32, [i64; 4]), Sums>,
}

impl SpillMerger {
    pub(super) fn new(merging: Merging, capacity: usize) -> SpillMerger {
        SpillMerger { merging, capacity: capacity.max(1), cells: HashMap::new() }
    }

    /// Adds superbrick `bin`'s record; returns whether the map is full (time to [`SpillMerger::flush`]).
    pub(super) fn add(&mut self, bin: usize, record: &Record) -> bool {
        let key = (bin as u32, self.merging.key(record));
        self.cells.entry(key).or_default().add(record, self.merging.attribute);
        self.cells.len() >= self.capacity
    }

    /// Writes every merged record to its superbrick's run at `cursor` (advanced) and empties the map. Each cell
    /// stands for at least one record added since the last flush, so no run grows past what the file put in it.
    pub(super) fn flush(&mut self, spill: &std::fs::File, cursor: &mut [u64]) -> std::io::Result<()> {
        let mut records: Vec<(u32, Record)> =
            self.cells.drain().map(|((bin, _), sums)| (bin, sums.record(self.merging.attribute))).collect();
        records.sort_unstable_by_key(|&(bin, _)| bin);
        self.cells.shrink_to(self.capacity);
        let mut bytes = Vec::new();
        for group in records.chunk_by(|a, b| a.0 == b.0) {
            let bin = group[0].0 as usize;
            encode(group.iter().map(|(_, r)| r), &mut bytes);
            spill.write_all_at(&bytes, cursor[bin] * RECORD_BYTES as u64)?;
            cursor[bin] += group.len() as u64;
        }
        Ok(())
    }
}

/// Moves each superbrick's run `starts[b]..ends[b]` down to follow the previous one, a piece at a time (runs only
/// move towards the file's start, so a piece never overwrites one not yet moved), and cuts the file to the end.
/// Returns the new offsets (`S³ + 1`).
pub(super) fn compact(spill: &std::fs::File, starts: &[u64], ends: &[u64]) -> std::io::Result<Vec<u64>> {
    const PIECE: u64 = 1 << 16;
    let mut compacted = vec![0u64; starts.len()];
    let mut buffer = Vec::new();
    for bin in 0..starts.len() - 1 {
        let (from, to) = (starts[bin], ends[bin]);
        let destination = compacted[bin];
        let mut moved = 0;
        while destination != from && from + moved < to {
            let n = PIECE.min(to - from - moved);
            buffer.resize((n as usize) * RECORD_BYTES, 0);
            spill.read_exact_at(&mut buffer, (from + moved) * RECORD_BYTES as u64)?;
            spill.write_all_at(&buffer, (destination + moved) * RECORD_BYTES as u64)?;
            moved += n;
        }
        compacted[bin + 1] = destination + (to - from);
    }
    spill.set_len(compacted[starts.len() - 1] * RECORD_BYTES as u64)?;
    Ok(compacted)
}

#[cfg(test)]
mod tests {
    use super::*;

    const DENSITY: Merging = Merging { cell: 0.01, attribute: false };

    #[test]
    fn records_in_one_cell_merge_at_their_centre_of_mass() {
        let records = vec![
            [0.101, 0.2, 0.3, 0.05, 1.0, 1.0],
            [0.103, 0.2, 0.3, 0.05, 3.0, 3.0],
            [0.5, 0.5, 0.5, 0.05, 1.0, 1.0],
            // Same cell, a kernel twice as wide: kept apart.
            [0.102, 0.2, 0.3, 0.1, 1.0, 1.0],
        ];
        let mut merged = merge_records(records.clone(), DENSITY);
        merged.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert_eq!(merged.len(), 3);
        let m = merged.iter().find(|r| r[MASS] == 4.0).unwrap();
        assert!((m[0] - 0.1025).abs() < 1e-6 && m[3] == 0.05 && m[WEIGHT] == 4.0, "{m:?}");
        // Nothing to merge: the records as given.
        assert_eq!(merge_records(records[2..].to_vec(), DENSITY), records[2..].to_vec());
        // An attribute's values merge to their mass-weighted mean.
        let attribute = Merging { cell: 0.01, attribute: true };
        let merged = merge_records(vec![[0.1; 6], [0.1, 0.1, 0.1, 0.1, 3.0, 5.0]], attribute);
        assert_eq!(merged.len(), 1);
        assert!((merged[0][WEIGHT] - (0.1 * 0.1 + 3.0 * 5.0) / 3.1).abs() < 1e-6, "{:?}", merged[0]);
        // Supports not known yet: the cell alone, and the count of particles in the support slot.
        let counted = merge_records(vec![[0.1, 0.1, 0.1, -1.0, 1.0, 1.0], [0.1, 0.1, 0.1, -5.0, 1.0, 1.0]], DENSITY);
        assert_eq!(counted.len(), 1);
        assert_eq!(multiplicity(&counted[0]), 6);
    }

    #[test]
    fn the_spill_merger_flushes_within_its_capacity_and_runs_compact() {
        let file = tempfile::tempfile().unwrap();
        // Two superbricks of 6 slots each; superbrick 0 gets five records in two cells, with a map of two cells.
        let starts = [0u64, 6, 12];
        let mut cursor = vec![0u64, 6];
        let mut merger = SpillMerger::new(DENSITY, 2);
        let a = [0.001, 0.001, 0.001, -1.0, 1.0, 1.0];
        let b = [0.5, 0.001, 0.001, -1.0, 1.0, 1.0];
        for (bin, r) in [(0, a), (0, a), (0, b), (0, a), (1, b)] {
            if merger.add(bin, &r) {
                merger.flush(&file, &mut cursor).unwrap();
            }
        }
        merger.flush(&file, &mut cursor).unwrap();
        // Full after the third record (two cells): a, a, b flushed as two records; then a, and superbrick 1's b.
        assert_eq!(cursor, [3, 7]);
        let compacted = compact(&file, &starts, &cursor).unwrap();
        assert_eq!(compacted, [0, 3, 4]);
        assert_eq!(file.metadata().unwrap().len(), 4 * RECORD_BYTES as u64);
        let mut bytes = vec![0u8; RECORD_BYTES];
        file.read_exact_at(&mut bytes, 3 * RECORD_BYTES as u64).unwrap();
        assert_eq!(f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]), 0.5, "superbrick 1 moved down");
        let counts: u64 = (0..3)
            .map(|i| {
                file.read_exact_at(&mut bytes, i * RECORD_BYTES as u64).unwrap();
                -f32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as u64
            })
            .sum();
        assert_eq!(counts, 4, "superbrick 0's records count its four particles");
    }
}
