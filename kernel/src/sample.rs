//! Histogram sample types: photon counts as `u16`/`u32` (TCSPC), or `f32` (rendered or
//! background-subtracted data, may be negative).

/// A histogram sample that the kernel can read.
///
/// Non-finite `f32` samples (NaN, ±∞) are **read as 0 and counted** (see
/// [`Row::non_finite`](crate::Row::non_finite) and [`Report`](crate::Report)), so one
/// corrupt bin never poisons a whole image.
///
/// ```
/// use vltm_kernel::Sample;
/// assert_eq!(7u16.value(), 7.0);
/// assert_eq!(f32::NAN.value(), 0.0);
/// assert!(!f32::INFINITY.is_valid());
/// ```
pub trait Sample: Copy {
    /// The sample as `f32`; non-finite values give 0.
    fn value(self) -> f32;
    /// Whether the sample is finite (always true for integer counts).
    fn is_valid(self) -> bool;
}

impl Sample for u16 {
    #[inline]
    fn value(self) -> f32 {
        f32::from(self)
    }
    #[inline]
    fn is_valid(self) -> bool {
        true
    }
}

impl Sample for u32 {
    #[inline]
    fn value(self) -> f32 {
        self as f32
    }
    #[inline]
    fn is_valid(self) -> bool {
        true
    }
}

impl Sample for f32 {
    #[inline]
    fn value(self) -> f32 {
        if self.is_finite() { self } else { 0.0 }
    }
    #[inline]
    fn is_valid(self) -> bool {
        self.is_finite()
    }
}
