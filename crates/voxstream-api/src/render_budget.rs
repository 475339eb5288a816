//! `--budget-mb` in the CLI's words: the engine's budget planner ([`voxstream_engine::MemoryBudget`]) splits the
//! budget and reports numbers; this module turns its refusals into one line naming the flag to change.

use anyhow::{anyhow, Result};
use voxstream_core::TreeShape;
use voxstream_engine::{machine_memory_bytes, BudgetError, MemoryBudget, MemoryPlan, MAX_BUDGET_MB};
use voxstream_render::FRAME_BYTES_PER_PIXEL;

/// Checks `--budget-mb` against this machine and a `width`×`height` image; `image_flags` names the image-size flags
/// in the message (`--width/--height`, `--size`).
pub fn check_budget(budget_mb: u64, width: u32, height: u32, image_flags: &str) -> Result<MemoryBudget> {
    MemoryBudget::new(budget_mb, width, height, machine_memory_bytes()).map_err(|e| budget_message(e, image_flags))
}

/// The whole split for a source of `shape` whose producer holds a cache of `host_cache_bytes`.
pub fn plan_budget(budget: &MemoryBudget, shape: &TreeShape, host_cache_bytes: u64) -> Result<MemoryPlan> {
    // Only `PoolsTooSmall` comes from here, and it names no image flag.
    budget.plan(shape, host_cache_bytes).map_err(|e| budget_message(e, "--width/--height"))
}

/// The planner's refusal as the CLI says it.
fn budget_message(error: BudgetError, image_flags: &str) -> anyhow::Error {
    match error {
        BudgetError::Zero => anyhow!("--budget-mb must be at least 1"),
        BudgetError::AboveLimit { budget_mb } => {
            anyhow!("--budget-mb {budget_mb} is larger than 1 TiB ({MAX_BUDGET_MB})")
        }
        BudgetError::AboveMachine { budget_mb, machine_mb } => {
            anyhow!("--budget-mb {budget_mb} is more than this machine's memory ({machine_mb} MiB): lower --budget-mb")
        }
        BudgetError::ImageTooLarge { width, height, image_mb, budget_mb } => anyhow!(
            "a {width}x{height} image needs {image_mb} MiB of the memory budget ({FRAME_BYTES_PER_PIXEL} bytes per \
             pixel), more than --budget-mb {budget_mb}: raise --budget-mb or lower {image_flags}"
        ),
        BudgetError::PoolsTooSmall { budget_mb, minimum_mb } => anyhow!(
            "--budget-mb {budget_mb} is too small for this source: the node and brick pools need at least \
             {minimum_mb} MiB (use --budget-mb {minimum_mb} or more)"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_image_beyond_the_budget_is_refused_naming_the_flags() {
        let message = check_budget(256, 16384, 16384, "--width/--height").unwrap_err().to_string();
        assert_eq!(
            message,
            "a 16384x16384 image needs 10240 MiB of the memory budget (40 bytes per pixel), more than --budget-mb \
             256: raise --budget-mb or lower --width/--height"
        );
    }

    #[test]
    fn a_budget_beyond_the_machine_is_refused() {
        if let Some(physical) = machine_memory_bytes() {
            let mb = (physical >> 20) + 1;
            if mb <= MAX_BUDGET_MB {
                let message = check_budget(mb, 64, 64, "--size").unwrap_err().to_string();
                assert!(message.contains("machine's memory") && message.contains("lower --budget-mb"), "{message}");
            }
        }
        assert_eq!(check_budget(0, 64, 64, "--size").unwrap_err().to_string(), "--budget-mb must be at least 1");
        assert!(check_budget(MAX_BUDGET_MB + 1, 64, 64, "--size").unwrap_err().to_string().contains("1 TiB"));
    }

    #[test]
    fn pools_too_small_name_the_budget_that_works() {
        let shape = TreeShape::new(2, 32, 6).unwrap();
        let budget = check_budget(1, 64, 64, "--size").unwrap();
        let message = plan_budget(&budget, &shape, 0).unwrap_err().to_string();
        assert!(message.starts_with("--budget-mb 1 is too small for this source"), "{message}");
        assert!(message.contains("(use --budget-mb "), "{message}");
    }
}
