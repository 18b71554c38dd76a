//! The complex `f32` loops of the planar path's inverse pass ([`super::planar`]), portable and
//! for AVX (through `pulp`'s safe wrappers, no `unsafe`): the pointwise product `X̂_j·κ̂_j`
//! each voxel's `sum += z·p; p *= step`, the transpose between the two inverse passes, and
//! the voxels' leg phases `e^{2πi·a·d}` (the kernel's `cis_turns`, 8 lanes).
//!
//! Every value is computed by the operations of `num_complex`'s `Complex32` product (two
//! products, then one subtraction or addition; AVX's `addsub` does the same in each lane, and
//! there is no fused multiply-add), so both versions give the portable loop's results bit for
//! bit (tested) and the same as before they were vectorised.

use num_complex::Complex32;
use vltm_kernel::cis_turns;

/// `dst[c·stride + r] = src[r·cols + c]` for r < rows, c < cols: tiles of 16 rows, each
/// destination row of a tile written as one contiguous run (the strided reads stay in L1).
pub(super) fn transpose(
    src: &[Complex32],
    rows: usize,
    cols: usize,
    dst: &mut [Complex32],
    stride: usize,
) {
    const B: usize = 16;
    for r0 in (0..rows).step_by(B) {
        let r1 = (r0 + B).min(rows);
        let block = &src[r0 * cols..r1 * cols];
        for c in 0..cols {
            let d = &mut dst[c * stride + r0..c * stride + r1];
            for (k, o) in d.iter_mut().enumerate() {
                *o = block[k * cols + c];
            }
        }
    }
}

/// The loops, by vector width.
pub(super) trait Lanes: Copy {
    /// `dst[k] = a[k]·b[k]` over the shortest of the three.
    fn mul(self, dst: &mut [Complex32], a: &[Complex32], b: &[Complex32]);
    /// Per `k`: `sum[k] += z[k]·p[k]`, then `p[k] *= step[k]`.
    fn accumulate(
        self,
        z: &[Complex32],
        p: &mut [Complex32],
        step: &[Complex32],
        sum: &mut [Complex32],
    );
    /// `dst[c·n + r] = src[r·stride + c]` for `r < n`, `c < cols` (the first `cols` columns
    /// of `n` rows of `src`, transposed; copies, so every version gives the same values).
    fn transpose(
        self,
        src: &[Complex32],
        stride: usize,
        n: usize,
        cols: usize,
        dst: &mut [Complex32],
    );
    /// `out[k] = cis_turns(a·d[k])` over the shorter of the two: the kernel's
    /// [`vltm_kernel::cis_turns`] by the same operations in the same order (round to nearest
    /// even, the quarter-turn reduction, the Taylor polynomials without fused multiply-adds),
    /// so every version gives its bits.
    fn cis(self, a: f32, d: &[f32], out: &mut [Complex32]);
}

/// Plain loops (the compiler's baseline vectorisation).
#[derive(Clone, Copy)]
pub(super) struct Portable;

impl Lanes for Portable {
    #[inline(always)]
    fn mul(self, dst: &mut [Complex32], a: &[Complex32], b: &[Complex32]) {
        for ((d, a), b) in dst.iter_mut().zip(a).zip(b) {
            *d = a * b;
        }
    }

    #[inline(always)]
    fn accumulate(
        self,
        z: &[Complex32],
        p: &mut [Complex32],
        step: &[Complex32],
        sum: &mut [Complex32],
    ) {
        for (((z, p), t), s) in z.iter().zip(p.iter_mut()).zip(step).zip(sum.iter_mut()) {
            *s += z * *p;
            *p *= t;
        }
    }

    #[inline(always)]
    fn transpose(
        self,
        src: &[Complex32],
        stride: usize,
        n: usize,
        cols: usize,
        dst: &mut [Complex32],
    ) {
        for (c, dst) in dst.chunks_exact_mut(n.max(1)).take(cols).enumerate() {
            for (d, src) in dst.iter_mut().zip(src.chunks(stride.max(1))) {
                *d = src[c];
            }
        }
    }

    #[inline(always)]
    fn cis(self, a: f32, d: &[f32], out: &mut [Complex32]) {
        for (o, &d) in out.iter_mut().zip(d) {
            *o = cis_turns(a * d);
        }
    }
}

#[cfg(target_arch = "x86_64")]
use core::arch::x86_64::{__m256, __m256d};
#[cfg(target_arch = "x86_64")]
use pulp::x86::V3;

#[cfg(target_arch = "x86_64")]
/// Four complex values per 256-bit vector (x86-64-v3: AVX2 + FMA, Haswell and Zen 1 on).
#[derive(Clone, Copy)]
pub(crate) struct Avx(pub(crate) V3);

/// `a·b` per complex lane: `(a.re·b.re − a.im·b.im, a.re·b.im + a.im·b.re)`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn cmul(s: V3, a: __m256, b: __m256) -> __m256 {
    let ba = s.avx._mm256_permute_ps::<0b10_11_00_01>(b);
    let re = s.avx._mm256_moveldup_ps(a);
    let im = s.avx._mm256_movehdup_ps(a);
    s.avx
        ._mm256_addsub_ps(s.avx._mm256_mul_ps(re, b), s.avx._mm256_mul_ps(im, ba))
}

/// [`vltm_kernel::cis_turns`] of 8 phases (turns) in lanes: see [`Lanes::cis`]. Returns
/// the 8 values interleaved (`re, im` of the first four, then of the last four).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn cis8(s: V3, t: __m256) -> [__m256; 2] {
    const TAU: f32 = core::f32::consts::TAU;
    let (a, i) = (&s.avx, &s.avx2);
    let k = |x: f32| a._mm256_set1_ps(x);
    // Round to nearest, ties to even, exceptions suppressed: `rintf`.
    let rint = |x: __m256| a._mm256_round_ps::<0x08>(x);
    let r = a._mm256_sub_ps(t, rint(t));
    let q4 = rint(a._mm256_mul_ps(k(4.0), r));
    let f = a._mm256_sub_ps(r, a._mm256_mul_ps(k(0.25), q4));
    let x = a._mm256_mul_ps(k(TAU), f);
    let x2 = a._mm256_mul_ps(x, x);
    // `c + x2·p`, in the kernel's order.
    let step = |c: f32, p: __m256| a._mm256_add_ps(k(c), a._mm256_mul_ps(x2, p));
    let sp = step(
        1.0,
        step(
            -1.0 / 6.0,
            step(1.0 / 120.0, step(-1.0 / 5040.0, k(1.0 / 362_880.0))),
        ),
    );
    let sin = a._mm256_mul_ps(x, sp);
    let cos = step(
        1.0,
        step(
            -0.5,
            step(
                1.0 / 24.0,
                step(-1.0 / 720.0, step(1.0 / 40_320.0, k(-1.0 / 3_628_800.0))),
            ),
        ),
    );
    // Quadrant `q4 & 3` (NaN converts to i32::MIN, whose low bits are 0, as `as i32` gives 0).
    let q = i._mm256_and_si256(a._mm256_cvtps_epi32(q4), a._mm256_set1_epi32(3));
    let odd = a._mm256_castsi256_ps(i._mm256_cmpeq_epi32(
        i._mm256_and_si256(q, a._mm256_set1_epi32(1)),
        a._mm256_set1_epi32(1),
    ));
    let two = a._mm256_set1_epi32(2);
    // −re for q ∈ {1, 2}, −im for q ∈ {2, 3}: bit 1 of q + 1 and of q, moved to the sign.
    let neg_re = i._mm256_slli_epi32::<30>(
        i._mm256_and_si256(i._mm256_add_epi32(q, a._mm256_set1_epi32(1)), two),
    );
    let neg_im = i._mm256_slli_epi32::<30>(i._mm256_and_si256(q, two));
    let re = a._mm256_xor_ps(
        a._mm256_blendv_ps(cos, sin, odd),
        a._mm256_castsi256_ps(neg_re),
    );
    let im = a._mm256_xor_ps(
        a._mm256_blendv_ps(sin, cos, odd),
        a._mm256_castsi256_ps(neg_im),
    );
    let (lo, hi) = (a._mm256_unpacklo_ps(re, im), a._mm256_unpackhi_ps(re, im));
    [
        a._mm256_permute2f128_ps::<0x20>(lo, hi),
        a._mm256_permute2f128_ps::<0x31>(lo, hi),
    ]
}

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn load(x: &[Complex32]) -> __m256 {
    let a: &[f32; 8] = bytemuck::cast_slice::<Complex32, f32>(x)
        .try_into()
        .unwrap_or(&[0.0; 8]);
    pulp::cast(*a)
}

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn store(x: &mut [Complex32], v: __m256) {
    let v: [f32; 8] = pulp::cast(v);
    bytemuck::cast_slice_mut::<Complex32, f32>(x).copy_from_slice(&v);
}

#[cfg(target_arch = "x86_64")]
impl Lanes for Avx {
    #[inline(always)]
    fn mul(self, dst: &mut [Complex32], a: &[Complex32], b: &[Complex32]) {
        let n = dst.len().min(a.len()).min(b.len());
        let (dst, a, b) = (&mut dst[..n], &a[..n], &b[..n]);
        let mut d4 = dst.chunks_exact_mut(4);
        let (mut a4, mut b4) = (a.chunks_exact(4), b.chunks_exact(4));
        for ((d, a), b) in (&mut d4).zip(&mut a4).zip(&mut b4) {
            store(d, cmul(self.0, load(a), load(b)));
        }
        Portable.mul(d4.into_remainder(), a4.remainder(), b4.remainder());
    }

    #[inline(always)]
    fn accumulate(
        self,
        z: &[Complex32],
        p: &mut [Complex32],
        step: &[Complex32],
        sum: &mut [Complex32],
    ) {
        let n = z.len().min(p.len()).min(step.len()).min(sum.len());
        let (z, p, step, sum) = (&z[..n], &mut p[..n], &step[..n], &mut sum[..n]);
        let mut p4 = p.chunks_exact_mut(4);
        let mut s4 = sum.chunks_exact_mut(4);
        let (mut z4, mut t4) = (z.chunks_exact(4), step.chunks_exact(4));
        for (((z, p), t), s) in (&mut z4).zip(&mut p4).zip(&mut t4).zip(&mut s4) {
            let pv = load(p);
            let zp = cmul(self.0, load(z), pv);
            store(s, self.0.avx._mm256_add_ps(load(s), zp));
            store(p, cmul(self.0, pv, load(t)));
        }
        Portable.accumulate(
            z4.remainder(),
            p4.into_remainder(),
            t4.remainder(),
            s4.into_remainder(),
        );
    }

    /// Blocks of 4 × 4 complex values through registers (unpack and swap halves).
    #[inline(always)]
    fn transpose(
        self,
        src: &[Complex32],
        stride: usize,
        n: usize,
        cols: usize,
        dst: &mut [Complex32],
    ) {
        let fits = n.is_multiple_of(4)
            && cols.is_multiple_of(4)
            && cols <= stride
            && src.len() >= n * stride
            && dst.len() >= cols * n;
        if !fits {
            return Portable.transpose(src, stride, n, cols, dst);
        }
        let a = &self.0.avx;
        for c0 in (0..cols).step_by(4) {
            for r0 in (0..n).step_by(4) {
                let row =
                    |k: usize| -> __m256d { pulp::cast(load(&src[(r0 + k) * stride + c0..][..4])) };
                let (a0, a1, a2, a3) = (row(0), row(1), row(2), row(3));
                let (t0, t1) = (a._mm256_unpacklo_pd(a0, a1), a._mm256_unpackhi_pd(a0, a1));
                let (t2, t3) = (a._mm256_unpacklo_pd(a2, a3), a._mm256_unpackhi_pd(a2, a3));
                let o = [
                    a._mm256_permute2f128_pd::<0x20>(t0, t2),
                    a._mm256_permute2f128_pd::<0x20>(t1, t3),
                    a._mm256_permute2f128_pd::<0x31>(t0, t2),
                    a._mm256_permute2f128_pd::<0x31>(t1, t3),
                ];
                for (k, o) in o.into_iter().enumerate() {
                    store(&mut dst[(c0 + k) * n + r0..][..4], pulp::cast(o));
                }
            }
        }
    }

    #[inline(always)]
    fn cis(self, a: f32, d: &[f32], out: &mut [Complex32]) {
        let n = d.len().min(out.len());
        let (d, out) = (&d[..n], &mut out[..n]);
        let mut o8 = out.chunks_exact_mut(8);
        let mut d8 = d.chunks_exact(8);
        let av = self.0.avx._mm256_set1_ps(a);
        for (o, d) in (&mut o8).zip(&mut d8) {
            let d: [f32; 8] = d.try_into().unwrap_or([0.0; 8]);
            let t = self.0.avx._mm256_mul_ps(av, pulp::cast(d));
            let [v0, v1] = cis8(self.0, t);
            store(&mut o[..4], v0);
            store(&mut o[4..], v1);
        }
        Portable.cis(a, d8.remainder(), o8.into_remainder());
    }
}

#[cfg(test)]
mod tests {
    #[cfg(target_arch = "x86_64")]
    use super::*;

    /// The AVX loops give the portable loops' values bit for bit (where the CPU has AVX2).
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx_equals_portable() {
        let Some(v3) = pulp::x86::V3::try_new() else {
            return;
        };
        let c = |i: usize, s: f32| {
            let t = i as f32 * s;
            Complex32::new((t * 1.3).sin() * 3.0, (t * 0.7).cos() - 0.25)
        };
        let bits = |v: &[Complex32]| -> Vec<u32> {
            v.iter()
                .flat_map(|c| [c.re.to_bits(), c.im.to_bits()])
                .collect()
        };
        for n in [0, 1, 3, 4, 7, 16, 33] {
            let a: Vec<_> = (0..n).map(|i| c(i, 0.618)).collect();
            let b: Vec<_> = (0..n).map(|i| c(i, 1.7)).collect();
            let t: Vec<_> = (0..n).map(|i| c(i, 0.1) / c(i, 0.1).norm()).collect();
            let mut want = vec![Complex32::default(); n];
            let mut got = want.clone();
            Portable.mul(&mut want, &a, &b);
            v3.vectorize(|| Avx(v3).mul(&mut got, &a, &b));
            assert_eq!(bits(&got), bits(&want), "mul, n = {n}");
            let (mut p0, mut s0) = (b.clone(), a.clone());
            let (mut p1, mut s1) = (b.clone(), a.clone());
            for _ in 0..5 {
                Portable.accumulate(&a, &mut p0, &t, &mut s0);
                v3.vectorize(|| Avx(v3).accumulate(&a, &mut p1, &t, &mut s1));
            }
            assert_eq!(bits(&p1), bits(&p0), "phase, n = {n}");
            assert_eq!(bits(&s1), bits(&s0), "sum, n = {n}");
        }
        // Leg phases: ties of the rounding (halves and quarters of a turn), large and
        // negative phases, NaN and infinities.
        let mut d: Vec<f32> = (0..203).map(|i| (i as f32 - 101.0) * 0.125).collect();
        d.extend((0..500).map(|i| (i as f32 * 0.6173).sin() * 1e4));
        d.extend([f32::NAN, f32::INFINITY, -f32::INFINITY, 1e9, -0.0, 3e-8]);
        for a in [1.0f32, 0.37, -2.5, 1234.5] {
            for n in [0, 5, 8, d.len()] {
                let mut want = vec![Complex32::default(); n];
                let mut got = want.clone();
                Portable.cis(a, &d[..n], &mut want);
                v3.vectorize(|| Avx(v3).cis(a, &d[..n], &mut got));
                assert_eq!(bits(&got), bits(&want), "cis, a = {a}, n = {n}");
            }
        }
        for (stride, n, cols) in [(32, 32, 16), (8, 4, 8), (6, 9, 3), (12, 8, 4)] {
            let src: Vec<_> = (0..stride * n).map(|i| c(i, 0.3)).collect();
            let mut want = vec![Complex32::default(); n * cols];
            let mut got = want.clone();
            Portable.transpose(&src, stride, n, cols, &mut want);
            v3.vectorize(|| Avx(v3).transpose(&src, stride, n, cols, &mut got));
            assert_eq!(bits(&got), bits(&want), "transpose {stride} {n} {cols}");
            assert_eq!(want[n + 2], src[2 * stride + 1]);
        }
    }
}
