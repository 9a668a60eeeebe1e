//! What a run may take from the machine: the memory budget (`--max-memory`) and the size of the
//! files it reads.

/// Share of the machine's memory a run may plan to use by default.
const DEFAULT_SHARE: f64 = 0.75;

/// Budget when the machine's memory cannot be read.
const FALLBACK_BYTES: u64 = 8 << 30;

/// The default `--max-memory`: three quarters of the machine's memory (or of the control
/// group's limit, when it is lower).
pub fn default_max_memory() -> u64 {
    match machine_memory() {
        Some(m) => (m as f64 * DEFAULT_SHARE) as u64,
        None => FALLBACK_BYTES,
    }
}

/// Physical memory (Linux: `MemTotal`), or the cgroup's limit when lower.
fn machine_memory() -> Option<u64> {
    let total = meminfo("MemTotal:")?;
    let limit = CGROUP_FILES.iter().filter_map(|(limit, _)| read_number(limit)).min();
    Some(limit.map_or(total, |l| l.min(total)))
}

/// The memory the machine can give now without swapping (Linux: `MemAvailable`), or the
/// room left under the cgroup's limit when less.
pub fn available_memory() -> Option<u64> {
    let available = meminfo("MemAvailable:")?;
    let room = CGROUP_FILES
        .iter()
        .filter_map(|(limit, usage)| Some(read_number(limit)?.saturating_sub(read_number(usage)?)))
        .min();
    Some(room.map_or(available, |r| r.min(available)))
}

/// The cgroup's memory limit and usage files (v2, then v1).
const CGROUP_FILES: [(&str, &str); 2] = [
    ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
    ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"),
];

/// A line of /proc/meminfo, in bytes.
fn meminfo(key: &str) -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let kib: u64 = text.lines().find(|l| l.starts_with(key))?.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

fn read_number(path: &str) -> Option<u64> {
    std::fs::read_to_string(path).ok()?.trim().parse().ok()
}

/// Parses a size: a number of bytes with an optional binary suffix, `K`, `M`, `G` or `T` (`KiB`,
/// `GB`... read alike): `8G`, `512M`, `1.5G`.
pub fn parse_size(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let split = t.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let shift = match unit.trim().to_ascii_uppercase().trim_end_matches("IB").trim_end_matches('B') {
        "" => 0,
        "K" => 10,
        "M" => 20,
        "G" => 30,
        "T" => 40,
        _ => return Err(format!("'{text}' is not a size; use e.g. 8G, 512M or 2T")),
    };
    match number.trim().parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 && x * ((1u64 << shift) as f64) < 1.8e19 => {
            Ok((x * (1u64 << shift) as f64) as u64)
        }
        _ => Err(format!("'{text}' is not a positive size; use e.g. 8G, 512M or 2T")),
    }
}

/// Largest input file read, as a share of the memory budget: a surface takes about nine times
/// its binary STL size once read and indexed (measured: 2.0 million triangles, 100 MB, took
/// 864 MB).
pub const FILE_SHARE: u64 = 10;

/// The limits of the files a run reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadLimits {
    /// Largest file read.
    pub file_bytes: u64,
    /// Largest total of a file's compressed arrays once inflated.
    pub inflated_bytes: u64,
}

impl ReadLimits {
    /// The limits under a memory budget.
    pub fn within(max_memory: u64) -> ReadLimits {
        ReadLimits { file_bytes: max_memory / FILE_SHARE, inflated_bytes: max_memory / FILE_SHARE }
    }
}

impl Default for ReadLimits {
    fn default() -> Self {
        ReadLimits::within(default_max_memory())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_with_binary_suffixes() {
        assert_eq!(parse_size("512M").unwrap(), 512 << 20);
        assert_eq!(parse_size("8G").unwrap(), 8 << 30);
        assert_eq!(parse_size("8GiB").unwrap(), 8 << 30);
        assert_eq!(parse_size("1.5g").unwrap(), 3 << 29);
        assert_eq!(parse_size("4096").unwrap(), 4096);
        for bad in ["", "G", "-1G", "8X", "1e30T", "nan"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }
}
