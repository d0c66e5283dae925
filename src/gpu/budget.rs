//! How much device memory a context allows itself: byte counts as users write them
//! (`512M`, `2G`), the explicit limit (`--memory-limit`, `VERISPLAT_MEMORY_LIMIT`), the host
//! memory available, and the budget that follows from them ([`BudgetSource`]).

use super::{GpuError, GpuResult};

/// Parses a byte count: a number with an optional K, M, G or T suffix (powers of 1024).
pub fn parse_bytes(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let (num, mult) = match t.chars().last().map(|c| c.to_ascii_uppercase()) {
        Some('K') => (&t[..t.len() - 1], 1u64 << 10),
        Some('M') => (&t[..t.len() - 1], 1 << 20),
        Some('G') => (&t[..t.len() - 1], 1 << 30),
        Some('T') => (&t[..t.len() - 1], 1 << 40),
        _ => (t, 1),
    };
    num.trim()
        .parse::<u64>()
        .ok()
        .and_then(|n| n.checked_mul(mult))
        .ok_or_else(|| format!("\"{text}\" is not a byte count (e.g. 536870912, 512M, 2G)"))
}

/// Where a context's device-memory budget comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BudgetSource {
    /// [`ContextOptions::memory_limit`](super::ContextOptions::memory_limit) or
    /// `VERISPLAT_MEMORY_LIMIT`.
    Limit,
    /// The largest device-local heap the driver advertises.
    Heap,
    /// Three quarters of the host memory available when the context was made (a CPU
    /// device, whose device memory is host memory, without an explicit limit).
    HostAvailable,
}

impl BudgetSource {
    /// What the budget is, for `-v`.
    pub fn describe(self) -> &'static str {
        match self {
            BudgetSource::Limit => "the explicit memory limit",
            BudgetSource::Heap => "the largest device-local heap",
            BudgetSource::HostAvailable => {
                "3/4 of the host memory available (a CPU device's memory is host memory; \
                 --memory-limit sets another)"
            }
        }
    }
}

/// `MemAvailable` of `/proc/meminfo` in bytes (Linux), if it can be read.
pub fn host_available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// The explicit limit: `option` when given, else `VERISPLAT_MEMORY_LIMIT` when set.
pub(crate) fn explicit_limit(option: Option<u64>) -> GpuResult<Option<u64>> {
    Ok(match option {
        Some(l) => Some(l),
        None => match crate::core::former_name::env_var("VERISPLAT_MEMORY_LIMIT") {
            Some(v) if !v.trim().is_empty() => Some(
                parse_bytes(&v)
                    .map_err(|e| GpuError::Input(format!("VERISPLAT_MEMORY_LIMIT: {e}")))?,
            ),
            _ => None,
        },
    })
}

/// The budget and where it comes from, given the explicit `limit`, the largest
/// device-local heap and whether device memory is host memory (a CPU device).
pub(crate) fn choose_budget(
    limit: Option<u64>,
    device_local_bytes: u64,
    host_memory: bool,
) -> (u64, BudgetSource) {
    // On a CPU implementation device memory is host memory and the advertised heap is
    // only a figure (lavapipe: 2 GiB), so an explicit limit may go beyond it; on a GPU
    // the heap caps it.
    match limit {
        Some(l) if host_memory => (l, BudgetSource::Limit),
        Some(l) => (l.min(device_local_bytes), BudgetSource::Limit),
        // A CPU device's scene fits where the host's memory does: the budget follows
        // what the host has available, not the figure the driver advertises.
        None if host_memory => match host_available_bytes() {
            Some(available) if available / 4 * 3 > device_local_bytes => {
                (available / 4 * 3, BudgetSource::HostAvailable)
            }
            _ => (device_local_bytes, BudgetSource::Heap),
        },
        None => (device_local_bytes, BudgetSource::Heap),
    }
}
