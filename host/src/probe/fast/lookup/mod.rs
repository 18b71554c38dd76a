//! The gated baseband + lookup evaluation of the diagonal: per laser row, one
//! inverse FFT per SPAD turns the band spectrum into a finely sampled, demodulated gated
//! phasor, and every (voxel, SPAD) pair then costs a 4-point interpolation instead of a
//! `J`-term band sum. Any geometry (1-D SPAD lines with a voxel pitch that does not divide
//! the SPAD pitch, tilted walls, point lists), where [`super::Planar`] does not apply.
//!
//! Units: metres of path throughout. For laser row `l`, SPAD `s` and voxel `v`,
//! `τ = d_lv + d_vs` is the hidden path only; the legs `d1_l + d4_s − t0` are folded into
//! the row's band spectra `HG_ls[j]` (`Row::band`, Ks × J) and listed in `Row::offsets`.
//!
//! **Method.** With `k_d = round(k_c)` the band centre (`k_c = NΔt/λ`), `span = NΔt` and a
//! grid length `L ≥ N`, the band is placed at bins `(k_lo + j − k_d) mod L` of a length-`L`
//! spectrum and inverse-transformed (`rustfft`, `f32`):
//!
//! ```text
//! Y_s[n] = Σ_j HG_s[j]·e^{2πi (k_lo + j − k_d) n / L} = e^{−2πi k_d τ_n/span}·Z_s(τ_n),   τ_n = n·span/L
//! Z_s(τ) = e^{2πi k_d n/L} · e^{2πi (k_d/L) t} · Σ_{q=−1..2} ℓ_q(t)·Y_s[n + q],    n + t = τ·L/span
//! ```
//!
//! `Y_s` is the band sum's own `span`-periodic function (no extra wrap-around), demodulated
//! to a smooth envelope of bandwidth `~m/σ`; `ℓ_q` are the 4-point cubic **Lagrange**
//! weights (nodes −1, 0, 1, 2). The carrier `e^{2πi k_d τ/span}` is split at the grid:
//! `e^{2πi k_d n/L}` from a table (exact integer phase `k_d·n mod L`, made once in `f64`)
//! and the sub-sample rest `e^{2πi (k_d/L)·t}` (≤ 1/8 turn) by the kernel's
//! [`vltm_kernel::cis_small_turns`] (the polynomials of [`vltm_kernel::cis_turns`] without its
//! range reduction): no large-argument phase error, no `rint` and no data-dependent quadrant
//! branch per pair. The Lagrange weights are the kernel's [`vltm_kernel::lagrange4`]; the
//! kernel's own lookup path ([`vltm_kernel::LookupProbe`]) is the same method on a
//! power-of-two grid with caller-owned memory, for firmware. The amplitude added to `acc[v]`
//! is `w(d_lv)·Σ_s w(d_vs)·Z_s(d_lv + d_vs)`, summed over the SPADs in `Complex32` and added
//! to the `Complex64` accumulator, as the kernel's band diagonal does. The guard is the
//! kernel's, bit for bit: a pair with `τ + offset_s` (in `f32`) outside [`Config::guard`]
//! adds 0. Distances are the kernel's [`vltm_kernel::geometry::dist`] (`f32`, correctly rounded); the
//! grid position `τ·L/span` is formed in `f64` from the `f32` τ.
//!
//! Each SPAD's table is stored rotated so that its guarded τ range is one contiguous run
//! (no modulo in the inner loop; a rounding step past either end takes a cold wrapping
//! path). The SPADs are processed in blocks of 8 as a structure of arrays: distances,
//! guard, Lagrange weights and the small phase vectorise; the 4-value table reads are
//! scalar.
//!
//! **Grid density.** `L` is the smallest `2^a·3^b·5^c ≥ max(N, R·span/σ, 8·span/λ)` with
//! [`SAMPLES_PER_SIGMA`] `R = 12`, i.e. an oversampling `L/N ≈ max(1, 12Δt/σ)` (3.56 for
//! λ = 0.13 m, Δt = 2.55 cm, σ = 2λ/3; ≈ 1 for λ/Δt ≥ 18). Lagrange's error falls as
//! `(δ/σ)⁴` (`δ = span/L`). Measured worst amplitude error of one SPAD's `Z(τ)` against the
//! `f64` band sum over the whole guard interval, relative to `max |Z|`, on random rows with
//! peaks, λ/Δt ∈ {6, 13, 40} (test `interpolation_error`), by `R`: 6 → 5.1e-5,
//! 8 → 1.6e-5, 10 → 9.1e-6, **12 → 4.4e-6**, 14 → 2.1e-6, 16 → 1.5e-6 (1.5e-6 at
//! σ ≈ 13Δt). Against the kernel's band diagonal (tests `matches_band_diagonal_*`:
//! one row, 16 SPADs × 200 voxels, λ/Δt from 6 to 40, `1/d` and unit weights, legs on and
//! off, 27–63 % of the voxels with some paths outside the guard): intensities within
//! 5.2e-6·max I (the kernel's own `f32` error against the `f64` band sum is up to 3.3e-6 on
//! the same probes), amplitudes within 2.6e-6·max |A| of the `f64` band sum. A 1 cm voxel
//! shift gives 0.25·max I (test `catches_a_one_centimetre_shift`).
//!
//! **Cost per row**: `Ks·5L·log₂L` flops of inverse FFTs (+ `Ks·L` copies), then
//! `Kv·Ks·(E0 + ~16)` (a distance, the guard test, Lagrange weights, 4 real×complex MACs, a
//! table phase and a small phase, one weight), against the band path's `Kv·Ks·(14J + E0)`.
//! Measured (ignored test `timing`, one core of a shared 2-core AMD EPYC VM, 28 SPADs on a
//! line × 4096 voxels, Nt = 254, λ = 0.13 m, Δt = 2.55 cm: N = 288, J = 136, L = 1024):
//! 19–30 ns per (voxel, SPAD) pair against 270–420 ns for the kernel's band diagonal in the
//! same run (13–14× faster; 2.2–3.5 ms per row, of which 0.06 ms are the FFT tables).
//! Parallel callers split the voxels; each worker rebuilds the row's tables (cheap).
//!
//! **Memory**: per worker ([`LookupScratch`], [`LookupDiagonal::scratch_bytes`]) `Ks·(L + 8) + L`
//! complex `f32` (the rotated tables and one FFT buffer), rustfft's scratch and `~40·Ks`
//! bytes of SPAD blocks; the shared [`LookupDiagonal`] holds the FFT plan and the `2L + 8`-entry
//! carrier table. No allocation per row.

use num_complex::{Complex32, Complex64};
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;
use vltm_kernel::geometry::dist;
use vltm_kernel::{Config, Point, Row, Sample, Scan, Weights, cis_small_turns, lagrange4};

/// Grid samples per gate std σ: the grid step is `δ = span/L ≤ σ/R` (see the module docs
/// for the interpolation error this gives).
pub const SAMPLES_PER_SIGMA: f64 = 12.0;

/// Extra table entries past `L` per SPAD (the 4-point stencil reads up to 3 past its start;
/// the rest absorbs rounding at the guard edges before the wrapping fallback is needed).
const EXTRA: usize = 8;

/// The lookup path of the diagonal for one configuration: the precomputed inverse-FFT plan,
/// carrier table and guard; [`LookupDiagonal::apply`] adds one laser row's diagonal
/// amplitudes. (The kernel's [`vltm_kernel::Lookup`] is the tables of the kernel's own lookup
/// path, on caller-owned memory.)
pub struct LookupDiagonal {
    cfg: Config,
    /// Grid length L.
    len: usize,
    /// Position of band bin 0 in the length-L spectrum: `(k_lo − k_d) mod L`.
    first: usize,
    /// Grid samples per metre of τ, `L/span`.
    per_m: f64,
    /// Carrier turns per grid sample, `k_d/L`.
    theta: f32,
    /// `carrier[k] = e^{2πi k_d k/L}`, `2L + EXTRA` entries.
    carrier: Vec<Complex32>,
    /// Guard interval of `τ + offset` in `f32` (the kernel's comparison).
    guard: (f32, f32),
    ifft: Arc<dyn Fft<f32>>,
}

/// Per-worker scratch of [`LookupDiagonal::apply`]: the row's baseband tables (SPAD-major) and the
/// FFT buffers. Resized (not reallocated in steady state) when the SPAD count changes.
#[derive(Clone, Debug)]
pub struct LookupScratch {
    /// One length-L spectrum / signal.
    spec: Vec<Complex32>,
    /// rustfft's scratch.
    fft: Vec<Complex32>,
    /// Per SPAD `L + EXTRA` values, `tab_s[k] = Y_s[(b_s + k) mod L]`.
    tables: Vec<Complex32>,
    /// Per SPAD the table origin `b_s` (an integer, as `f64`) and `b_s mod L`.
    base: Vec<(f64, usize)>,
    /// The row's SPADs in blocks of [`BLOCK`] (padded with never-valid SPADs).
    blocks: Vec<SpadBlock>,
}

/// SPADs per block of the inner loop (structure of arrays, so that the arithmetic per
/// (voxel, SPAD) vectorises; the table reads stay scalar).
const BLOCK: usize = 8;

/// One block of SPADs: positions, leg offsets and table origins.
#[derive(Clone, Copy, Debug)]
struct SpadBlock {
    x: [f32; BLOCK],
    y: [f32; BLOCK],
    z: [f32; BLOCK],
    /// `Row::offsets`; NaN for padding (never inside the guard).
    off: [f32; BLOCK],
    /// Table origin `b_s` as `f64`.
    base: [f64; BLOCK],
}

impl SpadBlock {
    const EMPTY: Self = Self {
        x: [0.0; BLOCK],
        y: [0.0; BLOCK],
        z: [0.0; BLOCK],
        off: [f32::NAN; BLOCK],
        base: [0.0; BLOCK],
    };
}

impl std::fmt::Debug for LookupDiagonal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LookupDiagonal")
            .field("len", &self.len)
            .field("n_fft", &self.cfg.n_fft())
            .field("bins", &self.cfg.bins())
            .finish_non_exhaustive()
    }
}

/// Smallest `2^a·3^b·5^c ≥ n` (a size rustfft transforms with its fast butterflies).
pub(super) fn fast_len(n: usize) -> usize {
    let n = n.max(1);
    let mut best = usize::MAX;
    let mut p5 = 1usize;
    while p5 < 2 * n {
        let mut p35 = p5;
        while p35 < 2 * n {
            let mut p = p35;
            while p < n {
                p *= 2;
            }
            best = best.min(p);
            p35 *= 3;
        }
        p5 *= 5;
    }
    best
}

/// 4-point cubic Lagrange interpolation at `t ∈ [0, 1)` between `q[1]` and `q[2]`.
#[inline(always)]
fn lagrange(q: &[Complex32; 4], t: f32) -> Complex32 {
    let w = lagrange4(t);
    q[0] * w[0] + q[1] * w[1] + q[2] * w[2] + q[3] * w[3]
}

impl LookupDiagonal {
    /// Plans the grid for `cfg` (length `L`, see the module docs).
    pub fn new(cfg: &Config) -> Self {
        Self::with_density(cfg, SAMPLES_PER_SIGMA)
    }

    /// As [`LookupDiagonal::new`] with `r` grid samples per σ instead of [`SAMPLES_PER_SIGMA`].
    fn with_density(cfg: &Config, r: f64) -> Self {
        let len = Self::len_with_density(cfg, r);
        let span = cfg.span();
        let k_d = (span / cfg.wavelength()).round() as i64;
        let first = (cfg.k_lo() - k_d).rem_euclid(len as i64) as usize;
        let (g_lo, g_hi) = cfg.guard();
        let ifft = FftPlanner::<f32>::new().plan_fft_inverse(len);
        let step = k_d.rem_euclid(len as i64) as u64;
        let carrier = (0..2 * len + EXTRA)
            .map(|k| {
                let q = (step * (k % len) as u64) % len as u64;
                let a = std::f64::consts::TAU * q as f64 / len as f64;
                Complex32::new(a.cos() as f32, a.sin() as f32)
            })
            .collect();
        Self {
            cfg: *cfg,
            len,
            first,
            per_m: len as f64 / span,
            theta: (k_d as f64 / len as f64) as f32,
            carrier,
            guard: (g_lo as f32, g_hi as f32),
            ifft,
        }
    }

    /// The grid length `L` of [`LookupDiagonal::new`] for `cfg`, without planning anything (for cost
    /// models and the memory budget).
    pub fn plan_len(cfg: &Config) -> usize {
        Self::len_with_density(cfg, SAMPLES_PER_SIGMA)
    }

    fn len_with_density(cfg: &Config, r: f64) -> usize {
        let n = cfg.n_fft();
        let span = cfg.span();
        let want = (r * span / cfg.sigma()).ceil();
        // δ ≤ σ/r for the interpolation, δ ≤ λ/8 for `cis_small_turns` (|θ·t| ≤ 1/8 turn).
        let want = want.max((8.0 * span / cfg.wavelength()).ceil());
        fast_len(n.max(if want.is_finite() { want as usize } else { n }))
    }

    /// Adds what the lookup path holds to `plan`, before any of it is made: the shared grid
    /// carrier (`2L + 8` complex f32) and inverse-FFT plan (twiddles, counted as `2L` complex
    /// f32), and per worker thread its [`LookupScratch`] for rows of `n_spads` SPADs (`L`
    /// spectrum, `L` FFT scratch, `n_spads·(L + 8)` tables) and `n_voxels` complex f64
    /// accumulators.
    pub fn add_to_plan(
        cfg: &Config,
        n_spads: usize,
        n_voxels: usize,
        threads: usize,
        plan: &mut crate::budget::Plan,
    ) {
        use crate::budget::{bytes, count};
        let len = Self::plan_len(cfg);
        let l = len as u128;
        plan.add(
            format!(
                "the lookup grid's carrier ({} complex f32)",
                count(2 * l + EXTRA as u128)
            ),
            bytes(2 * l + EXTRA as u128, 8),
        )
        .add(
            format!("the lookup grid's FFT plan (L = {})", count(l)),
            bytes(2 * l, 8),
        )
        .add(
            format!(
                "{threads} lookup scratches (one per thread, {} SPADs × L = {})",
                n_spads,
                count(l)
            ),
            bytes(
                threads,
                bytes(n_spads, bytes(len + EXTRA, 8).saturating_add(16))
                    .saturating_add(bytes(len, 16)),
            ),
        )
        .add(
            format!("{threads} accumulators of {n_voxels} voxels (one per thread)"),
            bytes(threads, bytes(n_voxels, 16)),
        );
    }

    /// Grid length `L` (a `2^a·3^b·5^c` size ≥ N).
    pub fn grid_len(&self) -> usize {
        self.len
    }

    /// Oversampling `L/N` of the grid relative to the kernel's DFT length.
    pub fn oversampling(&self) -> f64 {
        self.len as f64 / self.cfg.n_fft() as f64
    }

    /// Bytes of a worker's scratch for `n_spads` SPADs (tables + FFT buffers).
    pub fn scratch_bytes(&self, n_spads: usize) -> usize {
        8 * (n_spads * (self.len + EXTRA) + self.len + self.ifft.get_inplace_scratch_len())
            + 16 * n_spads
            + n_spads.div_ceil(BLOCK) * std::mem::size_of::<SpadBlock>()
    }

    /// A worker's scratch for rows of `n_spads` SPADs.
    pub fn scratch(&self, n_spads: usize) -> LookupScratch {
        let zero = Complex32::new(0.0, 0.0);
        LookupScratch {
            spec: vec![zero; self.len],
            fft: vec![zero; self.ifft.get_inplace_scratch_len()],
            tables: vec![zero; n_spads * (self.len + EXTRA)],
            base: vec![(0.0, 0); n_spads],
            blocks: vec![SpadBlock::EMPTY; n_spads.div_ceil(BLOCK)],
        }
    }

    /// Builds the row's baseband tables: per SPAD one inverse FFT, stored rotated so that
    /// the guarded τ range starts at entry ~2.
    fn tables(
        &self,
        spads: &[Point],
        row_band: &[Complex32],
        offsets: &[f32],
        s: &mut LookupScratch,
    ) {
        let (l, j) = (self.len, self.cfg.bins().max(1));
        let ks = offsets.len();
        s.blocks.clear();
        s.blocks.resize(ks.div_ceil(BLOCK), SpadBlock::EMPTY);
        s.tables.resize(ks * (l + EXTRA), Complex32::new(0.0, 0.0));
        s.base.resize(ks, (0.0, 0));
        s.spec.resize(l, Complex32::new(0.0, 0.0));
        let g_lo = self.guard.0 as f64;
        for (((hg, off), tab), base) in row_band
            .chunks_exact(j)
            .zip(offsets)
            .zip(s.tables.chunks_exact_mut(l + EXTRA))
            .zip(s.base.iter_mut())
        {
            s.spec.fill(Complex32::new(0.0, 0.0));
            let (head, tail) = hg.split_at(hg.len().min(l - self.first));
            s.spec[self.first..self.first + head.len()].copy_from_slice(head);
            s.spec[..tail.len()].copy_from_slice(tail);
            self.ifft.process_with_scratch(&mut s.spec, &mut s.fft);
            // Origin two samples before the guard's lower edge in τ = rel − offset.
            let b = ((g_lo - *off as f64) * self.per_m).floor() - 2.0;
            let b_mod = (b as i64).rem_euclid(l as i64) as usize;
            *base = (b, b_mod);
            let (a, c) = s.spec.split_at(b_mod);
            tab[..c.len()].copy_from_slice(c);
            tab[c.len()..l].copy_from_slice(a);
            let (period, extra) = tab.split_at_mut(l);
            extra.copy_from_slice(&period[..EXTRA]);
        }
        for (i, ((p, off), base)) in spads.iter().zip(offsets).zip(&s.base).enumerate() {
            let b = &mut s.blocks[i / BLOCK];
            let k = i % BLOCK;
            (b.x[k], b.y[k], b.z[k], b.off[k], b.base[k]) = (p[0], p[1], p[2], *off, base.0);
        }
    }

    #[cfg(test)]
    /// `Z_s(τ)` from SPAD `s`'s rotated table `tab` with origin `(b_s, b_s mod L)`.
    #[inline(always)]
    fn gated(&self, tab: &[Complex32], base: (f64, usize), tau: f32) -> Complex32 {
        let x = tau as f64 * self.per_m - base.0;
        // x ≥ 2 inside the guard: truncation is the floor there (and `x ≥ 1` is checked).
        let i = x as i64;
        let start = (i - 1) as usize; // wraps to a huge index for i < 1
        let q = tab.get(start..).and_then(|q| q.first_chunk::<4>());
        match (q, self.carrier.get(base.1.wrapping_add(i as usize))) {
            (Some(q), Some(c)) if x >= 1.0 => {
                let t = (x - i as f64) as f32;
                lagrange(q, t) * (c * cis_small_turns(self.theta * t))
            }
            _ => self.gated_wrapped(tab, base.1, x),
        }
    }

    /// [`LookupDiagonal::gated`] outside the table's contiguous run (rounding at a guard edge):
    /// wraps the grid index explicitly.
    #[cold]
    #[inline(never)]
    fn gated_wrapped(&self, tab: &[Complex32], b_mod: usize, x: f64) -> Complex32 {
        let l = self.len as i64;
        let m = x.floor();
        let k = ((m as i64) - 1).rem_euclid(l) as usize;
        let q = tab[k..]
            .first_chunk::<4>()
            .expect("tables hold L + 8 entries");
        let c = self.carrier[(b_mod as i64 + m as i64).rem_euclid(l) as usize];
        let t = (x - m) as f32;
        lagrange(q, t) * (c * cis_small_turns(self.theta * t))
    }

    /// Adds to `acc[v]` the diagonal amplitude contribution of this row for every voxel:
    /// `Σ_s w(d_lv)·w(d_vs)·Z_ls(d_lv + d_vs)`, Z from the row's band spectra
    /// (`row.band()`, Ks×J, gate weights and legs folded in:
    /// `Z_ls(τ) = Σ_j HG_ls[j]·e^{iν_j τ}` with τ the hidden path only), with the kernel's
    /// guard: paths with `τ + row.offsets()[s]` outside `cfg.guard()` contribute 0.
    ///
    /// Equals the kernel's `Probe` (diagonal, Gaussian gate) `push_row` to the interpolation
    /// error of the module docs. No allocation once `s` has the row's SPAD count.
    ///
    /// # Panics
    /// If `scan` has another configuration than this `LookupDiagonal`, if `row` was loaded for
    /// another SPAD count, or if `acc.len() ≠ voxels.len()`.
    pub fn apply<T: Sample>(
        &self,
        scan: &Scan<'_>,
        row: &Row<'_, T>,
        voxels: &[Point],
        s: &mut LookupScratch,
        acc: &mut [Complex64],
    ) {
        let cfg = scan.config();
        assert!(
            *cfg == self.cfg,
            "LookupDiagonal made for another configuration"
        );
        let spads = scan.spads();
        let ks = spads.len();
        assert_eq!(row.band().len(), ks * cfg.bins(), "row of another scan");
        assert_eq!(row.offsets().len(), ks, "row of another scan");
        assert_eq!(acc.len(), voxels.len(), "one accumulator per voxel");
        self.tables(spads, row.band(), row.offsets(), s);
        let laser = row.laser();
        let (g_lo, g_hi) = self.guard;
        let stride = self.len + EXTRA;
        let inv = matches!(cfg.weights(), Weights::Inv);
        let d_min = cfg.params().d_min as f32;
        let (per_m, theta) = (self.per_m, self.theta);
        // Per block: Lagrange weights × w(d_vs) (0 outside the guard), the small carrier
        // phase, the stencil start and the grid position.
        let mut wq = [[0.0f32; BLOCK]; 4];
        let mut cs = [Complex32::new(0.0, 0.0); BLOCK];
        let mut start = [0i32; BLOCK];
        let mut ok = [false; BLOCK];
        let mut xs = [0.0f64; BLOCK];
        for (a, v) in acc.iter_mut().zip(voxels) {
            let d_lv = dist(&laser, v);
            let mut sum = Complex32::new(0.0, 0.0);
            for (bi, b) in s.blocks.iter().enumerate() {
                // Vectorisable part: no table reads. `d_vs` is the kernel's `dist` written
                // out on the block's arrays (the same operations in the same order, so the
                // same bits): its `libm` square root is one scalar instruction the loop
                // cannot vectorise through.
                for k in 0..BLOCK {
                    let (dx, dy, dz) = (v[0] - b.x[k], v[1] - b.y[k], v[2] - b.z[k]);
                    let d_vs = (dx * dx + dy * dy + dz * dz).sqrt();
                    let tau = d_lv + d_vs;
                    let rel = tau + b.off[k];
                    let inside = rel >= g_lo && rel <= g_hi;
                    let x = tau as f64 * per_m - b.base[k];
                    let i = x as i32;
                    let t = if inside { (x - i as f64) as f32 } else { 0.0 };
                    let w = match (inside, inv) {
                        (false, _) => 0.0,
                        (true, true) => 1.0 / d_vs.max(d_min),
                        (true, false) => 1.0,
                    };
                    let l = lagrange4(t);
                    for (wq, l) in wq.iter_mut().zip(l) {
                        wq[k] = l * w;
                    }
                    cs[k] = cis_small_turns(theta * t);
                    start[k] = i.saturating_sub(1);
                    ok[k] = inside;
                    xs[k] = x;
                }
                // Table reads (scalar).
                let tabs = s.tables.get(bi * BLOCK * stride..).unwrap_or_default();
                for (k, tab) in tabs.chunks_exact(stride).take(BLOCK).enumerate() {
                    if !ok[k] {
                        continue;
                    }
                    let st = start[k] as usize; // huge for start < 0
                    let c_at = s.base[bi * BLOCK + k].1.wrapping_add(st).wrapping_add(1);
                    let w = [wq[0][k], wq[1][k], wq[2][k], wq[3][k]];
                    let q = tab.get(st..).and_then(|q| q.first_chunk::<4>());
                    sum += match (q, self.carrier.get(c_at)) {
                        (Some(q), Some(c)) if start[k] >= 0 => {
                            (q[0] * w[0] + q[1] * w[1] + q[2] * w[2] + q[3] * w[3]) * (c * cs[k])
                        }
                        // Outside the contiguous run (rounding at a guard edge).
                        _ => {
                            let w = cfg.weight(dist(v, &spads[bi * BLOCK + k]));
                            self.gated_wrapped(tab, s.base[bi * BLOCK + k].1, xs[k]) * w
                        }
                    };
                }
            }
            let z = sum * cfg.weight(d_lv);
            *a += Complex64::new(z.re as f64, z.im as f64);
        }
    }
}

#[cfg(test)]
mod tests;
