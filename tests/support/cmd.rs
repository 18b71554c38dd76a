//! Running the `vltm` binary from a test ([`super::vltm_bin`]): a temporary directory per
//! test, the command, its text, and the `.npy` volumes it writes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A temporary directory `vltm-<suite>-<process id>-<test>` under `std::env::temp_dir()`,
/// emptied when made and removed on drop.
pub struct TempDir(pub PathBuf);

impl TempDir {
    /// The directory of test `test` of the test file `suite` (e.g. `"cli"`).
    pub fn new(suite: &str, test: &str) -> Self {
        let p = std::env::temp_dir().join(format!("vltm-{suite}-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).expect("create temp dir");
        Self(p)
    }

    /// The path of `name` in the directory.
    pub fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    /// [`TempDir::path`] as a string, for a command-line argument.
    pub fn s(&self, name: &str) -> String {
        self.path(name).display().to_string()
    }

    /// Every file in the directory (not below) with its bytes.
    pub fn snapshot(&self) -> BTreeMap<String, Vec<u8>> {
        std::fs::read_dir(&self.0)
            .unwrap()
            .map(|e| {
                let e = e.unwrap();
                (
                    e.file_name().to_string_lossy().into_owned(),
                    std::fs::read(e.path()).unwrap(),
                )
            })
            .collect()
    }

    /// Every file and folder under the directory (names relative to it), recursively, sorted.
    pub fn files(&self) -> Vec<String> {
        fn walk(d: &Path, base: &Path, out: &mut Vec<String>) {
            for e in std::fs::read_dir(d).unwrap() {
                let p = e.unwrap().path();
                out.push(p.strip_prefix(base).unwrap().display().to_string());
                if p.is_dir() {
                    walk(&p, base, out);
                }
            }
        }
        let mut v = Vec::new();
        walk(&self.0, &self.0, &mut v);
        v.sort();
        v
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Runs `vltm args…` (in the test's working directory).
pub fn vltm(args: &[&str]) -> Output {
    Command::new(super::vltm_bin())
        .args(args)
        .output()
        .expect("run vltm")
}

/// Runs `vltm args…` in `cwd`.
pub fn vltm_in(cwd: &Path, args: &[&str]) -> Output {
    Command::new(super::vltm_bin())
        .current_dir(cwd)
        .args(args)
        .output()
        .expect("run vltm")
}

/// Bytes of a command's stdout or stderr as text (invalid UTF-8 replaced).
pub fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The adjacency a `--leak-correct auto` run printed on stdout (`out`).
pub fn auto_adjacency(out: &str) -> f64 {
    out.split("(--leak-correct auto): ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|x| x.parse().ok())
        .unwrap_or_else(|| panic!("no adjacency in {out}"))
}

/// The values and shape of a `.npy` volume; a failure names the file.
pub fn read_npy(p: &Path) -> (Vec<f32>, Vec<usize>) {
    vltm::export::npy::read_f32(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// The committed two-patch capture `fixtures/<stem>.npz`, checked ([`super::fixture`]).
pub fn npz_fixture(stem: &str) -> PathBuf {
    super::fixture(&format!("{stem}.npz"))
}
