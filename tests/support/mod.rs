//! Drives the kernel the way a host does: tables, row buffer, one probe, rows streamed in a
//! given order, `finish`. Shared by the test files via `mod support;`.
#![allow(dead_code)]

pub mod cmd;
pub mod prop;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use vltm_kernel::{ColumnF32, Config, Gate, Point, Probe, Report, RowBuffer, Sample, Scan, Target};

/// A scan for the kernel: apertures and histograms `hists[(l·Ks + s)·Nt + n]`.
#[derive(Clone, Copy, Debug)]
pub struct Data<'a, T> {
    /// Laser spots (one row each).
    pub lasers: &'a [Point],
    /// SPAD spots.
    pub spads: &'a [Point],
    /// Histograms, laser-major.
    pub hists: &'a [T],
}

impl<T: Sample> Data<'_, T> {
    /// The histograms of laser row `l`.
    pub fn row(&self, nt: usize, l: usize) -> &[T] {
        let len = self.spads.len() * nt;
        &self.hists[l * len..(l + 1) * len]
    }
}

/// The laser rows `0..Kl` in order.
pub fn all_rows(kl: usize) -> Vec<usize> {
    (0..kl).collect()
}

/// Streams the rows `order` of `data` through one probe and returns `(T, report)`.
pub fn run<T: Sample>(
    cfg: &Config,
    data: Data<'_, T>,
    target: Target,
    gate: Gate,
    voxels: &[Point],
    order: &[usize],
) -> (Vec<f64>, Report) {
    let ks = data.spads.len();
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, data.spads, &mut tables).expect("scan");
    let mut state = vec![0.0f64; Probe::state_len(cfg, target, gate, voxels.len(), ks)];
    let mut probe = Probe::new(&scan, target, gate, voxels, &mut state).expect("probe");
    let mut buf = vec![0.0f32; RowBuffer::len(cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).expect("row buffer");
    for &l in order {
        let row = rows
            .load(&scan, data.lasers[l], data.row(cfg.nt(), l))
            .expect("load");
        probe.push_row(&scan, &row).expect("push_row");
    }
    let mut out = vec![0.0f64; voxels.len()];
    let report = probe.finish(&scan, &mut out).expect("finish");
    (out, report)
}

/// Streams the rows `order` of `data` through a [`ColumnF32`] (factorised Gaussian column,
/// `f32` Kahan state) focused at `focus` and returns `(T, report)` as `f64`.
pub fn run_column_f32<T: Sample>(
    cfg: &Config,
    data: Data<'_, T>,
    focus: Point,
    voxels: &[Point],
    order: &[usize],
) -> (Vec<f64>, Report) {
    let ks = data.spads.len();
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, data.spads, &mut tables).expect("scan");
    let mut state = vec![0.0f32; ColumnF32::state_len(cfg, ks)];
    let mut col = ColumnF32::new(&scan, focus, &mut state).expect("column");
    let mut buf = vec![0.0f32; RowBuffer::len(cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).expect("row buffer");
    for &l in order {
        let row = rows
            .load(&scan, data.lasers[l], data.row(cfg.nt(), l))
            .expect("load");
        col.push_row(&scan, &row).expect("push_row");
    }
    let mut out = vec![0.0f32; voxels.len()];
    let report = col.finish(&scan, voxels, &mut out).expect("finish");
    (out.into_iter().map(f64::from).collect(), report)
}

/// Every (target kind, gate) combination the kernel offers, for a column focus `focus`.
pub fn all_probes(focus: Point) -> [(Target, Gate); 6] {
    [
        (Target::Diagonal, Gate::Gaussian),
        (Target::Diagonal, Gate::HigherOrder),
        (Target::Diagonal, Gate::None),
        (Target::Column(focus), Gate::Gaussian),
        (Target::Column(focus), Gate::HigherOrder),
        (Target::Column(focus), Gate::None),
    ]
}

/// Largest `|x − y|` relative to `max |y|` (0 when both are all zero).
pub fn max_rel_diff(x: &[f64], y: &[f64]) -> f64 {
    assert_eq!(x.len(), y.len());
    let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = x
        .iter()
        .zip(y)
        .fold(0.0f64, |m, (a, b)| m.max(nan_is_inf((a - b).abs())));
    if diff == 0.0 { 0.0 } else { diff / scale }
}

/// An error measure with NaN turned into +∞, so that `f64::max` (which drops NaN) cannot
/// hide a NaN result from a `worst ≤ tol` assertion.
pub fn nan_is_inf(err: f64) -> f64 {
    if err.is_nan() { f64::INFINITY } else { err }
}

/// The `vltm` binary the command-line tests run: `$VLTM_BIN`, or built once per test process
/// with the cargo, profile and target directory of the running test executable (see the
/// module documentation of `tests/cli.rs`).
pub fn vltm_bin() -> &'static Path {
    static BIN: OnceLock<PathBuf> = OnceLock::new();
    BIN.get_or_init(|| {
        if let Some(p) = std::env::var_os("VLTM_BIN") {
            return PathBuf::from(p);
        }
        let exe = std::env::current_exe().expect("test executable path");
        // <target>/<profile dir>/deps/cli-<hash>
        let profile_dir = exe
            .parent()
            .and_then(Path::parent)
            .expect("test executable in <target>/<profile>/deps");
        let target_dir = profile_dir.parent().expect("target directory");
        // `cargo test` builds into `debug/` with the `test` profile (opt-level 3 in this
        // workspace: building the binary with it shares the test build's dependencies and keeps
        // the demo fast); `cargo test --release` into `release/`; custom profiles into their name.
        let profile = match profile_dir.file_name().and_then(|n| n.to_str()) {
            Some("debug") => "test".to_string(),
            Some(p) => p.to_string(),
            None => panic!("unexpected test executable path {}", exe.display()),
        };
        let out = Command::new(env!("CARGO"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .env("CARGO_TARGET_DIR", target_dir)
            .args([
                "build",
                "--quiet",
                "-p",
                "vltm-cli",
                "--bin",
                "vltm",
                "--profile",
            ])
            .arg(&profile)
            .output()
            .expect("run cargo");
        assert!(
            out.status.success(),
            "cargo build -p vltm-cli --bin vltm --profile {profile} failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let p = profile_dir.join(format!("vltm{}", std::env::consts::EXE_SUFFIX));
        assert!(p.is_file(), "no binary at {}", p.display());
        p
    })
}

/// The voxels of object `name` of `scene` in `vol` (`Volume::surface_voxels`: its surface ±
/// one voxel, the set every ratio the README states is a mean over), its surface sampled
/// densely (40 × 40 points per patch or box face; a point scatterer is its one point).
pub fn scene_object_voxels(
    scene: &vltm::sim::Scene,
    name: &str,
    vol: &vltm::volume::Volume,
) -> Vec<usize> {
    let mut o = scene
        .object(name)
        .unwrap_or_else(|| panic!("no object {name}"))
        .clone();
    match &mut o {
        vltm::sim::Object::Patch(p) => p.samples = 40,
        vltm::sim::Object::Box(b) => b.samples = 40,
        vltm::sim::Object::Point(_) => {}
    }
    let pts: Vec<Point> = o
        .samples(0)
        .iter()
        .map(|p| p.position.map(|x| x as f32))
        .collect();
    vol.surface_voxels(&pts)
}

/// The mean of `v` over the voxels `idx`.
pub fn mean_over(v: &[f32], idx: &[usize]) -> f64 {
    idx.iter().map(|&i| f64::from(v[i])).sum::<f64>() / idx.len() as f64
}

/// The repository's root (the `vltm-suite` package).
pub fn repo_root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The committed fixture `rel` (a path under `fixtures/`, e.g. `"ytal/single/single.hdf5"`),
/// checked before a test reads it: a missing file, or a data file whose SHA-256 differs from
/// its line in `fixtures/SHA256SUMS`, fails with a message that names the file and says how to
/// restore it. A test never skips for a missing fixture.
pub fn fixture(rel: &str) -> PathBuf {
    let rel = rel.trim_start_matches("fixtures/");
    let path = repo_root().join("fixtures").join(rel);
    if let Err(e) = check_fixture(rel, &path) {
        panic!("{e}");
    }
    path
}

/// [`fixture`]'s check, as a `Result` (tests of the check itself).
pub fn check_fixture(rel: &str, path: &Path) -> Result<(), String> {
    let restore = format!(
        "restore it with `git checkout -- fixtures/{rel}` (fixtures/README.md says how it is made)"
    );
    let meta = std::fs::metadata(path)
        .map_err(|e| format!("fixture fixtures/{rel} is missing ({e}): {restore}"))?;
    if !meta.is_file() && !meta.is_dir() {
        return Err(format!("fixture fixtures/{rel} is not a file: {restore}"));
    }
    let Some(want) = fixture_sums().get(rel) else {
        return Ok(());
    };
    static CHECKED: OnceLock<std::sync::Mutex<std::collections::HashSet<PathBuf>>> =
        OnceLock::new();
    let checked = CHECKED.get_or_init(Default::default);
    if checked.lock().unwrap().contains(path) {
        return Ok(());
    }
    let bytes =
        std::fs::read(path).map_err(|e| format!("fixture fixtures/{rel}: {e}: {restore}"))?;
    let got = sha256_hex(&bytes);
    if &got != want {
        return Err(format!(
            "fixture fixtures/{rel} is damaged ({} bytes, SHA-256 {got}, fixtures/SHA256SUMS \
             says {want}): {restore}",
            bytes.len()
        ));
    }
    checked.lock().unwrap().insert(path.to_path_buf());
    Ok(())
}

/// `fixtures/SHA256SUMS` (`sha256sum` format, paths relative to `fixtures/`), parsed once.
pub fn fixture_sums() -> &'static std::collections::BTreeMap<String, String> {
    static SUMS: OnceLock<std::collections::BTreeMap<String, String>> = OnceLock::new();
    SUMS.get_or_init(|| {
        let p = repo_root().join("fixtures/SHA256SUMS");
        let text = std::fs::read_to_string(&p).unwrap_or_else(|e| {
            panic!(
                "fixtures/SHA256SUMS is missing ({e}): restore it with \
                 `git checkout -- fixtures/SHA256SUMS`"
            )
        });
        text.lines()
            .filter(|l| !l.trim().is_empty())
            .map(|l| {
                let (sum, name) = l
                    .split_once("  ")
                    .unwrap_or_else(|| panic!("fixtures/SHA256SUMS: bad line {l:?}"));
                (name.trim().to_string(), sum.trim().to_string())
            })
            .collect()
    })
}

/// The SHA-256 of `bytes`, as lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}
