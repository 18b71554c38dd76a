//! Stage 1's matrix product `C = H·Wᵀ` in AVX-512 lanes, for CPUs that have them.
//!
//! [`super::band`] computes a row's band spectra as one product of the row's histograms `H`
//! (Ks × Nt, SPAD-major, `f32`) with the fixed band-DFT table `W` ((2J + 2) × Nt).
//! `matrixmultiply` (the portable product) stops at AVX2; on a CPU with AVX-512 (x86-64-v4:
//! F, BW, CD, DQ, VL; detected at run time through `pulp`) this module runs the same product
//! 16 columns per vector, twice AVX2's width:
//!
//! * `W` is made once per capture in this layout, transposed to `[n][c]` with the columns
//!   padded to a multiple of 16 (`cp`); padded columns are zero (memory `cp·Nt` `f32`, e.g.
//!   64 × 700 × 4 B = 179 kB for J = 29, in place of the portable product's table);
//! * tiles of 6 histograms × 4 vectors (64 columns) hold 24 accumulators in registers: per
//!   time bin, 4 loads of `W`, 6 broadcasts of `H` and 24 fused multiply-adds;
//! * the time axis goes in chunks of [`CHUNK`] bins, so that a chunk of `W` (24 kB for 64
//!   columns) stays in L1 while every tile of the row reads it; a tile's partial sums are
//!   stored and reloaded between chunks.
//!
//! Numerics: every output is one `f32` sum over the bins in ascending order, one fused
//! multiply-add per bin (error ≲ √Nt·2⁻²⁴ of `Σ|H·W|`, the bound of `matrixmultiply`'s
//! blocked sums, which round differently: the two agree within it, tested). The results do
//! not depend on the number of threads or on the row's place in a batch.
//!
//! Cost: `2·Ks·Nt·cp` flops per row at up to 64 flops per cycle; measured on the exhaustive
//! 16×16 × 16×16 × 800-bin capture, 18 % → 11 % of a one-thread `direct` (docs/performance.md).

use core::arch::x86_64::__m512;
use pulp::x86::V4;

/// Time bins per chunk: a chunk of packed `W` for 64 columns is `64·4·CHUNK` bytes (24 kB),
/// half of a current x86 core's L1 data cache.
pub const CHUNK: usize = 96;

/// Histograms per tile.
const ROWS: usize = 6;

/// Vectors of 16 columns per tile.
const VECS: usize = 4;

/// The band-DFT table packed for the AVX-512 product (module docs).
#[derive(Clone)]
pub struct Packed {
    simd: V4,
    /// `w[n·cpv + v][l] = W[16v + l][n]`, zero for padded columns.
    w: Vec<[f32; 16]>,
    /// Vectors of 16 columns per time bin (`cp / 16`).
    cpv: usize,
    nt: usize,
}

impl std::fmt::Debug for Packed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Packed")
            .field("columns", &(self.cpv * 16))
            .field("nt", &self.nt)
            .finish_non_exhaustive()
    }
}

impl Packed {
    /// A zero table of `cols` columns (rows of `W`) over `nt` bins, packed, or `None` where
    /// the CPU has no AVX-512 (the caller keeps the portable product).
    pub fn zeros(cols: usize, nt: usize) -> Option<Self> {
        let simd = V4::try_new()?;
        let cpv = cols.div_ceil(16);
        Some(Self {
            simd,
            w: vec![[0.0f32; 16]; nt * cpv],
            cpv,
            nt,
        })
    }

    /// Sets `W[c][n] = x` (ignored outside the table).
    pub fn set(&mut self, c: usize, n: usize, x: f32) {
        if n < self.nt
            && let Some(v) = self.w.get_mut(n * self.cpv + c / 16)
            && c / 16 < self.cpv
        {
            v[c % 16] = x;
        }
    }

    /// Columns of the product's output rows: the table's, padded to a multiple of 16.
    pub fn stride(&self) -> usize {
        self.cpv * 16
    }

    /// `out[s·stride + c] = Σ_n h[s·Nt + n]·W[c][n]` for the `Ks = h.len() / Nt`
    /// histograms of `h` (`out` is resized to `Ks·stride`; padded columns are zero).
    pub fn product(&self, h: &[f32], out: &mut Vec<f32>) {
        let nt = self.nt.max(1);
        let ks = h.len() / nt;
        out.clear();
        out.resize(ks * self.stride(), 0.0);
        let op = Product {
            simd: self.simd,
            h: &h[..ks * nt],
            nt,
            ks,
            w: &self.w,
            cpv: self.cpv,
            out: bytemuck::cast_slice_mut(out),
        };
        self.simd.vectorize(op);
    }
}

/// One row's product, run under the AVX-512 target features.
struct Product<'a> {
    simd: V4,
    h: &'a [f32],
    nt: usize,
    ks: usize,
    w: &'a [[f32; 16]],
    cpv: usize,
    out: &'a mut [[f32; 16]],
}

impl pulp::NullaryFnOnce for Product<'_> {
    type Output = ();

    #[inline(always)]
    fn call(self) {
        let (nt, ks, cpv) = (self.nt, self.ks, self.cpv);
        for v0 in (0..cpv).step_by(VECS) {
            let nv = (cpv - v0).min(VECS);
            for n0 in (0..nt).step_by(CHUNK) {
                let t = Tile {
                    simd: self.simd,
                    h: self.h,
                    nt,
                    n0,
                    len: (nt - n0).min(CHUNK),
                    w: &self.w[n0 * cpv..],
                    cpv,
                    v0,
                    first: n0 == 0,
                };
                for s0 in (0..ks).step_by(ROWS) {
                    let out = &mut *self.out;
                    // Every (histograms, vectors) shape a tile can have, each unrolled.
                    macro_rules! tiles {
                        ($($r:literal),*) => {
                            match ((ks - s0).min(ROWS), nv) {
                                $(($r, 4) => t.run::<$r, 4>(s0, out),
                                  ($r, 3) => t.run::<$r, 3>(s0, out),
                                  ($r, 2) => t.run::<$r, 2>(s0, out),
                                  ($r, _) => t.run::<$r, 1>(s0, out),)*
                                _ => {}
                            }
                        };
                    }
                    tiles!(1, 2, 3, 4, 5, 6);
                }
            }
        }
    }
}

/// One chunk of the time axis and one group of column vectors.
#[derive(Clone, Copy)]
struct Tile<'a> {
    simd: V4,
    h: &'a [f32],
    nt: usize,
    /// The chunk's first bin and length.
    n0: usize,
    len: usize,
    /// Packed `W` from the chunk's first bin on.
    w: &'a [[f32; 16]],
    cpv: usize,
    /// The group's first vector.
    v0: usize,
    /// Whether this is the first chunk (the sums start at zero, else from `out`).
    first: bool,
}

impl Tile<'_> {
    /// Histograms `s0..s0 + R`, vectors `v0..v0 + V`: `R·V` sums in registers over the chunk.
    #[inline(always)]
    fn run<const R: usize, const V: usize>(self, s0: usize, out: &mut [[f32; 16]]) {
        let f = &self.simd.avx512f;
        let zero = [0.0f32; 16];
        let rows: [&[f32]; R] =
            core::array::from_fn(|i| &self.h[(s0 + i) * self.nt + self.n0..][..self.len]);
        let at = |i: usize, v: usize| (s0 + i) * self.cpv + self.v0 + v;
        let mut acc: [[__m512; V]; R] = [[f._mm512_setzero_ps(); V]; R];
        if !self.first {
            for (i, acc) in acc.iter_mut().enumerate() {
                for (v, a) in acc.iter_mut().enumerate() {
                    *a = pulp::cast(out.get(at(i, v)).copied().unwrap_or(zero));
                }
            }
        }
        for (n, wn) in self.w.chunks_exact(self.cpv).take(self.len).enumerate() {
            // Always `V` vectors (`v0 + V ≤ cpv` by construction).
            let Some(wn) = wn
                .get(self.v0..self.v0 + V)
                .and_then(|w| <&[[f32; 16]; V]>::try_from(w).ok())
            else {
                break;
            };
            let wv: [__m512; V] = core::array::from_fn(|v| pulp::cast(wn[v]));
            for (acc, row) in acc.iter_mut().zip(&rows) {
                let b = f._mm512_set1_ps(row[n]);
                for (a, w) in acc.iter_mut().zip(&wv) {
                    *a = f._mm512_fmadd_ps(b, *w, *a);
                }
            }
        }
        for (i, acc) in acc.iter().enumerate() {
            for (v, a) in acc.iter().enumerate() {
                if let Some(o) = out.get_mut(at(i, v)) {
                    *o = pulp::cast(*a);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The packed product against an `f64` sum, on every tile shape (1–13 histograms, so
    /// every remainder of 6), 1–5 column vectors (one and two groups, padded columns) and
    /// time axes shorter than, equal to and longer than a chunk; skipped without AVX-512.
    #[test]
    fn packed_product_matches_f64_sums() {
        if V4::try_new().is_none() {
            // Nothing to pack for: the caller must get `None` and keep the portable product.
            assert!(Packed::zeros(68, 100).is_none());
            eprintln!("no AVX-512 on this CPU: the portable product only (band.rs tests)");
            return;
        }
        let mut seed = 0x9e37_79b9u32;
        let mut rnd = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        for (cols, nt, ks) in [
            (60, 700, 13),
            (68, CHUNK, 7),
            (3, 1, 5),
            (16, CHUNK + 1, 6),
            (33, 250, 1),
            (80, 2 * CHUNK - 1, 12),
        ] {
            let w: Vec<f32> = (0..cols * nt).map(|_| rnd()).collect();
            let h: Vec<f32> = (0..ks * nt).map(|_| 100.0 * rnd()).collect();
            let mut p = Packed::zeros(cols, nt).unwrap();
            for (i, &x) in w.iter().enumerate() {
                p.set(i / nt, i % nt, x);
            }
            // Outside the table: ignored.
            p.set(p.stride(), 0, 1.0);
            p.set(0, nt, 1.0);
            let mut out = Vec::new();
            p.product(&h, &mut out);
            assert_eq!(out.len(), ks * p.stride());
            for s in 0..ks {
                for c in 0..p.stride() {
                    let (exact, abs) = (0..nt).fold((0.0f64, 0.0f64), |(e, a), n| {
                        let x = if c < cols {
                            f64::from(h[s * nt + n]) * f64::from(w[c * nt + n])
                        } else {
                            0.0
                        };
                        (e + x, a + x.abs())
                    });
                    let got = f64::from(out[s * p.stride() + c]);
                    let tol = 4.0 * (nt as f64).sqrt() * f64::from(f32::EPSILON) * abs + 1e-30;
                    assert!(
                        (got - exact).abs() <= tol,
                        "{cols}×{nt}, {ks} histograms: [{s}][{c}] {got} vs {exact} (±{tol:.2e})"
                    );
                }
            }
        }
    }
}
