//! The planar FFT convolution: for a regular SPAD grid on the wall and voxel
//! slices parallel to it, the camera leg of every voxel of a slice is one 2-D convolution.
//!
//! For band bin j, slice depth z and a laser row (or a factorised column's spectra `U_a`):
//!
//! ```text
//! C_j(v) = Σ_s HG_s[j] · κ_{j,z}(x_v − x_s),   κ_{j,z}(Δ) = w(d) e^{iν_j d},  d = √(|Δ|² + z²)
//! A(v)  += w_leg(v) · Σ_j e^{iν_j d_leg(v)} · C_j(v)
//! ```
//!
//! with `d_leg = |x_l − x_v|` (diagonal, per row) or `|x_a − x_b|` and `w_leg = 1` (the
//! end of a factorised column). The convolution is zero-padded to `Mx × My ≥
//! (nsx + nvx − 1) × (nsy + nvy − 1)` (lengths `2^a·3^b`): one forward 2-D FFT of the SPAD image per
//! bin (shared by all slices), then per (slice, bin) a pointwise product with the
//! precomputed `κ̂` and one inverse 2-D FFT. Both transforms are pruned: the forward pass
//! skips the all-zero rows of the padded SPAD image, the inverse pass computes only the
//! output rows that hold voxels. Transforms are `rustfft` (AVX), `f32`; the inverse pass goes
//! bin by bin in buffers that stay in L1, its product, transpose, per-voxel sums and the
//! voxels' leg phases in AVX lanes (`fast::lanes`; bit-identical to the portable loops, which
//! [`Planar::set_portable`] forces).
//!
//! **Voxel pitch.** Voxels finer than the SPADs by an integer factor `r` per axis (`p_s =
//! r·p_v`, e.g. a 32×32 slice over a 16×16 SPAD grid) are split into `r_x·r_y` polyphase
//! sub-grids, each on the SPAD lattice with its own sub-pitch offset and its own `κ̂`; a
//! 1-D SPAD line is the `nsy = 1` case. Other pitch ratios, tilted or non-planar SPAD sets
//! and point-list volumes are not planar: [`Planar::new`] says why and the caller uses the
//! band or lookup path.
//!
//! Equality with the band sum: exact up to `f32` FFT rounding (≈ 1e-6 of the largest
//! term), **for paths inside the guard interval**. The band path zeroes each (laser, SPAD)
//! path outside [`vltm_kernel::Config::guard`]; a convolution cannot, so the caller
//! evaluates the few voxels that have such paths on the band path (see `ltm`).
//!
//! Cost per row `J·[F(M)·(nsx/Mx + 1) + S·(6M + F(M)·(1 + nvx/Mx))] + Kv·(8J + 40)` flops
//! (S = slices × phases, F(M) = 2.5·M·log₂M per pruned half), against the band path's
//! `Kv·Ks·(14J + 60)`. Memory: `κ̂` = S·J·M complex `f32` (shared, read-only) and per worker
//! `J·M` complex scratch and one bin's buffers.
//!
//! Threads: [`Planar::new`] builds `κ̂` on the thread pool, one (slice, bin) table per task;
//! [`Planar::apply`] runs on the caller's thread (the probes call it once per row, rows in
//! parallel), and [`Planar::apply_parallel`] (an image made once: a factorised column's) runs
//! the slices in parallel. Every value is computed by the same operations whatever the
//! number of threads: the results are bit-identical.

pub(super) use super::lanes::transpose;
use super::lanes::{Lanes, Portable};
use super::lattice::{Layout, layout};
use num_complex::{Complex32, Complex64};
use rayon::prelude::*;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;
use vltm_kernel::{Config, Point};

/// Largest `κ̂` table accepted (bytes); larger problems are not planar.
pub const MAX_TABLE_BYTES: usize = 2 << 30;

/// One (depth, phase) slice: its `κ̂` and where its voxels sit in the inverse transform.
#[derive(Clone, Debug)]
struct Slice {
    /// (cell `i'x·My + i'y` of the output image, voxel index), rows of `cy` along y.
    outputs: Vec<(u32, u32)>,
    cy: usize,
}

/// Precomputed planar convolution for one (SPAD grid, voxel grid, configuration).
pub struct Planar {
    bins: usize,
    mx: usize,
    my: usize,
    nsx: usize,
    /// Output rows (i'x) the inverse y-pass must compute.
    rows_out: usize,
    /// Cell of each SPAD in the `[Mx][My]` image.
    spad_cell: Vec<usize>,
    slices: Vec<Slice>,
    /// `κ̂[slice][j][ky][kx]` (transposed spectrum layout), scaled by 1/(Mx·My).
    khat: Vec<[f32; 2]>,
    klo_per_span: f32,
    inv_span: f32,
    fy: Arc<dyn Fft<f32>>,
    fx: Arc<dyn Fft<f32>>,
    ix: Arc<dyn Fft<f32>>,
    iy: Arc<dyn Fft<f32>>,
    /// The portable loops instead of the dispatched ones ([`Planar::set_portable`]).
    portable: bool,
    /// Lengths of a worker's [`Work`] buffers (`Planar::measure_work`).
    work_lens: [usize; 4],
}

/// Per-worker scratch of [`Planar::apply`]: the transformed spectrum and one bin's work.
/// [`Scratch::default`] holds nothing; [`Planar::apply`] sizes it on a worker's first row.
#[derive(Default)]
pub struct Scratch {
    /// `X̂` of the row, `[j][ky][kx]` (`J·M`).
    x: Vec<Complex32>,
    /// `None` until the first [`Planar::apply`].
    work: Option<Work>,
}

/// One bin's buffers of the inverse pass (they stay in L1) and a slice's per-voxel sums.
struct Work {
    /// `X̂_j·κ̂_j`, then its inverse transform along x (`M`).
    y: Vec<Complex32>,
    /// The output rows `[ix][ky]`, then `[ix][iy]` (`rows_out·My`).
    z: Vec<Complex32>,
    fft: Vec<Complex32>,
    /// Per output of a slice: the leg's phase `e^{iν_j d}` (advanced bin by bin), its step
    /// `e^{iΔν d}` and the sum over bins.
    p: Vec<Complex32>,
    step: Vec<Complex32>,
    sum: Vec<Complex32>,
    /// Per output: the leg's weight `w_leg` and length `d_leg` (m).
    wt: Vec<f32>,
    d: Vec<f32>,
}

impl std::fmt::Debug for Planar {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Planar")
            .field("bins", &self.bins)
            .field("mx", &self.mx)
            .field("my", &self.my)
            .field("slices", &self.slices.len())
            .finish_non_exhaustive()
    }
}

impl Planar {
    /// Prepares the convolution of `spads` onto the voxel grid `voxels` (C order over
    /// `shape = [nx, ny, nz]`, as [`crate::volume::Volume`]), or says why it does not apply.
    /// Lattice tolerance: `1e-5·λ` (a phase error ≤ 6e-5 rad).
    ///
    /// # Errors
    /// A one-line reason (irregular SPADs, pitch ratio, table too large).
    pub fn new(
        cfg: &Config,
        spads: &[Point],
        voxels: &[Point],
        shape: [usize; 3],
    ) -> Result<Self, String> {
        Self::with_layout(cfg, layout(spads, voxels, shape, 1e-5 * cfg.wavelength())?)
    }

    /// [`Planar::new`] on a layout the planner already made ([`super::lattice::layout`] of
    /// the SPADs and the voxel grid, lattice tolerance `1e-5·λ`).
    ///
    /// # Errors
    /// A one-line reason (table too large).
    pub(crate) fn with_layout(cfg: &Config, lay: Layout) -> Result<Self, String> {
        let (mx, my) = (lay.mx, lay.my);
        let m = mx * my;
        let bins = cfg.bins();
        let n_slices = lay.subgrids.len();
        n_slices
            .checked_mul(bins)
            .and_then(|x| x.checked_mul(m))
            .and_then(|x| x.checked_mul(8))
            .filter(|&b| b <= MAX_TABLE_BYTES)
            .ok_or_else(|| {
                format!(
                    "its kernel table would exceed {} GiB",
                    MAX_TABLE_BYTES >> 30
                )
            })?;
        let mut planner = FftPlanner::<f32>::new();
        let fy = planner.plan_fft_forward(my);
        let fx = planner.plan_fft_forward(mx);
        let ix = planner.plan_fft_inverse(mx);
        let iy = planner.plan_fft_inverse(my);
        let span = cfg.span();
        let scale = 1.0 / m as f64;
        // `[f32; 2]` zeros: allocated zeroed by the system (pages mapped as the threads below
        // write them), where a `Complex32` fill would be one serial pass over the table.
        let mut khat = vec![[0.0f32; 2]; n_slices * bins * m];
        let specs: Vec<_> = lay
            .subgrids
            .iter()
            .map(|s| (s.dz, s.dx, s.dy, s.cx, s.cy))
            .collect();
        let slices = lay
            .subgrids
            .into_iter()
            .map(|s| Slice {
                outputs: s.outputs,
                cy: s.cy,
            })
            .collect();
        let spad_cell = lay.cell;
        let (nsx, nsy) = (lay.nsx, lay.nsy);
        let (px, py) = (lay.px, lay.py);
        // One FFT table per (slice, bin), each its own chunk of `khat`: built in parallel (one
        // image and scratch per thread), every chunk by the same operations as on one thread.
        let scratch_len = fy
            .get_inplace_scratch_len()
            .max(fx.get_inplace_scratch_len());
        let _t = crate::timings::section("planar tables", crate::timings::Kind::Parallel);
        let table: &mut [Complex32] = bytemuck::cast_slice_mut(&mut khat);
        table.par_chunks_mut(m).enumerate().for_each_init(
            || {
                (
                    vec![Complex32::new(0.0, 0.0); m],
                    vec![Complex32::new(0.0, 0.0); scratch_len],
                )
            },
            |(img, scratch), (i, out)| {
                let (dz, dx, dy, cx, cy) = specs[i / bins];
                let j = i % bins;
                img.fill(Complex32::new(0.0, 0.0));
                let k = (cfg.k_lo() + j as i64) as f64;
                let (x0, x1) = (-(nsx as i64 - 1), cx as i64);
                let (y0, y1) = (-(nsy as i64 - 1), cy as i64);
                // A sub-grid on the lattice (offsets 0) has a mirror-symmetric kernel: each
                // value made once for (|Δx|, |Δy|) (the same operations give the same bits).
                let sym = dx == 0.0 && dy == 0.0;
                let (ax0, ay0, ax1, ay1) = if sym {
                    (0, 0, (-x0).max(x1 - 1) + 1, (-y0).max(y1 - 1) + 1)
                } else {
                    (x0, y0, x1, y1)
                };
                for ax in ax0..ax1 {
                    for ay in ay0..ay1 {
                        let ex = dx + ax as f64 * px;
                        let ey = dy + ay as f64 * py;
                        let d = (ex * ex + ey * ey + dz * dz).sqrt();
                        let turns = k * d / span;
                        let a = std::f64::consts::TAU * (turns - turns.round());
                        let w = cfg.weight(d as f32) as f64 * scale;
                        let v = Complex32::new((w * a.cos()) as f32, (w * a.sin()) as f32);
                        let m = |a: i64| if sym { [a, -a] } else { [a, a] };
                        for bx in m(ax).into_iter().filter(|b| (x0..x1).contains(b)) {
                            for by in m(ay).into_iter().filter(|b| (y0..y1).contains(b)) {
                                let cx_ = bx.rem_euclid(mx as i64) as usize;
                                let cy_ = by.rem_euclid(my as i64) as usize;
                                img[cx_ * my + cy_] = v;
                            }
                        }
                    }
                }
                fy.process_with_scratch(img, scratch);
                transpose(img, mx, my, out, mx);
                fx.process_with_scratch(out, scratch);
            },
        );
        drop(_t);
        let rows_out = lay.rows_out;
        Ok(Self {
            bins,
            mx,
            my,
            nsx,
            rows_out,
            spad_cell,
            slices,
            khat,
            klo_per_span: (cfg.k_lo() as f64 / span) as f32,
            inv_span: (1.0 / span) as f32,
            fy,
            fx,
            ix,
            iy,
            portable: false,
            work_lens: [0; 4],
        }
        .with_work_lens())
    }

    /// `self` with its [`Work`] lengths recorded.
    fn with_work_lens(mut self) -> Self {
        self.work_lens = self.measure_work();
        self
    }

    /// FFT size `(Mx, My)` and number of (depth, phase) slices.
    pub fn shape(&self) -> (usize, usize, usize) {
        (self.mx, self.my, self.slices.len())
    }

    /// Bytes of the shared `κ̂` table.
    pub fn table_bytes(&self) -> usize {
        self.khat.len() * 8
    }

    /// The transformed spectrum of one row (`J·M` complex, zeroed).
    fn spectrum(&self) -> Vec<Complex32> {
        vec![Complex32::new(0.0, 0.0); self.bins * self.mx * self.my]
    }

    /// Lengths of [`Work`]'s buffers: `y`, `z`, `fft` and the per-output ones.
    fn measure_work(&self) -> [usize; 4] {
        let f = [&self.fy, &self.fx, &self.ix, &self.iy]
            .iter()
            .map(|f| f.get_inplace_scratch_len())
            .max()
            .unwrap_or(0);
        let n = self
            .slices
            .iter()
            .map(|s| s.outputs.len())
            .max()
            .unwrap_or(0);
        [self.mx * self.my, self.rows_out * self.my, f.max(1), n]
    }

    /// Whether `s` is sized for this convolution.
    fn fits(&self, s: &Scratch) -> bool {
        s.x.len() == self.bins * self.mx * self.my
            && s.work
                .as_ref()
                .is_some_and(|w| [w.y.len(), w.z.len(), w.fft.len(), w.p.len()] == self.work_lens)
    }

    /// One bin's buffers and a slice's per-voxel sums (see [`Work`]).
    fn work(&self) -> Work {
        let [y, z, f, n] = self.work_lens;
        let zero = Complex32::new(0.0, 0.0);
        let v = || vec![zero; n];
        Work {
            y: vec![zero; y],
            z: vec![zero; z],
            fft: vec![zero; f],
            p: v(),
            step: v(),
            sum: v(),
            wt: vec![0.0f32; n],
            d: vec![0.0f32; n],
        }
    }

    /// Forces the portable loops (no runtime dispatch to the CPU's vector extensions); the
    /// results are bit-identical either way (tested).
    pub fn set_portable(&mut self, portable: bool) {
        self.portable = portable;
    }

    /// The forward transforms of one spectrum: per bin the SPAD image, its FFT along y (the
    /// non-zero rows only), a transpose, then along x, into `x` (`J·M`).
    fn forward(&self, spectra: &[Complex32], x: &mut [Complex32], w: &mut Work) {
        let (mx, my, j_n) = (self.mx, self.my, self.bins);
        let m = mx * my;
        let img = &mut w.y[..self.nsx * my];
        for j in 0..j_n {
            img.fill(Complex32::new(0.0, 0.0));
            for (cell, h) in self
                .spad_cell
                .iter()
                .zip(spectra.iter().skip(j).step_by(j_n))
            {
                img[*cell] = *h;
            }
            self.fy.process_with_scratch(img, &mut w.fft);
            let xt = &mut x[j * m..(j + 1) * m];
            xt.fill(Complex32::new(0.0, 0.0));
            transpose(img, self.nsx, my, xt, mx);
        }
        self.fx.process_with_scratch(x, &mut w.fft);
    }

    /// Slice `si` of the transformed spectrum `x` (from [`Self::forward`]), bin by bin in
    /// `w`'s buffers: the product with its `κ̂`, the inverse transforms (the output rows only)
    /// and each voxel's leg phase times the bin's value added to the voxel's sum; then every
    /// voxel of the slice with `skip[v] == false` handed to `emit(v, term)` in the slice's
    /// output order. The loops run under [`pulp`]'s dispatch (or portable).
    #[allow(clippy::too_many_arguments)]
    fn slice_terms(
        &self,
        si: usize,
        x: &[Complex32],
        w: &mut Work,
        voxels: &[Point],
        leg: &impl Fn(&Point) -> (f32, f32),
        skip: &[bool],
        emit: impl FnMut(usize, Complex64),
    ) {
        let op = SliceOp {
            p: self,
            si,
            x,
            w,
            voxels,
            leg,
            skip,
            emit,
        };
        if self.portable {
            return op.run(Portable);
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(v3) = pulp::x86::V3::try_new() {
            return v3.vectorize(|| op.run(super::lanes::Avx(v3)));
        }
        pulp::Arch::new().dispatch(op);
    }

    /// Adds `w_leg(v)·Σ_j e^{iν_j d_leg(v)}·Σ_s spectra[s·J + j]·κ_j(x_v − x_s)` to `acc[v]`
    /// for every voxel with `skip[v] == false` (see the module docs); `leg(v)` returns
    /// `(d_leg, w_leg)`. `spectra` is Ks·J (the kernel's `Row::band` or a column's `U_a`).
    pub fn apply(
        &self,
        spectra: &[Complex32],
        voxels: &[Point],
        leg: impl Fn(&Point) -> (f32, f32),
        skip: &[bool],
        s: &mut Scratch,
        acc: &mut [Complex64],
    ) {
        // A worker's first row sizes its scratch (one sized for another `Planar` is remade).
        if !self.fits(s) {
            *s = Scratch {
                x: self.spectrum(),
                work: Some(self.work()),
            };
        }
        let Scratch { x, work } = s;
        let Some(work) = work else { return };
        self.forward(spectra, x, work);
        for si in 0..self.slices.len() {
            self.slice_terms(si, x, work, voxels, &leg, skip, |v, t| acc[v] += t);
        }
    }

    /// [`Planar::apply`] of one spectrum with the slices in parallel, for an image made once
    /// (a factorised column's): the forward transforms as there, then each slice on a pool
    /// thread (its own scratch) into a list of `(voxel, term)`, and the lists added to `acc`
    /// in slice order, so that `acc` is bit-identical to [`Planar::apply`]'s (the same
    /// operations on every value, in the same order; checked by a test). Memory: `J·M`
    /// complex for the spectrum, per thread one bin's scratch, and one complex per output
    /// until the lists are added.
    pub fn apply_parallel(
        &self,
        spectra: &[Complex32],
        voxels: &[Point],
        leg: impl Fn(&Point) -> (f32, f32) + Sync,
        skip: &[bool],
        acc: &mut [Complex64],
    ) {
        let mut x = self.spectrum();
        self.forward(spectra, &mut x, &mut self.work());
        let x = &x;
        let terms: Vec<Vec<(usize, Complex64)>> = (0..self.slices.len())
            .into_par_iter()
            .map_init(
                || self.work(),
                |w, si| {
                    let mut out = Vec::with_capacity(self.slices[si].outputs.len());
                    self.slice_terms(si, x, w, voxels, &leg, skip, |v, t| {
                        out.push((v, t));
                    });
                    out
                },
            )
            .collect();
        for (v, t) in terms.into_iter().flatten() {
            acc[v] += t;
        }
    }
}

/// One slice's work ([`Planar::slice_terms`]), run under the dispatched target features.
struct SliceOp<'a, L, E> {
    p: &'a Planar,
    si: usize,
    x: &'a [Complex32],
    w: &'a mut Work,
    voxels: &'a [Point],
    leg: &'a L,
    skip: &'a [bool],
    emit: E,
}

/// Without AVX: the portable loops, under the target features the CPU has.
impl<L, E> pulp::WithSimd for SliceOp<'_, L, E>
where
    L: Fn(&Point) -> (f32, f32),
    E: FnMut(usize, Complex64),
{
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        self.run(Portable);
    }
}

impl<L, E> SliceOp<'_, L, E>
where
    L: Fn(&Point) -> (f32, f32),
    E: FnMut(usize, Complex64),
{
    #[inline(always)]
    fn run(self, lanes: impl Lanes) {
        let SliceOp {
            p,
            si,
            x,
            w,
            voxels,
            leg,
            skip,
            mut emit,
        } = self;
        let (mx, my, j_n, rows) = (p.mx, p.my, p.bins, p.rows_out);
        let m = mx * my;
        let (klo, inv) = (p.klo_per_span, p.inv_span);
        let slice = &p.slices[si];
        let n = slice.outputs.len();
        let cy = slice.cy.max(1);
        let kh: &[Complex32] = bytemuck::cast_slice(&p.khat[si * j_n * m..(si + 1) * j_n * m]);
        let Work {
            y,
            z,
            fft,
            p: ph,
            step,
            sum,
            wt,
            d,
        } = w;
        let (ph, step, sum, d) = (&mut ph[..n], &mut step[..n], &mut sum[..n], &mut d[..n]);
        // Each voxel's leg: its phase at the band's first bin and its step per bin, in lanes
        // (a skipped voxel: zero, and not emitted).
        let skipped = |v: u32| skip.get(v as usize).copied().unwrap_or(true);
        for (o, &(_, v)) in slice.outputs.iter().enumerate() {
            (d[o], wt[o]) = if skipped(v) {
                (0.0, 0.0)
            } else {
                leg(&voxels[v as usize])
            };
        }
        lanes.cis(klo, d, ph);
        lanes.cis(inv, d, step);
        for (o, &(_, v)) in slice.outputs.iter().enumerate() {
            if skipped(v) {
                (ph[o], step[o]) = (Complex32::new(0.0, 0.0), Complex32::new(0.0, 0.0));
            }
        }
        sum.fill(Complex32::new(0.0, 0.0));
        for (xj, kj) in x.chunks_exact(m).zip(kh.chunks_exact(m)).take(j_n) {
            lanes.mul(y, xj, kj);
            p.ix.process_with_scratch(y, fft);
            // [ky][kx] → [ix][ky], only the rows ix < rows_out.
            lanes.transpose(y, mx, my, rows, z);
            p.iy.process_with_scratch(z, fft);
            // Sum and phase per voxel: the outputs are rows of `cy` cells along y.
            let rows = ph.chunks_exact_mut(cy).zip(step.chunks_exact(cy));
            for ((zrow, (ph, st)), sm) in z.chunks_exact(my).zip(rows).zip(sum.chunks_exact_mut(cy))
            {
                lanes.accumulate(&zrow[..cy], ph, st, sm);
            }
        }
        for (o, &(_, v)) in slice.outputs.iter().enumerate() {
            let v = v as usize;
            if skip.get(v).copied().unwrap_or(true) {
                continue;
            }
            let sum = sum[o] * wt[o];
            emit(v, Complex64::new(sum.re as f64, sum.im as f64));
        }
    }
}

#[cfg(test)]
mod tests {

    /// `apply_parallel` (the slices on 1, 2 or 3 threads) gives `apply`'s accumulators bit
    /// for bit, with some voxels skipped, over a volume of 6 slices of the two-patches wall.
    #[test]
    fn parallel_slices_equal_apply() {
        use super::Planar;
        use num_complex::{Complex32, Complex64};
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/two_patches.npz");
        let c = crate::io::open(&path).unwrap();
        let wave = crate::probe::Wave {
            wavelength: Some(0.3),
            sigma: Some(0.3),
            ..crate::probe::Wave::default()
        };
        let cfg = wave.config(&c.geometry).unwrap();
        let vol = crate::volume::Volume::parse("-0.5:0.5:8,-0.5:0.5:8,0.5:1.2:6").unwrap();
        let p = Planar::new(&cfg, &c.geometry.spads, &vol.points, vol.shape).unwrap();
        let n = c.geometry.spads.len() * cfg.bins();
        let spectra: Vec<Complex32> = (0..n)
            .map(|i| {
                let t = i as f32 * 0.618_034;
                Complex32::new((t * 1.3).sin(), (t * 0.7).cos() - 0.25)
            })
            .collect();
        let skip: Vec<bool> = (0..vol.len()).map(|v| v % 7 == 3).collect();
        let focus = [-0.45f32, 0.0, 0.8];
        let leg = |b: &[f32; 3]| (vltm_kernel::geometry::dist(&focus, b), 1.0);
        let mut want = vec![Complex64::new(0.5, -0.25); vol.len()];
        let mut s = super::Scratch::default();
        p.apply(&spectra, &vol.points, leg, &skip, &mut s, &mut want);
        assert!(want.iter().any(|a| a.norm() > 1e-6));
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut got = vec![Complex64::new(0.5, -0.25); vol.len()];
            pool.install(|| p.apply_parallel(&spectra, &vol.points, leg, &skip, &mut got));
            let same = got
                .iter()
                .zip(&want)
                .all(|(a, b)| a.re.to_bits() == b.re.to_bits() && a.im.to_bits() == b.im.to_bits());
            assert!(same, "{threads} threads");
        }
    }

    /// The portable loops ([`Planar::set_portable`]) give the dispatched loops' accumulators
    /// bit for bit (no fused multiply-add in either), as a CPU without AVX2 runs them.
    #[test]
    fn portable_equals_dispatched() {
        use super::Planar;
        use num_complex::{Complex32, Complex64};
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/two_patches.npz");
        let c = crate::io::open(&path).unwrap();
        let wave = crate::probe::Wave {
            wavelength: Some(0.3),
            sigma: Some(0.3),
            ..crate::probe::Wave::default()
        };
        let cfg = wave.config(&c.geometry).unwrap();
        let vol = crate::volume::Volume::parse("-0.5:0.5:8,-0.5:0.5:8,0.5:1.2:3").unwrap();
        let mut p = Planar::new(&cfg, &c.geometry.spads, &vol.points, vol.shape).unwrap();
        let n = c.geometry.spads.len() * cfg.bins();
        let spectra: Vec<Complex32> = (0..n)
            .map(|i| Complex32::new((i as f32 * 0.37).sin(), (i as f32 * 0.11).cos()))
            .collect();
        let skip = vec![false; vol.len()];
        let leg = |b: &[f32; 3]| (vltm_kernel::geometry::dist(&[0.1, 0.2, 0.0], b), 0.5);
        let mut run = |portable| {
            p.set_portable(portable);
            let mut acc = vec![Complex64::new(0.0, 0.0); vol.len()];
            p.apply(
                &spectra,
                &vol.points,
                leg,
                &skip,
                &mut super::Scratch::default(),
                &mut acc,
            );
            acc
        };
        let (a, b) = (run(false), run(true));
        assert!(a.iter().any(|a| a.norm() > 1e-6));
        assert!(a.iter().zip(&b).all(|(a, b)| a == b));
    }
}
