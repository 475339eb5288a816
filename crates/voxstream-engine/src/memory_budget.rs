//! The budget planner: one memory budget split among the image, the host-side (store) brick cache and the node and
//! brick pools, checked before anything is allocated.
//!
//! GigaVoxels [P09] §5 sizes its two pools once (a 4 MB node pool beside a 430 MB brick pool); Reichl's framework
//! (seed 004 ch. 4) adds a host cache in front of the disk. voxstream derives all of them from one budget in MiB:
//!
//! ```text
//! budget ─┬─ image: FRAME_BYTES_PER_PIXEL per pixel (counted first; it must leave something)
//!         ├─ host cache: 1/STORE_CACHE_SHARE of what the image leaves (only for a store read from disk)
//!         └─ pools: the rest, split by PoolCapacities::plan (node pool 1/16, bricks, one production batch)
//! ```
//!
//! [`MemoryBudget::new`] checks the budget against the machine and the image (before the source is opened: the
//! host cache is sized from it); [`MemoryBudget::plan`] completes the split once the tree's shape is known and
//! returns every part in a [`MemoryPlan`]. Errors carry numbers, not flags: front ends name their own flags.

use voxstream_core::{CoreError, PoolCapacities, TreeShape};
use voxstream_render::{frame_buffer_bytes, FRAME_BYTES_PER_PIXEL};

/// Largest accepted budget in MiB (1 TiB): guards against typos that would overflow.
pub const MAX_BUDGET_MB: u64 = 1 << 20;

/// Share of what the image leaves given to a store's host-side brick cache (the rest goes to the pools).
pub const STORE_CACHE_SHARE: u64 = 8;

const MIB: u64 = 1 << 20;

/// A budget that cannot be split.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BudgetError {
    /// A budget of 0 MiB.
    #[error("the memory budget must be at least 1 MiB")]
    Zero,
    /// A budget beyond [`MAX_BUDGET_MB`].
    #[error("a memory budget of {budget_mb} MiB is larger than 1 TiB ({MAX_BUDGET_MB} MiB)")]
    AboveLimit {
        /// The budget asked for, MiB.
        budget_mb: u64,
    },
    /// A budget beyond the machine's memory.
    #[error("a memory budget of {budget_mb} MiB is more than this machine's memory ({machine_mb} MiB)")]
    AboveMachine {
        /// The budget asked for, MiB.
        budget_mb: u64,
        /// The machine's memory (or the cgroup's limit), MiB, rounded down.
        machine_mb: u64,
    },
    /// An image whose per-pixel buffers take the whole budget.
    #[error(
        "a {width}x{height} image needs {image_mb} MiB of the memory budget ({FRAME_BYTES_PER_PIXEL} bytes per \
         pixel), more than the {budget_mb} MiB budget"
    )]
    ImageTooLarge {
        /// Image width, pixels.
        width: u32,
        /// Image height, pixels.
        height: u32,
        /// What the image needs, MiB, rounded up.
        image_mb: u64,
        /// The budget asked for, MiB.
        budget_mb: u64,
    },
    /// What the image and the host cache leave is less than the smallest useful pools.
    #[error("a memory budget of {budget_mb} MiB is too small for this source: the node and brick pools need at least {minimum_mb} MiB of budget")]
    PoolsTooSmall {
        /// The budget asked for, MiB.
        budget_mb: u64,
        /// The smallest budget that works, MiB: the pools' minimum scaled up by their share of the budget, and more
        /// than `budget_mb`.
        minimum_mb: u64,
    },
}

/// A budget checked against the machine and the image; the host cache's share is known, the pools' not yet.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryBudget {
    budget_mb: u64,
    total_bytes: u64,
    image_bytes: u64,
}

/// Every part of the budget, in bytes; the parts add up to at most [`MemoryPlan::total_bytes`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryPlan {
    /// The whole budget.
    pub total_bytes: u64,
    /// The image's per-pixel buffers.
    pub image_bytes: u64,
    /// The producer's host-side cache (0 for built-in scenes and volumes held in memory).
    pub host_cache_bytes: u64,
    /// What is left for the pools: the budget [`Session`](crate::Session) and `CacheManager::new` are given.
    pub pool_bytes: u64,
    /// The pools' capacities within `pool_bytes`.
    pub pools: PoolCapacities,
}

impl MemoryBudget {
    /// Checks `budget_mb` against the machine's memory (`None`: unknown, not checked) and a `width`×`height` image.
    pub fn new(
        budget_mb: u64,
        width: u32,
        height: u32,
        machine_bytes: Option<u64>,
    ) -> Result<MemoryBudget, BudgetError> {
        if budget_mb == 0 {
            return Err(BudgetError::Zero);
        }
        if budget_mb > MAX_BUDGET_MB {
            return Err(BudgetError::AboveLimit { budget_mb });
        }
        let total_bytes = budget_mb * MIB;
        if let Some(machine) = machine_bytes.filter(|&machine| total_bytes > machine) {
            return Err(BudgetError::AboveMachine { budget_mb, machine_mb: machine / MIB });
        }
        let image_bytes = frame_buffer_bytes(width, height);
        if image_bytes >= total_bytes {
            return Err(BudgetError::ImageTooLarge { width, height, image_mb: image_bytes.div_ceil(MIB), budget_mb });
        }
        Ok(MemoryBudget { budget_mb, total_bytes, image_bytes })
    }

    /// The whole budget, MiB, as asked for.
    pub fn budget_mb(&self) -> u64 {
        self.budget_mb
    }

    /// The whole budget, bytes.
    pub fn total_bytes(&self) -> u64 {
        self.total_bytes
    }

    /// The image's per-pixel buffers, bytes.
    pub fn image_bytes(&self) -> u64 {
        self.image_bytes
    }

    /// Bytes for a store's host-side brick cache, when the source streams from disk.
    pub fn store_cache_bytes(&self) -> u64 {
        (self.total_bytes - self.image_bytes) / STORE_CACHE_SHARE
    }

    /// The whole split for a tree of `shape` whose producer holds a cache of `host_cache_bytes` (what it was given:
    /// [`MemoryBudget::store_cache_bytes`] for a streamed store, 0 otherwise).
    pub fn plan(&self, shape: &TreeShape, host_cache_bytes: u64) -> Result<MemoryPlan, BudgetError> {
        let pool_bytes = self.pool_bytes(host_cache_bytes);
        let pools = PoolCapacities::plan(shape, pool_bytes).map_err(|_| BudgetError::PoolsTooSmall {
            budget_mb: self.budget_mb,
            minimum_mb: self.minimum_mb(shape, host_cache_bytes),
        })?;
        Ok(MemoryPlan {
            total_bytes: self.total_bytes,
            image_bytes: self.image_bytes,
            host_cache_bytes,
            pool_bytes,
            pools,
        })
    }

    /// What the image and a host cache of `host_cache_bytes` leave for the pools.
    fn pool_bytes(&self, host_cache_bytes: u64) -> u64 {
        self.total_bytes.saturating_sub(self.image_bytes).saturating_sub(host_cache_bytes)
    }

    /// The smallest budget, in MiB, whose pools fit a tree of `shape` beside the same image and host cache: a
    /// store's cache ([`MemoryBudget::store_cache_bytes`]) grows with the budget, any other (a particle or mesh
    /// index) is fixed. Checked against [`PoolCapacities::plan`] itself, so the figure works; always more than now.
    fn minimum_mb(&self, shape: &TreeShape, host_cache_bytes: u64) -> u64 {
        let scales = host_cache_bytes > 0 && host_cache_bytes == self.store_cache_bytes();
        let fits = |budget_mb: u64| {
            let total = budget_mb.saturating_mul(MIB);
            let cache =
                if scales { total.saturating_sub(self.image_bytes) / STORE_CACHE_SHARE } else { host_cache_bytes };
            let pools = total.saturating_sub(self.image_bytes).saturating_sub(cache);
            PoolCapacities::plan(shape, pools).is_ok()
        };
        // A first guess from the pools' own minimum, then up by sixteenths until the planner accepts it (the node
        // pool's share and the production batch come out of the pools too).
        let minimum_pool = match PoolCapacities::plan(shape, 0) {
            Err(CoreError::BudgetTooSmall { minimum_bytes, .. }) => minimum_bytes,
            _ => 0,
        };
        let minimum_pool = if scales {
            minimum_pool.saturating_mul(STORE_CACHE_SHARE) / (STORE_CACHE_SHARE - 1)
        } else {
            minimum_pool
        };
        let guess =
            self.image_bytes.saturating_add(if scales { 0 } else { host_cache_bytes }).saturating_add(minimum_pool);
        let mut budget_mb = guess.div_ceil(MIB).max(self.budget_mb + 1);
        while !fits(budget_mb) && budget_mb <= MAX_BUDGET_MB {
            budget_mb += (budget_mb / 16).max(1);
        }
        budget_mb
    }
}

/// Memory this process may use in bytes: `MemTotal` of `/proc/meminfo`, lowered to the cgroup's `memory.max`
/// where one is set; `None` where the platform reports neither.
pub fn machine_memory_bytes() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = meminfo.lines().find(|l| l.starts_with("MemTotal:"))?;
    let total = line.split_whitespace().nth(1)?.parse::<u64>().ok()? * 1024;
    let cgroup_limit =
        std::fs::read_to_string("/sys/fs/cgroup/memory.max").ok().and_then(|t| t.trim().parse::<u64>().ok());
    Some(cgroup_limit.map_or(total, |limit| limit.min(total)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn octree() -> TreeShape {
        TreeShape::new(2, 16, 6).unwrap()
    }

    #[test]
    fn the_parts_add_up_to_the_budget() {
        let budget = MemoryBudget::new(64, 512, 512, None).unwrap();
        assert_eq!(budget.image_bytes(), 512 * 512 * FRAME_BYTES_PER_PIXEL);
        let cache = budget.store_cache_bytes();
        assert_eq!(cache, (64 * MIB - budget.image_bytes()) / STORE_CACHE_SHARE);
        let plan = budget.plan(&octree(), cache).unwrap();
        assert_eq!(plan.image_bytes + plan.host_cache_bytes + plan.pool_bytes, 64 * MIB);
        assert_eq!(plan.pools, PoolCapacities::plan(&octree(), plan.pool_bytes).unwrap());
        // Without a host cache, the pools get everything the image leaves.
        assert_eq!(budget.plan(&octree(), 0).unwrap().pool_bytes, 64 * MIB - budget.image_bytes());
    }

    #[test]
    fn budgets_beyond_the_limits_are_refused_with_their_numbers() {
        assert_eq!(MemoryBudget::new(0, 64, 64, None), Err(BudgetError::Zero));
        assert_eq!(
            MemoryBudget::new(MAX_BUDGET_MB + 1, 64, 64, None),
            Err(BudgetError::AboveLimit { budget_mb: MAX_BUDGET_MB + 1 })
        );
        assert_eq!(
            MemoryBudget::new(300, 64, 64, Some(256 * MIB + 5)),
            Err(BudgetError::AboveMachine { budget_mb: 300, machine_mb: 256 })
        );
        assert!(MemoryBudget::new(256, 64, 64, Some(256 * MIB)).is_ok());
    }

    #[test]
    fn an_image_beyond_the_budget_is_refused() {
        let error = MemoryBudget::new(256, 16384, 16384, None).unwrap_err();
        assert_eq!(error, BudgetError::ImageTooLarge { width: 16384, height: 16384, image_mb: 10240, budget_mb: 256 });
    }

    #[test]
    fn pools_too_small_name_a_budget_that_works() {
        // 1 MiB with a 64x64 image (160 KiB): the pools of 32³ bricks do not fit.
        let shape = TreeShape::new(2, 32, 6).unwrap();
        let budget = MemoryBudget::new(1, 64, 64, None).unwrap();
        let Err(BudgetError::PoolsTooSmall { budget_mb: 1, minimum_mb }) = budget.plan(&shape, 0) else {
            panic!("1 MiB should not hold the pools");
        };
        assert!(minimum_mb > 1);
        let enough = MemoryBudget::new(minimum_mb, 64, 64, None).unwrap();
        assert!(enough.plan(&shape, 0).is_ok(), "{minimum_mb} MiB should hold the pools");
    }

    #[test]
    fn a_fixed_host_cache_adds_to_the_minimum_instead_of_scaling_it() {
        // A particle index of 53.5 MiB and a 10 MiB image in a 64 MiB budget: the pools get what is left, half a
        // MiB of 64. Scaling their minimum by that share named a budget a hundred times too large (the "9 TiB" of
        // issue 41); the index is fixed, so the minimum is the image, the index and the pools' minimum, and that
        // budget works.
        let shape = TreeShape::new(2, 32, 8).unwrap();
        let index = 53 * MIB + MIB / 2;
        let budget = MemoryBudget::new(64, 512, 512, None).unwrap();
        let Err(BudgetError::PoolsTooSmall { budget_mb: 64, minimum_mb }) = budget.plan(&shape, index) else {
            panic!("64 MiB should not hold the index and the pools");
        };
        let Err(CoreError::BudgetTooSmall { minimum_bytes, .. }) = PoolCapacities::plan(&shape, 0) else {
            panic!("the pools have a minimum");
        };
        let exact = (budget.image_bytes() + index + minimum_bytes).div_ceil(MIB);
        assert!(
            minimum_mb >= exact && minimum_mb <= exact + exact / 16 + 1,
            "{minimum_mb} MiB, about {exact} expected"
        );
        let enough = MemoryBudget::new(minimum_mb, 512, 512, None).unwrap();
        assert!(enough.plan(&shape, index).is_ok(), "{minimum_mb} MiB should hold the index and the pools");
    }

    #[test]
    fn a_store_cache_minimum_holds_the_cache_it_grows_with() {
        let shape = TreeShape::new(2, 32, 6).unwrap();
        let budget = MemoryBudget::new(1, 64, 64, None).unwrap();
        let Err(BudgetError::PoolsTooSmall { minimum_mb, .. }) = budget.plan(&shape, budget.store_cache_bytes()) else {
            panic!("1 MiB should not hold the pools of 32³ bricks");
        };
        let enough = MemoryBudget::new(minimum_mb, 64, 64, None).unwrap();
        assert!(enough.plan(&shape, enough.store_cache_bytes()).is_ok(), "{minimum_mb} MiB should hold them");
        let less = MemoryBudget::new(minimum_mb * 15 / 16, 64, 64, None).unwrap();
        assert!(less.plan(&shape, less.store_cache_bytes()).is_err(), "{minimum_mb} MiB is about the least");
    }

    #[test]
    fn the_machine_reports_its_memory_on_linux() {
        if cfg!(target_os = "linux") {
            assert!(machine_memory_bytes().unwrap() > MIB);
        }
    }
}
