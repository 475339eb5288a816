//! The blend record: how far each resident brick may stand in for its parent, at its eight corners.
//!
//! Thiele et al. ([T23], seed 003, `notes/thiele-lod-blending.md` §"temporal" and §"spatial"): a brick that just
//! arrived fades in from its parent over a few frames, and a brick whose neighbour is still coarser blends towards
//! its parent where that neighbour touches, so the image has neither pops nor seams. Both come down to one number
//! per brick corner, the **cap** on the brick's weight against its parent: the renderer takes
//! `min(cone weight, cap)` with the cap interpolated trilinearly between the corners, where the cone weight is the
//! quadrilinear level blend it uses anyway. A cap of 1 everywhere is no blending at all (the same bits).
//!
//! Corner `c` is `x + 2y + 4z` with `x, y, z ∈ {0, 1}` the corner's side along each axis (0 = lower).
//!
//! `fade` is the brick's own fade-in. While it is below 1 the renderer draws none of the brick's descendants (it
//! shows this brick blended with its parent instead): a child can only fade in from a parent that is fully in, so
//! the image never jumps from a half-faded parent to a child that starts from the whole parent.
//!
//! | record | offset | bytes | field | meaning |
//! |---|---|---|---|---|
//! | [`BrickBlend`] | 0 | 4 | `corner0` | cap at corner (0, 0, 0), in `[0, 1]` |
//! | | 4 … 28 | 4 each | `corner1` … `corner7` | caps at the other corners |
//! | | 32 | 4 | `fade` | the brick's own fade-in, in `[0, 1]`: below 1, its descendants are not drawn |

use bytemuck::{Pod, Zeroable};

/// Per brick slot: the cap on the brick's weight against its parent at each of its eight corners.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct BrickBlend {
    /// Cap at corner (0, 0, 0).
    pub corner0: f32,
    /// Cap at corner (1, 0, 0).
    pub corner1: f32,
    /// Cap at corner (0, 1, 0).
    pub corner2: f32,
    /// Cap at corner (1, 1, 0).
    pub corner3: f32,
    /// Cap at corner (0, 0, 1).
    pub corner4: f32,
    /// Cap at corner (1, 0, 1).
    pub corner5: f32,
    /// Cap at corner (0, 1, 1).
    pub corner6: f32,
    /// Cap at corner (1, 1, 1).
    pub corner7: f32,
    /// The brick's own fade-in: below 1, its descendants are not drawn.
    pub fade: f32,
}

impl BrickBlend {
    /// No blending: the brick stands in for its parent fully everywhere.
    pub const FULL: BrickBlend = BrickBlend::uniform(1.0);

    /// The same cap at every corner.
    pub const fn uniform(cap: f32) -> BrickBlend {
        BrickBlend {
            corner0: cap,
            corner1: cap,
            corner2: cap,
            corner3: cap,
            corner4: cap,
            corner5: cap,
            corner6: cap,
            corner7: cap,
            fade: cap,
        }
    }

    /// The caps as an array, corner `x + 2y + 4z`.
    pub fn corners(&self) -> [f32; 8] {
        [self.corner0, self.corner1, self.corner2, self.corner3, self.corner4, self.corner5, self.corner6, self.corner7]
    }

    /// The record holding `corners` and `fade`.
    pub fn new(corners: [f32; 8], fade: f32) -> BrickBlend {
        let [corner0, corner1, corner2, corner3, corner4, corner5, corner6, corner7] = corners;
        BrickBlend { corner0, corner1, corner2, corner3, corner4, corner5, corner6, corner7, fade }
    }

    /// Whether every corner is 1 (the brick itself is drawn as if there were no blending).
    pub fn is_full(&self) -> bool {
        self.corners().iter().all(|&c| c >= 1.0)
    }

    /// Whether the brick has faded in completely (its descendants may be drawn).
    pub fn is_in(&self) -> bool {
        self.fade >= 1.0
    }

    /// The cap at `p` in brick-relative coordinates (`[0, 1]³`), trilinear between the corners.
    pub fn at(&self, p: [f32; 3]) -> f32 {
        let c = self.corners();
        let [x, y, z] = p.map(|v| v.clamp(0.0, 1.0));
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let y0 = lerp(lerp(c[0], c[1], x), lerp(c[2], c[3], x), y);
        let y1 = lerp(lerp(c[4], c[5], x), lerp(c[6], c[7], x), y);
        lerp(y0, y1, z)
    }
}

impl Default for BrickBlend {
    fn default() -> Self {
        BrickBlend::FULL
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn offsets_are_as_documented() {
        assert_eq!(size_of::<BrickBlend>(), 36);
        assert_eq!(align_of::<BrickBlend>(), 4);
        assert_eq!(offset_of!(BrickBlend, corner0), 0);
        assert_eq!(offset_of!(BrickBlend, corner1), 4);
        assert_eq!(offset_of!(BrickBlend, corner3), 12);
        assert_eq!(offset_of!(BrickBlend, corner7), 28);
        assert_eq!(offset_of!(BrickBlend, fade), 32);
    }

    #[test]
    fn corners_are_x_plus_2y_plus_4z() {
        let blend = BrickBlend::new([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0], 0.5);
        assert_eq!(blend.corner5, 5.0);
        assert_eq!(blend.at([0.0, 0.0, 0.0]), 0.0);
        assert_eq!(blend.at([1.0, 0.0, 0.0]), 1.0);
        assert_eq!(blend.at([0.0, 1.0, 0.0]), 2.0);
        assert_eq!(blend.at([0.0, 0.0, 1.0]), 4.0);
        assert_eq!(blend.at([1.0, 1.0, 1.0]), 7.0);
        // Trilinear: the centre is the mean of the corners.
        assert_eq!(blend.at([0.5, 0.5, 0.5]), 3.5);
        assert!(BrickBlend::FULL.is_full());
        assert!(!blend.is_full());
        assert!(!blend.is_in() && BrickBlend::FULL.is_in());
        assert_eq!(BrickBlend::FULL.at([0.3, 0.9, 0.1]), 1.0);
    }
}
