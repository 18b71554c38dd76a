//! Geometry shared by the kernel, the host and the firmware: Euclidean distances between
//! points of the scene (metres of optical path, c ≡ 1) and the alias-window check of the
//! factorised column.
//!
//! * [`dist`]: `f32` points, correctly rounded `sqrtf` — the kernel's per-pair path lengths
//!   (relative error ≈ 1e-7). Summation order `(dx² + dy²) + dz²`, so every caller gets the
//!   same bits.
//! * [`dist64`]: an `f32` point to an `f64` point, in `f64` (the leg origins of
//!   [`Legs::FirstAndLast`](crate::Legs), set-up and host paths).
//! * [`dist64_f64`]: two `f64` points.
//! * [`widen`] and [`leaves_window`]: the factorised column's check that every path time
//!   `leg + path` of a voxel stays inside [`alias_window`] (the absolute form of
//!   [`Config::alias_free`]).
//!
//! Cost: a distance is 3 subtractions, 3 multiplies, 2 additions and one square root. No
//! memory.

use crate::config::{Config, Point};
use core::ops::Add;

/// Euclidean distance between two `f32` points, in `f32` (correctly rounded `sqrtf`).
///
/// ```
/// assert_eq!(vltm_kernel::geometry::dist(&[0.0, 3.0, 0.0], &[4.0, 0.0, 0.0]), 5.0);
/// ```
#[inline]
pub fn dist(a: &Point, b: &Point) -> f32 {
    let (x, y, z) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    libm::sqrtf(x * x + y * y + z * z)
}

/// Euclidean distance from an `f32` point to an `f64` point, in `f64`.
#[inline]
pub fn dist64(a: &Point, b: &[f64; 3]) -> f64 {
    let (x, y, z) = (
        f64::from(a[0]) - b[0],
        f64::from(a[1]) - b[1],
        f64::from(a[2]) - b[2],
    );
    libm::sqrt(x * x + y * y + z * z)
}

/// Euclidean distance between two `f64` points, in `f64`.
#[inline]
pub fn dist64_f64(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let (x, y, z) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    libm::sqrt(x * x + y * y + z * z)
}

/// The range `r = (min, max)` widened to contain `x` (an empty range is `(+∞, −∞)`).
#[inline]
pub fn widen<F: Copy + PartialOrd>(r: (F, F), x: F) -> (F, F) {
    (if x < r.0 { x } else { r.0 }, if x > r.1 { x } else { r.1 })
}

/// Absolute path times `(t0 + lo, t0 + hi)` of [`Config::alias_free`] (m): the window in
/// which the factorised column's band sum has no wrap-around.
pub fn alias_window(cfg: &Config) -> (f64, f64) {
    let (lo, hi) = cfg.alias_free();
    (lo + cfg.t0(), hi + cfg.t0())
}

/// Whether some path time `leg + path` with `leg ∈ legs` and `path ∈ paths` (ranges
/// `(min, max)`) leaves `window` ([`alias_window`]). `false` for an empty `legs` range (no
/// row yet).
///
/// ```
/// use vltm_kernel::geometry::leaves_window;
/// assert!(!leaves_window((0.0, 10.0), (1.0, 2.0), (3.0, 8.0)));
/// assert!(leaves_window((0.0, 10.0), (1.0, 2.5), (3.0, 8.0)));
/// assert!(!leaves_window((0.0, 10.0), (f64::INFINITY, f64::NEG_INFINITY), (3.0, 80.0)));
/// ```
#[inline]
pub fn leaves_window<F: Copy + PartialOrd + Add<Output = F>>(
    window: (F, F),
    legs: (F, F),
    paths: (F, F),
) -> bool {
    legs.0 <= legs.1 && (legs.0 + paths.0 < window.0 || legs.1 + paths.1 > window.1)
}
