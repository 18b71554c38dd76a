//! The memory budget: every allocation whose size comes from a file, a sidecar, a scene or an
//! argument is checked against it **before** it is made, so that a header claiming 10¹²
//! samples or a time axis of 10⁹ bins gives a one-line error instead of an aborted process.
//!
//! # Where the default comes from
//!
//! The process-wide budget is the smallest of the limits the process really runs under, less
//! headroom ([`limits`], [`describe`]):
//!
//! - **physical memory** (`MemTotal` of `/proc/meminfo`): half of it, the rest is left to the
//!   system and to other programs;
//! - **the address-space limit** `RLIMIT_AS` and **the data-segment limit** `RLIMIT_DATA`
//!   (`ulimit -v`, `ulimit -d`, as batch schedulers set them; read from `/proc/self/limits`):
//!   three quarters of the limit less [`THREAD_RESERVE`] per worker thread — these limits count
//!   address space, and every thread reserves a stack and an allocator arena in it;
//! - **the cgroup's memory limit** (a container's or a systemd unit's): `memory.max` (cgroup
//!   v2) or `memory.limit_in_bytes` (v1) of the process's cgroup and its ancestors, three
//!   quarters of it (the page cache of the files read is charged to the cgroup too).
//!
//! Where none can be read the budget is 8 GiB. [`set`] replaces the default (the CLI's
//! `--max-memory`, the `max_memory` parameter of other front ends), but never above the hard
//! limits (address space, data segment, cgroup) less their headroom: past those the process
//! is killed or aborted whatever the budget says.
//!
//! # What is checked
//!
//! [`check`] compares one allocation with the budget; [`Plan`] adds up the named buffers a pass
//! holds at once (a capture, its tables, per-thread buffers) and, when they do not fit, names
//! the largest in the one-line error, before any of them is made.

use std::sync::OnceLock;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::human;
use crate::error::{Error, Result};

/// The budget in bytes; 0 = not set yet (the default applies).
static BUDGET: AtomicU64 = AtomicU64::new(0);

/// The budget when no limit can be read (bytes).
const FALLBACK: u64 = 8 << 30;

/// Address space reserved per worker thread on top of the buffers (stack and allocator arena),
/// subtracted from address-space and data-segment limits (bytes).
pub const THREAD_RESERVE: u64 = 64 << 20;

/// One limit the process runs under.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Limit {
    /// What it is, e.g. `the address-space limit RLIMIT_AS`.
    pub name: String,
    /// The limit in bytes.
    pub bytes: u64,
    /// The budget it allows once headroom is taken off (bytes).
    pub allows: u64,
    /// Whether exceeding it kills or aborts the process (address space, data segment, cgroup),
    /// as opposed to physical memory (swapping, the system's OOM killer).
    pub hard: bool,
}

/// The limits the process runs under (those that could be read and are not unlimited),
/// read once.
pub fn limits() -> &'static [Limit] {
    static LIMITS: OnceLock<Vec<Limit>> = OnceLock::new();
    LIMITS.get_or_init(read_limits)
}

fn read_limits() -> Vec<Limit> {
    let threads = std::thread::available_parallelism().map_or(1, usize::from) as u64;
    let quarter = |b: u64| b - b / 4;
    let mut out = Vec::new();
    if let Some(m) = physical_memory() {
        out.push(Limit {
            name: "half of the physical memory".into(),
            bytes: m,
            allows: m / 2,
            hard: false,
        });
    }
    if let Ok(text) = std::fs::read_to_string("/proc/self/limits") {
        for (key, name) in [
            (
                "Max address space",
                "the address-space limit RLIMIT_AS (ulimit -v)",
            ),
            (
                "Max data size",
                "the data-segment limit RLIMIT_DATA (ulimit -d)",
            ),
        ] {
            if let Some(b) = rlimit_soft(&text, key) {
                out.push(Limit {
                    name: name.into(),
                    bytes: b,
                    allows: quarter(b).saturating_sub(THREAD_RESERVE.saturating_mul(threads + 1)),
                    hard: true,
                });
            }
        }
    }
    if let Some((b, file)) = cgroup_limit() {
        out.push(Limit {
            name: format!("the cgroup's memory limit {file}"),
            bytes: b,
            allows: quarter(b),
            hard: true,
        });
    }
    out
}

/// The soft limit of `key` in `/proc/self/limits` text, in bytes (`None` if unlimited).
fn rlimit_soft(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    line[key.len()..].split_whitespace().next()?.parse().ok()
}

/// The smallest memory limit of the process's cgroup and its ancestors: cgroup v2
/// `memory.max`, else v1 `memory.limit_in_bytes` (values of 2⁶² and above are "unlimited").
/// Returns the limit and the file it came from.
fn cgroup_limit() -> Option<(u64, String)> {
    let groups = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let mut best: Option<(u64, String)> = None;
    let mut consider = |dir: std::path::PathBuf, file: &str| {
        // The cgroup and every ancestor up to the mount point.
        let mut d = Some(dir.as_path());
        while let Some(p) = d {
            let f = p.join(file);
            if let Some(b) = std::fs::read_to_string(&f)
                .ok()
                .and_then(|s| s.trim().parse::<u64>().ok())
                .filter(|&b| b < 1 << 62)
                && best.as_ref().is_none_or(|(x, _)| b < *x)
            {
                best = Some((b, f.display().to_string()));
            }
            if p == std::path::Path::new("/sys/fs/cgroup") || p.parent().is_none() {
                break;
            }
            d = p.parent();
        }
    };
    for line in groups.lines() {
        let mut parts = line.splitn(3, ':');
        let (_, ctrl, path) = (parts.next()?, parts.next()?, parts.next()?);
        let rel = path.trim_start_matches('/');
        if ctrl.is_empty() {
            consider(
                std::path::Path::new("/sys/fs/cgroup").join(rel),
                "memory.max",
            );
        } else if ctrl.split(',').any(|c| c == "memory") {
            consider(
                std::path::Path::new("/sys/fs/cgroup/memory").join(rel),
                "memory.limit_in_bytes",
            );
        }
    }
    best
}

/// Sets the process-wide budget in bytes (at least 1 MiB; at most what the hard limits
/// allow, see the module docs).
pub fn set(bytes: u64) {
    BUDGET.store(cap(bytes.max(1 << 20)), Ordering::Relaxed);
}

/// `bytes` capped by the hard limits' allowances.
fn cap(bytes: u64) -> u64 {
    limits()
        .iter()
        .filter(|l| l.hard)
        .fold(bytes, |b, l| b.min(l.allows.max(1 << 20)))
}

/// The process-wide budget in bytes.
pub fn get() -> u64 {
    match BUDGET.load(Ordering::Relaxed) {
        0 => default_budget(),
        b => b,
    }
}

/// The default budget: the smallest allowance of [`limits`] (at least 1 MiB), or 8 GiB where
/// none can be read.
pub fn default_budget() -> u64 {
    limits()
        .iter()
        .map(|l| l.allows)
        .min()
        .map_or(FALLBACK, |b| b.max(1 << 20))
}

/// The budget and where it came from, for people: e.g. `2.9 GB: 3/4 of the address-space
/// limit RLIMIT_AS (ulimit -v) of 4.1 GB less 64 MiB per thread (other limits: half of the
/// physical memory of 25 GB)`.
pub fn describe() -> String {
    let b = get();
    let set_by_user = BUDGET.load(Ordering::Relaxed) != 0;
    let binding = limits().iter().min_by_key(|l| l.allows);
    let how = |l: &Limit| match (l.hard, l.name.contains("RLIMIT")) {
        (false, _) => format!("{} of {}", l.name, human(l.bytes.into())),
        (true, true) => format!(
            "3/4 of {} of {} less {} per thread",
            l.name,
            human(l.bytes.into()),
            human(THREAD_RESERVE.into())
        ),
        (true, false) => format!("3/4 of {} of {}", l.name, human(l.bytes.into())),
    };
    let source = if set_by_user {
        match binding.filter(|l| l.hard && l.allows.max(1 << 20) == b) {
            Some(l) => format!("the size asked for, capped at {}", how(l)),
            None => "as asked for (max_memory)".into(),
        }
    } else {
        match binding {
            Some(l) => how(l),
            None => "no memory limit could be read: the fallback of 8 GiB".into(),
        }
    };
    let others: Vec<String> = limits()
        .iter()
        .filter(|l| binding != Some(*l))
        .map(|l| format!("{} {}", l.name, human(l.bytes.into())))
        .collect();
    if others.is_empty() {
        format!("{}: {source}", human(b.into()))
    } else {
        format!(
            "{}: {source} (other limits: {})",
            human(b.into()),
            others.join(", ")
        )
    }
}

/// `MemTotal` of `/proc/meminfo` in bytes.
fn physical_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// The largest small text file (a PTU sidecar, a scene) vltm reads: 16 MiB.
pub const MAX_TEXT_FILE: u64 = 16 << 20;

/// Checks that `path` is a regular file (following links) before it is opened: a missing
/// file is an [`Error::Io`] "No such file or directory" whatever its extension; a named
/// pipe, a device or a directory is refused in one line (reading one would block, or never
/// end). Returns its size in bytes.
///
/// # Errors
/// [`Error::Io`] when it cannot be examined; [`Error::Format`] when it is not a regular file.
pub fn regular_file(path: &std::path::Path) -> Result<u64> {
    let m = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if m.is_file() {
        return Ok(m.len());
    }
    let kind = {
        use std::os::unix::fs::FileTypeExt as _;
        let t = m.file_type();
        if t.is_dir() {
            "a directory"
        } else if t.is_fifo() {
            "a named pipe"
        } else if t.is_socket() {
            "a socket"
        } else if t.is_char_device() || t.is_block_device() {
            "a device"
        } else {
            "not a regular file"
        }
    };
    Err(Error::Format {
        path: path.into(),
        field: "file".into(),
        expected: "a regular file".into(),
        found: kind.into(),
    })
}

/// Reads a small text file (a PTU sidecar, a scene) after checking that it is a regular file
/// of at most [`MAX_TEXT_FILE`] bytes: a link to `/dev/zero` or a huge file is refused before
/// it is read.
///
/// # Errors
/// As [`regular_file`]; [`Error::Format`] for a larger file; [`Error::Io`] for a read error.
pub fn read_text(path: &std::path::Path) -> Result<String> {
    let len = regular_file(path)?;
    if len > MAX_TEXT_FILE {
        return Err(Error::Format {
            path: path.into(),
            field: "size".into(),
            expected: format!(
                "at most {} (a JSON description)",
                human(MAX_TEXT_FILE.into())
            ),
            found: human(len.into()),
        });
    }
    use std::io::Read as _;
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut s = String::new();
    // The size may change between the check and the read: never read more than the cap.
    f.take(MAX_TEXT_FILE + 1)
        .read_to_string(&mut s)
        .map_err(|e| Error::io(path, e))?;
    if s.len() as u64 > MAX_TEXT_FILE {
        return Err(Error::Format {
            path: path.into(),
            field: "size".into(),
            expected: format!("at most {}", human(MAX_TEXT_FILE.into())),
            found: "more (it grew while read)".into(),
        });
    }
    Ok(s)
}

/// Checks that `bytes` fit the budget; `what` says what they are for, e.g. "H of 10¹²
/// samples claimed by F.npz's header".
///
/// # Errors
/// [`Error::Memory`] naming `what`, the size it needs and the budget.
pub fn check(what: impl FnOnce() -> String, bytes: u128) -> Result<()> {
    let budget = get();
    if bytes > u128::from(budget) {
        return Err(Error::Memory {
            what: what(),
            need: bytes,
            budget,
        });
    }
    Ok(())
}

/// The named buffers a pass holds at once, checked together against the budget before any
/// is made ([`Plan::check`] names the largest when they do not fit).
#[derive(Clone, Debug, Default)]
pub struct Plan {
    items: Vec<(String, u128)>,
}

impl Plan {
    /// An empty plan.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a buffer of `bytes` named `name` (e.g. `the lookup grid's carrier (2·10⁹ complex
    /// f32)`); zero-sized buffers are skipped.
    pub fn add(&mut self, name: impl Into<String>, bytes: u128) -> &mut Self {
        if bytes > 0 {
            self.items.push((name.into(), bytes));
        }
        self
    }

    /// The sum of the buffers (saturating).
    pub fn total(&self) -> u128 {
        self.items
            .iter()
            .fold(0u128, |a, (_, b)| a.saturating_add(*b))
    }

    /// The largest buffer and its size.
    pub fn largest(&self) -> Option<(&str, u128)> {
        self.items
            .iter()
            .max_by_key(|(_, b)| *b)
            .map(|(n, b)| (n.as_str(), *b))
    }

    /// Whether the buffers fit the budget.
    pub fn fits(&self) -> bool {
        self.total() <= u128::from(get())
    }

    /// Checks the sum against the budget.
    ///
    /// # Errors
    /// [`Error::Memory`] naming `what`, the largest buffer, the sum and the budget.
    pub fn check(&self, what: impl FnOnce() -> String) -> Result<()> {
        check(
            || match self.largest() {
                Some((n, b)) => format!("{}; largest buffer: {n}, {}", what(), human(b)),
                None => what(),
            },
            self.total(),
        )
    }
}

/// `count · size` bytes, saturating (a size from a file must never wrap).
pub fn bytes(count: impl TryInto<u128>, size: u128) -> u128 {
    count.try_into().unwrap_or(u128::MAX).saturating_mul(size)
}

/// A count for people: exact below a million, else `1.5·10⁹` (`10¹²` for a power of ten).
pub fn count(n: u128) -> String {
    if n < 1_000_000 {
        return n.to_string();
    }
    const SUP: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    let e = n.ilog10();
    let exp: String = e
        .to_string()
        .bytes()
        .map(|d| SUP[usize::from(d - b'0')])
        .collect();
    let m = n as f64 / 10f64.powi(e as i32);
    if n.is_multiple_of(10u128.pow(e)) && m.round() == 1.0 {
        format!("10{exp}")
    } else {
        format!("{m:.1}·10{exp}")
    }
}

/// Parses a size: a number of bytes with an optional unit `k`, `M`, `G`, `T` (powers of
/// 1024; a trailing `B` or `iB` is accepted), e.g. `12G`, `500MiB`, `1048576`.
///
/// # Errors
/// [`Error::Argument`] (`max_memory`) for anything else, or a size under 1 MiB.
pub fn parse_size(s: &str) -> Result<u64> {
    let bad = || {
        Error::arg(
            "max_memory",
            format!("expected a size such as 12G or 500M, found `{s}`"),
        )
    };
    let t = s.trim();
    let t = t
        .strip_suffix("iB")
        .or_else(|| t.strip_suffix('B'))
        .unwrap_or(t);
    let (num, shift) = match t.chars().last() {
        Some('k' | 'K') => (&t[..t.len() - 1], 10),
        Some('m' | 'M') => (&t[..t.len() - 1], 20),
        Some('g' | 'G') => (&t[..t.len() - 1], 30),
        Some('t' | 'T') => (&t[..t.len() - 1], 40),
        _ => (t, 0),
    };
    let v: f64 = num.trim().parse().map_err(|_| bad())?;
    let b = v * f64::from(1u32 << (shift / 2)) * f64::from(1u32 << (shift - shift / 2));
    if !(b.is_finite() && b >= f64::from(1u32 << 20) && b < 1.8e19) {
        return Err(Error::arg(
            "max_memory",
            format!("expected a size from 1M to 16E bytes, found `{s}`"),
        ));
    }
    Ok(b as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_print() {
        assert_eq!(parse_size("12G").unwrap(), 12 << 30);
        assert_eq!(parse_size("500MiB").unwrap(), 500 << 20);
        assert_eq!(parse_size("2048k").unwrap(), 2 << 20);
        assert_eq!(parse_size("1048576").unwrap(), 1 << 20);
        assert!(parse_size("12 parsecs").is_err());
        assert!(parse_size("1k").is_err());
        assert!(parse_size("-5G").is_err());
        assert_eq!(human(4_000_000_000_000), "4.0 TB");
        assert_eq!(human(12_884_901_888), "13 GB");
        assert_eq!(human(17), "17 B");
        assert_eq!(count(12345), "12345");
        assert_eq!(count(1_000_000_000_000), "10¹²");
        assert_eq!(count(1_500_000_000), "1.5·10⁹");
        assert_eq!(bytes(u64::MAX, 4), u128::from(u64::MAX) * 4);
        assert_eq!(bytes(-1i64, 4), u128::MAX);
    }

    #[test]
    fn the_check_names_what_and_sizes() {
        assert!(default_budget() >= 1 << 20);
        let e = check(
            || "H of 10^12 samples claimed by F.npz".into(),
            4_000_000_000_000_000,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("F.npz") && e.contains("4.0 PB") && e.contains("budget"),
            "{e}"
        );
        assert!(check(|| unreachable!(), 1024).is_ok());
    }

    #[test]
    fn limits_parse_and_the_plan_names_its_largest_buffer() {
        let text = "Limit                     Soft Limit           Hard Limit           Units\n\
Max data size             unlimited            unlimited            bytes\n\
Max address space         4096000000           unlimited            bytes\n";
        assert_eq!(rlimit_soft(text, "Max address space"), Some(4_096_000_000));
        assert_eq!(rlimit_soft(text, "Max data size"), None);
        // The default is the smallest allowance, and a set budget never exceeds a hard one.
        let least = limits().iter().map(|l| l.allows).min();
        assert_eq!(default_budget(), least.map_or(FALLBACK, |b| b.max(1 << 20)));
        let d = describe();
        assert!(
            ["physical memory", "limit", "fallback", "asked"]
                .iter()
                .any(|w| d.contains(w)),
            "{d}"
        );
        let mut p = Plan::new();
        p.add("tables", 10).add("carrier", 1 << 40).add("empty", 0);
        assert_eq!(p.total(), (1 << 40) + 10);
        assert_eq!(p.largest(), Some(("carrier", 1 << 40)));
        let e = p.check(|| "direct light".into()).unwrap_err().to_string();
        assert!(e.contains("largest buffer: carrier, 1.1 TB"), "{e}");
        assert!(Plan::new().add("small", 1).fits());
    }

    #[test]
    fn only_small_regular_files_are_read() {
        let dir = std::env::temp_dir().join(format!("vltm-budget-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let small = dir.join("s.json");
        std::fs::write(&small, "{}").unwrap();
        assert_eq!(read_text(&small).unwrap(), "{}");
        assert_eq!(regular_file(&small).unwrap(), 2);
        // A sparse file one byte over the cap: refused by its size, not read.
        let big = dir.join("b.json");
        std::fs::File::create(&big)
            .unwrap()
            .set_len(MAX_TEXT_FILE + 1)
            .unwrap();
        let e = read_text(&big).unwrap_err().to_string();
        assert!(e.contains("b.json") && e.contains("at most 17 MB"), "{e}");
        // A device, a directory, a missing file.
        let e = read_text(std::path::Path::new("/dev/zero"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("a device"), "{e}");
        let e = regular_file(&dir).unwrap_err().to_string();
        assert!(e.contains("a directory"), "{e}");
        let e = regular_file(&dir.join("nothere.xyz"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("nothere.xyz") && e.contains("No such file"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
