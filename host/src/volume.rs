//! Voxel sets: wall-parallel grids from a `SPEC` and explicit point lists.
//!
//! `SPEC` is `x0:x1:nx,y0:y1:ny,z0:z1:nz` in metres with inclusive end points (`nx` samples
//! from `x0` to `x1`; `x0:x0:1` is a single plane). A point list is `x,y,z;x,y,z;…`.
//! Voxels are ordered C-style over `(nx, ny, nz)`: index `(ix·ny + iy)·nz + iz`, the layout of
//! the `.npy` outputs. Voxels must be in front of the wall (z > 0); the virtual lens cannot
//! image a point on the wall itself.

use crate::error::{Error, Result};
use vltm_kernel::Point;

/// A set of voxels with an optional grid structure.
#[derive(Clone, Debug, PartialEq)]
pub struct Volume {
    /// Voxel centres, C order over `shape`.
    pub points: Vec<Point>,
    /// `[nx, ny, nz]` for grids; `[K, 1, 1]` for point lists.
    pub shape: [usize; 3],
    /// First and last coordinate along x, y, z (grids only).
    pub axes: Option<[[f32; 2]; 3]>,
}

/// Largest number of voxels accepted from a SPEC (guards against typos such as `…:100000`).
pub const MAX_VOXELS: usize = 50_000_000;

fn num(arg: &str, s: &str, what: &str) -> Result<f32> {
    let v: f32 = s
        .trim()
        .parse()
        .map_err(|_| Error::arg(arg, format!("{what}: `{s}` is not a number")))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::arg(arg, format!("{what}: `{s}` is not finite")))
    }
}

impl Volume {
    /// A grid with `n[i]` samples from `lo[i]` to `hi[i]` (inclusive) per axis.
    ///
    /// # Errors
    /// [`Error::Argument`] for zero samples, a non-finite bound, a voxel at z ≤ 0, or more than
    /// [`MAX_VOXELS`] voxels.
    pub fn grid(lo: [f32; 3], hi: [f32; 3], n: [usize; 3]) -> Result<Self> {
        let arg = "volume";
        if n.contains(&0) {
            return Err(Error::arg(arg, "every axis needs at least 1 sample"));
        }
        let total = n
            .iter()
            .try_fold(1usize, |a, &b| a.checked_mul(b))
            .filter(|&t| t <= MAX_VOXELS);
        let Some(total) = total else {
            return Err(Error::arg(
                arg,
                format!(
                    "{}×{}×{} voxels is more than the {MAX_VOXELS} a volume may hold (a guard \
                     against typos, docs/limits.md): use a coarser grid, or split the volume \
                     into slabs (z ranges) run one after the other",
                    n[0], n[1], n[2]
                ),
            ));
        };
        if lo.iter().chain(&hi).any(|c| !c.is_finite()) {
            return Err(Error::arg(arg, "bounds must be finite"));
        }
        if lo[2].min(hi[2]) <= 0.0 {
            return Err(Error::arg(
                arg,
                format!(
                    "z must be > 0 (in front of the wall), found {}",
                    lo[2].min(hi[2])
                ),
            ));
        }
        let at = |i: usize, k: usize| {
            if n[i] == 1 {
                lo[i]
            } else {
                lo[i] + (hi[i] - lo[i]) * k as f32 / (n[i] - 1) as f32
            }
        };
        let mut points = Vec::with_capacity(total);
        for ix in 0..n[0] {
            for iy in 0..n[1] {
                for iz in 0..n[2] {
                    points.push([at(0, ix), at(1, iy), at(2, iz)]);
                }
            }
        }
        Ok(Self {
            points,
            shape: n,
            axes: Some([[lo[0], hi[0]], [lo[1], hi[1]], [lo[2], hi[2]]]),
        })
    }

    /// A list of points.
    ///
    /// # Errors
    /// [`Error::Argument`] for an empty list or a point at z ≤ 0.
    pub fn points(points: Vec<Point>) -> Result<Self> {
        if points.is_empty() {
            return Err(Error::arg("volume", "the point list is empty"));
        }
        if let Some(p) = points
            .iter()
            .find(|p| p[2].is_nan() || p[2] <= 0.0 || !p.iter().all(|c| c.is_finite()))
        {
            return Err(Error::arg(
                "volume",
                format!("voxel {p:?} is not in front of the wall (need finite z > 0)"),
            ));
        }
        let k = points.len();
        Ok(Self {
            points,
            shape: [k, 1, 1],
            axes: None,
        })
    }

    /// Parses a `SPEC` (`x0:x1:nx,y0:y1:ny,z0:z1:nz`) or a point list (`x,y,z;x,y,z`).
    ///
    /// ```
    /// let v = vltm::volume::Volume::parse("-0.5:0.5:3,0:0:1,0.4:1.2:5").unwrap();
    /// assert_eq!(v.shape, [3, 1, 5]);
    /// assert_eq!(v.points[1], [-0.5, 0.0, 0.6]);
    /// assert!(vltm::volume::Volume::parse("-1:1:3,0:0:1,0:1:5").is_err()); // z = 0 is the wall
    /// ```
    ///
    /// # Errors
    /// [`Error::Argument`] (`volume`) naming the malformed part.
    pub fn parse(spec: &str) -> Result<Self> {
        let arg = "volume";
        if spec.contains(':') {
            let axes: Vec<&str> = spec.split(',').collect();
            if axes.len() != 3 {
                return Err(Error::arg(
                    arg,
                    format!(
                        "expected x0:x1:nx,y0:y1:ny,z0:z1:nz, found {} axes in `{spec}`",
                        axes.len()
                    ),
                ));
            }
            let (mut lo, mut hi, mut n) = ([0.0; 3], [0.0; 3], [0; 3]);
            for (i, (ax, name)) in axes.iter().zip(["x", "y", "z"]).enumerate() {
                let parts: Vec<&str> = ax.split(':').collect();
                if parts.len() != 3 {
                    return Err(Error::arg(
                        arg,
                        format!("axis {name}: expected {name}0:{name}1:n{name}, found `{ax}`"),
                    ));
                }
                lo[i] = num(arg, parts[0], name)?;
                hi[i] = num(arg, parts[1], name)?;
                n[i] = parts[2].trim().parse().map_err(|_| {
                    Error::arg(
                        arg,
                        format!(
                            "axis {name}: sample count `{}` is not a positive integer",
                            parts[2]
                        ),
                    )
                })?;
            }
            Self::grid(lo, hi, n)
        } else {
            let pts = spec
                .split(';')
                .filter(|s| !s.trim().is_empty())
                .map(|p| parse_point(arg, p))
                .collect::<Result<Vec<_>>>()?;
            Self::points(pts)
        }
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether there are no voxels (never true for a constructed volume).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Index of the voxel nearest to `p`.
    pub fn nearest(&self, p: Point) -> usize {
        let d = |q: &Point| (0..3).map(|i| (q[i] - p[i]).powi(2)).sum::<f32>();
        (0..self.points.len())
            .min_by(|&a, &b| d(&self.points[a]).total_cmp(&d(&self.points[b])))
            .unwrap_or(0)
    }

    /// The voxels an object's surface passes through (the nearest voxel of each point of
    /// `surface`, a dense sampling of it), grown by one voxel in every grid direction, in
    /// volume order: "its surface ± one voxel", the set every object mean of vltm's figures
    /// is taken over. Cost: `O(|surface| · len)`.
    pub fn surface_voxels(&self, surface: &[Point]) -> Vec<usize> {
        let [nx, ny, nz] = self.shape;
        let mut on = vec![false; self.len()];
        for p in surface {
            on[self.nearest(*p)] = true;
        }
        let mut grown = on.clone();
        for i in (0..self.len()).filter(|&i| on[i]) {
            let (ix, iy, iz) = (i / (ny * nz), (i / nz) % ny, i % nz);
            let r = |c: usize, n: usize| c.saturating_sub(1)..=(c + 1).min(n - 1);
            for jx in r(ix, nx) {
                for jy in r(iy, ny) {
                    for jz in r(iz, nz) {
                        grown[(jx * ny + jy) * nz + jz] = true;
                    }
                }
            }
        }
        (0..self.len()).filter(|&i| grown[i]).collect()
    }

    /// Grid pitch along each axis (0 for single-sample axes and point lists).
    pub fn pitch(&self) -> [f32; 3] {
        match self.axes {
            Some(ax) => core::array::from_fn(|i| {
                if self.shape[i] > 1 {
                    (ax[i][1] - ax[i][0]).abs() / (self.shape[i] - 1) as f32
                } else {
                    0.0
                }
            }),
            None => [0.0; 3],
        }
    }
}

/// Parses `x,y,z` (metres) for the argument `arg`.
///
/// # Errors
/// [`Error::Argument`] if it is not three finite numbers.
pub fn parse_point(arg: &str, s: &str) -> Result<Point> {
    let c: Vec<&str> = s.split(',').collect();
    if c.len() != 3 {
        return Err(Error::arg(
            arg,
            format!("expected X,Y,Z in metres, found `{s}`"),
        ));
    }
    Ok([
        num(arg, c[0], "x")?,
        num(arg, c[1], "y")?,
        num(arg, c[2], "z")?,
    ])
}
