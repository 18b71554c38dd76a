//! [`FixedRowBuffer`] → [`FixedRow`]: one laser row's integer band spectra, from `u16`
//! histograms or from photon sums.

use super::arith::round_shift;
use super::config::FixedConfig;
use super::nco::{cis_q15, phase_step};
use super::photons::FixedPhotons;
use super::scan::FixedScan;
use crate::config::Point;
use crate::error::{ArgumentError, check_len, check_points};
use crate::phase::TwiddleStep;

/// Caller-owned `i32` buffer for one row's band spectra: `Ks·(2J + 1)` (`HG` as re/im
/// pairs, then the leg offsets `x_s` as `f32` bits).
#[derive(Debug)]
pub struct FixedRowBuffer<'m> {
    pub(super) buf: &'m mut [i32],
}

/// One laser row in fixed point: band spectra `HG` (`i32`, LSB [`FixedConfig::hg_lsb`]).
#[derive(Debug)]
pub struct FixedRow<'r> {
    pub(super) laser: Point,
    pub(super) hg: &'r [i32],
    pub(super) offsets: &'r [i32],
}

impl FixedRow<'_> {
    /// The laser spot.
    pub const fn laser(&self) -> Point {
        self.laser
    }
    /// `HG[s·2J + 2j]` (re), `HG[s·2J + 2j + 1]` (im).
    pub const fn band(&self) -> &[i32] {
        self.hg
    }
    pub(super) fn offset(&self, s: usize) -> f32 {
        self.offsets
            .get(s)
            .map_or(0.0, |&b| f32::from_bits(b as u32))
    }
}

impl<'m> FixedRowBuffer<'m> {
    /// Length in `i32`: `Ks·(2J + 1)`.
    pub const fn len(fc: &FixedConfig, n_spads: usize) -> usize {
        n_spads * (2 * fc.cfg.bins() + 1)
    }

    /// Wraps `buf` (length [`FixedRowBuffer::len`]).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] for a wrong length.
    pub fn new(scan: &FixedScan<'_>, buf: &'m mut [i32]) -> Result<Self, ArgumentError> {
        check_len(
            "row buffer",
            Self::len(&scan.fc, scan.spads.len()),
            buf.len(),
        )?;
        Ok(Self { buf })
    }

    /// Band spectra of one row of `u16` histograms (SPAD-major, `hists[s·Nt + n]`): the DFT
    /// in `i32`/`i64` integers (`Ks·J·Nt` MACs), then gate weights and leg phases.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] for a wrong `hists` length or a buffer made for another scan;
    /// [`ArgumentError::NonFinite`] for a non-finite laser position.
    pub fn load<'r>(
        &'r mut self,
        scan: &FixedScan<'_>,
        laser: Point,
        hists: &[u16],
    ) -> Result<FixedRow<'r>, ArgumentError> {
        let cfg = &scan.fc.cfg;
        let (nt, n, k_lo) = (cfg.nt(), cfg.n_fft().max(1), cfg.k_lo());
        check_len("histograms", scan.spads.len() * nt, hists.len())?;
        let twiddle = scan.twiddle.as_chunks::<2>().0;
        self.fill(scan, laser, |s, jj| {
            let h = hists.get(s * nt..(s + 1) * nt).unwrap_or(&[]);
            let mut q = TwiddleStep::new(k_lo + jj as i64, 0, n);
            let (mut re, mut im) = (0i64, 0i64);
            for &c in h {
                if let Some([wr, wi]) = twiddle.get(q.index()) {
                    let c = i32::from(c);
                    re += i64::from(c * i32::from(wr.to_bits()));
                    im += i64::from(c * i32::from(wi.to_bits()));
                }
                q.advance();
            }
            (re, im)
        })
    }

    /// Band spectra of one row from its photon events ([`FixedPhotons`]): **bit-identical**
    /// to [`FixedRowBuffer::load`] on the histograms of the same photons, since the DFT sums
    /// are integers (exact, in any order) and the rest of the computation is shared.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] for a buffer or `photons` made for another scan;
    /// [`ArgumentError::NonFinite`] for a non-finite laser position.
    pub fn load_photons<'r>(
        &'r mut self,
        scan: &FixedScan<'_>,
        laser: Point,
        photons: &FixedPhotons<'_>,
    ) -> Result<FixedRow<'r>, ArgumentError> {
        let j = scan.fc.cfg.bins();
        check_len(
            "photon sums",
            FixedPhotons::len(&scan.fc, scan.spads.len()),
            photons.d.len(),
        )?;
        let d = photons.d.as_chunks::<2>().0;
        self.fill(scan, laser, |s, jj| {
            d.get(s * j + jj).map_or((0, 0), |&[re, im]| (re, im))
        })
    }

    /// The shared tail of [`FixedRowBuffer::load`] and [`FixedRowBuffer::load_photons`]:
    /// `HG_j = round(D_j·ĝ_j·p_j / 2^(30+sh))` from the DFT sums `dft(s, j) = D_j` of SPAD `s`.
    pub(super) fn fill<'r>(
        &'r mut self,
        scan: &FixedScan<'_>,
        laser: Point,
        mut dft: impl FnMut(usize, usize) -> (i64, i64),
    ) -> Result<FixedRow<'r>, ArgumentError> {
        let fc = &scan.fc;
        let cfg = &fc.cfg;
        let (ks, j) = (scan.spads.len(), cfg.bins());
        check_len("row buffer", Self::len(fc, ks), self.buf.len())?;
        check_points("laser", &[laser])?;
        let d1 = scan.laser_leg(&laser);
        let k_lo = cfg.k_lo();
        let too_short = ArgumentError::Length {
            what: "row buffer",
            expected: Self::len(fc, ks),
            found: 0,
        };
        let (hg_all, offsets) = self.buf.split_at_mut_checked(2 * ks * j).ok_or(too_short)?;
        let sh = 30 + fc.sh;
        // Not `zip` over `chunks_exact`: its out-of-line `Zip::new` divides by the chunk
        // length, a panicking branch in the no-panic link (as in band/probe.rs).
        for (s, (off, sp)) in offsets.iter_mut().zip(scan.spads).enumerate() {
            let Some(hg) = hg_all.get_mut(2 * s * j..2 * (s + 1) * j) else {
                break;
            };
            let x = d1 + scan.sensor_leg(sp) - cfg.t0();
            *off = (x as f32).to_bits() as i32;
            let step_x = phase_step(x, fc.two32_per_span);
            let mut phi = (k_lo as i32 as u32).wrapping_mul(step_x);
            for (jj, (out, g)) in hg
                .as_chunks_mut::<2>()
                .0
                .iter_mut()
                .zip(scan.gate)
                .enumerate()
            {
                let (re, im) = dft(s, jj);
                // HG = D·ĝ·p >> (30 + sh), in i128 (see the budget).
                let g = i128::from(g.to_bits());
                let (pc, ps) = cis_q15(phi);
                let (pc, ps) = (i128::from(pc), i128::from(ps));
                let (re, im) = (i128::from(re) * g, i128::from(im) * g);
                out[0] = round_shift(re * pc - im * ps, sh) as i32;
                out[1] = round_shift(re * ps + im * pc, sh) as i32;
                phi = phi.wrapping_add(step_x);
            }
        }
        Ok(FixedRow {
            laser,
            hg: hg_all,
            offsets,
        })
    }
}
