//! Stage 1 on the host: the band spectra of a whole laser row as **one matrix product**.
//!
//! For a row of Ks histograms `H` (Ks × Nt, SPAD-major) the raw band spectra are
//! `B = H · Wᵀ` with `W` the (2J × Nt) real matrix of `cos / sin (−2π k_j n / N)` rows
//! (`k_j = k_lo + j`, the kernel's band, DESIGN §B.2.2), so `B[s][2j], B[s][2j+1]` are the
//! real and imaginary parts of `Σ_n H_s[n] e^{−2πi k_j n/N}` — laid out exactly as the
//! kernel's `Complex32` spectra. The product runs in `matrixmultiply`'s `sgemm` (through
//! `ndarray`; AVX2/FMA picked at run time), ≈ 60 % of one core's f32 peak instead of the
//! kernel's portable integer-phase loop (3 GFLOP/s). The un-gated phasor
//! `M_s = Σ_n H_s[n] e^{−iΩ nΔt}` is two more dot products per histogram.
//!
//! Numerics: `W` is made in `f64` with the exact integer phase `(k·n) mod N` and rounded to
//! `f32` (error ≤ 6e-8, as the kernel's twiddle table); the sums are `f32` with sgemm's
//! blocked order (error ≲ √Nt·2⁻²⁴ of `Σ|H|`, inside the property tests' `ε_f32`).
//!
//! Cost per row `2·Ks·Nt·(2J + 2)` flops; memory `(2J + 2)·Nt` f32 for `W`.
//!
//! **Large tables.** `W` grows as `J·Nt`, and `J` grows with `Nt` (the band is a fixed share of
//! the DFT period), so `W` grows as `Nt²`: 100,000 bins would need 13 GB for a 40 kB capture.
//! Above [`MAX_TABLE_BYTES`] no table is made: each row's sums run over one band bin at a
//! time, its `Nt` phasors made by a complex recurrence in `f64` (resynchronised on the exact
//! integer phase every 256 bins, error ≲ 1e-13) and reused for every SPAD; memory O(Nt), the
//! same flops as the product at the speed of a plain loop.

use ndarray::linalg::general_mat_mul;
use ndarray::{Array2, ArrayView2, ArrayViewMut2};
use num_complex::Complex32;
use vltm_kernel::Config;

/// Largest band-DFT table `W` made (bytes); above it the sums run table-free (module docs).
pub const MAX_TABLE_BYTES: usize = 256 << 20;

/// The band DFT matrix of a configuration (see the module docs).
#[derive(Clone, Debug)]
pub struct BandDft {
    nt: usize,
    bins: usize,
    /// The band's first bin `k_lo` and the DFT period N.
    k_lo: i64,
    n: i64,
    /// (2J × Nt): row 2j = cos, row 2j+1 = sin of −2π k_j n/N; `None` above
    /// [`MAX_TABLE_BYTES`].
    w: Option<Array2<f32>>,
    /// cos / sin of −Ω nΔt (the un-gated carrier), Nt each.
    carrier: [Vec<f32>; 2],
}

impl BandDft {
    /// Bytes of the table `W` for `cfg` (saturating), whether or not it is made.
    pub fn table_bytes(cfg: &Config) -> u128 {
        (2 * cfg.bins() as u128).saturating_mul(cfg.nt() as u128) * 4
    }

    /// Builds `W` for `cfg` (cost `2J·Nt` sincos in `f64`, once), or no table above
    /// [`MAX_TABLE_BYTES`] (module docs).
    pub fn new(cfg: &Config) -> Self {
        let (nt, bins, n) = (cfg.nt(), cfg.bins(), cfg.n_fft() as i64);
        let w = (Self::table_bytes(cfg) <= MAX_TABLE_BYTES as u128).then(|| {
            let mut w = Array2::<f32>::zeros((2 * bins, nt));
            for j in 0..bins {
                let k = (cfg.k_lo() + j as i64).rem_euclid(n);
                for t in 0..nt {
                    let (c, s) = phasor(k, t as i64, n);
                    w[[2 * j, t]] = c as f32;
                    w[[2 * j + 1, t]] = s as f32;
                }
            }
            w
        });
        let turns = -cfg.dt() / cfg.wavelength();
        let phase = |t: usize| {
            let x = t as f64 * turns;
            std::f64::consts::TAU * (x - x.round())
        };
        let carrier = [
            (0..nt).map(|t| phase(t).cos() as f32).collect(),
            (0..nt).map(|t| phase(t).sin() as f32).collect(),
        ];
        Self {
            nt,
            bins,
            k_lo: cfg.k_lo(),
            n,
            w,
            carrier,
        }
    }

    /// Whether the table `W` was made (else the sums run table-free).
    pub fn has_table(&self) -> bool {
        self.w.is_some()
    }

    /// Number of band bins J.
    pub fn bins(&self) -> usize {
        self.bins
    }

    /// Raw band spectra and un-gated phasors of one row: `hists` is Ks × Nt (SPAD-major,
    /// finite values only — zero non-finite samples first), `band` Ks·J, `ungated` Ks.
    /// The signature of [`vltm_kernel::RowBuffer::load_with`]'s closure.
    ///
    /// # Panics
    /// If the lengths disagree with the configuration (callers size them from it).
    pub fn apply(&self, hists: &[f32], band: &mut [Complex32], ungated: &mut [Complex32]) {
        let ks = ungated.len();
        assert_eq!(hists.len(), ks * self.nt, "histograms");
        assert_eq!(band.len(), ks * self.bins, "band");
        if ks == 0 || self.nt == 0 {
            return;
        }
        match &self.w {
            Some(w) => {
                let a = ArrayView2::from_shape((ks, self.nt), hists).expect("checked shape");
                let out: &mut [f32] = bytemuck::cast_slice_mut(band);
                let mut c =
                    ArrayViewMut2::from_shape((ks, 2 * self.bins), out).expect("checked shape");
                general_mat_mul(1.0, &a, &w.t(), 0.0, &mut c);
            }
            None => self.apply_without_table(hists, band, ks),
        }
        for (h, m) in hists.chunks_exact(self.nt).zip(ungated.iter_mut()) {
            *m = Complex32::new(dot(h, &self.carrier[0]), dot(h, &self.carrier[1]));
        }
    }
}

impl BandDft {
    /// The band sums one bin at a time, its phasors by recurrence (module docs).
    fn apply_without_table(&self, hists: &[f32], band: &mut [Complex32], ks: usize) {
        let mut tw = vec![(0.0f64, 0.0f64); self.nt];
        for j in 0..self.bins {
            let k = (self.k_lo + j as i64).rem_euclid(self.n);
            let step = phasor(k, 1, self.n);
            let mut z = (1.0, 0.0);
            for (t, w) in tw.iter_mut().enumerate() {
                if t % 256 == 0 {
                    z = phasor(k, t as i64, self.n);
                }
                *w = z;
                z = (z.0 * step.0 - z.1 * step.1, z.0 * step.1 + z.1 * step.0);
            }
            for s in 0..ks {
                let h = &hists[s * self.nt..(s + 1) * self.nt];
                let (re, im) = h.iter().zip(&tw).fold((0.0f64, 0.0f64), |(a, b), (&x, w)| {
                    (a + f64::from(x) * w.0, b + f64::from(x) * w.1)
                });
                band[s * self.bins + j] = Complex32::new(re as f32, im as f32);
            }
        }
    }
}

/// `(cos, sin)` of `−2π (k·t mod n)/n`, the phase reduced exactly in integers.
fn phasor(k: i64, t: i64, n: i64) -> (f64, f64) {
    let q = (i128::from(k) * i128::from(t)).rem_euclid(i128::from(n));
    let a = -std::f64::consts::TAU * q as f64 / n as f64;
    (a.cos(), a.sin())
}

/// Dot product in eight independent lanes (vectorises).
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    let tail: f32 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
    acc.iter().sum::<f32>() + tail
}

#[cfg(test)]
mod tests {
    use super::*;
    use vltm_kernel::{Params, RowBuffer, Scan};

    /// The matrix product equals the kernel's own stage 1 on the same row.
    #[test]
    fn gemm_equals_kernel_stage1() {
        let cfg = Config::try_new(&Params {
            t0: 0.3,
            ..Params::new(0.25, 300, 0.012)
        })
        .unwrap();
        let spads: Vec<[f32; 3]> = (0..7).map(|i| [0.1 * i as f32, 0.05, 0.0]).collect();
        let mut tables = vec![0.0f32; Scan::tables_len(&cfg, spads.len())];
        let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
        let hists: Vec<f32> = (0..spads.len() * cfg.nt())
            .map(|i| ((i * 7919) % 97) as f32 * 0.37)
            .collect();
        let mut b1 = vec![0.0f32; RowBuffer::len(&cfg, spads.len())];
        let mut b2 = b1.clone();
        let mut r1 = RowBuffer::new(&scan, &mut b1).unwrap();
        let mut r2 = RowBuffer::new(&scan, &mut b2).unwrap();
        let laser = [0.3, 0.2, 0.0];
        let a = r1.load(&scan, laser, &hists).unwrap();
        let dft = BandDft::new(&cfg);
        let b = r2
            .load_with(&scan, laser, &hists, |band, m| dft.apply(&hists, band, m))
            .unwrap();
        let scale: f32 = hists.iter().map(|x| x.abs()).sum::<f32>() / spads.len() as f32;
        let g0 = cfg.gate_weight(cfg.bins() / 2) as f32;
        for (x, y) in a.band().iter().zip(b.band()) {
            assert!((x - y).norm() <= 2e-6 * scale * g0, "{x} vs {y}");
        }
        for (x, y) in a.ungated().iter().zip(b.ungated()) {
            assert!((x - y).norm() <= 2e-6 * scale, "{x} vs {y}");
        }
        assert_eq!(a.offsets(), b.offsets());
        // The table-free sums give the same spectra.
        let mut free = BandDft::new(&cfg);
        free.w = None;
        let mut b3 = vec![0.0f32; RowBuffer::len(&cfg, spads.len())];
        let mut r3 = RowBuffer::new(&scan, &mut b3).unwrap();
        let c = r3
            .load_with(&scan, laser, &hists, |band, m| free.apply(&hists, band, m))
            .unwrap();
        for (x, y) in a.band().iter().zip(c.band()) {
            assert!((x - y).norm() <= 2e-6 * scale * g0, "{x} vs {y}");
        }
        assert!(!free.has_table() && dft.has_table());
    }

    /// 100,000 bins: no 13 GB table is made.
    #[test]
    fn huge_tables_are_not_made() {
        let cfg = Config::try_new(&Params::new(0.05, 100_000, 0.001)).unwrap();
        assert!(BandDft::table_bytes(&cfg) > MAX_TABLE_BYTES as u128);
        assert!(!BandDft::new(&cfg).has_table());
    }
}
