//! A binary brick of the fused scene (seed 004 §8.4.1): 8³ voxels, two bits each — the *sign* of the voxel centre's
//! averaged distance to the surface (set = behind the surface) and whether that sign is *confident* (§8.3.4) — the
//! average error of the samples that last set it, the colours of its surface voxels (§8.5), and their surface
//! offsets.
//!
//! Bits are stored as eight 64-bit words, one per z slice, bit `x + 8·y`. Colours are kept in blocks of 4×4×2 voxels
//! (the thesis' sub-brick of 32 voxels) as RGB565, and only for blocks that hold a surface voxel: a brick is 16
//! blocks, and a typical surface brick colours a few of them.
//!
//! **Surface offsets** (our addition to the thesis' two bits): a voxel whose averaged distance lies within
//! [`OFFSET_RANGE`] voxels of the surface also keeps that distance, as one signed byte (1/63.5 of a voxel), with a byte
//! of the weight it was averaged over, in blocks of the same 4×4×2 shape kept only where such a voxel is. A sign bit
//! alone places the surface on a voxel face, up to half a voxel from where the frames saw it; two distances of opposite
//! sign place it between the voxel centres, as a TSDF's zero crossing does. The distances are projective (along the
//! line of sight), larger than the distance to the surface where it is seen at a slant, so the range is two voxels:
//! both voxels of a face then keep one even at grazing views. `--sign-only` fusions keep none.

/// Voxels along a brick's edge.
pub const BRICK: i32 = 8;
/// Voxels in a brick.
pub const BRICK_VOXELS: usize = 512;

/// The index of voxel `(x, y, z)` (each `0..8`) in a brick's bit set.
#[inline]
pub fn voxel_index(x: i32, y: i32, z: i32) -> usize {
    (x + BRICK * y + BRICK * BRICK * z) as usize
}

/// 512 bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Bits(pub [u64; 8]);

impl Bits {
    #[inline]
    pub fn get(&self, i: usize) -> bool {
        self.0[i >> 6] >> (i & 63) & 1 == 1
    }

    #[inline]
    pub fn set(&mut self, i: usize, value: bool) {
        let mask = 1u64 << (i & 63);
        if value {
            self.0[i >> 6] |= mask;
        } else {
            self.0[i >> 6] &= !mask;
        }
    }

    pub fn count(&self) -> u32 {
        self.0.iter().map(|w| w.count_ones()).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.0.iter().all(|&w| w == 0)
    }

    pub fn and(&self, other: &Bits) -> Bits {
        Bits(std::array::from_fn(|i| self.0[i] & other.0[i]))
    }
}

/// Colours of the 32 voxels of one 4×4×2 block, RGB565 (0 = none).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ColourBlock {
    /// Which of the brick's 16 blocks: `bx + 2·by + 4·bz` with `bx, by ∈ 0..2`, `bz ∈ 0..4`.
    pub block: u8,
    pub rgb565: [u16; 32],
}

/// The block of voxel `(x, y, z)` and the voxel's slot in it.
#[inline]
pub fn colour_slot(x: i32, y: i32, z: i32) -> (u8, usize) {
    let block = (x / 4 + 2 * (y / 4) + 4 * (z / 2)) as u8;
    let slot = (x % 4 + 4 * (y % 4) + 16 * (z % 2)) as usize;
    (block, slot)
}

/// Surface offsets of the 32 voxels of one 4×4×2 block (slots as [`ColourBlock`]'s): the averaged signed distance
/// in 1/63.5 of a voxel ([`NO_OFFSET`] where a voxel keeps none) and the weight it was averaged over (frames).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OffsetBlock {
    pub block: u8,
    pub offset: [i8; 32],
    pub weight: [u8; 32],
}

/// The most weight a surface offset accumulates (frames; windows overlap by half, so about half as many frames
/// seen): later frames still move it by at least 1/255 of their distance each.
pub const MAX_OFFSET_WEIGHT: f32 = 255.0;

/// The offset byte of a voxel that has none.
pub const NO_OFFSET: i8 = i8::MIN;
/// The largest surface offset kept, voxels.
pub const OFFSET_RANGE: f32 = 2.0;
/// Offset bytes per voxel of distance.
const OFFSET_SCALE: f32 = 127.0 / OFFSET_RANGE;

/// RGB565 of an sRGB colour; never 0 (0 marks "no colour"), pure black becomes the darkest blue.
pub fn to_rgb565(rgb: [u8; 3]) -> u16 {
    let value = (u16::from(rgb[0] >> 3) << 11) | (u16::from(rgb[1] >> 2) << 5) | u16::from(rgb[2] >> 3);
    value.max(1)
}

/// sRGB of an RGB565 colour.
pub fn from_rgb565(value: u16) -> [u8; 3] {
    let r = ((value >> 11) & 31) as u8;
    let g = ((value >> 5) & 63) as u8;
    let b = (value & 31) as u8;
    [(r << 3) | (r >> 2), (g << 2) | (g >> 4), (b << 3) | (b >> 2)]
}

/// One brick of the fused scene.
#[derive(Clone, Debug, PartialEq)]
pub struct BinaryBrick {
    /// Set where the voxel centre lies behind the surface (its averaged signed distance is negative).
    pub inside: Bits,
    /// Set where the sign was decided with at least the confidence weight (§8.3.4).
    pub confident: Bits,
    /// Average uncertainty (metres) of the depth samples of the last window that changed this brick;
    /// `f32::INFINITY` while no window has.
    pub error: f32,
    /// Whether a window of the cache has processed it; `false` while only the sub-cache has (§8.3.3).
    pub integrated: bool,
    /// Colours of surface voxels, in blocks sorted by block index.
    pub colours: Vec<ColourBlock>,
    /// Surface offsets, in blocks sorted by block index.
    pub offsets: Vec<OffsetBlock>,
}

impl Default for BinaryBrick {
    fn default() -> Self {
        BinaryBrick {
            inside: Bits::default(),
            confident: Bits::default(),
            error: f32::INFINITY,
            integrated: false,
            colours: Vec::new(),
            offsets: Vec::new(),
        }
    }
}

impl BinaryBrick {
    /// Bytes this brick holds, counting its colour and offset blocks.
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<BinaryBrick>()
            + self.colours.capacity() * std::mem::size_of::<ColourBlock>()
            + self.offsets.capacity() * std::mem::size_of::<OffsetBlock>()
    }

    /// The colour of voxel `(x, y, z)`, if it has one.
    pub fn colour(&self, x: i32, y: i32, z: i32) -> Option<[u8; 3]> {
        let (block, slot) = colour_slot(x, y, z);
        let found = self.colours.binary_search_by_key(&block, |b| b.block).ok()?;
        let value = self.colours[found].rgb565[slot];
        (value != 0).then(|| from_rgb565(value))
    }

    /// Sets the colour of voxel `(x, y, z)`, allocating its block on first use.
    pub fn set_colour(&mut self, x: i32, y: i32, z: i32, rgb: [u8; 3]) {
        let (block, slot) = colour_slot(x, y, z);
        let at = match self.colours.binary_search_by_key(&block, |b| b.block) {
            Ok(at) => at,
            Err(at) => {
                self.colours.insert(at, ColourBlock { block, rgb565: [0; 32] });
                at
            }
        };
        self.colours[at].rgb565[slot] = to_rgb565(rgb);
    }

    /// The surface offset of voxel `(x, y, z)`: its averaged signed distance in voxels (within ±[`OFFSET_RANGE`],
    /// negative behind the surface), if it keeps one.
    pub fn offset(&self, x: i32, y: i32, z: i32) -> Option<f32> {
        let (block, slot) = colour_slot(x, y, z);
        let found = self.offsets.binary_search_by_key(&block, |b| b.block).ok()?;
        let value = self.offsets[found].offset[slot];
        (value != NO_OFFSET).then(|| f32::from(value) / OFFSET_SCALE)
    }

    /// The surface offset of voxel `(x, y, z)` (voxels) and the weight it was averaged over, if it keeps one.
    pub fn offset_and_weight(&self, x: i32, y: i32, z: i32) -> Option<(f32, f32)> {
        let (block, slot) = colour_slot(x, y, z);
        let found = &self.offsets[self.offsets.binary_search_by_key(&block, |b| b.block).ok()?];
        (found.offset[slot] != NO_OFFSET)
            .then(|| (f32::from(found.offset[slot]) / OFFSET_SCALE, f32::from(found.weight[slot])))
    }

    /// Keeps `distance` (voxels, clamped to ±[`OFFSET_RANGE`]) averaged over `weight` (clamped to 1 to
    /// [`MAX_OFFSET_WEIGHT`]) as the surface offset of voxel `(x, y, z)`, allocating its block on first use.
    pub fn set_offset(&mut self, x: i32, y: i32, z: i32, distance: f32, weight: f32) {
        let (block, slot) = colour_slot(x, y, z);
        let at = match self.offsets.binary_search_by_key(&block, |b| b.block) {
            Ok(at) => at,
            Err(at) => {
                self.offsets.insert(at, OffsetBlock { block, offset: [NO_OFFSET; 32], weight: [0; 32] });
                at
            }
        };
        self.offsets[at].offset[slot] = (distance.clamp(-OFFSET_RANGE, OFFSET_RANGE) * OFFSET_SCALE).round() as i8;
        self.offsets[at].weight[slot] = weight.clamp(1.0, MAX_OFFSET_WEIGHT).round() as u8;
    }

    /// Copies voxel `(x, y, z)`'s colour from `from`, where it has one.
    pub fn keep_colour(&mut self, from: &BinaryBrick, x: i32, y: i32, z: i32) {
        if let Some(rgb) = from.colour(x, y, z) {
            self.set_colour(x, y, z, rgb);
        }
    }

    /// Whether the brick holds nothing a reader needs: no voxel behind the surface. Outside is what an absent
    /// brick means, so such a brick is removed after a window (§8.4.3: "all empty bricks are collected and
    /// removed").
    pub fn is_empty(&self) -> bool {
        self.inside.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_set_get_count() {
        let mut bits = Bits::default();
        for (i, &v) in [0usize, 63, 64, 200, 511].iter().enumerate() {
            bits.set(v, true);
            assert!(bits.get(v));
            assert_eq!(bits.count(), i as u32 + 1);
        }
        bits.set(64, false);
        assert!(!bits.get(64) && bits.get(63) && bits.get(200));
        assert_eq!(voxel_index(7, 7, 7), 511);
        assert_eq!(voxel_index(1, 2, 3), 1 + 16 + 192);
    }

    #[test]
    fn colour_slots_cover_the_brick_once() {
        let mut seen = std::collections::HashSet::new();
        for z in 0..8 {
            for y in 0..8 {
                for x in 0..8 {
                    let (block, slot) = colour_slot(x, y, z);
                    assert!(block < 16 && slot < 32);
                    assert!(seen.insert((block, slot)), "{x},{y},{z}");
                }
            }
        }
        assert_eq!(seen.len(), 512);
    }

    #[test]
    fn colours_round_trip_through_rgb565() {
        let mut brick = BinaryBrick::default();
        brick.set_colour(5, 2, 7, [255, 128, 0]);
        brick.set_colour(0, 0, 0, [0, 0, 0]);
        assert_eq!(brick.colours.len(), 2);
        assert!(brick.colours[0].block < brick.colours[1].block);
        let c = brick.colour(5, 2, 7).unwrap();
        assert!(c.iter().zip([255u8, 128, 0]).all(|(&a, b)| (a as i32 - b as i32).abs() <= 8), "{c:?}");
        assert!(brick.colour(0, 0, 0).is_some(), "black is a colour, not none");
        assert_eq!(brick.colour(1, 0, 0), None);
    }

    #[test]
    fn offsets_and_their_weights_round_trip() {
        let mut brick = BinaryBrick::default();
        brick.set_colour(5, 2, 7, [255, 128, 0]);
        brick.set_offset(5, 2, 7, -0.3, 12.0);
        brick.set_offset(4, 3, 6, 3.0, 1000.0);
        brick.set_offset(0, 0, 0, 0.0, 0.0);
        assert_eq!(brick.offsets.len(), 2, "(5,2,7) and (4,3,6) share a block");
        let (d, w) = brick.offset_and_weight(5, 2, 7).unwrap();
        assert!((d + 0.3).abs() <= 0.5 / OFFSET_SCALE && w == 12.0, "{d} {w}");
        assert_eq!(brick.offset(4, 3, 6), Some(OFFSET_RANGE), "clamped to the range");
        assert_eq!(brick.offset_and_weight(4, 3, 6).unwrap().1, MAX_OFFSET_WEIGHT);
        assert_eq!(brick.offset_and_weight(0, 0, 0), Some((0.0, 1.0)), "zero is an offset, not none");
        assert_eq!(brick.colour(0, 0, 0), None, "an offset without a colour");
        assert_eq!(brick.offset(1, 1, 1), None);
        let mut copy = BinaryBrick::default();
        copy.keep_colour(&brick, 5, 2, 7);
        assert_eq!(copy.colours, brick.colours);
        assert!(copy.offsets.is_empty());
    }
}
