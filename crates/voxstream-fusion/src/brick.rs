//! A binary brick of the fused scene (seed 004 §8.4.1): 8³ voxels, two bits each — the *sign* of the voxel centre's
//! averaged distance to the surface (set = behind the surface) and whether that sign is *confident* (§8.3.4) — the
//! average error of the samples that last set it, and the colours of its surface voxels (§8.5).
//!
//! Bits are stored as eight 64-bit words, one per z slice, bit `x + 8·y`. Colours are kept in blocks of 4×4×2 voxels
//! (the thesis' sub-brick of 32 voxels) as RGB565, and only for blocks that hold a surface voxel: a brick is 16
//! blocks, and a typical surface brick colours a few of them.

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
}

impl Default for BinaryBrick {
    fn default() -> Self {
        BinaryBrick {
            inside: Bits::default(),
            confident: Bits::default(),
            error: f32::INFINITY,
            integrated: false,
            colours: Vec::new(),
        }
    }
}

impl BinaryBrick {
    /// Bytes this brick holds, counting its colour blocks.
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<BinaryBrick>() + self.colours.capacity() * std::mem::size_of::<ColourBlock>()
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
}
