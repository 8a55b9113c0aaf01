//! What the machine's memory allows: inputs whose size a header or a
//! parameter declares are checked against it before anything that size is
//! allocated, so a hostile or mistaken file is refused by name instead of
//! aborting the process.

/// The memory the system has available (Linux: `MemAvailable` of
/// /proc/meminfo), if known.
pub fn available() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// `Some((needed, available))` in GB when `needed` bytes exceed the memory
/// available (never when that is unknown).
pub fn shortfall_gb(needed: u64) -> Option<(f64, f64)> {
    available()
        .filter(|&have| needed > have)
        .map(|have| (needed as f64 / 1e9, have as f64 / 1e9))
}
