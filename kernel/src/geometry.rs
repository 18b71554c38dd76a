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
//! * [`pitch`]: the spacing of a grid of `f32` points (the coarser axis), from [`dist`].
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

/// The pitch of a C-order grid of `shape = [nx, ny]` points (`pts[i·ny + j]`, as the
/// relay wall's laser and SPAD grids): the coarser of the two axes' spacings, each the
/// [`dist`] from the first point to its neighbour along the axis (`pts[ny]` along x,
/// `pts[1]` along y), in `f32`; 0 along an axis of one point (and where `pts` has no such
/// neighbour), so 0 for a single point.
///
/// ```
/// use vltm_kernel::geometry::pitch;
/// let grid = [[0.0, 0.0, 0.0], [0.0, 0.1, 0.0], [0.3, 0.0, 0.0], [0.3, 0.1, 0.0]];
/// assert_eq!(pitch(&grid, [2, 2]), 0.3);
/// assert_eq!(pitch(&grid[..1], [1, 1]), 0.0);
/// ```
pub fn pitch(pts: &[Point], shape: [usize; 2]) -> f32 {
    let step = |i: usize, n: usize| match (pts.first(), pts.get(i)) {
        (Some(a), Some(b)) if n > 1 => dist(a, b),
        _ => 0.0,
    };
    let px = step(shape[1], shape[0]);
    let py = step(1, shape[1]);
    px.max(py)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The pitch is the coarser axis, each axis's spacing the distance of the grid's first
    /// point to its neighbour along it, bit for bit; an axis of one point counts 0.
    #[test]
    fn pitch_is_the_coarser_axis() {
        // 3 × 2 points (C order: x rows of 2), x step 0.25, y step 0.1, on a tilted plane.
        let pts: [Point; 6] = core::array::from_fn(|k| {
            let (i, j) = ((k / 2) as f32, (k % 2) as f32);
            [0.25 * i, 0.1 * j, 0.05 * i + 0.01 * j]
        });
        assert_eq!(pitch(&pts, [3, 2]), dist(&pts[0], &pts[2]));
        assert!(pitch(&pts, [3, 2]) > dist(&pts[0], &pts[1]));
        // One row: only y counts; one column: only x.
        assert_eq!(pitch(&pts[..2], [1, 2]), dist(&pts[0], &pts[1]));
        let col = [pts[0], pts[2], pts[4]];
        assert_eq!(pitch(&col, [3, 1]), dist(&pts[0], &pts[2]));
        assert_eq!(pitch(&pts[..1], [1, 1]), 0.0);
        assert_eq!(pitch(&[], [1, 1]), 0.0);
        // A shape larger than the points has no neighbour along x: 0 there, not a panic.
        assert_eq!(pitch(&pts[..2], [2, 2]), dist(&pts[0], &pts[1]));
    }
}
