//! The transfer-function table: value → colour and extinction (or step opacity), as the per-sample loop reads it.
//!
//! A sample's normalised value `v ∈ [0, 1]` (what bricks hold) maps to table position `v · (entry_count − 1)`,
//! linear between entries. What the fourth component holds is stated by [`TransferTableHeader::contents`]:
//! - [`TABLE_HOLDS_EXTINCTION`]: `σ` per world unit; the opacity of a step `Δt` is `1 − exp(−σ·Δt)` (the opacity
//!   correction of GigaVoxels [P09] §6 / [R08] §5), one `exp` per sample;
//! - [`TABLE_HOLDS_STEP_OPACITY`]: the opacity of one step of [`TransferTableHeader::step`] world units, already
//!   corrected, so the loop needs no `exp`; a segment with another step uses a table built for that step.
//!
//! Colours are linear (not sRGB) and not premultiplied.
//!
//! [`TransferTableHeader`] (16 bytes):
//!
//! | offset | bytes | field | meaning |
//! |---|---|---|---|
//! | 0 | 4 | [`entry_count`](TransferTableHeader::entry_count) | entries in the table (≥ 2) |
//! | 4 | 4 | [`contents`](TransferTableHeader::contents) | [`TABLE_HOLDS_EXTINCTION`] or [`TABLE_HOLDS_STEP_OPACITY`] |
//! | 8 | 4 | [`step`](TransferTableHeader::step) | world units of the step the opacities are corrected for (0 for extinction) |
//! | 12 | 4 | padding | zero |
//!
//! [`TransferTableEntry`] (16 bytes, an array stride of 16 in WGSL too):
//!
//! | offset | bytes | field | meaning |
//! |---|---|---|---|
//! | 0 | 4 | [`r`](TransferTableEntry::r) | linear red |
//! | 4 | 4 | [`g`](TransferTableEntry::g) | linear green |
//! | 8 | 4 | [`b`](TransferTableEntry::b) | linear blue |
//! | 12 | 4 | [`a`](TransferTableEntry::a) | extinction σ per world unit, or the opacity of one step (see above) |

use bytemuck::{Pod, Zeroable};

/// [`TransferTableHeader::contents`]: the fourth component is extinction per world unit.
pub const TABLE_HOLDS_EXTINCTION: u32 = 0;
/// [`TransferTableHeader::contents`]: the fourth component is the opacity of one step, pre-corrected.
pub const TABLE_HOLDS_STEP_OPACITY: u32 = 1;

/// How to read the table that follows it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TransferTableHeader {
    /// Entries in the table (at least 2).
    pub entry_count: u32,
    /// [`TABLE_HOLDS_EXTINCTION`] or [`TABLE_HOLDS_STEP_OPACITY`].
    pub contents: u32,
    /// World units of the step the opacities are corrected for (0 when the table holds extinction).
    pub step: f32,
    /// Zero; pads the header to 16 bytes.
    pub padding: u32,
}

/// One entry of the transfer-function table.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TransferTableEntry {
    /// Linear red.
    pub r: f32,
    /// Linear green.
    pub g: f32,
    /// Linear blue.
    pub b: f32,
    /// Extinction per world unit, or the opacity of one step (see [`TransferTableHeader::contents`]).
    pub a: f32,
}

impl TransferTableEntry {
    /// The entry as `[r, g, b, a]` (what a shader loads as one `vec4<f32>`).
    #[inline]
    pub fn to_array(self) -> [f32; 4] {
        [self.r, self.g, self.b, self.a]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn offsets_are_as_documented() {
        assert_eq!(size_of::<TransferTableHeader>(), 16);
        assert_eq!(align_of::<TransferTableHeader>(), 4);
        assert_eq!(offset_of!(TransferTableHeader, entry_count), 0);
        assert_eq!(offset_of!(TransferTableHeader, contents), 4);
        assert_eq!(offset_of!(TransferTableHeader, step), 8);
        assert_eq!(offset_of!(TransferTableHeader, padding), 12);

        assert_eq!(size_of::<TransferTableEntry>(), 16);
        assert_eq!(align_of::<TransferTableEntry>(), 4);
        assert_eq!(offset_of!(TransferTableEntry, r), 0);
        assert_eq!(offset_of!(TransferTableEntry, g), 4);
        assert_eq!(offset_of!(TransferTableEntry, b), 8);
        assert_eq!(offset_of!(TransferTableEntry, a), 12);
    }

    #[test]
    fn a_table_is_a_flat_run_of_four_floats() {
        let table = [
            TransferTableEntry { r: 1.0, g: 2.0, b: 3.0, a: 4.0 },
            TransferTableEntry { r: 5.0, g: 6.0, b: 7.0, a: 8.0 },
        ];
        let floats: &[f32] = bytemuck::cast_slice(&table);
        assert_eq!(floats, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
        assert_eq!(table[1].to_array(), [5.0, 6.0, 7.0, 8.0]);
    }
}
