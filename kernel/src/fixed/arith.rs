//! Scaled integer arithmetic: an `i64` times an `f32` weight through its exact mantissa and
//! exponent, and rounding shifts, both saturating to `i64`.

/// `round(z·w·2^sh)` for a finite `w ≥ 0`, through the exact `f32` mantissa and exponent of
/// `w` (`i128` product, rounding shift), saturated to `i64` (unreachable within the budget).
#[inline]
pub(super) fn scale(z: i64, w: f32, sh: i32) -> i64 {
    let b = w.to_bits();
    let e = ((b >> 23) & 0xff) as i32;
    if e == 0 || e == 0xff {
        return 0; // zero or subnormal (w < 1.2e-38), or non-finite (cannot happen)
    }
    let m = i128::from((b & 0x7f_ffff) | 0x80_0000);
    let s = e - 150 + sh; // w·2^sh = m·2^s
    let p = i128::from(z) * m;
    let r = if s >= 0 {
        p << s.min(40)
    } else {
        let k = (-s).min(126) as u32;
        (p + (1i128 << (k - 1))) >> k
    };
    r.clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64
}

/// Rounding arithmetic shift right of an `i128` by `k ≥ 1`, narrowed to `i64` (saturating).
#[inline]
pub(super) fn round_shift(x: i128, k: u32) -> i64 {
    let r = (x + (1i128 << (k - 1))) >> k;
    r.clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_rounds_exactly() {
        assert_eq!(scale(1000, 0.5, 0), 500);
        assert_eq!(scale(1000, 0.25, 2), 1000);
        assert_eq!(scale(-3, 0.5, 0), -1); // −1.5 rounds half up
        assert_eq!(scale(7, 3.0, -1), 11); // 10.5 → 11
        assert_eq!(scale(i64::MAX, 2.0, 10), i64::MAX); // saturates
        assert_eq!(scale(5, 0.0, 0), 0);
    }
}
