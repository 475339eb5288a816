//! Splitting `--budget-mb` between everything that grows with the image or the data: the frame's per-pixel
//! buffers ([`FRAME_BYTES_PER_PIXEL`]), a store's host-side brick cache, and the node and brick pools. The budget
//! is checked before anything is allocated: one beyond the machine's memory, or too small for the image, is refused
//! with one line naming the flag to change.

use anyhow::{bail, Result};
use voxstream_render::{frame_buffer_bytes, FRAME_BYTES_PER_PIXEL};

use crate::memory::physical_memory_bytes;

/// Largest accepted `--budget-mb` (1 TiB): guards against typos that would overflow.
pub const MAX_BUDGET_MB: u64 = 1 << 20;

/// Share of what the frame leaves given to a store's host-side brick cache (the rest goes to the pools).
pub const STORE_CACHE_SHARE: u64 = 8;

/// `--budget-mb`, split.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RenderBudget {
    /// The whole budget, bytes.
    pub total_bytes: u64,
    /// The frame's per-pixel buffers, bytes.
    pub frame_bytes: u64,
}

impl RenderBudget {
    /// Checks `budget_mb` against the machine and a `width`×`height` frame; `flags` names the image-size flags in
    /// the message (`--width/--height`, `--size`).
    pub fn plan(budget_mb: u64, width: u32, height: u32, flags: &str) -> Result<RenderBudget> {
        if budget_mb == 0 {
            bail!("--budget-mb must be at least 1");
        }
        if budget_mb > MAX_BUDGET_MB {
            bail!("--budget-mb {budget_mb} is larger than 1 TiB ({MAX_BUDGET_MB})");
        }
        let total_bytes = budget_mb << 20;
        if let Some(physical) = physical_memory_bytes() {
            if total_bytes > physical {
                bail!(
                    "--budget-mb {budget_mb} is more than this machine's memory ({} MiB): lower --budget-mb",
                    physical >> 20
                );
            }
        }
        let frame_bytes = frame_buffer_bytes(width, height);
        if frame_bytes >= total_bytes {
            bail!(
                "a {width}x{height} image needs {} MiB of the memory budget ({FRAME_BYTES_PER_PIXEL} bytes per pixel), \
                 more than --budget-mb {budget_mb}: raise --budget-mb or lower {flags}",
                frame_bytes.div_ceil(1 << 20)
            );
        }
        Ok(RenderBudget { total_bytes, frame_bytes })
    }

    /// Bytes for a store's host-side brick cache.
    pub fn store_cache_bytes(&self) -> u64 {
        (self.total_bytes - self.frame_bytes) / STORE_CACHE_SHARE
    }

    /// Bytes left for the pools once the frame and a producer cache of `producer_cache_bytes` are counted.
    pub fn pool_bytes(&self, producer_cache_bytes: u64) -> u64 {
        self.total_bytes.saturating_sub(self.frame_bytes).saturating_sub(producer_cache_bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_parts_add_up_to_the_budget() {
        let budget = RenderBudget::plan(64, 512, 512, "--width/--height").unwrap();
        assert_eq!(budget.frame_bytes, 512 * 512 * FRAME_BYTES_PER_PIXEL);
        let cache = budget.store_cache_bytes();
        assert_eq!(budget.frame_bytes + cache + budget.pool_bytes(cache), 64 << 20);
    }

    #[test]
    fn an_image_beyond_the_budget_is_refused_naming_the_flags() {
        let message = RenderBudget::plan(256, 16384, 16384, "--width/--height").unwrap_err().to_string();
        assert!(message.contains("10240 MiB") && message.contains("--budget-mb"), "{message}");
        assert!(message.contains("--width/--height"), "{message}");
    }

    #[test]
    fn a_budget_beyond_the_machine_is_refused() {
        if let Some(physical) = physical_memory_bytes() {
            let mb = (physical >> 20) + 1;
            if mb <= MAX_BUDGET_MB {
                let message = RenderBudget::plan(mb, 64, 64, "--size").unwrap_err().to_string();
                assert!(message.contains("machine's memory"), "{message}");
            }
        }
        assert!(RenderBudget::plan(0, 64, 64, "--size").is_err());
        assert!(RenderBudget::plan(MAX_BUDGET_MB + 1, 64, 64, "--size").is_err());
    }
}
