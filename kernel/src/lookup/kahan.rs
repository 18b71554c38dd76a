//! The accumulators of the lookup paths ([`LookupProbe`](crate::LookupProbe) and
//! [`LookupSlice`](crate::LookupSlice)): per voxel a **Kahan-compensated `f32` complex sum**
//! `[s.re, s.im, c.re, c.im]` in caller memory ([`KahanSums`]).
//!
//! Error: `≤ 2u·Σ_rows |row sum|` plus `O(n u²)` (`u = 2⁻²⁴`; Higham, *Accuracy and Stability
//! of Numerical Algorithms*, §4.3), independent of the number of rows and far below the
//! lookup tolerance; no `f64` arithmetic per row (soft float on a Cortex-M4F), only in
//! [`KahanSums::amplitude`] and [`KahanSums::intensities`]. Cost: 8 `f32` additions per
//! complex addition ([`add`]). Memory: `4Kv` `f32` of caller state ([`KahanSums::state_len`]:
//! the bytes of the band diagonal's `2Kv` `f64`).

use crate::error::ArgumentError;
use num_complex::{Complex32, Complex64};

/// Kahan-compensated complex `f32` sums in caller memory, one per voxel, each
/// `[s.re, s.im, c.re, c.im]`: the sum `s` and its running compensation `c` (the rounding
/// error still to subtract); the value is `s − c`.
#[derive(Debug)]
pub(crate) struct KahanSums<'m> {
    acc: &'m mut [[f32; 4]],
}

impl<'m> KahanSums<'m> {
    /// Length in `f32` of the state of `n` sums: `4n`.
    pub(crate) const fn state_len(n: usize) -> usize {
        n.saturating_mul(4)
    }

    /// The sums held in `state` (whose length the caller has checked against
    /// [`KahanSums::state_len`]), as they are: [`KahanSums::reset`] zeroes them.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] (`"state"`, `expected` as given) if `state` is not a whole number
    /// of sums.
    pub(crate) fn new(state: &'m mut [f32], expected: usize) -> Result<Self, ArgumentError> {
        let found = state.len();
        let acc = bytemuck::try_cast_slice_mut(state).map_err(|_| ArgumentError::Length {
            what: "state",
            expected,
            found,
        })?;
        Ok(Self { acc })
    }

    /// Number of sums.
    pub(crate) const fn len(&self) -> usize {
        self.acc.len()
    }

    /// Zeroes every sum and compensation.
    pub(crate) fn reset(&mut self) {
        self.acc.fill([0.0; 4]);
    }

    /// The sums, in voxel order, for a row's additions by [`add`].
    #[inline(always)]
    pub(crate) fn iter_mut(&mut self) -> core::slice::IterMut<'_, [f32; 4]> {
        self.acc.iter_mut()
    }

    /// Adds another set of sums value by value (`s − c` of each, compensated), over the
    /// shorter of the two lengths.
    pub(crate) fn merge(&mut self, other: &KahanSums<'_>) {
        for (a, b) in self.acc.iter_mut().zip(other.acc.iter()) {
            add(a, Complex32::new(b[0] - b[2], b[1] - b[3]));
        }
    }

    /// The value `s − c` of sum `i` in `f64` (0 past the end).
    pub(crate) fn amplitude(&self, i: usize) -> Complex64 {
        self.acc.get(i).map_or(Complex64::new(0.0, 0.0), value)
    }

    /// `out[i] = |s − c|²` of sum `i`, in `f64`, over the shorter of the two lengths.
    pub(crate) fn intensities(&self, out: &mut [f64]) {
        for (o, a) in out.iter_mut().zip(self.acc.iter()) {
            *o = value(a).norm_sqr();
        }
    }

    /// [`KahanSums::intensities`] in `f32` (no `f64`): `s − c` rounded once to `f32`
    /// (a relative `2u` more).
    pub(crate) fn intensities_f32(&self, out: &mut [f32]) {
        for (o, a) in out.iter_mut().zip(self.acc.iter()) {
            *o = Complex32::new(a[0] - a[2], a[1] - a[3]).norm_sqr();
        }
    }
}

/// Kahan step: `acc = [s.re, s.im, c.re, c.im]` += `z` (`c` the running compensation, the
/// rounding error still to subtract). Rust does not reassociate floating-point operations,
/// so the compensation survives optimisation.
#[inline(always)]
pub(crate) fn add(acc: &mut [f32; 4], z: Complex32) {
    let [s_re, s_im, c_re, c_im] = *acc;
    let (y_re, y_im) = (z.re - c_re, z.im - c_im);
    let (t_re, t_im) = (s_re + y_re, s_im + y_im);
    *acc = [t_re, t_im, (t_re - s_re) - y_re, (t_im - s_im) - y_im];
}

/// The compensated sum's value `s − c`, in `f64`.
#[inline]
fn value(a: &[f32; 4]) -> Complex64 {
    Complex64::new(
        f64::from(a[0]) - f64::from(a[2]),
        f64::from(a[1]) - f64::from(a[3]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Compensation with teeth: 2²⁰ additions of 0.1 to 1e4 (each below half an ulp of the
    /// sum's magnitude in relative terms) stay within a few ulps of the exact sum, where a
    /// plain `f32` sum drifts by orders of magnitude more; merge adds values; reset zeroes.
    #[test]
    fn compensated_sums_merge_and_reset() {
        let (mut a, mut b) = ([0.0f32; 8], [0.0f32; 8]);
        let mut x = KahanSums::new(&mut a, 8).unwrap();
        let mut y = KahanSums::new(&mut b, 8).unwrap();
        assert_eq!((x.len(), KahanSums::state_len(2)), (2, 8));
        let n = 1u32 << 20;
        let mut plain = 1e4f32;
        for s in x.iter_mut() {
            add(s, Complex32::new(1e4, -1e4));
        }
        for _ in 0..n {
            for s in x.iter_mut() {
                add(s, Complex32::new(0.1, -0.1));
            }
            plain += 0.1;
        }
        let exact = 1e4 + f64::from(n) * f64::from(0.1f32);
        let got = x.amplitude(1);
        let ulp = f64::from(f32::EPSILON) * exact;
        assert!((got.re - exact).abs() <= 2.0 * ulp, "{got} vs {exact}");
        assert!((got.im + exact).abs() <= 2.0 * ulp, "{got} vs {exact}");
        assert!(
            (f64::from(plain) - exact).abs() > 100.0 * ulp,
            "no teeth: {plain}"
        );
        for s in y.iter_mut() {
            add(s, Complex32::new(1.0, 2.0));
        }
        x.merge(&y);
        assert!((x.amplitude(0).re - (exact + 1.0)).abs() <= 2.0 * ulp);
        let mut out = [0.0f64; 2];
        y.intensities(&mut out);
        let mut out32 = [0.0f32; 2];
        y.intensities_f32(&mut out32);
        assert_eq!((out, out32), ([5.0; 2], [5.0; 2]));
        assert_eq!(x.amplitude(2), Complex64::new(0.0, 0.0));
        x.reset();
        assert_eq!(x.amplitude(0), Complex64::new(0.0, 0.0));
        assert!(KahanSums::new(&mut [0.0f32; 6], 8).is_err());
    }
}
