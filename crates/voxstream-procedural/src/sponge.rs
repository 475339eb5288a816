//! The Menger sponge, N = 3: an exact, unbounded-depth fractal for deep-zoom tests.
//!
//! GigaVoxels [R08] §7 / [P09] §8: the Sierpinski (Menger) sponge, with one brick instanced at every non-empty tile.
//! Here a node at level `d` holds the sponge's iteration `d + log₃M` as a binary brick: voxel `g` (integer, at the
//! level's voxel grid) is solid unless, at some base-3 digit, two or more of its coordinates have digit 1. The test
//! is exact integer arithmetic, so any depth the tree allows (3²⁵·M voxels per axis and more) is produced exactly.
//! The oracle marks the 7 empty children of every tile as constant 0 without producing them.

use voxstream_core::{NodeContent, NodeKey, ProduceError, Produced, Producer, TreeShape, VoxelFormat, VOXEL_MAX};

/// The Menger sponge producer.
#[derive(Clone, Copy, Debug)]
pub struct MengerSponge {
    shape: TreeShape,
    /// `log₃ M`: sponge iterations resolved inside one brick.
    digits_per_brick: u32,
}

/// Default brick edge for the sponge (one brick resolves two sponge iterations).
pub const SPONGE_BRICK_SIZE: u32 = 9;
/// Default deepest level: voxels of 3⁻²⁵/9 of the scene, far below float32's reach.
pub const SPONGE_MAX_LEVEL: u32 = 25;

impl MengerSponge {
    /// A sponge with bricks of `brick_size` voxels (a power of 3) and `max_level` levels.
    pub fn new(brick_size: u32, max_level: u32) -> Result<MengerSponge, voxstream_core::CoreError> {
        let mut digits = 0;
        let mut m = brick_size;
        while m > 1 && m.is_multiple_of(3) {
            m /= 3;
            digits += 1;
        }
        if m != 1 || digits == 0 {
            return Err(voxstream_core::CoreError::InvalidShape(format!(
                "the sponge needs a brick size that is a power of 3 (3, 9, 27), got {brick_size}"
            )));
        }
        let shape = TreeShape::new(3, brick_size, max_level)?;
        if max_level + digits > 39 {
            return Err(voxstream_core::CoreError::InvalidShape("sponge too deep for 64-bit voxel indices".into()));
        }
        Ok(MengerSponge { shape, digits_per_brick: digits })
    }
}

impl Default for MengerSponge {
    fn default() -> Self {
        MengerSponge {
            shape: TreeShape { n: 3, brick_size: SPONGE_BRICK_SIZE, max_level: SPONGE_MAX_LEVEL },
            digits_per_brick: 2,
        }
    }
}

/// Whether the cell `g` of a `3^digits` grid belongs to the sponge's iteration `digits`.
#[inline]
pub fn is_solid(g: [u64; 3], digits: u32) -> bool {
    let mut g = g;
    for _ in 0..digits {
        let ones = g.iter().filter(|&&v| v % 3 == 1).count();
        if ones >= 2 {
            return false;
        }
        g = g.map(|v| v / 3);
    }
    true
}

impl Producer for MengerSponge {
    fn shape(&self) -> TreeShape {
        self.shape
    }

    fn oracle(&self, key: NodeKey) -> Option<f32> {
        (!is_solid(key.ijk, key.level)).then_some(0.0)
    }

    /// One byte per voxel: the sponge's voxels are 0 and 1 (bytes 0 and 255), so its bricks take half the memory
    /// and half the cache lines.
    fn voxel_format(&self) -> VoxelFormat {
        VoxelFormat::for_bytes([0.0, 255.0]).unwrap_or(VoxelFormat::Wide)
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        if !is_solid(key.ijk, key.level) {
            return Ok(Produced { content: NodeContent::Empty, is_terminal: true });
        }
        let m = self.shape.brick_size as i64;
        let b = self.shape.stored_brick_size() as i64;
        let digits = key.level + self.digits_per_brick;
        let extent = (self.shape.nodes_per_axis(key.level) as i64) * m;
        let base = key.ijk.map(|v| v as i64 * m - 1);
        let mut index = 0;
        for k in 0..b {
            for j in 0..b {
                for i in 0..b {
                    let g = [base[0] + i, base[1] + j, base[2] + k];
                    let inside = g.iter().all(|&v| (0..extent).contains(&v));
                    voxels[index] = if inside && is_solid(g.map(|v| v as u64), digits) { VOXEL_MAX } else { 0 };
                    index += 1;
                }
            }
        }
        Ok(Produced { content: NodeContent::Brick, is_terminal: key.level >= self.shape.max_level })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_iteration_has_twenty_cubes() {
        let mut solid = 0;
        for z in 0..3 {
            for y in 0..3 {
                for x in 0..3 {
                    solid += is_solid([x, y, z], 1) as u32;
                }
            }
        }
        assert_eq!(solid, 20);
    }

    #[test]
    fn second_iteration_has_four_hundred_cubes() {
        let mut solid = 0;
        for z in 0..9 {
            for y in 0..9 {
                for x in 0..9 {
                    solid += is_solid([x, y, z], 2) as u32;
                }
            }
        }
        assert_eq!(solid, 400);
    }

    #[test]
    fn root_brick_is_iteration_two_with_empty_border() {
        let sponge = MengerSponge::default();
        let shape = sponge.shape();
        let mut voxels = vec![0u16; shape.voxels_per_brick()];
        sponge.produce(NodeKey::ROOT, &mut voxels).unwrap();
        let solid = voxels.iter().filter(|&&v| v == VOXEL_MAX).count();
        assert_eq!(solid, 400, "border voxels lie outside the scene and are empty");
    }

    #[test]
    fn oracle_marks_the_seven_holes() {
        let sponge = MengerSponge::default();
        let empty = (0..27).filter(|&c| sponge.oracle(NodeKey::ROOT.child(c, 3)).is_some()).count();
        assert_eq!(empty, 7);
    }

    #[test]
    fn deep_nodes_are_exact() {
        let sponge = MengerSponge::default();
        // A node at level 22 on the main diagonal corner: every digit 0 → solid.
        let key = NodeKey { level: 22, ijk: [0, 0, 0] };
        let mut voxels = vec![0u16; sponge.shape().voxels_per_brick()];
        assert_eq!(sponge.produce(key, &mut voxels).unwrap().content, NodeContent::Brick);
        // Centre hole of the level-22 node at index (1,1,·) in its own 3×3 split: ijk·3+1.
        assert!(sponge.oracle(NodeKey { level: 23, ijk: [1, 1, 0] }).is_some());
        assert!(sponge.oracle(NodeKey { level: 23, ijk: [1, 0, 0] }).is_none());
    }

    #[test]
    fn bricks_are_stored_as_bytes_without_loss() {
        use voxstream_core::{BrickPool, NodeId, PoolVoxels};
        let sponge = MengerSponge::default();
        let shape = sponge.shape();
        let format = sponge.voxel_format();
        let VoxelFormat::Narrow { scale, offset } = format else { panic!("the sponge's bricks should be bytes") };
        let mut pool = BrickPool::with_format(&shape, 2, format);
        let mut voxels = vec![0u16; shape.voxels_per_brick()];
        let key = NodeKey { level: 3, ijk: [0, 2, 0] };
        sponge.produce(key, &mut voxels).unwrap();
        let (slot, _) = pool.insert(NodeId(1), &voxels, 0).unwrap();
        let PoolVoxels::Narrow(bytes) = pool.brick(slot) else { panic!("a narrow pool stores bytes") };
        let mut solid = 0;
        for (&wide, &byte) in voxels.iter().zip(bytes) {
            assert!(wide == 0 || wide == VOXEL_MAX, "the sponge writes only 0 and 1, got {wide}");
            assert_eq!(byte, if wide == VOXEL_MAX { 255 } else { 0 });
            solid += (byte == 255) as usize;
        }
        assert!(solid > 0 && solid < bytes.len(), "a brick with both solid and empty voxels");
        // The values the renderer reads from the bytes are exactly the sponge's 0 and 1.
        assert_eq!(0.0 * scale + offset, 0.0);
        assert_eq!(255.0 * scale + offset, 1.0);
    }

    #[test]
    fn brick_sizes_must_be_powers_of_three() {
        assert!(MengerSponge::new(8, 10).is_err());
        assert!(MengerSponge::new(27, 10).is_ok());
    }
}
