//! The fixture pipeline, shared word for word by the firmware and the host generator (which
//! includes this file with `#[path]`), so both run the same kernel calls in the same order.
//!
//! Per laser row: [`RowBuffer::load`] the row's histograms → push to the Gaussian diagonal
//! and the Gaussian column `T(FOCUS, ·)`; then feed the same counts again as photon events
//! ([`RowBuffer::begin_photons`] / [`RowBuffer::push_photon`] / [`RowBuffer::end_photons`],
//! reusing the one row buffer) → push to a second diagonal. Finally [`Probe::finish`] all three.

use crate::fixture::{
    BINS, FOCUS, LASERS, N_FFT, N_LASERS, N_VOXELS, NT, P1_VOXEL, P2_VOXEL, ROW, SLICE, SPADS,
    VOXELS, params,
};
use vltm_kernel::{
    ArgumentError, Config, ConfigError, Gate, Probe, Report, RowBuffer, Scan, Target,
};

/// Caller-owned buffers of the pipeline (`'static` arrays in the firmware, `Vec`s on the host).
pub struct Buffers<'a> {
    /// `Scan::tables_len` `f32`.
    pub tables: &'a mut [f32],
    /// `RowBuffer::len` `f32`.
    pub row: &'a mut [f32],
    /// Diagonal × Gaussian state, histogram rows.
    pub diag: &'a mut [f64],
    /// Column × Gaussian state (factorised).
    pub column: &'a mut [f64],
    /// Diagonal × Gaussian state, photon-event rows.
    pub diag_photons: &'a mut [f64],
}

/// What the pipeline computes: intensities `T = |A|²` per voxel and the probes' reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Results {
    /// Diagonal `T(v, v)`, Gaussian gate, from histogram rows.
    pub diag: [f64; N_VOXELS],
    /// Column `T(FOCUS, v)`, Gaussian gate (factorised).
    pub col: [f64; N_VOXELS],
    /// Diagonal from the same counts fed as photon events.
    pub diag_photons: [f64; N_VOXELS],
    /// Report of the histogram diagonal.
    pub report_diag: Report,
    /// Report of the column (`aliased` counts voxels outside the alias-free range).
    pub report_col: Report,
    /// Report of the photon diagonal (`dropped` photons).
    pub report_photons: Report,
}

impl Results {
    /// All zeros (a `const` so that a `static` of it lives in `.bss`).
    pub const ZERO: Self = Self {
        diag: [0.0; N_VOXELS],
        col: [0.0; N_VOXELS],
        diag_photons: [0.0; N_VOXELS],
        report_diag: Report {
            rows: 0,
            non_finite: 0,
            dropped: 0,
            aliased: 0,
        },
        report_col: Report {
            rows: 0,
            non_finite: 0,
            dropped: 0,
            aliased: 0,
        },
        report_photons: Report {
            rows: 0,
            non_finite: 0,
            dropped: 0,
            aliased: 0,
        },
    };
}

/// Why the pipeline stopped.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Failure {
    /// The fixture's parameters were rejected.
    Config(ConfigError),
    /// The fixture's constants `BINS`/`N_FFT` do not match the configuration.
    Sizes,
    /// The scan data has the wrong length.
    ScanData,
    /// A kernel call rejected its arguments.
    Kernel(ArgumentError),
}

impl From<ArgumentError> for Failure {
    fn from(e: ArgumentError) -> Self {
        Self::Kernel(e)
    }
}

/// Runs the fixture scan (`N_LASERS · ROW` counts, the layout of `scan.bin`) through the
/// kernel into `out`.
///
/// # Errors
/// [`Failure`] if a buffer or the scan data does not fit the configuration.
pub fn run(scan_data: &[u16], b: Buffers<'_>, out: &mut Results) -> Result<(), Failure> {
    let cfg = Config::try_new(&params()).map_err(Failure::Config)?;
    if cfg.bins() != BINS || cfg.n_fft() != N_FFT {
        return Err(Failure::Sizes);
    }
    if scan_data.len() != N_LASERS * ROW {
        return Err(Failure::ScanData);
    }
    let scan = Scan::new(&cfg, &SPADS, b.tables)?;
    let mut rows = RowBuffer::new(&scan, b.row)?;
    let mut diag = Probe::new(&scan, Target::Diagonal, Gate::Gaussian, &VOXELS, b.diag)?;
    let mut col = Probe::new(
        &scan,
        Target::Column(FOCUS),
        Gate::Gaussian,
        &VOXELS,
        b.column,
    )?;
    let mut diag_ph = Probe::new(
        &scan,
        Target::Diagonal,
        Gate::Gaussian,
        &VOXELS,
        b.diag_photons,
    )?;
    for (hists, laser) in scan_data.chunks_exact(ROW).zip(LASERS) {
        // Histogram row: what a TCSPC unit hands over at the end of a laser position.
        let row = rows.load(&scan, laser, hists)?;
        diag.push_row(&scan, &row)?;
        col.push_row(&scan, &row)?;
        // The same counts as photon events, folded in as they would arrive.
        rows.begin_photons();
        for (spad, hist) in hists.chunks_exact(NT).enumerate() {
            for (bin, &count) in hist.iter().enumerate() {
                for _ in 0..count {
                    rows.push_photon(&scan, spad, bin);
                }
            }
        }
        let row = rows.end_photons(&scan, laser)?;
        diag_ph.push_row(&scan, &row)?;
    }
    out.report_diag = diag.finish(&scan, &mut out.diag)?;
    out.report_col = col.finish(&scan, &mut out.col)?;
    out.report_photons = diag_ph.finish(&scan, &mut out.diag_photons)?;
    Ok(())
}

/// Index of the largest value (first on ties); 0 for an empty slice.
pub fn argmax(x: &[f64]) -> usize {
    let mut best = 0;
    for (i, v) in x.iter().enumerate() {
        if x.get(best).is_some_and(|b| *v > *b) {
            best = i;
        }
    }
    best
}

/// The firmware's own sanity checks; the exit status of the firmware. 0 = passed.
///
/// * 3: the diagonal does not peak at P1's voxel;
/// * 4: in the z = 0.5 slice without P1, the column `T(P1, ·)` does not peak at P2's voxel
///   (the first-order indirect light P1 → P2);
/// * 5: the photon-event diagonal differs from the histogram one by more than 1e-4 of its
///   peak (the two orders of `f32` summation agree to ≈ 1e-6);
/// * 6: a report is off (rows ≠ 16, photons dropped, non-finite samples, aliased voxels).
pub fn verdict(r: &Results) -> i32 {
    if argmax(&r.diag) != P1_VOXEL {
        return 3;
    }
    let mut slice = [0.0f64; SLICE];
    for ((s, c), i) in slice.iter_mut().zip(r.col).zip(0..) {
        *s = if i == P1_VOXEL { 0.0 } else { c };
    }
    if argmax(&slice) != P2_VOXEL {
        return 4;
    }
    let peak = r.diag.get(P1_VOXEL).copied().unwrap_or(0.0);
    for (a, b) in r.diag.iter().zip(r.diag_photons) {
        if !((a - b).abs() <= 1e-4 * peak) {
            return 5;
        }
    }
    let rows = N_LASERS as u64;
    for rep in [r.report_diag, r.report_col, r.report_photons] {
        if rep.rows != rows || rep.dropped != 0 || rep.non_finite != 0 || rep.aliased != 0 {
            return 6;
        }
    }
    0
}
