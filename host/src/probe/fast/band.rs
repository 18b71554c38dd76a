//! Stage 1 on the host: the band spectra of a whole laser row as **one matrix product**.
//!
//! For a row of Ks histograms `H` (Ks × Nt, SPAD-major) the raw band spectra are
//! `B = H · Wᵀ` with `W` the (2J × Nt) real matrix of `cos / sin (−2π k_j n / N)` rows
//! (`k_j = k_lo + j`, the kernel's band), so `B[s][2j], B[s][2j+1]` are the
//! real and imaginary parts of `Σ_n H_s[n] e^{−2πi k_j n/N}` — laid out exactly as the
//! kernel's `Complex32` spectra. The product runs in `matrixmultiply`'s `sgemm` (through
//! `ndarray`; AVX2/FMA picked at run time), ≈ 60 % of one core's AVX2 f32 peak instead of
//! the kernel's portable integer-phase loop (3 GFLOP/s); on a CPU with AVX-512 in
//! [`super::sgemm`]'s 16-lane tiles instead (`W` packed once; 18 % → 11 % of a one-thread
//! exhaustive `direct`; [`BandDft::portable_table`] keeps `sgemm`, and both agree within the sums'
//! rounding, tested). The un-gated phasor
//! `M_s = Σ_n H_s[n] e^{−iΩ nΔt}` is two more rows of `W` (the carrier's cos and sin), so the
//! row is read once, not three times (the product's 8-column panels leave room for them:
//! 2J + 2 = 68 columns take the same 9 panels as 66).
//!
//! Numerics: `W` is made in `f64` with the exact integer phase `(k·n) mod N` and rounded to
//! `f32` (error ≤ 6e-8, as the kernel's twiddle table); the sums are `f32` with sgemm's
//! blocked order (error ≲ √Nt·2⁻²⁴ of `Σ|H|`, inside the property tests' `ε_f32`).
//!
//! Cost per row `2·Ks·Nt·(2J + 2)` flops; memory `(2J + 2)·Nt` f32 for `W` and, per call,
//! `Ks·(2J + 2)` f32 for the product before it is split into spectra and phasors.
//!
//! **Large tables.** `W` grows as `J·Nt`, and `J` grows with `Nt` (the band is a fixed share of
//! the DFT period), so `W` grows as `Nt²`: 100,000 bins would need 13 GB for a 40 kB capture.
//! Above [`MAX_TABLE_BYTES`] no table is made: each row's sums run over one band bin at a
//! time, its `Nt` phasors made by a complex recurrence in `f64` (resynchronised on the exact
//! integer phase every 256 bins, error ≲ 1e-13) and reused for every SPAD; memory O(Nt), the
//! same flops as the product at the speed of a plain loop.
//!
//! **Long axes: the FFT.** The product costs `J·Nt` per histogram and `J ∝ N ≥ Nt`, so it grows
//! as `Nt²`. Where one N-point FFT per histogram is cheaper — `5·N·log₂N / 2` flops (two real
//! histograms packed into one complex transform) against `4·J·Nt` at the product's 4× better
//! flop rate, or whenever the table is not made — the band bins are read off the N-point
//! FFT of the zero-padded histogram (`rustfft`, `f32`, any N: mixed radix, Rader or
//! Bluestein, all O(N log N)). Same spectra: the FFT's bins are the DFT's (error
//! ≲ log₂N·2⁻²⁴ of `‖H‖₂·√N`, below the sums' own). Memory: one N-point complex buffer and
//! rustfft's scratch per call.

use ndarray::linalg::general_mat_mul;
use ndarray::{Array2, ArrayView2, ArrayViewMut2};
use num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;
use vltm_kernel::Config;

/// Largest band-DFT table `W` made (bytes); above it the sums run table-free (module docs).
pub const MAX_TABLE_BYTES: usize = 256 << 20;

/// How stage 1 runs (module docs).
#[derive(Clone)]
enum Method {
    /// The matrix product with the table `W` (`matrixmultiply`).
    Table(Array2<f32>),
    /// The same product with `W` packed for AVX-512 lanes ([`super::sgemm`]).
    #[cfg(target_arch = "x86_64")]
    Packed(super::sgemm::Packed),
    /// One band bin at a time, phasors by recurrence.
    TableFree,
    /// One N-point FFT per pair of histograms.
    Fft(Arc<dyn Fft<f32>>),
}

impl std::fmt::Debug for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Table(_) => "Table",
            #[cfg(target_arch = "x86_64")]
            Self::Packed(_) => "Packed",
            Self::TableFree => "TableFree",
            Self::Fft(_) => "Fft",
        })
    }
}

/// The band DFT matrix of a configuration (see the module docs).
#[derive(Clone, Debug)]
pub struct BandDft {
    nt: usize,
    bins: usize,
    /// The band's first bin `k_lo` and the DFT period N.
    k_lo: i64,
    n: i64,
    /// The table `W` ((2J + 2) × Nt: row 2j = cos, row 2j+1 = sin of −2π k_j n/N, the last
    /// two the carrier's), none above [`MAX_TABLE_BYTES`], or the FFT.
    method: Method,
    /// cos / sin of −Ω nΔt (the un-gated carrier), Nt each.
    carrier: [Vec<f32>; 2],
}

impl BandDft {
    /// Bytes of the table `W` for `cfg` (saturating), whether or not it is made: its
    /// `2J + 2` rows padded to a multiple of 16, as [`super::sgemm`] holds them (the portable
    /// product's table is at most this).
    pub fn table_bytes(cfg: &Config) -> u128 {
        (2 * cfg.bins() as u128 + 2)
            .next_multiple_of(16)
            .saturating_mul(cfg.nt() as u128)
            * 4
    }

    /// Builds `W` for `cfg` (cost `2J·Nt` sincos in `f64`, once), or no table above
    /// [`MAX_TABLE_BYTES`] (module docs).
    pub fn new(cfg: &Config) -> Self {
        let table = Self::table_bytes(cfg) <= MAX_TABLE_BYTES as u128;
        if Self::fft_is_cheaper(cfg) || !table {
            return Self::fft(cfg);
        }
        Self::table(cfg)
    }

    /// One FFT per pair of histograms, whatever the product would cost (module docs).
    pub fn fft(cfg: &Config) -> Self {
        let fft = FftPlanner::<f32>::new().plan_fft_forward(cfg.n_fft());
        Self::with_method(cfg, Method::Fft(fft))
    }

    /// Whether one FFT per pair of histograms costs less than the matrix product (module docs:
    /// `5·N·log₂N / 2` against `J·Nt`, the product's flops counted at a quarter).
    pub fn fft_is_cheaper(cfg: &Config) -> bool {
        let n = cfg.n_fft() as f64;
        let fft = 2.5 * n * n.log2().max(1.0);
        (cfg.bins() as f64) * (cfg.nt() as f64) > fft
    }

    /// The matrix product (or table-free sums above [`MAX_TABLE_BYTES`]), whatever the FFT
    /// would cost; in AVX-512 lanes where the CPU has them ([`super::sgemm`]).
    pub fn table(cfg: &Config) -> Self {
        #[cfg(target_arch = "x86_64")]
        if Self::table_bytes(cfg) <= MAX_TABLE_BYTES as u128
            && let Some(mut p) = super::sgemm::Packed::zeros(2 * cfg.bins() + 2, cfg.nt())
        {
            entries(cfg, |c, t, x| p.set(c, t, x));
            return Self::with_method(cfg, Method::Packed(p));
        }
        Self::portable_table(cfg)
    }

    /// [`BandDft::table`] with the portable product (`matrixmultiply`: AVX2 and FMA where the
    /// CPU has them, never AVX-512), whatever the CPU; its spectra equal the AVX-512 ones
    /// within the sums' rounding (tested).
    pub fn portable_table(cfg: &Config) -> Self {
        let w = (Self::table_bytes(cfg) <= MAX_TABLE_BYTES as u128).then(|| {
            let mut w = Array2::<f32>::zeros((2 * cfg.bins() + 2, cfg.nt()));
            entries(cfg, |c, t, x| w[[c, t]] = x);
            w
        });
        Self::with_method(cfg, w.map_or(Method::TableFree, Method::Table))
    }

    fn with_method(cfg: &Config, method: Method) -> Self {
        let nt = cfg.nt();
        let (cos, sin) = carrier(cfg).into_iter().unzip();
        let carrier = [cos, sin];
        Self {
            nt,
            bins: cfg.bins(),
            k_lo: cfg.k_lo(),
            n: cfg.n_fft() as i64,
            method,
            carrier,
        }
    }

    /// Whether the table `W` was made (else the sums run table-free or by FFT).
    pub fn has_table(&self) -> bool {
        !matches!(self.method, Method::TableFree | Method::Fft(_))
    }

    /// Whether the product runs in AVX-512 lanes ([`super::sgemm`]).
    pub fn uses_avx512(&self) -> bool {
        #[cfg(target_arch = "x86_64")]
        return matches!(self.method, Method::Packed(_));
        #[cfg(not(target_arch = "x86_64"))]
        false
    }

    /// Whether the spectra come from one FFT per pair of histograms.
    pub fn uses_fft(&self) -> bool {
        matches!(self.method, Method::Fft(_))
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
        // Spectra and phasors in one product (module docs) of `cols` columns per histogram.
        let mut out = Vec::new();
        let cols = match &self.method {
            Method::Table(w) => {
                let cols = 2 * self.bins + 2;
                out.resize(ks * cols, 0.0f32);
                let a = ArrayView2::from_shape((ks, self.nt), hists).expect("checked shape");
                let mut c = ArrayViewMut2::from_shape((ks, cols), &mut out).expect("checked shape");
                general_mat_mul(1.0, &a, &w.t(), 0.0, &mut c);
                cols
            }
            #[cfg(target_arch = "x86_64")]
            Method::Packed(p) => {
                p.product(hists, &mut out);
                p.stride()
            }
            // No product: the spectra, then the phasors.
            Method::TableFree => {
                self.apply_without_table(hists, band, ks);
                return self.ungated(hists, ungated);
            }
            Method::Fft(fft) => {
                self.apply_fft(fft.as_ref(), hists, band, ks);
                return self.ungated(hists, ungated);
            }
        };
        // Split the product's rows into spectra and phasors.
        let band: &mut [f32] = bytemuck::cast_slice_mut(band);
        for ((o, b), m) in out
            .chunks_exact(cols)
            .zip(band.chunks_exact_mut(2 * self.bins))
            .zip(ungated.iter_mut())
        {
            b.copy_from_slice(&o[..2 * self.bins]);
            *m = Complex32::new(o[2 * self.bins], o[2 * self.bins + 1]);
        }
    }
}

impl BandDft {
    /// The un-gated phasors `M_s` as dot products with the carrier (the paths without the
    /// product).
    fn ungated(&self, hists: &[f32], ungated: &mut [Complex32]) {
        for (h, m) in hists.chunks_exact(self.nt).zip(ungated.iter_mut()) {
            *m = Complex32::new(dot(h, &self.carrier[0]), dot(h, &self.carrier[1]));
        }
    }

    /// The band bins from one N-point FFT per pair of histograms (module docs): `z = h₁ + i·h₂`,
    /// `Z = FFT(z)`, then `H₁[k] = (Z[k] + Z̄[N−k])/2`, `H₂[k] = (Z[k] − Z̄[N−k])/(2i)`.
    fn apply_fft(&self, fft: &dyn Fft<f32>, hists: &[f32], band: &mut [Complex32], ks: usize) {
        let n = self.n as usize;
        let mut buf = vec![Complex32::new(0.0, 0.0); n];
        let mut scratch = vec![Complex32::new(0.0, 0.0); fft.get_inplace_scratch_len()];
        let bins: Vec<usize> = (0..self.bins)
            .map(|j| (self.k_lo + j as i64).rem_euclid(self.n) as usize)
            .collect();
        let mut s = 0;
        while s < ks {
            let pair = s + 1 < ks;
            buf.fill(Complex32::new(0.0, 0.0));
            let h1 = &hists[s * self.nt..(s + 1) * self.nt];
            if pair {
                let h2 = &hists[(s + 1) * self.nt..(s + 2) * self.nt];
                for ((z, &a), &b) in buf.iter_mut().zip(h1).zip(h2) {
                    *z = Complex32::new(a, b);
                }
            } else {
                for (z, &a) in buf.iter_mut().zip(h1) {
                    z.re = a;
                }
            }
            fft.process_with_scratch(&mut buf, &mut scratch);
            for (j, &k) in bins.iter().enumerate() {
                if pair {
                    let zk = buf[k];
                    let zm = buf[(n - k) % n].conj();
                    band[s * self.bins + j] = (zk + zm) * 0.5;
                    let d = (zk - zm) * 0.5;
                    // d / i = (d.im, −d.re)
                    band[(s + 1) * self.bins + j] = Complex32::new(d.im, -d.re);
                } else {
                    band[s * self.bins + j] = buf[k];
                }
            }
            s += if pair { 2 } else { 1 };
        }
    }

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

/// Every entry `W[c][t]` of the table for `cfg` handed to `put(c, t, value)` (module docs).
fn entries(cfg: &Config, mut put: impl FnMut(usize, usize, f32)) {
    let (nt, bins, n) = (cfg.nt(), cfg.bins(), cfg.n_fft() as i64);
    for j in 0..bins {
        let k = (cfg.k_lo() + j as i64).rem_euclid(n);
        for t in 0..nt {
            let (c, s) = phasor(k, t as i64, n);
            put(2 * j, t, c as f32);
            put(2 * j + 1, t, s as f32);
        }
    }
    for (t, (c, s)) in carrier(cfg).into_iter().enumerate() {
        put(2 * bins, t, c);
        put(2 * bins + 1, t, s);
    }
}

/// The un-gated carrier `e^{−iΩ nΔt}` per bin, as `f32` `(cos, sin)` (phase in `f64`,
/// reduced to one turn).
fn carrier(cfg: &Config) -> Vec<(f32, f32)> {
    let turns = -cfg.dt() / cfg.wavelength();
    (0..cfg.nt())
        .map(|t| {
            let x = t as f64 * turns;
            let a = std::f64::consts::TAU * (x - x.round());
            (a.cos() as f32, a.sin() as f32)
        })
        .collect()
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
pub(crate) mod tests {
    use super::*;
    use vltm_kernel::{Params, RowBuffer, Scan};

    /// The stage-1 tests' row: 300 bins of 12 mm (λ = 0.25 m), 7 SPADs on a line, and their
    /// histograms (positive, uneven).
    pub(crate) fn sample_row() -> (Config, Vec<[f32; 3]>, Vec<f32>) {
        let cfg = Config::try_new(&Params {
            t0: 0.3,
            ..Params::new(0.25, 300, 0.012)
        })
        .unwrap();
        let spads: Vec<[f32; 3]> = (0..7).map(|i| [0.1 * i as f32, 0.05, 0.0]).collect();
        let hists = (0..spads.len() * cfg.nt())
            .map(|i| ((i * 7919) % 97) as f32 * 0.37)
            .collect();
        (cfg, spads, hists)
    }

    /// The matrix product equals the kernel's own stage 1 on the same row.
    #[test]
    fn gemm_equals_kernel_stage1() {
        let (cfg, spads, hists) = sample_row();
        let mut tables = vec![0.0f32; Scan::tables_len(&cfg, spads.len())];
        let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
        let mut b1 = vec![0.0f32; RowBuffer::len(&cfg, spads.len())];
        let mut b2 = b1.clone();
        let mut r1 = RowBuffer::new(&scan, &mut b1).unwrap();
        let laser = [0.3, 0.2, 0.0];
        let a = r1.load(&scan, laser, &hists).unwrap();
        let scale: f32 = hists.iter().map(|x| x.abs()).sum::<f32>() / spads.len() as f32;
        let g0 = cfg.gate_weight(cfg.bins() / 2) as f32;
        // The dispatched product (AVX-512 lanes where the CPU has them) and the portable one.
        let dft = BandDft::table(&cfg);
        let portable = BandDft::portable_table(&cfg);
        assert!(!portable.uses_avx512() && portable.has_table() && dft.has_table());
        // The AVX-512 product exactly where the CPU has AVX-512.
        #[cfg(target_arch = "x86_64")]
        assert_eq!(dft.uses_avx512(), pulp::x86::V4::try_new().is_some());
        for d in [&dft, &portable] {
            let mut r2 = RowBuffer::new(&scan, &mut b2).unwrap();
            let b = r2
                .load_with(&scan, laser, &hists, |band, m| d.apply(&hists, band, m))
                .unwrap();
            for (x, y) in a.band().iter().zip(b.band()) {
                assert!((x - y).norm() <= 2e-6 * scale * g0, "{d:?}: {x} vs {y}");
            }
            for (x, y) in a.ungated().iter().zip(b.ungated()) {
                assert!((x - y).norm() <= 2e-6 * scale, "{d:?}: {x} vs {y}");
            }
            assert_eq!(a.offsets(), b.offsets());
        }
        // The table-free sums give the same spectra.
        let mut free = BandDft::table(&cfg);
        free.method = Method::TableFree;
        let mut b3 = vec![0.0f32; RowBuffer::len(&cfg, spads.len())];
        let mut r3 = RowBuffer::new(&scan, &mut b3).unwrap();
        let c = r3
            .load_with(&scan, laser, &hists, |band, m| free.apply(&hists, band, m))
            .unwrap();
        for (x, y) in a.band().iter().zip(c.band()) {
            assert!((x - y).norm() <= 2e-6 * scale * g0, "{x} vs {y}");
        }
        assert!(!free.has_table() && dft.has_table());
        // The FFT gives the same spectra, for an odd number of SPADs (pairs and a single).
        let fft = BandDft::fft(&cfg);
        let mut b4 = vec![0.0f32; RowBuffer::len(&cfg, spads.len())];
        let mut r4 = RowBuffer::new(&scan, &mut b4).unwrap();
        let d = r4
            .load_with(&scan, laser, &hists, |band, m| fft.apply(&hists, band, m))
            .unwrap();
        for (x, y) in a.band().iter().zip(d.band()) {
            assert!((x - y).norm() <= 2e-6 * scale * g0, "{x} vs {y}");
        }
        assert!(fft.uses_fft());
    }

    /// 100,000 bins by FFT against the exact DFT in f64, for two SPADs (one packed pair).
    #[test]
    fn fft_matches_f64_dft_on_long_axes() {
        let cfg = Config::try_new(&Params::new(0.05, 100_000, 0.0005)).unwrap();
        let dft = BandDft::new(&cfg);
        assert!(dft.uses_fft());
        let nt = cfg.nt();
        let hists: Vec<f32> = (0..2 * nt)
            .map(|i| {
                let t = (i % nt) as f64 * 0.0005;
                let c = if i < nt { 20.0 } else { 31.0 };
                ((-((t - c) / 0.01).powi(2)).exp() + ((i * 7919) % 13) as f64 * 1e-3) as f32
            })
            .collect();
        let mut band = vec![Complex32::new(0.0, 0.0); 2 * cfg.bins()];
        let mut m = vec![Complex32::new(0.0, 0.0); 2];
        dft.apply(&hists, &mut band, &mut m);
        let n = cfg.n_fft() as i64;
        for s in 0..2 {
            let h = &hists[s * nt..(s + 1) * nt];
            let l1: f64 = h.iter().map(|x| f64::from(x.abs())).sum();
            for j in (0..cfg.bins()).step_by(97) {
                let k = (cfg.k_lo() + j as i64).rem_euclid(n);
                let (re, im) = h.iter().enumerate().fold((0.0, 0.0), |(a, b), (t, &x)| {
                    let (c, si) = phasor(k, t as i64, n);
                    (a + f64::from(x) * c, b + f64::from(x) * si)
                });
                let got = band[s * cfg.bins() + j];
                let err =
                    ((f64::from(got.re) - re).powi(2) + (f64::from(got.im) - im).powi(2)).sqrt();
                assert!(err <= 1e-5 * l1, "bin {j}: {got} vs ({re}, {im}), l1 {l1}");
            }
        }
    }

    /// 100,000 bins: no 13 GB table is made.
    #[test]
    fn huge_tables_are_not_made() {
        let cfg = Config::try_new(&Params::new(0.05, 100_000, 0.001)).unwrap();
        assert!(BandDft::table_bytes(&cfg) > MAX_TABLE_BYTES as u128);
        assert!(!BandDft::new(&cfg).has_table());
        assert!(!BandDft::table(&cfg).has_table());
    }
}
