//! Writing output files so that a failure loses nothing.
//!
//! Every file vltm writes (volumes, figures, captures, PTU streams and their sidecars) goes
//! through a [`Transaction`]: each file is first written to a temporary file in the same
//! directory (`.NAME.vltm-tmp-PID-N`), flushed and synced, and only when **every** file of the
//! transaction has been written are the temporary files renamed onto their targets (a rename
//! within one directory is atomic on POSIX file systems), and the directory is synced. So:
//!
//! * a write that fails partway (disk full, I/O error, a bug in an encoder) leaves the previous
//!   file intact and no partial file: the temporary files are removed;
//! * a multi-file output (a volume and its PNG; a capture, its PTU stream and the sidecar) is
//!   all or nothing: nothing new is left behind when one part fails; should a rename itself
//!   fail after others succeeded, the renamed files that did not exist before are removed
//!   (files that were replaced cannot be restored: that is the one window left, between two
//!   renames in one directory).
//!
//! A target that exists and is not a regular file (`/dev/null`, `/dev/full`, a FIFO) is
//! written directly: renaming over a device would replace it.
//!
//! Cost: one extra `fsync` per file and one per directory; memory: none beyond the caller's.

use std::fs::{self, File, OpenOptions};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, Result};

/// Distinguishes the temporary files of one process.
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// One file of a transaction.
#[derive(Debug)]
struct Stage {
    target: PathBuf,
    /// The temporary file, or `None` when the target is written directly.
    tmp: Option<PathBuf>,
    /// Whether the target existed before (it is not removed on a rollback).
    existed: bool,
}

/// A set of output files written all or nothing (see the [module documentation](self)).
#[derive(Debug, Default)]
pub struct Transaction {
    staged: Vec<Stage>,
}

impl Transaction {
    /// An empty transaction.
    pub fn new() -> Self {
        Self::default()
    }

    /// Writes the file `path` of the transaction: `write` fills the (temporary) file, which is
    /// then flushed and synced. Nothing is visible at `path` before [`Transaction::commit`].
    ///
    /// # Errors
    /// [`Error::Argument`] (`out`) if `path` was already staged or names a directory;
    /// [`Error::Io`] naming `path` if the temporary file cannot be created or synced; any
    /// error of `write`. On error the temporary file is removed.
    pub fn stage(
        &mut self,
        path: &Path,
        write: impl FnOnce(&mut File) -> Result<()>,
    ) -> Result<()> {
        if self.staged.iter().any(|s| s.target == path) {
            return Err(Error::arg(
                "out",
                format!("{} is written twice by one command", path.display()),
            ));
        }
        let meta = fs::metadata(path).ok();
        if meta.as_ref().is_some_and(fs::Metadata::is_dir) {
            return Err(Error::arg(
                "out",
                format!("{} is a directory", path.display()),
            ));
        }
        let existed = meta.is_some();
        if meta.is_some_and(|m| !m.is_file()) {
            // A device or FIFO: write in place.
            let mut f = OpenOptions::new()
                .write(true)
                .truncate(true)
                .open(path)
                .map_err(|e| Error::io(path, e))?;
            write(&mut f)?;
            self.staged.push(Stage {
                target: path.to_path_buf(),
                tmp: None,
                existed,
            });
            return Ok(());
        }
        let tmp = temp_path(path);
        let mut f = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(|e| Error::io(path, e))?;
        let written = write(&mut f).and_then(|()| f.sync_all().map_err(|e| Error::io(path, e)));
        drop(f);
        if let Err(e) = written {
            let _ = fs::remove_file(&tmp);
            return Err(e);
        }
        self.staged.push(Stage {
            target: path.to_path_buf(),
            tmp: Some(tmp),
            existed,
        });
        Ok(())
    }

    /// Moves every staged file onto its target and syncs their directories.
    ///
    /// # Errors
    /// [`Error::Io`] naming the target whose rename failed; the targets renamed before it that
    /// did not exist before are removed and every remaining temporary file is deleted.
    pub fn commit(mut self) -> Result<()> {
        let staged = std::mem::take(&mut self.staged);
        let mut done: Vec<&Stage> = Vec::new();
        for (i, s) in staged.iter().enumerate() {
            let Some(tmp) = &s.tmp else {
                done.push(s);
                continue;
            };
            if let Err(e) = fs::rename(tmp, &s.target) {
                for d in &done {
                    if !d.existed && d.tmp.is_some() {
                        let _ = fs::remove_file(&d.target);
                    }
                }
                for rest in &staged[i..] {
                    if let Some(t) = &rest.tmp {
                        let _ = fs::remove_file(t);
                    }
                }
                return Err(Error::io(&s.target, e));
            }
            done.push(s);
        }
        for s in &staged {
            if s.tmp.is_some()
                && let Some(dir) = parent(&s.target)
                && let Ok(d) = File::open(dir)
            {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }
}

impl Drop for Transaction {
    fn drop(&mut self) {
        for s in &self.staged {
            if let Some(t) = &s.tmp {
                let _ = fs::remove_file(t);
            }
        }
    }
}

/// Writes one file all or nothing (a transaction of one file).
///
/// # Errors
/// As [`Transaction::stage`] and [`Transaction::commit`].
pub fn write_file(path: &Path, write: impl FnOnce(&mut File) -> Result<()>) -> Result<()> {
    let mut t = Transaction::new();
    t.stage(path, write)?;
    t.commit()
}

/// Writes `bytes` to `path` all or nothing.
///
/// # Errors
/// As [`write_file`].
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_file(path, |f| {
        std::io::Write::write_all(f, bytes).map_err(|e| Error::io(path, e))
    })
}

/// The directory holding `path` (`.` for a bare file name).
fn parent(path: &Path) -> Option<&Path> {
    match path.parent() {
        Some(p) if p.as_os_str().is_empty() => Some(Path::new(".")),
        p => p,
    }
}

/// A fresh temporary name beside `path`.
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp = format!(".{name}.vltm-tmp-{}-{n}", std::process::id());
    match parent(path) {
        Some(dir) => dir.join(tmp),
        None => PathBuf::from(tmp),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn dir(name: &str) -> crate::scratch::Scratch {
        crate::scratch::Scratch::dir(&format!("atomic-{name}"))
    }

    fn names(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_leaves_nothing() {
        let d = dir("fail");
        let p = d.join("v.npy");
        fs::write(&p, b"good").unwrap();
        let r = write_file(&p, |f| {
            f.write_all(b"half").unwrap();
            Err(Error::arg("test", "fails partway"))
        });
        assert!(r.is_err());
        assert_eq!(fs::read(&p).unwrap(), b"good");
        assert_eq!(names(&d), ["v.npy"]);
        write_bytes(&p, b"new").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"new");
        assert_eq!(names(&d), ["v.npy"]);
    }

    #[test]
    fn a_multi_file_output_is_all_or_nothing() {
        let d = dir("multi");
        let (a, b) = (d.join("a.npz"), d.join("a.ptu"));
        let mut t = Transaction::new();
        t.stage(&a, |f| f.write_all(b"A").map_err(|e| Error::io(&a, e)))
            .unwrap();
        assert!(
            t.stage(&b, |_| Err(Error::arg("test", "second part fails")))
                .is_err()
        );
        drop(t);
        assert!(names(&d).is_empty(), "{:?}", names(&d));
        let mut t = Transaction::new();
        t.stage(&a, |f| f.write_all(b"A").map_err(|e| Error::io(&a, e)))
            .unwrap();
        t.stage(&b, |f| f.write_all(b"B").map_err(|e| Error::io(&b, e)))
            .unwrap();
        assert!(names(&d).iter().all(|n| n.contains("vltm-tmp")));
        t.commit().unwrap();
        assert_eq!(names(&d), ["a.npz", "a.ptu"]);
    }

    #[test]
    fn a_failed_rename_rolls_back_new_files() {
        let d = dir("rename");
        let a = d.join("new.npy");
        let blocker = d.join("blocked");
        let mut t = Transaction::new();
        t.stage(&a, |f| f.write_all(b"A").map_err(|e| Error::io(&a, e)))
            .unwrap();
        t.stage(&blocker, |f| {
            f.write_all(b"B").map_err(|e| Error::io(&blocker, e))
        })
        .unwrap();
        // A directory appears at the second target after staging: its rename fails.
        fs::create_dir(&blocker).unwrap();
        fs::write(blocker.join("x"), b"x").unwrap();
        assert!(t.commit().is_err());
        assert_eq!(
            names(&d),
            ["blocked"],
            "the first, new, file is rolled back"
        );
    }

    #[test]
    fn devices_are_written_in_place_and_errors_named() {
        write_bytes(Path::new("/dev/null"), b"x").unwrap();
        assert!(Path::new("/dev/null").exists());
        if Path::new("/dev/full").exists() {
            let e = write_bytes(Path::new("/dev/full"), &[0; 8192]).unwrap_err();
            assert!(e.to_string().contains("/dev/full"), "{e}");
        }
        let d = dir("dir");
        assert!(write_bytes(&d, b"x").is_err());
    }
}
