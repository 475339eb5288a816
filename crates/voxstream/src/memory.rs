//! The process's memory as the kernel counts it (peak resident set size), for `--stats` and benchmarks, and the
//! machine's, for refusing a budget it cannot hold.

/// Memory this process may use in bytes: `MemTotal` of `/proc/meminfo`, lowered to the cgroup's `memory.max`
/// where one is set; `None` where the platform reports neither.
pub fn physical_memory_bytes() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = meminfo.lines().find(|l| l.starts_with("MemTotal:"))?;
    let total = line.split_whitespace().nth(1)?.parse::<u64>().ok()? * 1024;
    let cgroup_limit =
        std::fs::read_to_string("/sys/fs/cgroup/memory.max").ok().and_then(|t| t.trim().parse::<u64>().ok());
    Some(cgroup_limit.map_or(total, |limit| limit.min(total)))
}

/// Peak resident set size of this process in bytes (`VmHWM`), if the platform reports it.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Bytes this process has read through read-like system calls so far (`rchar` of `/proc/self/io`): every byte
/// the store's files delivered, whether from the disk or the page cache.
pub fn bytes_read() -> Option<u64> {
    let io = std::fs::read_to_string("/proc/self/io").ok()?;
    let line = io.lines().find(|l| l.starts_with("rchar:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

#[cfg(test)]
mod tests {
    #[test]
    fn physical_memory_is_reported_on_linux() {
        if cfg!(target_os = "linux") {
            assert!(super::physical_memory_bytes().unwrap() > 1 << 20);
        }
    }

    #[test]
    fn peak_rss_is_reported_on_linux() {
        if cfg!(target_os = "linux") {
            assert!(super::peak_rss_bytes().unwrap() > 0);
        }
    }
}
