//! A small hand-built tree for the traversal's unit tests: N = 2, bricks of 8 voxels, the root's brick and its eight
//! children (bricks, constants or missing), each brick filled from a field of the unit cube; and an integrand that
//! records what the traversal hands it. Small enough to reason about by hand, real enough to exercise every seam.

use std::ops::ControlFlow;

use glam::DVec3;
use voxstream_core::{
    BrickBlend, BrickSlot, FeedbackBuffer, Node, PoolCapacity, PoolVoxels, TileId, TreeShape, TreeView, VoxelFormat,
    BLOCK_CELLS,
};

use super::{Ray, Traversal};
use crate::integrand::{Integrand, Sample};
use crate::settings::RenderSettings;
use crate::step_table::StepLength;

/// What a child of the root holds.
#[derive(Clone, Copy, Debug)]
pub(super) enum Child {
    Brick,
    Constant(f32),
    Missing,
}

/// The tree's pools, owned.
pub(super) struct TestTree {
    shape: TreeShape,
    nodes: Vec<Node>,
    voxels: Vec<u16>,
    brick_ranges: Vec<[u16; 2]>,
    block_ranges: Vec<[u16; 2]>,
    pub(super) blends: Vec<BrickBlend>,
}

impl TestTree {
    /// The root's brick sampled from `root_field`, the children's (child `x + 2y + 4z`) from `child_field`; values
    /// clamped to `[0, 1]` and stored in 16 bits.
    pub(super) fn new(
        root_field: impl Fn(DVec3) -> f64,
        child_field: impl Fn(DVec3) -> f64,
        children: [Child; 8],
    ) -> TestTree {
        let shape = TreeShape::new(2, 8, 1).unwrap();
        let (b, m) = (shape.stored_brick_size() as usize, shape.brick_size as f64);
        let blocks = shape.blocks_per_axis();
        let mut tree = TestTree {
            shape,
            nodes: vec![Node::MISSING; 16],
            voxels: Vec::new(),
            brick_ranges: Vec::new(),
            block_ranges: Vec::new(),
            blends: Vec::new(),
        };
        // One brick of `field` for the node at `level`, `ijk`: voxel `i` (border included) centred at
        // `(ijk + (i − 0.5) / M) / N^level`.
        let add_brick = |tree: &mut TestTree, field: &dyn Fn(DVec3) -> f64, level: i32, ijk: [u32; 3]| {
            let size = 0.5f64.powi(level);
            let start = tree.voxels.len();
            for z in 0..b {
                for y in 0..b {
                    for x in 0..b {
                        let local = [x, y, z].map(|i| (i as f64 - 0.5) / m);
                        let p = DVec3::from_array(std::array::from_fn(|a| (ijk[a] as f64 + local[a]) * size));
                        tree.voxels.push((field(p).clamp(0.0, 1.0) * 65_535.0).round() as u16);
                    }
                }
            }
            let brick = &tree.voxels[start..];
            let range =
                |it: &mut dyn Iterator<Item = u16>| it.fold([u16::MAX, 0], |[lo, hi], v| [lo.min(v), hi.max(v)]);
            tree.brick_ranges.push(range(&mut brick.iter().copied()));
            // A block's cells lie between the voxels at its cell indices and one past them.
            for bz in 0..blocks {
                for by in 0..blocks {
                    for bx in 0..blocks {
                        let span = |c: usize| c * BLOCK_CELLS..=((c + 1) * BLOCK_CELLS).min(b - 1);
                        let mut values = span(bz).flat_map(|z| {
                            span(by).flat_map(move |y| span(bx).map(move |x| brick[(z * b + y) * b + x]))
                        });
                        tree.block_ranges.push(range(&mut values));
                    }
                }
            }
            tree.blends.push(BrickBlend::FULL);
            BrickSlot((tree.brick_ranges.len() - 1) as u32)
        };
        let root_slot = add_brick(&mut tree, &root_field, 0, [0; 3]);
        tree.nodes[0].set_brick(Some(root_slot));
        tree.nodes[0].set_child_tile(Some(TileId(1)));
        for (index, child) in children.into_iter().enumerate() {
            let ijk = [index as u32 & 1, index as u32 >> 1 & 1, index as u32 >> 2 & 1];
            tree.nodes[8 + index] = match child {
                Child::Brick => {
                    let mut node = Node::MISSING;
                    node.set_brick(Some(add_brick(&mut tree, &child_field, 1, ijk)));
                    node.set_terminal(true);
                    node
                }
                Child::Constant(value) => Node::constant(value),
                Child::Missing => Node::MISSING,
            };
        }
        tree
    }

    /// The view a frame would get.
    pub(super) fn view(&self) -> TreeView<'_> {
        TreeView {
            shape: self.shape,
            nodes: &self.nodes,
            voxels: PoolVoxels::Wide(&self.voxels),
            voxel_format: VoxelFormat::default(),
            brick_ranges: &self.brick_ranges,
            block_ranges: &self.block_ranges,
            brick_blends: &self.blends,
            capacity: PoolCapacity { tiles: 2, bricks: self.brick_ranges.len() as u32 },
        }
    }

    /// A feedback buffer for this tree.
    pub(super) fn feedback(&self) -> FeedbackBuffer {
        FeedbackBuffer::new(2, self.brick_ranges.len() as u32)
    }

    /// A traversal of this tree with `settings`.
    pub(super) fn traversal<'a>(&'a self, feedback: &'a FeedbackBuffer, settings: &RenderSettings) -> Traversal<'a> {
        Traversal::new(self.view(), feedback, settings)
    }
}

/// A primary ray from `origin` towards `direction` (normalised), with a narrow cone (the finest level everywhere).
pub(super) fn ray(origin: [f64; 3], direction: [f64; 3]) -> Ray {
    Ray { origin: DVec3::from(origin), direction: DVec3::from(direction).normalize(), spread: 1e-4, start: 0.0 }
}

/// Records every sample (with the step it stands for), constant and level handed over, in order; values at or
/// below `threshold` cannot contribute (`None`: every value can).
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct Record {
    pub(super) threshold: Option<f32>,
    pub(super) step: f64,
    /// `(t, value, step)` of each sample.
    pub(super) samples: Vec<(f64, f32, f64)>,
    /// `(from, to, value)` of each constant segment.
    pub(super) constants: Vec<(f64, f64, f32)>,
    /// The level of each segment.
    pub(super) levels: Vec<u32>,
}

impl Integrand for Record {
    fn can_contribute(&self, _lower: f32, upper: f32) -> bool {
        self.threshold.is_none_or(|threshold| upper > threshold)
    }

    fn wants_gradient(&self) -> bool {
        false
    }

    fn set_step(&mut self, step: StepLength) {
        self.step = step.world;
    }

    fn sample(&mut self, sample: Sample) -> ControlFlow<()> {
        self.samples.push((sample.t, sample.value, self.step));
        ControlFlow::Continue(())
    }

    fn constant(&mut self, from: f64, to: f64, value: f32) -> ControlFlow<()> {
        self.constants.push((from, to, value));
        ControlFlow::Continue(())
    }

    fn set_level(&mut self, level: u32) {
        self.levels.push(level);
    }
}
