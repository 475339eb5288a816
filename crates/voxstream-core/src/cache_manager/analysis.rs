//! Brick analysis before upload ([R08] §4): a produced node becomes a constant or a brick prepared for the pool, on
//! the worker thread that produced it.

use crate::brick_pool::{dequantize, PreparedBrick, VOXEL_MAX};
use crate::error::ProduceError;
use crate::key::{NodeKey, TreeShape};
use crate::producer::{NodeContent, Produced, Producer};
use crate::voxel_format::VoxelFormat;

/// What a produced node holds, ready to apply.
pub(super) enum AnalysedContent {
    /// One value throughout (0 for an empty node).
    Constant(f32),
    /// Voxels, prepared for the pool on the worker that produced them.
    Brick(PreparedBrick),
}

pub(super) struct AnalysedBrick {
    pub(super) content: AnalysedContent,
    pub(super) is_terminal: bool,
    /// The producer's bounds of the whole subtree (stored units, rounded outwards), for a brick with children.
    pub(super) subtree_range: Option<[u16; 2]>,
}

/// Asks `producer` for the brick of `key`, then analyses it.
pub(super) fn produce_analysed<P: Producer>(
    producer: &P,
    key: NodeKey,
    shape: &TreeShape,
    format: VoxelFormat,
) -> Result<AnalysedBrick, ProduceError> {
    let mut voxels = vec![0u16; shape.voxels_per_brick()];
    let produced = producer.produce(key, &mut voxels)?;
    let mut analysed = analyse(produced, &voxels, key, shape, format);
    if matches!(analysed.content, AnalysedContent::Brick(_)) && !analysed.is_terminal {
        analysed.subtree_range = producer.subtree_range(key).map(|[lo, hi]| {
            let stored = |v: f32| (v.clamp(0.0, 1.0) * VOXEL_MAX as f32) as f64;
            [stored(lo).floor() as u16, stored(hi).ceil() as u16]
        });
    }
    Ok(analysed)
}

/// Brick analysis before upload ([R08] §4): a terminal brick of equal voxels is a constant node. A non-terminal one
/// stays a brick: equal voxels at a coarse level (an average) say nothing of the finer levels, and a constant node
/// is never subdivided; only the producer may declare a whole subtree constant. A brick is prepared for a pool of
/// `format` here, on the producing thread.
pub(super) fn analyse(
    produced: Produced,
    voxels: &[u16],
    key: NodeKey,
    shape: &TreeShape,
    format: VoxelFormat,
) -> AnalysedBrick {
    let is_terminal = produced.is_terminal || key.level >= shape.max_level;
    let content = match produced.content {
        NodeContent::Brick if is_terminal && voxels.iter().all(|&v| v == voxels[0]) => {
            AnalysedContent::Constant(dequantize(voxels[0]))
        }
        NodeContent::Brick => AnalysedContent::Brick(PreparedBrick::new(shape, format, voxels)),
        NodeContent::Empty => AnalysedContent::Constant(0.0),
        NodeContent::Constant(value) => AnalysedContent::Constant(value),
    };
    AnalysedBrick { content, is_terminal, subtree_range: None }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_terminal_bricks_of_equal_voxels_become_constants() {
        let shape = TreeShape::new(2, 8, 3).unwrap();
        let flat = vec![VOXEL_MAX; shape.voxels_per_brick()];
        let brick = |is_terminal| Produced { content: NodeContent::Brick, is_terminal };
        let analyse_at =
            |produced, level| analyse(produced, &flat, NodeKey { level, ijk: [0; 3] }, &shape, VoxelFormat::Wide);
        assert!(matches!(analyse_at(brick(true), 1).content, AnalysedContent::Constant(v) if v == 1.0));
        // The finest level is terminal whatever the producer says.
        assert!(matches!(analyse_at(brick(false), shape.max_level).content, AnalysedContent::Constant(_)));
        let coarse = analyse_at(brick(false), 1);
        assert!(matches!(coarse.content, AnalysedContent::Brick(_)) && !coarse.is_terminal);
        let empty = analyse_at(Produced { content: NodeContent::Empty, is_terminal: false }, 1);
        assert!(matches!(empty.content, AnalysedContent::Constant(v) if v == 0.0));
        let constant = analyse_at(Produced { content: NodeContent::Constant(0.5), is_terminal: false }, 1);
        assert!(matches!(constant.content, AnalysedContent::Constant(v) if v == 0.5));
        assert_eq!(coarse.subtree_range, None);
    }
}
