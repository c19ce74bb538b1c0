//! What the process has used, from /proc (Linux; zeros elsewhere): CPU seconds for the
//! reports and the comparisons, peak memory for the reports.

/// CPU seconds (user + system) this process has used, from /proc (Linux; 0 elsewhere).
pub fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let Some(rest) = stat.rsplit_once(')').map(|(_, r)| r) else {
        return 0.0;
    };
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|f| f.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // Linux reports these in USER_HZ, which is 100 on every mainstream architecture.
    (ticks(11) + ticks(12)) / 100.0
}

/// Peak resident memory in bytes (VmHWM), from /proc (Linux; 0 elsewhere).
pub fn peak_memory_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

/// How much memory this process may use, and what sets that.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MemoryLimit {
    pub bytes: u64,
    /// "this machine has" (its memory), "the cgroup allows" or "ulimit -v allows".
    pub source: &'static str,
}

/// The memory this process may use: the smallest of the machine's memory (MemTotal), the
/// cgroup's limit (memory.max, cgroup v2) and the address-space limit (`ulimit -v`). None
/// where none of them can be read (not Linux).
pub fn memory_limit() -> Option<MemoryLimit> {
    let read = |path: &str| std::fs::read_to_string(path).ok();
    let total = read("/proc/meminfo").and_then(|s| {
        s.lines()
            .find(|l| l.starts_with("MemTotal:"))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|kb| kb.parse::<u64>().ok())
            .map(|kb| kb.saturating_mul(1024))
    });
    let cgroup = read("/sys/fs/cgroup/memory.max").and_then(|s| s.trim().parse::<u64>().ok());
    // "Max address space  unlimited  unlimited  bytes" (soft limit first).
    let address_space = read("/proc/self/limits").and_then(|s| {
        s.lines()
            .find(|l| l.starts_with("Max address space"))
            .and_then(|l| l.split_whitespace().nth(3))
            .and_then(|v| v.parse::<u64>().ok())
    });
    [
        (total, "this machine has"),
        (cgroup, "the cgroup allows"),
        (address_space, "ulimit -v allows"),
    ]
    .into_iter()
    .filter_map(|(bytes, source)| bytes.map(|bytes| MemoryLimit { bytes, source }))
    .min_by_key(|l| l.bytes)
}

/// A byte count in GB (10^9) with one decimal, or MB below 1 GB: "~13.4 GB".
pub fn format_bytes(bytes: u64) -> String {
    if bytes >= 1_000_000_000 {
        format!("{:.1} GB", bytes as f64 / 1e9)
    } else {
        format!("{:.0} MB", (bytes as f64 / 1e6).max(1.0))
    }
}

/// Checks that `needed` bytes fit in the memory this process may use; the error says
/// "WHAT needs ~N GB, this machine has M GB" (or what else sets the limit).
pub fn check_memory(what: &str, needed: u64, limit: Option<MemoryLimit>) -> Result<(), String> {
    match limit {
        Some(limit) if needed > limit.bytes => Err(format!(
            "{what} needs ~{} of memory, {} {}",
            format_bytes(needed),
            limit.source,
            format_bytes(limit.bytes)
        )),
        _ => Ok(()),
    }
}
