//! [`FixedPhotons`]: a row's photon events folded into integer DFT sums as they arrive.

use super::config::FixedConfig;
use super::scan::FixedScan;
use crate::error::{ArgumentError, check_len};
use crate::phase::{TwiddleStep, wrap};

/// Caller-owned integer accumulators of one row's **photon events** for the fixed-point path:
/// the DFT sums `D_j` of every SPAD (`i64` re/im) and a photon count per SPAD, so firmware
/// without an FPU folds TCSPC events as they arrive and never stores histograms
/// ([`FixedRowBuffer::load_photons`](crate::FixedRowBuffer::load_photons) then gives the row, bit-identical to the histogram path).
///
/// Per photon: `J` integer complex additions (one twiddle each, the index stepped by the
/// photon's bin). Memory: [`FixedPhotons::len`] `i64`. A SPAD's photons beyond the budget's
/// `Hmax = 65535·Nt` (what one `u16` histogram can hold), an unknown SPAD or a bin outside
/// `0..Nt` are dropped and counted ([`FixedPhotons::dropped`]), never an error or a panic.
#[derive(Debug)]
pub struct FixedPhotons<'m> {
    pub(super) d: &'m mut [i64],
    pub(super) dropped: u64,
}

impl<'m> FixedPhotons<'m> {
    /// Length in `i64`: `Ks·2J` sums, then `Ks` photon counts.
    pub const fn len(fc: &FixedConfig, n_spads: usize) -> usize {
        n_spads * (2 * fc.cfg.bins() + 1)
    }

    /// Wraps `buf` (length [`FixedPhotons::len`]) and zeroes it: an empty row.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] for a wrong length.
    pub fn new(scan: &FixedScan<'_>, buf: &'m mut [i64]) -> Result<Self, ArgumentError> {
        check_len(
            "photon sums",
            Self::len(&scan.fc, scan.spads.len()),
            buf.len(),
        )?;
        buf.fill(0);
        Ok(Self { d: buf, dropped: 0 })
    }

    /// Empties the row (all sums, counts and the dropped counter to 0).
    pub fn reset(&mut self) {
        self.d.fill(0);
        self.dropped = 0;
    }

    /// Photons dropped since the last [`FixedPhotons::reset`].
    pub const fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Folds one photon of SPAD `spad` in time bin `bin` into the row. Infallible.
    pub fn push(&mut self, scan: &FixedScan<'_>, spad: usize, bin: usize) {
        let cfg = &scan.fc.cfg;
        let (j, nt, n) = (cfg.bins(), cfg.nt(), cfg.n_fft().max(1));
        let ks = scan.spads.len();
        let Some((sums, counts)) = self.d.split_at_mut_checked(ks.saturating_mul(2 * j)) else {
            self.dropped += 1;
            return;
        };
        let start = spad.saturating_mul(2 * j);
        let (Some(d), Some(count)) = (
            sums.get_mut(start..start.saturating_add(2 * j)),
            counts.get_mut(spad),
        ) else {
            self.dropped += 1;
            return;
        };
        if bin >= nt || *count >= 65535 * nt as i64 {
            self.dropped += 1;
            return;
        }
        *count += 1;
        // Twiddle index (k_j·bin) mod N, stepped by `bin` per band bin; the first product in
        // u64 (it reaches 2⁶⁰).
        let mut q = TwiddleStep::new(bin as i64, wrap(cfg.k_lo(), n) as u64, n);
        let twiddle = scan.twiddle.as_chunks::<2>().0;
        for pair in d.as_chunks_mut::<2>().0 {
            if let Some([wr, wi]) = twiddle.get(q.index()) {
                pair[0] = pair[0].wrapping_add(i64::from(wr.to_bits()));
                pair[1] = pair[1].wrapping_add(i64::from(wi.to_bits()));
            }
            q.advance();
        }
    }
}
