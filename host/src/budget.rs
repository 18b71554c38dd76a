//! The memory budget: every allocation whose size comes from a file, a sidecar, a scene or an
//! argument is checked against it **before** it is made, so that a header claiming 10¹²
//! samples or a time axis of 10⁹ bins gives a one-line error instead of an aborted process.
//!
//! The budget is process-wide: half of the machine's physical memory by default (`MemTotal`
//! of `/proc/meminfo`; 8 GiB where that cannot be read), set with [`set`] (the CLI's
//! `--max-memory`). [`check`] compares one allocation with it; callers add up what they hold
//! at once (a capture, its tables, per-thread buffers) and check the sum.

use std::sync::atomic::{AtomicU64, Ordering};

#[cfg(test)]
use crate::error::human;
use crate::error::{Error, Result};

/// The budget in bytes; 0 = not set yet (the default applies).
static BUDGET: AtomicU64 = AtomicU64::new(0);

/// The budget when physical memory cannot be read (bytes).
const FALLBACK: u64 = 8 << 30;

/// Sets the process-wide budget in bytes (at least 1 MiB).
pub fn set(bytes: u64) {
    BUDGET.store(bytes.max(1 << 20), Ordering::Relaxed);
}

/// The process-wide budget in bytes.
pub fn get() -> u64 {
    match BUDGET.load(Ordering::Relaxed) {
        0 => default_budget(),
        b => b,
    }
}

/// Half of the physical memory, or 8 GiB where that cannot be read.
pub fn default_budget() -> u64 {
    physical_memory().map_or(FALLBACK, |m| m / 2)
}

/// `MemTotal` of `/proc/meminfo` in bytes.
fn physical_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
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
}
