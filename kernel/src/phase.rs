//! Phase generation: `cis(2π·t) = e^{i2πt}` from a phase in **turns**, in plain `f32`
//! arithmetic that gives the same bits on the host and on a Cortex-M.
//!
//! * Reduction: `r = t − rint(t)` (exact for |t| < 2²³), then to the nearest quarter turn,
//!   leaving `x = 2π·f` with |f| ≤ 1/8.
//! * Polynomials: Taylor series of sin to x⁹ and of cos to x¹⁰ on |x| ≤ π/4 (truncation
//!   < 2e-9), evaluated by Horner in f32.
//! * Measured error (unit test `cis_accuracy`, 2·10⁵ phases over ±1000 turns, against f64
//!   `sin`/`cos`): max |cis − exact| ≤ 2.5e-7 in each component, i.e. ≈ 2 ulp of f32.
//!   The error of the *phase argument* itself (an `f32` product `t = ν·τ/2π`) dominates for
//!   large `t`: ≈ 6e-8·|t| turns.
//!
//! * Twiddle stepping ([`TwiddleStep`]): the integer phase accumulator `q = (k·n) mod N` into a
//!   table of `e^{−2πiq/N}`, stepped by `k mod N` per sample: exact (no drift with n), shared by
//!   the float and the fixed-point band DFTs and the photon paths.
//!
//! micromath is not used here: its `sin`/`cos` are 1.1e-3 off (STYLE.md); `libm`'s `sincosf`
//! reduces in `f64`, which is soft-float on a Cortex-M4F. `libm`'s f64 functions are used only
//! for one-off setup (tables, seeds).

use num_complex::Complex32;

const TAU: f32 = core::f32::consts::TAU;

/// `e^{i2πt}` for a phase `t` in turns. Infallible for every input: NaN or ±∞ give NaN.
///
/// ```
/// let c = vltm_kernel::cis_turns(0.25);
/// assert!(c.re.abs() < 1e-7 && (c.im - 1.0).abs() < 1e-7);
/// ```
#[inline]
pub fn cis_turns(t: f32) -> Complex32 {
    let r = t - libm::rintf(t);
    let q4 = libm::rintf(4.0 * r);
    let Complex32 { re: c, im: s } = cis_small(r - 0.25 * q4);
    // q4 ∈ {−2, −1, 0, 1, 2}; rotate by q4 quarter turns. (`as i32` saturates; NaN → 0.)
    match (q4 as i32) & 3 {
        0 => Complex32::new(c, s),
        1 => Complex32::new(-s, c),
        2 => Complex32::new(-c, -s),
        _ => Complex32::new(s, -c),
    }
}

/// `e^{i2πt}` for a small phase `|t| ≤ 1/8` turn: the polynomials of [`cis_turns`] (Taylor
/// series of sin to x⁹ and cos to x¹⁰ on `|x| ≤ π/4`, truncation < 2e-9, Horner in `f32`)
/// without its range reduction — no `rint`, no quadrant branch — for callers whose phases are
/// already reduced (interpolation offsets, residual carriers). Outside `|t| ≤ 1/8` the error
/// grows as the Taylor remainder.
///
/// ```
/// let c = vltm_kernel::phase::cis_small(0.125);
/// assert!((c.re - core::f32::consts::FRAC_1_SQRT_2).abs() < 2e-7);
/// ```
#[inline(always)]
pub fn cis_small(t: f32) -> Complex32 {
    let x = TAU * t;
    let x2 = x * x;
    let s = x
        * (1.0
            + x2 * (-1.0 / 6.0
                + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362_880.0)))));
    let c = 1.0
        + x2 * (-0.5
            + x2 * (1.0 / 24.0
                + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40_320.0 + x2 * (-1.0 / 3_628_800.0)))));
    Complex32::new(c, s)
}

/// `e^{i2πt}` for a phase in turns given in `f64`: reduced in `f64` (exact), evaluated in
/// `f32`. For seeds computed once per row or histogram.
#[inline]
pub fn cis_turns_f64(t: f64) -> Complex32 {
    cis_turns((t - libm::rint(t)) as f32)
}

/// `k mod n` in `0..n` (`n = 0` is read as 1), without a panicking branch.
///
/// ```
/// assert_eq!(vltm_kernel::phase::wrap(-3, 10), 7);
/// ```
#[inline]
pub fn wrap(k: i64, n: usize) -> usize {
    k.checked_rem_euclid(n.max(1) as i64).unwrap_or(0) as usize
}

/// Integer phase accumulator over a table of `N` twiddles `e^{−2πiq/N}`: the index
/// `q = (k·n) mod N` of sample `n`, stepped by `k mod N` (all `< N ≤ 2³⁰`, no overflow).
///
/// ```
/// use vltm_kernel::phase::TwiddleStep;
/// let mut t = TwiddleStep::new(-3, 2, 10); // k = −3, from n = 2, N = 10
/// let q: Vec<usize> = (0..4).map(|_| { let q = t.index(); t.advance(); q }).collect();
/// assert_eq!(q, [4, 1, 8, 5]); // (−3·n) mod 10 for n = 2, 3, 4, 5
/// ```
#[derive(Clone, Copy, Debug)]
pub struct TwiddleStep {
    q: usize,
    step: usize,
    n: usize,
}

impl TwiddleStep {
    /// The accumulator of frequency `k` at sample `start` for a table of `n` entries
    /// (`n = 0` is read as 1). The first product is taken in `u64` (it reaches 2⁶⁰).
    #[inline]
    pub fn new(k: i64, start: u64, n: usize) -> Self {
        let n = n.max(1);
        let step = wrap(k, n) as u64;
        let q = ((step * (start % n as u64)) % n as u64) as usize;
        Self {
            q,
            step: step as usize,
            n,
        }
    }
    /// The current table index `(k·n) mod N`.
    #[inline(always)]
    pub const fn index(&self) -> usize {
        self.q
    }
    /// Next sample: `q ← (q + k) mod N` (one add, one compare).
    #[inline(always)]
    pub fn advance(&mut self) {
        self.q += self.step;
        if self.q >= self.n {
            self.q -= self.n;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn twiddle_step_is_k_n_mod_n() {
        for (k, start, n) in [
            (5i64, 0u64, 7usize),
            (-11, 3, 289),
            (140, 254, 289),
            (0, 9, 4),
            (1 << 29, (1 << 40) + 3, (1 << 30) - 1),
        ] {
            let mut t = TwiddleStep::new(k, start, n);
            for i in 0..50u64 {
                let want = (i128::from(k) * i128::from(start + i)).rem_euclid(n as i128) as usize;
                assert_eq!(t.index(), want, "k={k} n={}", start + i);
                t.advance();
            }
        }
    }

    #[test]
    fn cis_accuracy() {
        let mut worst = 0.0f64;
        let n = 200_000;
        for i in 0..n {
            let t = (i as f32 / n as f32 - 0.5) * 2000.0 + 1e-3 * i as f32 % 1.0;
            let c = cis_turns(t);
            let a = core::f64::consts::TAU * t as f64;
            let e = (c.re as f64 - libm::cos(a))
                .abs()
                .max((c.im as f64 - libm::sin(a)).abs());
            worst = worst.max(e);
        }
        assert!(worst < 2.5e-7, "max error {worst}");
        for (t, re, im) in [
            (0.0f32, 1.0f32, 0.0f32),
            (0.5, -1.0, 0.0),
            (-0.25, 0.0, -1.0),
            (0.125, 0.70710677, 0.70710677),
        ] {
            let c = cis_turns(t);
            assert!(
                (c.re - re).abs() < 1e-7 && (c.im - im).abs() < 1e-7,
                "{t}: {c}"
            );
        }
        assert!(cis_turns(f32::NAN).re.is_nan());
        assert!(cis_turns(f32::INFINITY).re.is_nan());
    }
}
