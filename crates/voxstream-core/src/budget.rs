//! Splitting one memory budget between the node pool and the brick pool.
//!
//! GigaVoxels [P09] §5: both pools are caches of fixed size (their paper: a 4 MB node pool beside a 430 MB brick
//! pool). voxstream derives both capacities from one `--budget-mb`, counting every per-slot byte (nodes, voxels,
//! bookkeeping, feedback flags), so the pools can never exceed it. The bricks produced but not yet copied into the
//! pool (one production batch) are counted too: the batch is sized from the budget (at most a sixteenth of it).

use crate::brick_pool::brick_record_bytes;
use crate::cache_manager::PRODUCTION_BATCH;
use crate::error::CoreError;
use crate::key::TreeShape;
use crate::lru::LRU_BYTES_PER_SLOT;
use crate::node::Node;
use crate::node_pool::TILE_RECORD_BYTES;
use crate::voxel_format::VoxelFormat;

/// Share of the budget given to the node pool (the rest holds bricks).
pub const NODE_POOL_SHARE: f64 = 1.0 / 16.0;

/// Bytes of one voxel as producers write it (`u16`, values normalised to `[0, 1]`); the pool may keep 8 bits
/// ([`VoxelFormat`]).
pub const VOXEL_BYTES: usize = 2;

/// Capacities of both pools, derived from a byte budget.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PoolCapacities {
    /// Tiles of `N³` nodes, the root tile included.
    pub tiles: u32,
    /// Bricks of `(M+2)³` voxels.
    pub bricks: u32,
    /// Bytes per tile, all bookkeeping included.
    pub bytes_per_tile: u64,
    /// Bytes per brick, all bookkeeping included.
    pub bytes_per_brick: u64,
    /// Bricks produced concurrently before they are copied into the pool (a transient outside the pools).
    pub production_batch: u32,
    /// The budget these capacities respect.
    pub budget_bytes: u64,
}

impl PoolCapacities {
    /// Plans capacities so that `tiles·bytes_per_tile + bricks·bytes_per_brick ≤ budget_bytes`, for 16-bit voxels.
    pub fn plan(shape: &TreeShape, budget_bytes: u64) -> Result<PoolCapacities, CoreError> {
        PoolCapacities::plan_for(shape, VoxelFormat::Wide, budget_bytes)
    }

    /// [`PoolCapacities::plan`] for a pool that stores voxels as `format` says (8-bit voxels: about twice the
    /// bricks).
    pub fn plan_for(shape: &TreeShape, format: VoxelFormat, budget_bytes: u64) -> Result<PoolCapacities, CoreError> {
        let bytes_per_tile = (shape.nodes_per_tile() as usize * std::mem::size_of::<Node>()
            + TILE_RECORD_BYTES
            + LRU_BYTES_PER_SLOT
            + 1) as u64;
        let bytes_per_brick =
            (shape.voxels_per_brick() * format.voxel_bytes() + brick_record_bytes(shape) + LRU_BYTES_PER_SLOT + 1)
                as u64;
        // The smallest useful cache: the root tile plus a few tiles, a parent brick and all its children.
        let min_tiles = 4u64;
        let min_bricks = 2 * shape.nodes_per_tile() as u64;
        let produced_brick_bytes = (shape.voxels_per_brick() * VOXEL_BYTES) as u64;
        let minimum_bytes = min_tiles * bytes_per_tile + min_bricks * bytes_per_brick + produced_brick_bytes;
        if budget_bytes < minimum_bytes {
            return Err(CoreError::BudgetTooSmall { budget_bytes, minimum_bytes });
        }
        let production_batch = (budget_bytes / 16 / produced_brick_bytes).clamp(1, PRODUCTION_BATCH as u64);
        let pool_bytes = budget_bytes - production_batch * produced_brick_bytes;
        let node_bytes = ((pool_bytes as f64 * NODE_POOL_SHARE) as u64).max(min_tiles * bytes_per_tile);
        let tiles = (node_bytes / bytes_per_tile).min(crate::node::MAX_TILE_INDEX as u64);
        let bricks = (pool_bytes.saturating_sub(tiles * bytes_per_tile) / bytes_per_brick).min(u32::MAX as u64 - 1);
        if bricks < min_bricks {
            return Err(CoreError::BudgetTooSmall { budget_bytes, minimum_bytes });
        }
        Ok(PoolCapacities {
            tiles: tiles as u32,
            bricks: bricks as u32,
            bytes_per_tile,
            bytes_per_brick,
            production_batch: production_batch as u32,
            budget_bytes,
        })
    }

    /// Bytes used by `tiles` tiles and `bricks` bricks.
    pub fn bytes_for(&self, tiles: u32, bricks: u32) -> u64 {
        tiles as u64 * self.bytes_per_tile + bricks as u64 * self.bytes_per_brick
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn zero_budget_is_an_error() {
        let shape = TreeShape::new(2, 8, 10).unwrap();
        assert!(matches!(PoolCapacities::plan(&shape, 0), Err(CoreError::BudgetTooSmall { .. })));
    }

    proptest! {
        #[test]
        fn plan_never_exceeds_the_budget(budget in 0u64..(1 << 34), n in 2u32..4, m in 2u32..33) {
            let shape = TreeShape::new(n, m, 8).unwrap();
            if let Ok(caps) = PoolCapacities::plan(&shape, budget) {
                let batch_bytes = caps.production_batch as u64 * (shape.voxels_per_brick() * VOXEL_BYTES) as u64;
                prop_assert!(caps.bytes_for(caps.tiles, caps.bricks) + batch_bytes <= budget);
                prop_assert!(caps.production_batch >= 1);
                prop_assert!(caps.tiles >= 4);
                prop_assert!(caps.bricks >= 2 * shape.nodes_per_tile());
            }
        }
    }
}
