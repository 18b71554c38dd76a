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

use ndarray::linalg::general_mat_mul;
use ndarray::{Array2, ArrayView2, ArrayViewMut2};
use num_complex::Complex32;
use vltm_kernel::Config;

/// The band DFT matrix of a configuration (see the module docs).
#[derive(Clone, Debug)]
pub struct BandDft {
    nt: usize,
    bins: usize,
    /// (2J × Nt): row 2j = cos, row 2j+1 = sin of −2π k_j n/N.
    w: Array2<f32>,
    /// cos / sin of −Ω nΔt (the un-gated carrier), Nt each.
    carrier: [Vec<f32>; 2],
}

impl BandDft {
    /// Builds `W` for `cfg` (cost `2J·Nt` sincos in `f64`, once).
    pub fn new(cfg: &Config) -> Self {
        let (nt, bins, n) = (cfg.nt(), cfg.bins(), cfg.n_fft() as i64);
        let mut w = Array2::<f32>::zeros((2 * bins, nt));
        for j in 0..bins {
            let k = (cfg.k_lo() + j as i64).rem_euclid(n);
            for t in 0..nt {
                let q = (k * t as i64) % n;
                let a = -std::f64::consts::TAU * q as f64 / n as f64;
                w[[2 * j, t]] = a.cos() as f32;
                w[[2 * j + 1, t]] = a.sin() as f32;
            }
        }
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
            w,
            carrier,
        }
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
        let a = ArrayView2::from_shape((ks, self.nt), hists).expect("checked shape");
        let out: &mut [f32] = bytemuck::cast_slice_mut(band);
        let mut c = ArrayViewMut2::from_shape((ks, 2 * self.bins), out).expect("checked shape");
        general_mat_mul(1.0, &a, &self.w.t(), 0.0, &mut c);
        for (h, m) in hists.chunks_exact(self.nt).zip(ungated.iter_mut()) {
            *m = Complex32::new(dot(h, &self.carrier[0]), dot(h, &self.carrier[1]));
        }
    }
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
    }
}
