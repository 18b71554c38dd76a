//! Scratch directories for the library's unit tests: `vltm-<tag>-<process id>` under the
//! system's temporary directory, emptied when made and removed (with what the test wrote)
//! when dropped, so that a test run leaves nothing behind. Test builds only.

use std::ops::Deref;
use std::path::{Path, PathBuf};

/// A scratch directory, or a file's path inside one of its own (module docs).
#[derive(Debug)]
pub(crate) struct Scratch {
    dir: PathBuf,
    path: PathBuf,
}

impl Scratch {
    /// An empty directory `vltm-<tag>-<process id>`.
    pub(crate) fn dir(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("vltm-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create a scratch directory");
        Self {
            path: dir.clone(),
            dir,
        }
    }

    /// The path `name` inside an empty directory of its own (`vltm-<tag>-<name>-<pid>`),
    /// so that tests running at once never share a file.
    pub(crate) fn file(tag: &str, name: &str) -> Self {
        let mut s = Self::dir(&format!("{tag}-{name}"));
        s.path = s.dir.join(name);
        s
    }
}

impl Deref for Scratch {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
