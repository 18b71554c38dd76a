//! The confocal FFT convolution: direct light of a **confocal** capture (each wall point lit
//! and watched together) on a regular wall grid, over wall-parallel voxel slices.
//!
//! Row `l` of a confocal capture is one histogram with laser and SPAD at the same wall point
//! `x_l`, so the diagonal's hidden path is `τ = 2·|x_l − x_v|` and both lens weights are
//! `w(|x_l − x_v|)`. For a slice at depth z below the wall and band bin j:
//!
//! ```text
//! A(v) = Σ_j Σ_l HG_l[j] · κ_{j,z}(x_v − x_l),   κ_{j,z}(Δ) = w(d)²·e^{iν_j·2d},   d = √(|Δ|² + z²)
//! ```
//!
//! with `HG_l` the row's band spectrum (gate weights, legs and t0 folded in, as
//! `vltm_kernel::Row::band`). The kernel depends on the lateral offset only: per (bin,
//! slice) a 2-D convolution over the wall grid. The sum over j commutes with the
//! transforms, so per slice `A_z = F⁻¹[Σ_j X̂_j · κ̂_{j,z}]`, `X̂_j = F[HG_·[j]]`:
//!
//! * one forward 2-D FFT of the wall image per band bin, shared by every slice
//!   ([`Confocal::forward`]; pruned: the y-pass skips the all-zero padding rows);
//! * per slice, J kernel images, each transformed and multiplied into one accumulator, then
//!   **one** inverse FFT (pruned to the output rows) ([`Confocal::image`]). A kernel image's
//!   phases are `u32` fractions of a turn, `phase0 + j·step` in wrapping arithmetic (exact
//!   modulo a turn up to the seeds' rounding, 2⁻³³ turn each; the same value whichever
//!   thread computes bin j), turned into `e^{iφ}` by `f32` polynomials (error < 1e-7). The
//!   kernel depends on the offset through `|Δ|²`: where the offsets along an axis mirror
//!   about an integer centre (a volume centred on the wall grid, or on a polyphase
//!   sub-grid's own centre, within `1e-6·λ`), the mirrored rows are copied after their
//!   y-pass and the mirrored columns before it, so a centred volume computes and
//!   transforms about half the rows and a quarter of the cells.
//!
//! `κ̂` is never stored: memory does not grow with the number of slices. The padding is as in
//! [`super::planar`] (`Mx × My ≥ (n_w + n_v − 1)` per axis, lengths `2^a·3^b`), as is the
//! polyphase split of voxel grids finer than the wall grid by an integer factor per axis
//! (each phase a sub-grid with its own kernel offsets). Point lists, other pitch ratios and
//! irregular or tilted wall points do not apply ([`Confocal::new`] says why; the caller uses
//! the lookup or band path).
//!
//! Equality with the band sum: the same band sum up to `f32` FFT rounding, **for paths
//! inside the guard interval**: when the rows share one leg offset the guard is applied in the
//! kernel itself (`guard` of [`Confocal::run`]); otherwise the caller evaluates the voxels that
//! have a path outside [`vltm_kernel::Config::guard`] on the band path, as for the planar path.
//! A pass calls [`Confocal::run`] once (the steps are public for benchmarks).
//!
//! Cost: `J·F(M)/2` (forward) `+ S·J·(F(M) + 12M) + S·F(M)/2` flops (S = slices × phases,
//! `F(M) = 5M·log₂M`; an upper bound: mirrored offsets and twins cut the kernel transforms
//! by up to a half and a quarter), against the band path's `Kv·K·(14J + 60)` over K rows.
//! Memory: the spectra `J·M` complex `f32` (shared, [`Confocal::spectra_bytes`]; twice that
//! when a layout has transposed twins, for `X̂ᵀ`), per worker about `5M` complex `f32` (the
//! image, two kernel spectra, the sum and a twin's) and 12 bytes per computed kernel cell,
//! the output.
//!
//! Threads: the bins' forward transforms and the sub-grids in parallel; a few sub-grids are
//! split into runs of bins by a rule of the problem's size only (`IMAGE_TASKS`), each run
//! summed in bin order and the runs added in order, so the image is bit-identical on any
//! number of threads (tested).

use super::lattice::{Layout, SubGrid, layout};
use super::planar::{MAX_TABLE_BYTES, transpose};
use num_complex::{Complex32, Complex64};
use rayon::prelude::*;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;
use vltm_kernel::{Config, Point};

/// Tasks of [`Confocal::image`] over a few sub-grids split into runs of bins, fixed so that
/// the rounding never depends on the threads. Memory: as many partial sums of `M` complex.
const IMAGE_TASKS: usize = 32;

/// Precomputed confocal convolution for one (wall grid, voxel grid, configuration).
pub struct Confocal {
    cfg: Config,
    lay: Layout,
    /// Per sub-grid, the later sub-grid whose kernel is its transpose ([`twins`]).
    twin: Vec<Option<usize>>,
    fy: Arc<dyn Fft<f32>>,
    fx: Arc<dyn Fft<f32>>,
    ix: Arc<dyn Fft<f32>>,
    iy: Arc<dyn Fft<f32>>,
}

impl std::fmt::Debug for Confocal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Confocal")
            .field("bins", &self.cfg.bins())
            .field("mx", &self.lay.mx)
            .field("my", &self.lay.my)
            .field("slices", &self.lay.subgrids.len())
            .finish_non_exhaustive()
    }
}

/// One axis of a slice's kernel image: which image indices (offset index `a ∈ [−(n_w − 1),
/// c − 1]`, stored at `a mod M`) are computed and which are copies of their mirror image.
///
/// The kernel depends on the offset `e = d + a·p` through `e²` only: when the mirror
/// centre `−2d/p` is an integer `m` (within `tol`, m of offset), offsets `a` and `m − a` are
/// the same kernel values. The offset `a` is computed when its mirror `m − a` lies outside
/// the range or is not above `a`; otherwise it is a copy of the mirror's.
#[derive(Debug, Default)]
struct AxisKernel {
    /// Computed image indices (ascending) and their offsets `e` (m).
    computed: Vec<(usize, f64)>,
    /// Copies `(destination, source)` of image indices.
    copies: Vec<(usize, usize)>,
}

impl AxisKernel {
    fn new(n_wall: usize, n_vox: usize, m: usize, d: f64, p: f64, tol: f64) -> Self {
        let (lo, hi) = (-(n_wall as i64 - 1), n_vox as i64 - 1);
        let c2 = if p > 0.0 { -2.0 * d / p } else { f64::NAN };
        let mirror = ((c2 - c2.round()).abs() * p <= tol).then(|| c2.round() as i64);
        let idx = |a: i64| a.rem_euclid(m as i64) as usize;
        let mut k = Self::default();
        for a in lo..=hi {
            match mirror.map(|c| c - a) {
                Some(b) if b > a && b <= hi => k.copies.push((idx(a), idx(b))),
                _ => k.computed.push((idx(a), d + a as f64 * p)),
            }
        }
        k.computed.sort_by_key(|c| c.0);
        k
    }
}

/// One slice's kernel over the `[Mx][My]` image, for every band bin, on the computed rows
/// and columns ([`AxisKernel`]; the mirrored ones are copied): per computed cell the phase
/// `ν_j·2d` at bin 0 and its step per bin as `u32` fractions of a turn (the phase at bin j
/// is `phase0 + j·step` in wrapping arithmetic: exact modulo one turn, up to the rounding of
/// the two seeds, `j·2⁻³³` turn), and the amplitude `w(d)²/M` (0 outside the guard).
struct Table {
    rows: AxisKernel,
    cols: AxisKernel,
    /// The computed columns as runs `(first image column, length)`.
    segments: Vec<(usize, usize)>,
    /// Runs `(first image row, rows)` of computed rows: the y-pass transforms these.
    row_runs: Vec<(usize, usize)>,
    /// Per image row, the row it takes after the y-pass: itself when computed, its mirror
    /// when a copy, the all-zero row `Mx` (past the image) when neither.
    source_row: Vec<u32>,
    /// Runs of columns neither computed nor copied (zero in every computed row).
    zero_cols: Vec<(usize, usize)>,
    phase0: Vec<u32>,
    step: Vec<u32>,
    amp: Vec<f32>,
}

/// One worker's state while it sums `Σ_j X̂_j·κ̂_j` over a run of bins of one slice.
struct BinSum {
    /// The kernel's phase per cell at bin `next`.
    phase: Vec<u32>,
    /// The bin `phase` is at (`usize::MAX`: not seeded).
    next: usize,
    img: Vec<Complex32>,
    /// The kernel spectra of a pair of bins.
    spec: Vec<Complex32>,
    spec2: Vec<Complex32>,
    sum: Vec<Complex32>,
    /// The transposed sum of the slice's twin (empty without one).
    sum_t: Vec<Complex32>,
    fft: Vec<Complex32>,
}

impl BinSum {
    /// Drops everything but the sums (a run's partial sum waiting to be added).
    fn shrink_to_sums(&mut self) {
        for v in [
            &mut self.img,
            &mut self.spec,
            &mut self.spec2,
            &mut self.fft,
        ] {
            *v = Vec::new();
        }
        self.phase = Vec::new();
    }
}

/// Per sub-grid of `lay`, the later sub-grid at the same depth whose kernel is its
/// transpose, `κ_b(a_x, a_y) = κ_a(a_y, a_x)`: a square FFT and wall lattice (`Mx = My`,
/// `n_x = n_y`, pitches equal), the sub-grids' extents swapped and their offsets swapped
/// within `tol` (m) over the widest offset range (the polyphase phases (0, 1) and (1, 0) of
/// a square grid). Such a pair computes one kernel spectrum `K` per bin: `S_a += X̂⊙K` and
/// `S_bᵀ += X̂ᵀ⊙K` ([`Confocal::image`]).
pub(crate) fn twins(lay: &Layout, tol: f64) -> Vec<Option<usize>> {
    let n = lay.subgrids.len();
    let mut twin = vec![None; n];
    if lay.mx != lay.my || lay.nsx != lay.nsy {
        return twin;
    }
    let mut taken = vec![false; n];
    for a in 0..n {
        if taken[a] {
            continue;
        }
        let sa = &lay.subgrids[a];
        let reach = lay.nsx.max(sa.cx).max(sa.cy) as f64;
        let skew = reach * (lay.px - lay.py).abs();
        let b = (a + 1..n).find(|&b| {
            let sb = &lay.subgrids[b];
            !taken[b]
                && sb.dz == sa.dz
                && (sb.cx, sb.cy) == (sa.cy, sa.cx)
                && (sb.dx - sa.dy).abs() + skew <= tol
                && (sb.dy - sa.dx).abs() + skew <= tol
        });
        if let Some(b) = b {
            taken[b] = true;
            twin[a] = Some(b);
        }
    }
    twin
}

/// Ascending indices as runs `(first, length)` of consecutive ones.
fn runs(idx: impl IntoIterator<Item = usize>) -> Vec<(usize, usize)> {
    let mut r: Vec<(usize, usize)> = Vec::new();
    for i in idx {
        match r.last_mut() {
            Some((s, n)) if *s + *n == i => *n += 1,
            _ => r.push((i, 1)),
        }
    }
    r
}

/// `dst[c·R + r] = src[rows[r]·cols + c]` for r < R = `rows.len()`, c < `cols`: a transpose
/// that reads each destination column's values from the listed source rows (tiles of 16
/// rows, each destination run written contiguously, as [`transpose`]).
fn transpose_rows(src: &[Complex32], rows: &[u32], cols: usize, dst: &mut [Complex32]) {
    const B: usize = 16;
    let n = rows.len();
    for r0 in (0..n).step_by(B) {
        let r1 = (r0 + B).min(n);
        let from = &rows[r0..r1];
        for c in 0..cols {
            for (o, &sr) in dst[c * n + r0..c * n + r1].iter_mut().zip(from) {
                *o = src[sr as usize * cols + c];
            }
        }
    }
}

/// A fraction of a turn in `u32` units (2⁻³² turn), rounded, modulo one turn.
fn turns_u32(t: f64) -> u32 {
    let f = t - t.floor();
    (f * 4_294_967_296.0).round() as u64 as u32
}

/// `e^{i2πp/2³²}` in `f32`: the nearest quarter turn from the top bits, the remainder
/// (at most 1/8 turn) by [`vltm_kernel::cis_small_turns`]'s polynomials (error < 1e-7),
/// rotated without a branch (the loops over an image vectorise).
#[inline(always)]
fn cis_u32(p: u32) -> Complex32 {
    let q = p.wrapping_add(1 << 29) >> 30;
    let r = p.wrapping_sub(q << 30) as i32;
    let f = r as f32 * (1.0 / 4_294_967_296.0);
    let Complex32 { re: c, im: s } = vltm_kernel::cis_small_turns(f);
    // Quarter turns: q = 1 → (−s, c), q = 2 → (−c, −s), q = 3 → (s, −c).
    let odd = q & 1 == 1;
    let (a, b) = if odd { (s, c) } else { (c, s) };
    let neg_re = ((q + 1) & 2) << 30;
    let neg_im = (q & 2) << 30;
    Complex32::new(
        f32::from_bits(a.to_bits() ^ neg_re),
        f32::from_bits(b.to_bits() ^ neg_im),
    )
}

impl Confocal {
    /// Prepares the convolution of the confocal wall points `wall` (the capture's laser
    /// spots, row order) onto the voxel grid `voxels` (C order over `shape = [nx, ny, nz]`),
    /// or says why it does not apply. Lattice tolerance `1e-5·λ`.
    ///
    /// # Errors
    /// A one-line reason (irregular wall points, pitch ratio, spectra too large).
    pub fn new(
        cfg: &Config,
        wall: &[Point],
        voxels: &[Point],
        shape: [usize; 3],
    ) -> Result<Self, String> {
        Self::with_layout(cfg, layout(wall, voxels, shape, 1e-5 * cfg.wavelength())?)
    }

    /// [`Confocal::new`] on a layout already made by [`layout`] (the wall points and voxels
    /// it was made of, lattice tolerance `1e-5·λ`).
    ///
    /// # Errors
    /// A one-line reason (spectra too large).
    pub(crate) fn with_layout(cfg: &Config, lay: Layout) -> Result<Self, String> {
        let m = lay.mx * lay.my;
        let twin = twins(&lay, 1e-6 * cfg.wavelength());
        let copies = 1 + usize::from(twin.iter().any(Option::is_some));
        cfg.bins()
            .checked_mul(m)
            .and_then(|x| x.checked_mul(8 * copies))
            .filter(|&b| b <= MAX_TABLE_BYTES)
            .ok_or_else(|| {
                format!(
                    "its wall spectra would exceed {} GiB",
                    MAX_TABLE_BYTES >> 30
                )
            })?;
        let mut planner = FftPlanner::<f32>::new();
        Ok(Self {
            cfg: *cfg,
            twin,
            fy: planner.plan_fft_forward(lay.my),
            fx: planner.plan_fft_forward(lay.mx),
            ix: planner.plan_fft_inverse(lay.mx),
            iy: planner.plan_fft_inverse(lay.my),
            lay,
        })
    }

    /// FFT size `(Mx, My)` and number of (depth, phase) slices.
    pub fn shape(&self) -> (usize, usize, usize) {
        (self.lay.mx, self.lay.my, self.lay.subgrids.len())
    }

    /// Length of the spectra buffer: `J·Mx·My` complex values.
    pub fn spectra_len(&self) -> usize {
        self.cfg.bins() * self.lay.mx * self.lay.my
    }

    /// Bytes of the spectra buffer ([`Confocal::image`] makes as much again for the
    /// transposed spectra when the layout has transposed twins).
    pub fn spectra_bytes(&self) -> usize {
        self.spectra_len() * 8
    }

    /// The whole convolution of a pass over the capture's rows: `fill(start, band)` writes the
    /// folded band spectra `HG` (module docs) of rows `start..start + n` into `band` (`n·J`
    /// values, `n ≤ batch`, rows in order); each is placed at its wall point
    /// ([`Confocal::place`]), then the forward transforms ([`Confocal::forward`]) and the image
    /// ([`Confocal::image`] with `guard`) give `A(v)` of every voxel with `skip[v] == false`
    /// (0 elsewhere). Memory: the spectra ([`Confocal::spectra_bytes`]), one batch of
    /// `batch·J` complex `f32` and the output.
    ///
    /// # Errors
    /// The first error of `fill`, at once.
    pub fn run<E>(
        &self,
        guard: Option<f32>,
        batch: usize,
        skip: &[bool],
        mut fill: impl FnMut(usize, &mut [Complex32]) -> Result<(), E>,
    ) -> Result<Vec<Complex64>, E> {
        let (rows, j_n, batch) = (self.lay.cell.len(), self.cfg.bins(), batch.max(1));
        let mut spectra = self.spectra();
        let mut band = vec![Complex32::new(0.0, 0.0); batch.min(rows) * j_n];
        let rows_t =
            crate::timings::section("rows: read, band spectra", crate::timings::Kind::Parallel);
        for start in (0..rows).step_by(batch) {
            let n = batch.min(rows - start);
            let band = &mut band[..n * j_n];
            fill(start, band)?;
            for (k, hg) in band.chunks_exact(j_n).enumerate() {
                self.place(&mut spectra, start + k, hg);
            }
        }
        drop(rows_t);
        let _t = crate::timings::section("confocal image", crate::timings::Kind::Parallel);
        self.forward(&mut spectra);
        let mut acc = vec![Complex64::new(0.0, 0.0); skip.len()];
        self.image(guard, &spectra, skip, &mut acc);
        Ok(acc)
    }

    /// A zeroed spectra buffer ([`Confocal::spectra_len`]).
    pub fn spectra(&self) -> Vec<Complex32> {
        vec![Complex32::new(0.0, 0.0); self.spectra_len()]
    }

    /// Places row `l`'s band spectrum `hg` (J values, `Row::band`) at its wall point.
    ///
    /// # Panics
    /// If `l` is not a wall point or `hg` is not J long.
    pub fn place(&self, spectra: &mut [Complex32], l: usize, hg: &[Complex32]) {
        let m = self.lay.mx * self.lay.my;
        assert_eq!(hg.len(), self.cfg.bins(), "one band spectrum");
        let cell = self.lay.cell[l];
        for (j, h) in hg.iter().enumerate() {
            spectra[j * m + cell] = *h;
        }
    }

    /// Transforms the placed spectra in place, bins in parallel: `[j][ix][iy]` wall images
    /// become `[j][ky][kx]` spectra.
    pub fn forward(&self, spectra: &mut [Complex32]) {
        let (mx, my) = (self.lay.mx, self.lay.my);
        let m = mx * my;
        let nsx = self.lay.nsx;
        let flen = self
            .fy
            .get_inplace_scratch_len()
            .max(self.fx.get_inplace_scratch_len())
            .max(1);
        spectra.par_chunks_mut(m).for_each_init(
            || {
                (
                    vec![Complex32::new(0.0, 0.0); m],
                    vec![Complex32::new(0.0, 0.0); flen],
                )
            },
            |(t, fft), img| {
                self.fy.process_with_scratch(&mut img[..nsx * my], fft);
                t.fill(Complex32::new(0.0, 0.0));
                transpose(&img[..nsx * my], nsx, my, t, mx);
                self.fx.process_with_scratch(t, fft);
                img.copy_from_slice(t);
            },
        );
    }

    /// Adds `A(v)` (module docs) to `acc[v]` for every voxel with `skip[v] == false`, from
    /// spectra made by [`Confocal::forward`]. Slices and runs of bins in parallel.
    ///
    /// `guard`: the kernel's guard applied in the convolution itself. When every row has the
    /// same leg offset `offset = d1 + d4 − t0` (always so for wall-to-wall time axes), whether
    /// a path is inside [`Config::guard`] depends on its offset `x_v − x_l` only, so `κ` is
    /// set to 0 where `2d + offset` (in `f32`, the kernel's comparison) is outside and no
    /// voxel needs the band path. With `None`, the caller evaluates the voxels with a path
    /// outside the guard otherwise.
    ///
    /// # Panics
    /// If `spectra` is not [`Confocal::spectra_len`] long.
    pub fn image(
        &self,
        guard: Option<f32>,
        spectra: &[Complex32],
        skip: &[bool],
        acc: &mut [Complex64],
    ) {
        assert_eq!(spectra.len(), self.spectra_len(), "spectra");
        let bins = self.cfg.bins();
        let (mx, my) = (self.lay.mx, self.lay.my);
        let m = mx * my;
        // The transposed spectra `X̂ᵀ`, for the sub-grids with a twin.
        let twins = self.twin.iter().any(Option::is_some);
        let mut spectra_t = Vec::new();
        if twins {
            spectra_t = vec![Complex32::new(0.0, 0.0); spectra.len()];
            spectra_t
                .par_chunks_mut(m)
                .zip(spectra.par_chunks(m))
                .for_each(|(t, x)| transpose(x, my, mx, t, my));
        }
        let is_twin: Vec<bool> = {
            let mut v = vec![false; self.twin.len()];
            for b in self.twin.iter().flatten() {
                v[*b] = true;
            }
            v
        };
        let jobs: Vec<usize> = (0..self.lay.subgrids.len())
            .filter(|&i| !is_twin[i])
            .collect();
        // Runs of bins per sub-grid: about IMAGE_TASKS tasks in all (at least 8 pairs of
        // bins each), else one run per sub-grid with its worker state reused from one
        // sub-grid to the next. The split depends on the problem only, never on the number of
        // threads: each run's sum is made in bin order and the runs are added in order, so the
        // image is the same on any number of threads.
        let runs = IMAGE_TASKS
            .div_ceil(jobs.len().max(1))
            .min(bins.div_ceil(16))
            .max(1);
        // Bins go two at a time (one pass over the sums per pair).
        let pairs = bins.div_ceil(2);
        let per = pairs.div_ceil(runs);
        // Sub-grid i, its twin, the twin's transposed spectra and the kernel table.
        let job = |i: usize| {
            let sg = &self.lay.subgrids[i];
            let twin = self.twin[i].map(|t| &self.lay.subgrids[t]);
            (
                sg,
                twin,
                twin.map(|_| &spectra_t[..]),
                self.table(sg, guard),
            )
        };
        let parts: Vec<Vec<(u32, Complex64)>> = if runs == 1 {
            jobs.par_iter()
                .map_init(
                    || self.bin_sum(0, false),
                    |b, &i| {
                        let (sg, twin, xt, table) = job(i);
                        self.reset(b, &table, twin.is_some());
                        for p in 0..pairs {
                            self.add_pair(&table, spectra, xt, p, b);
                        }
                        self.finish(b, sg, twin, skip)
                    },
                )
                .collect()
        } else {
            jobs.par_iter()
                .map(|&i| {
                    let (sg, twin, xt, table) = job(i);
                    let cells = table.step.len();
                    let parts: Vec<BinSum> = (0..runs)
                        .into_par_iter()
                        .map(|r| {
                            let mut b = self.bin_sum(cells, twin.is_some());
                            for p in r * per..((r + 1) * per).min(pairs) {
                                self.add_pair(&table, spectra, xt, p, &mut b);
                            }
                            // Only the sums travel on (the scratch is dropped here).
                            b.shrink_to_sums();
                            b
                        })
                        .collect();
                    let sum = parts.into_iter().reduce(|mut a, b| {
                        a.sum.iter_mut().zip(&b.sum).for_each(|(x, y)| *x += y);
                        a.sum_t.iter_mut().zip(&b.sum_t).for_each(|(x, y)| *x += y);
                        a
                    });
                    sum.map_or_else(Vec::new, |b| {
                        let mut b = self.with_scratch(b, twin.is_some());
                        self.finish(&mut b, sg, twin, skip)
                    })
                })
                .collect()
        };
        for (v, a) in parts.into_iter().flatten() {
            acc[v as usize] += a;
        }
    }

    /// A worker's state for a table of `cells` computed cells (with a twin's sum or not).
    fn bin_sum(&self, cells: usize, twin: bool) -> BinSum {
        let m = self.lay.mx * self.lay.my;
        let flen = [&self.fy, &self.fx, &self.ix, &self.iy]
            .iter()
            .map(|f| f.get_inplace_scratch_len())
            .max()
            .unwrap_or(0)
            .max(1);
        let zero = Complex32::new(0.0, 0.0);
        BinSum {
            phase: vec![0; cells],
            next: usize::MAX,
            img: vec![zero; m + self.lay.my],
            spec: vec![zero; m],
            spec2: vec![zero; m],
            sum: vec![zero; m],
            sum_t: if twin { vec![zero; m] } else { Vec::new() },
            fft: vec![zero; flen],
        }
    }

    /// `b`'s sums with fresh scratch buffers (as [`Self::bin_sum`] makes them) for
    /// [`Self::finish`].
    fn with_scratch(&self, b: BinSum, twin: bool) -> BinSum {
        BinSum {
            sum: b.sum,
            sum_t: b.sum_t,
            ..self.bin_sum(0, twin)
        }
    }

    /// Makes a used worker state ready for `table` (and a twin or not), as
    /// [`Self::bin_sum`] would.
    fn reset(&self, b: &mut BinSum, table: &Table, twin: bool) {
        let zero = Complex32::new(0.0, 0.0);
        let m = self.lay.mx * self.lay.my;
        b.next = usize::MAX;
        b.phase.resize(table.step.len(), 0);
        // Rows not computed are never read (the transpose reads the zero row past the
        // image for them): only that row must be zero.
        b.img[m..].fill(zero);
        b.sum.fill(zero);
        b.sum_t.clear();
        if twin {
            b.sum_t.resize(m, zero);
        }
    }

    /// The voxels of sub-grid `sg` (and of its twin) from a state that summed every bin.
    fn finish(
        &self,
        b: &mut BinSum,
        sg: &SubGrid,
        twin: Option<&SubGrid>,
        skip: &[bool],
    ) -> Vec<(u32, Complex64)> {
        let (mx, my) = (self.lay.mx, self.lay.my);
        let mut out = self.inverse(sg, &mut b.sum, &mut b.fft, skip);
        if let Some(tw) = twin {
            // `S_b = (S_bᵀ)ᵀ`, into the spent image buffer (zeroed again by `reset`).
            transpose(&b.sum_t, my, mx, &mut b.img[..mx * my], my);
            out.extend(self.inverse(tw, &mut b.img[..mx * my], &mut b.fft, skip));
        }
        out
    }

    /// The kernel table of slice `sg` ([`Table`]): `w(d)²/M·e^{iν_j 2d}` per computed cell.
    /// Mirrored offsets are copies when the mirror centre is an integer within `1e-6·λ`
    /// (a tenth of the lattice tolerance of [`layout`]). With `guard` (the rows' common leg
    /// offset, [`Confocal::image`]) the cells whose path leaves the guard are 0.
    fn table(&self, sg: &SubGrid, guard: Option<f32>) -> Table {
        let (mx, my) = (self.lay.mx, self.lay.my);
        let tol = 1e-6 * self.cfg.wavelength();
        let rows = AxisKernel::new(self.lay.nsx, sg.cx, mx, sg.dx, self.lay.px, tol);
        let cols = AxisKernel::new(self.lay.nsy, sg.cy, my, sg.dy, self.lay.py, tol);
        let segments = runs(cols.computed.iter().map(|c| c.0));
        let row_runs = runs(rows.computed.iter().map(|c| c.0));
        let mut source_row: Vec<u32> = vec![mx as u32; mx];
        for &(r, _) in &rows.computed {
            source_row[r] = r as u32;
        }
        for &(dst, src) in &rows.copies {
            source_row[dst] = src as u32;
        }
        let mut used = vec![false; my];
        for c in cols
            .computed
            .iter()
            .map(|c| c.0)
            .chain(cols.copies.iter().map(|c| c.0))
        {
            used[c] = true;
        }
        let zero_cols = runs((0..my).filter(|&c| !used[c]));
        let span = self.cfg.span();
        let scale = 1.0 / (mx * my) as f64;
        let k0 = self.cfg.k_lo() as f64;
        let (g_lo, g_hi) = self.cfg.guard();
        let inside = |d: f64| {
            guard.is_none_or(|off| {
                let d = d as f32;
                let rel = d + d + off;
                rel >= g_lo as f32 && rel <= g_hi as f32
            })
        };
        let n = rows.computed.len() * cols.computed.len();
        let mut t = Table {
            phase0: Vec::with_capacity(n),
            step: Vec::with_capacity(n),
            amp: Vec::with_capacity(n),
            rows,
            cols,
            segments,
            row_runs,
            source_row,
            zero_cols,
        };
        for &(_, ex) in &t.rows.computed {
            for &(_, ey) in &t.cols.computed {
                let d = (ex * ex + ey * ey + sg.dz * sg.dz).sqrt();
                let w = self.cfg.weight(d as f32) as f64;
                let per_k = 2.0 * d / span;
                t.phase0.push(turns_u32(k0 * per_k));
                t.step.push(turns_u32(per_k));
                t.amp.push(if inside(d) {
                    (w * w * scale) as f32
                } else {
                    0.0
                });
            }
        }
        t
    }

    /// `sum += Σ_j X̂_j · κ̂_{j,z}` over the pair of bins `j = 2·pair, 2·pair + 1` (the second
    /// when there is one) for the slice of `table` (and `sum_t += Σ_j X̂ᵀ_j · κ̂_{j,z}` for
    /// its twin): one pass over the sums.
    fn add_pair(
        &self,
        table: &Table,
        spectra: &[Complex32],
        spectra_t: Option<&[Complex32]>,
        pair: usize,
        b: &mut BinSum,
    ) {
        let m = self.lay.mx * self.lay.my;
        let j = 2 * pair;
        let two = j + 1 < self.cfg.bins();
        let mut spec = std::mem::take(&mut b.spec);
        self.kernel(table, j, b, &mut spec);
        let mut spec2 = std::mem::take(&mut b.spec2);
        // A lone bin (the last of an odd run) pairs with itself under a zero kernel.
        let j2 = if two {
            self.kernel(table, j + 1, b, &mut spec2);
            j + 1
        } else {
            spec2.fill(Complex32::new(0.0, 0.0));
            j
        };
        let x = &spectra[j * m..(j + 1) * m];
        let x2 = &spectra[j2 * m..(j2 + 1) * m];
        match spectra_t {
            None => {
                for ((((s, x), k), x2), k2) in
                    b.sum.iter_mut().zip(x).zip(&spec).zip(x2).zip(&spec2)
                {
                    *s += x * k + x2 * k2;
                }
            }
            Some(t) => {
                let xt = &t[j * m..(j + 1) * m];
                let xt2 = &t[j2 * m..(j2 + 1) * m];
                for (((((((s, st), x), xt), k), x2), xt2), k2) in b
                    .sum
                    .iter_mut()
                    .zip(b.sum_t.iter_mut())
                    .zip(x)
                    .zip(xt)
                    .zip(&spec)
                    .zip(x2)
                    .zip(xt2)
                    .zip(&spec2)
                {
                    *s += x * k + x2 * k2;
                    *st += xt * k + xt2 * k2;
                }
            }
        }
        b.spec = spec;
        b.spec2 = spec2;
    }

    /// The kernel spectrum `κ̂_{j,z}` of the slice of `table` at bin `j` into `spec`
    /// (`[ky][kx]`), the phases of `b` stepped to bin `j + 1`.
    fn kernel(&self, table: &Table, j: usize, b: &mut BinSum, spec: &mut [Complex32]) {
        let my = self.lay.my;
        if b.next != j {
            let jj = j as u32;
            for ((p, &p0), &st) in b.phase.iter_mut().zip(&table.phase0).zip(&table.step) {
                *p = p0.wrapping_add(st.wrapping_mul(jj));
            }
        }
        // The computed rows: their gap columns zeroed, their computed columns, then the
        // mirrored columns; then the y-pass over each run of computed rows. The mirrored and
        // the all-zero rows are read from their source by the transpose.
        let per_row = table.cols.computed.len();
        for (r, &(row, _)) in table.rows.computed.iter().enumerate() {
            let img = &mut b.img[row * my..(row + 1) * my];
            for &(c0, len) in &table.zero_cols {
                img[c0..c0 + len].fill(Complex32::new(0.0, 0.0));
            }
            let mut k = r * per_row;
            for &(c0, len) in &table.segments {
                for (((o, p), &st), &a) in img[c0..c0 + len]
                    .iter_mut()
                    .zip(&mut b.phase[k..k + len])
                    .zip(&table.step[k..k + len])
                    .zip(&table.amp[k..k + len])
                {
                    *o = cis_u32(*p) * a;
                    *p = p.wrapping_add(st);
                }
                k += len;
            }
            for &(dst, src) in &table.cols.copies {
                img[dst] = img[src];
            }
        }
        b.next = j + 1;
        for &(r0, n) in &table.row_runs {
            self.fy
                .process_with_scratch(&mut b.img[r0 * my..(r0 + n) * my], &mut b.fft);
        }
        // Transposed from each row's source (the mirrored rows read their mirror).
        transpose_rows(&b.img, &table.source_row, my, spec);
        self.fx.process_with_scratch(spec, &mut b.fft);
    }

    /// The inverse transform of one slice's sum and its voxels' amplitudes.
    fn inverse(
        &self,
        sg: &SubGrid,
        sum: &mut [Complex32],
        fft: &mut [Complex32],
        skip: &[bool],
    ) -> Vec<(u32, Complex64)> {
        let (mx, my) = (self.lay.mx, self.lay.my);
        let rows = self.lay.rows_out;
        if sum.is_empty() {
            return Vec::new();
        }
        self.ix.process_with_scratch(sum, fft);
        let mut out = vec![Complex32::new(0.0, 0.0); rows * my];
        for r in 0..my {
            for c in 0..rows {
                out[c * my + r] = sum[r * mx + c];
            }
        }
        self.iy.process_with_scratch(&mut out, fft);
        sg.outputs
            .iter()
            .filter(|(_, v)| !skip.get(*v as usize).copied().unwrap_or(true))
            .map(|&(cell, v)| {
                let a = out[cell as usize];
                (v, Complex64::new(a.re as f64, a.im as f64))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests;
