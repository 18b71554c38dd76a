//! The fixture scan through the kernel's **fixed-point** path (`vltm_kernel::Fixed*`, for
//! MCUs without an FPU): Gaussian diagonal and factorised Gaussian column from the `u16`
//! histograms, and the diagonal again from the same counts fed as photon events
//! (`FixedPhotons`), which must be bit-identical; then the diagonal on the fixed-point
//! **lookup path** (`FixedLookupProbe`: a block-exponent integer grid per SPAD and integer
//! cubic interpolation instead of the `J`-term band sum), and the column `T(FOCUS, ·)` on it in
//! passes of their own over the rows (sharing one state, and the photon sums' memory as
//! scratch). Shared word for word by the firmware (bin `vltm-firmware-fixed`) and the host
//! generator (`gen`, which writes `fixture/expected_fixed.txt`), like `pipeline.rs`.
//!
//! The per-bin arithmetic is integer; distances, weights and phase seeds are IEEE `f32`/`f64`
//! (soft float on the M0), so the firmware reproduces the host bit for bit.

use crate::fixture::{BINS, N_FFT};
use crate::fixture::{FOCUS, LASERS, N_LASERS, N_SPADS, N_VOXELS, ROW, SPADS, VOXELS, params};
use crate::pipeline::Failure;
use vltm_kernel::{
    Config, FixedColumn, FixedConfig, FixedDiagonal, FixedLimits, FixedLookup, FixedLookupGrid,
    FixedLookupProbe, FixedPhotons, FixedRowBuffer, FixedScan, I1F15, LookupParams, Target,
};

/// Headroom budget of the fixture: its 16 rows, 4 SPADs, legs ≥ 0.3 m (voxels at z ≥ 0.35 m).
pub const LIMITS: FixedLimits = FixedLimits::new(N_LASERS as u32, N_SPADS as u32, 0.3);
/// `FixedScan::tables_len`: `2N + J` Q1.15.
pub const FIXED_TABLES_LEN: usize = 2 * N_FFT + BINS;
/// `FixedRowBuffer::len`: `Ks·(2J + 1)` `i32`.
pub const FIXED_ROW_LEN: usize = N_SPADS * (2 * BINS + 1);
/// `FixedDiagonal::state_len`: `2Kv` `i64`.
pub const FIXED_DIAG_LEN: usize = 2 * N_VOXELS;
/// `FixedColumn::state_len`: `2·Ks·J` `i64`.
pub const FIXED_COLUMN_LEN: usize = 2 * N_SPADS * BINS;
/// `FixedPhotons::len`: `Ks·(2J + 1)` `i64`.
pub const FIXED_PHOTONS_LEN: usize = N_SPADS * (2 * BINS + 1);

/// Grid tolerance of the fixed-point lookup diagonal (`LookupParams::tolerance`).
pub const FIXED_LOOKUP_TOLERANCE: f64 = 1e-4;
/// Its grid length `L` (checked at run time).
pub const FIXED_LOOKUP_GRID: usize = 256;
/// `FixedLookup::tables_len`: `L` Q1.15.
pub const FIXED_LOOKUP_TABLES_LEN: usize = FIXED_LOOKUP_GRID;
/// `FixedLookupProbe::scratch_len`: `2(L + 3) + 2Kv` `i32` (taken from the photon sums'
/// memory, `2·FIXED_PHOTONS_LEN` `i32`).
pub const FIXED_LOOKUP_SCRATCH_LEN: usize = 2 * (FIXED_LOOKUP_GRID + 3) + 2 * N_VOXELS;

/// The fixture's fixed-point lookup grid.
pub fn fixed_lookup_params() -> LookupParams {
    LookupParams {
        tolerance: FIXED_LOOKUP_TOLERANCE,
        grid_len: None,
        ..LookupParams::new()
    }
}

/// Caller-owned buffers of the fixed-point pipeline.
pub struct FixedBuffers<'a> {
    /// Q1.15 tables.
    pub tables: &'a mut [I1F15],
    /// Row spectra.
    pub row: &'a mut [i32],
    /// Diagonal accumulators.
    pub diag: &'a mut [i64],
    /// Column state.
    pub column: &'a mut [i64],
    /// Photon-event sums of one row (then the lookup probes' scratch, as `i32`).
    pub photons: &'a mut [i64],
    /// Diagonal accumulators of the photon-event rows.
    pub diag_photons: &'a mut [i64],
    /// Q1.15 twiddles of the lookup path.
    pub lookup_tables: &'a mut [I1F15],
    /// Lookup probes' accumulators (`2Kv` `i64`: the diagonal's, then the column's).
    pub lookup_state: &'a mut [i64],
}

/// Intensities `T = |A|²` of the fixed-point pipeline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixedResults {
    /// Gaussian diagonal.
    pub diag: [f64; N_VOXELS],
    /// Gaussian column `T(FOCUS, v)`.
    pub col: [f64; N_VOXELS],
    /// Gaussian diagonal from photon events (bit-identical to `diag`).
    pub diag_photons: [f64; N_VOXELS],
    /// Gaussian diagonal on the fixed-point lookup path.
    pub lookup_diag: [f64; N_VOXELS],
    /// Gaussian column `T(FOCUS, v)` on the fixed-point lookup path.
    pub lookup_col: [f64; N_VOXELS],
    /// Photon events dropped (none expected).
    pub dropped: u64,
    /// Rows accumulated by each probe; aliased voxels of the column.
    pub rows: [u32; 2],
    /// Column voxels outside the alias-free range.
    pub aliased: usize,
}

impl FixedResults {
    /// All zeros.
    pub const ZERO: Self = Self {
        diag: [0.0; N_VOXELS],
        col: [0.0; N_VOXELS],
        diag_photons: [0.0; N_VOXELS],
        lookup_diag: [0.0; N_VOXELS],
        lookup_col: [0.0; N_VOXELS],
        dropped: 0,
        rows: [0; 2],
        aliased: 0,
    };
}

/// Runs the fixture scan through the fixed-point path.
///
/// # Errors
/// [`Failure`] if the configuration, the budget or a buffer is rejected.
pub fn run_fixed(
    scan_data: &[u16],
    b: FixedBuffers<'_>,
    out: &mut FixedResults,
) -> Result<(), Failure> {
    let cfg = Config::try_new(&params()).map_err(Failure::Config)?;
    let fc = FixedConfig::try_new(&cfg, &LIMITS).map_err(Failure::Config)?;
    if cfg.bins() != BINS || cfg.n_fft() != N_FFT {
        return Err(Failure::Sizes);
    }
    if scan_data.len() != N_LASERS * ROW {
        return Err(Failure::ScanData);
    }
    let scan = FixedScan::new(&fc, &SPADS, b.tables)?;
    let mut rows = FixedRowBuffer::new(&scan, b.row)?;
    let mut diag = FixedDiagonal::new(&VOXELS, b.diag)?;
    let mut col = FixedColumn::new(&scan, FOCUS, b.column)?;
    let mut photons = FixedPhotons::new(&scan, &mut *b.photons)?;
    let mut diag_p = FixedDiagonal::new(&VOXELS, b.diag_photons)?;
    let nt = cfg.nt();
    for (hists, laser) in scan_data.chunks_exact(ROW).zip(LASERS) {
        let row = rows.load(&scan, laser, hists)?;
        diag.push_row(&scan, &row)?;
        col.push_row(&scan, &row)?;
        // The same counts as photon events, as a TCSPC would deliver them.
        photons.reset();
        for (i, &c) in hists.iter().enumerate() {
            for _ in 0..c {
                photons.push(&scan, i / nt, i % nt);
            }
        }
        out.dropped += photons.dropped();
        let row = rows.load_photons(&scan, laser, &photons)?;
        diag_p.push_row(&scan, &row)?;
    }
    diag.finish(&fc, &mut out.diag)?;
    diag_p.finish(&fc, &mut out.diag_photons)?;
    // The lookup diagonal, then the lookup column, each in a pass of its own over the rows,
    // on one state and on the photon sums' memory as scratch (the microbit's 16 KB of RAM).
    let grid = FixedLookupGrid::try_new(&fc, &fixed_lookup_params()).map_err(Failure::Config)?;
    if grid.grid().len() != FIXED_LOOKUP_GRID {
        return Err(Failure::Sizes);
    }
    let lookup = FixedLookup::new(&grid, b.lookup_tables)?;
    let scratch: &mut [i32] =
        bytemuck::try_cast_slice_mut(&mut b.photons[..]).map_err(|_| Failure::Sizes)?;
    let scratch = scratch
        .get_mut(..FIXED_LOOKUP_SCRATCH_LEN)
        .ok_or(Failure::Sizes)?;
    for (target, res) in [
        (Target::Diagonal, &mut out.lookup_diag),
        (Target::Column(FOCUS), &mut out.lookup_col),
    ] {
        let mut probe = FixedLookupProbe::new(
            &lookup,
            target,
            &VOXELS,
            &mut *b.lookup_state,
            &mut *scratch,
        )?;
        for (hists, laser) in scan_data.chunks_exact(ROW).zip(LASERS) {
            let row = rows.load(&scan, laser, hists)?;
            probe.push_row(&scan, &lookup, &row)?;
        }
        probe.finish(res)?;
    }
    out.aliased = col.finish(&scan, &VOXELS, &mut out.col)?;
    out.rows = [diag.rows(), col.rows()];
    Ok(())
}

/// The fixed-point firmware's own checks (0 = passed): 3 / 4 as `pipeline::verdict` (the
/// diagonal peaks at P1, the column in the slice at P2), 5 if the photon-event diagonal is not
/// bit-identical to the histogram one, 6 if rows ≠ 16, photons were dropped or voxels aliased,
/// 8 if the lookup diagonal does not peak at P1 or the lookup diagonal's or column's
/// intensities differ from the band path's by more than 2e-3 of the largest (amplitudes within
/// 1e-3: its derived bound is ~1e-3 of the element's scale).
pub fn verdict_fixed(r: &FixedResults) -> i32 {
    use crate::fixture::{P1_VOXEL, P2_VOXEL, SLICE};
    use crate::pipeline::argmax;
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
    if r.diag_photons
        .iter()
        .zip(r.diag)
        .any(|(p, d)| p.to_bits() != d.to_bits())
    {
        return 5;
    }
    if r.rows != [N_LASERS as u32; 2] || r.aliased != 0 || r.dropped != 0 {
        return 6;
    }
    if argmax(&r.lookup_diag) != P1_VOXEL
        || rel_t(&r.lookup_diag, &r.diag) > 2e-3
        || rel_t(&r.lookup_col, &r.col) > 2e-3
    {
        return 8;
    }
    0
}

/// `max |T_lookup − T_band| / max T_band` (no square root in `core`: an amplitude error
/// `≤ ε·max|A|` gives `≤ (2ε + ε²)·max T` here).
pub fn rel_t(lookup: &[f64], band: &[f64]) -> f64 {
    let big = band.iter().fold(0.0f64, |m, x| m.max(*x));
    let worst = lookup
        .iter()
        .zip(band)
        .fold(0.0f64, |m, (l, b)| m.max((l - b).abs()));
    worst / big
}
