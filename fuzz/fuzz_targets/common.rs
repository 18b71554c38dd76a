//! Shared by the fuzz targets: a small memory budget (so that a size the budget should have
//! refused shows up as a crash under libFuzzer's `-malloc_limit_mb`), and a scratch file per
//! process for the readers that take a path.

use std::path::PathBuf;
use vltm::io::RowSource;

/// 256 MiB: with `-malloc_limit_mb=512`, any single allocation the budget did not bound
/// crashes the run.
pub fn init() {
    vltm::budget::set(256 << 20);
}

/// Writes `data` to a per-process scratch file with extension `ext` (in /dev/shm when it
/// exists) and returns its path.
pub fn scratch(ext: &str, data: &[u8]) -> PathBuf {
    let dir = if std::path::Path::new("/dev/shm").is_dir() {
        PathBuf::from("/dev/shm")
    } else {
        std::env::temp_dir()
    };
    let p = dir.join(format!("vltm-fuzz-{}.{ext}", std::process::id()));
    std::fs::write(&p, data).expect("scratch file");
    p
}

/// Reads every row of `src` (errors are fine; panics and aborts are not).
pub fn drain(src: &mut dyn RowSource) {
    let mut row = Vec::new();
    for l in 0..src.geometry().lasers.len() {
        if src.read_row(l, &mut row).is_err() {
            return;
        }
    }
}
