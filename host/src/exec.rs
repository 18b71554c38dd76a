//! Execution options shared by the simulator and the probes: the evaluation [`EvalPath`], progress
//! reporting through a callback ([`Progress`]), and the sizes the thread pool works in.
//!
//! The library never draws anything itself: a caller that wants a progress bar passes a
//! [`Progress`] implementation in [`Exec::progress`] (the `vltm` command line draws one with
//! indicatif; tests and bindings pass their own or none). [`Progress::advance`] may be called
//! from worker threads, hence `Sync`.
//!
//! Threads: every parallel loop runs on rayon's global pool (set its size with
//! `rayon::ThreadPoolBuilder::build_global`, the CLI's `--threads`). Rows are read in batches
//! of `row_batch` (2 per thread) and voxel sets split into chunks of `chunk_len`, so memory
//! is set by the pool size, never by the number of laser rows.

use std::fmt;

/// Receives progress of a long pass (rendering or probing rows).
pub trait Progress: Sync {
    /// A pass named `label` over `total` units (laser rows) begins.
    fn start(&self, label: &str, total: u64);
    /// `n` more units of the current pass are done.
    fn advance(&self, n: u64);
    /// The current pass ended, completed or not.
    fn finish(&self);
    /// A warning about the run (one line, e.g. that few of the probed paths lie in the
    /// capture's window); the default drops it.
    fn warn(&self, _message: &str) {}
}

/// How the voxel sums of the diagonal and of Gaussian columns are evaluated (the CLI's
/// `--path`). All paths compute the same numbers (see `tests/proptest_fast.rs` for the
/// tolerances); they differ in cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum EvalPath {
    /// The cheapest applicable path by the flop model: for the diagonal the
    /// least of planar (when the SPADs — for a confocal capture the scanned wall points — form
    /// a regular grid and the volume is a wall-parallel grid whose pitch divides its pitch, or
    /// any other regular wall-parallel grid resampled from such a grid within its stated
    /// bound, [`crate::probe::resample`]), phasor, lookup and band; for
    /// Gaussian-gated columns planar
    /// or band.
    #[default]
    Auto,
    /// The kernel's band sum per (voxel, SPAD): any geometry, every probe.
    Band,
    /// The planar FFT convolution ([`crate::probe::fast::planar`]; for confocal captures
    /// [`crate::probe::fast::confocal`]) for the diagonal and Gaussian-gated columns (the
    /// diagonal also on grids off the wall's lattice, resampled: [`crate::probe::resample`]);
    /// an error if it does not apply (another geometry, another gate, a resampling bound
    /// above [`crate::probe::resample::MAX_ERROR`]).
    Planar,
    /// Diagonal only: the gated baseband + cubic lookup ([`crate::probe::fast::lookup`]), any
    /// geometry (confocal captures included); an error for columns.
    Lookup,
    /// Diagonal only: the full-phasor table per histogram with 8 voxels per vector
    /// ([`crate::probe::fast::phasor`]), any geometry (`auto` takes it on paired and confocal
    /// scans and on SPAD grids off the FFT path where it beats the lookup); an error for
    /// columns.
    Phasor,
}

impl EvalPath {
    /// The path's name as the CLI's `--path` spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Band => "band",
            Self::Planar => "planar",
            Self::Lookup => "lookup",
            Self::Phasor => "phasor",
        }
    }
}

/// Execution options of a probe or a render.
#[derive(Clone, Copy, Default)]
pub struct Exec<'p> {
    /// Where progress goes (`None`: nowhere).
    pub progress: Option<&'p dyn Progress>,
    /// Evaluation path (probes only).
    pub path: EvalPath,
}

impl fmt::Debug for Exec<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Exec")
            .field("progress", &self.progress.is_some())
            .field("path", &self.path)
            .finish()
    }
}

/// One pass reported to [`Exec::progress`]: started on creation, finished when dropped.
pub(crate) struct Pass<'p>(Option<&'p dyn Progress>);

impl<'p> Pass<'p> {
    /// Starts a pass named `label` over `total` rows.
    pub(crate) fn start(exec: Exec<'p>, label: &str, total: usize) -> Self {
        if let Some(p) = exec.progress {
            p.start(label, total as u64);
        }
        Self(exec.progress)
    }

    /// `n` more rows are done.
    pub(crate) fn advance(&self, n: usize) {
        if let Some(p) = self.0 {
            p.advance(n as u64);
        }
    }
}

impl Drop for Pass<'_> {
    fn drop(&mut self) {
        if let Some(p) = self.0 {
            p.finish();
        }
    }
}

/// Rows read per batch before they are processed in parallel: two per pool thread.
pub(crate) fn row_batch() -> usize {
    2 * rayon::current_num_threads()
}

/// Chunk length that splits `n` voxels into about four chunks per pool thread (at least 64
/// voxels each).
pub(crate) fn chunk_len(n: usize) -> usize {
    n.div_ceil(4 * rayon::current_num_threads()).max(64)
}
