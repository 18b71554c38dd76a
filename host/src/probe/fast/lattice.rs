//! The wall lattice and the voxel grid's layout shared by the FFT paths ([`super::planar`],
//! [`super::confocal`], [`super::resample`], `aligned`) and read by the planner: a regular
//! lattice of wall points in a plane `z = const` (the SPADs, or a confocal scan's wall
//! points), a wall-parallel voxel grid whose x–y pitch divides the lattice's, and how the
//! grid's (depth, phase) sub-grids sit in a zero-padded 2-D convolution of `Mx × My`
//! ([`fft_len`]: lengths `2^a·3^b`).
//!
//! Units: metres. Tolerances are absolute (m): the paths use `1e-5·λ`. Cost: `O(Kv + Ks·log Ks)`
//! with the voxel checks in parallel; memory: one output index per voxel.

use rayon::prelude::*;
use vltm_kernel::Point;

/// A regular 1-D lattice `origin + k·pitch`, k = 0..n.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Axis {
    origin: f64,
    pitch: f64,
    n: usize,
}

/// Sorted distinct values of `xs` merged within `tol`, checked to form a lattice.
fn lattice(xs: impl Iterator<Item = f64>, tol: f64) -> Option<Axis> {
    let mut v: Vec<f64> = xs.collect();
    v.sort_by(f64::total_cmp);
    let mut d: Vec<f64> = Vec::new();
    for x in v {
        match d.last() {
            Some(&l) if (x - l).abs() <= tol => {}
            _ => d.push(x),
        }
    }
    let n = d.len();
    let origin = *d.first()?;
    let pitch = if n > 1 {
        (d[n - 1] - origin) / (n - 1) as f64
    } else {
        0.0
    };
    d.iter()
        .enumerate()
        .all(|(k, &x)| (x - (origin + k as f64 * pitch)).abs() <= tol)
        .then_some(Axis { origin, pitch, n })
}

/// The SPADs as a full regular grid in a plane `z = const`: lattice index per SPAD.
struct SpadGrid {
    x: Axis,
    y: Axis,
    z: f64,
    index: Vec<(usize, usize)>,
}

fn spad_grid(spads: &[Point], tol: f64) -> Result<SpadGrid, String> {
    let z0 = spads.first().ok_or("no SPADs")?[2] as f64;
    if spads.iter().any(|p| (p[2] as f64 - z0).abs() > tol) {
        return Err("the SPADs are not in one plane z = const".into());
    }
    let x = lattice(spads.iter().map(|p| p[0] as f64), tol)
        .ok_or("the SPAD x coordinates are not a regular lattice")?;
    let y = lattice(spads.iter().map(|p| p[1] as f64), tol)
        .ok_or("the SPAD y coordinates are not a regular lattice")?;
    if x.n * y.n != spads.len() {
        return Err(format!(
            "{} SPADs do not fill their {}×{} lattice",
            spads.len(),
            x.n,
            y.n
        ));
    }
    let idx = |a: &Axis, c: f32| {
        if a.n == 1 {
            0
        } else {
            ((c as f64 - a.origin) / a.pitch).round() as usize
        }
    };
    let index: Vec<(usize, usize)> = spads
        .iter()
        .map(|p| (idx(&x, p[0]), idx(&y, p[1])))
        .collect();
    let mut seen = vec![false; spads.len()];
    for &(i, j) in &index {
        let k = i * y.n + j;
        if k >= seen.len() || std::mem::replace(&mut seen[k], true) {
            return Err("two SPADs share a lattice site".into());
        }
    }
    Ok(SpadGrid { x, y, z: z0, index })
}

/// Origin (m), pitch (m), points per axis (x, y) and the plane's z (m) of a wall lattice.
pub(crate) type WallLattice = ([f64; 2], [f64; 2], [usize; 2], f64);

/// A regular wall lattice in a plane `z = const` (the SPADs, or a confocal capture's wall
/// points): origin and pitch along x and y (m; pitch 0 along an axis of one point), points
/// per axis and the plane's z, or why the points are not one (lattice tolerance `tol`, m).
///
/// # Errors
/// A one-line reason, as [`layout`] gives it.
pub(crate) fn wall_lattice(wall: &[Point], tol: f64) -> Result<WallLattice, String> {
    let g = spad_grid(wall, tol)?;
    Ok((
        [g.x.origin, g.y.origin],
        [g.x.pitch, g.y.pitch],
        [g.x.n, g.y.n],
        g.z,
    ))
}

/// How a voxel axis maps onto a SPAD axis: polyphase factor, offsets, sub-grid lengths.
#[derive(Clone, Debug)]
struct AxisMap {
    /// SPAD lattice pitch used for the kernel offsets (m).
    pitch: f64,
    /// Per phase φ: offset `v(φ) − s(0)` (m) and number of voxels `⌈(nv − φ)/r⌉`.
    phases: Vec<(f64, usize)>,
}

fn axis_map(s: &Axis, v: &[f64], tol: f64, name: &str) -> Result<AxisMap, String> {
    let nv = v.len();
    let pv = if nv > 1 {
        (v[nv - 1] - v[0]) / (nv - 1) as f64
    } else {
        0.0
    };
    let (pitch, r) = match (s.n > 1, nv > 1) {
        (_, false) => (if s.n > 1 { s.pitch } else { 1.0 }, 1),
        (false, true) => (pv, 1),
        (true, true) => {
            let r = (s.pitch / pv).round();
            if r < 1.0 || (r * pv - s.pitch).abs() > tol {
                return Err(format!(
                    "voxel pitch {pv:.6} m along {name} does not divide the SPAD pitch {:.6} m",
                    s.pitch
                ));
            }
            (s.pitch, r as usize)
        }
    };
    let phases = (0..r.min(nv))
        .map(|f| (v[f] - s.origin, (nv - f).div_ceil(r)))
        .collect();
    Ok(AxisMap { pitch, phases })
}

/// One (depth, phase) sub-grid of a wall-parallel voxel grid on a wall lattice: its offsets
/// from the lattice origin and where its voxels sit in the convolution's output image.
#[derive(Clone, Debug)]
pub(super) struct SubGrid {
    /// Depth below the wall plane (m).
    pub(super) dz: f64,
    /// Offset of the sub-grid's first voxel from the lattice origin, x and y (m).
    pub(super) dx: f64,
    pub(super) dy: f64,
    /// Voxels of the sub-grid along x and y.
    pub(super) cx: usize,
    pub(super) cy: usize,
    /// (cell `i'x·My + i'y` of the output image, voxel index).
    pub(super) outputs: Vec<(u32, u32)>,
}

/// A regular wall lattice and a wall-parallel voxel grid whose pitch divides it, laid out for
/// a zero-padded 2-D convolution (shared by [`super::Planar`] and [`super::confocal`]).
#[derive(Clone, Debug)]
pub(crate) struct Layout {
    /// FFT size (`2^a·3^b ≥ n_s + n_v − 1` per axis, [`fft_len`]).
    pub(super) mx: usize,
    pub(super) my: usize,
    /// Wall lattice size.
    pub(super) nsx: usize,
    pub(super) nsy: usize,
    /// Wall lattice pitch x, y (m).
    pub(super) px: f64,
    pub(super) py: f64,
    /// Output rows the inverse y-pass must compute.
    pub(super) rows_out: usize,
    /// Cell `ix·My + iy` of each wall point (input order).
    pub(super) cell: Vec<usize>,
    /// The (depth, phase) sub-grids, depth-major.
    pub(super) subgrids: Vec<SubGrid>,
}

/// The smallest `2^a·3^b ≥ n`: a transform length `rustfft` runs at nearly the speed of a
/// power of two, often much shorter than the next one (192 for 175–192, 144 for 129–144).
pub(crate) fn fft_len(n: usize) -> usize {
    let p2 = n.max(1).next_power_of_two();
    let mut best = p2;
    let mut t = 1usize;
    while t < p2 {
        let mut m = t;
        while m < n {
            m *= 2;
        }
        best = best.min(m);
        t *= 3;
    }
    best
}

impl Layout {
    /// FFT size `(Mx, My)` and number of (depth, phase) sub-grids.
    pub(crate) fn size(&self) -> (usize, usize, usize) {
        (self.mx, self.my, self.subgrids.len())
    }
}

/// Lays out `voxels` (C order over `shape`) against the wall lattice `wall`, or says why
/// they do not fit (lattice tolerance `tol`, m).
pub(crate) fn layout(
    wall: &[Point],
    voxels: &[Point],
    shape: [usize; 3],
    tol: f64,
) -> Result<Layout, String> {
    let [nx, ny, nz] = shape;
    if nx * ny * nz != voxels.len() || voxels.is_empty() {
        return Err("the voxels are not a grid".into());
    }
    let g = spad_grid(wall, tol)?;
    let at = |ix: usize, iy: usize, iz: usize| voxels[(ix * ny + iy) * nz + iz];
    // The volume must be a product grid: x depends on ix only, y on iy, z on iz (x-planes
    // checked in parallel).
    let product = (0..nx).into_par_iter().all(|ix| {
        (0..ny).all(|iy| {
            (0..nz).all(|iz| {
                let p = at(ix, iy, iz);
                let q = [at(ix, 0, 0)[0], at(0, iy, 0)[1], at(0, 0, iz)[2]];
                !(0..3).any(|c| (p[c] - q[c]).abs() as f64 > tol)
            })
        })
    });
    if !product {
        return Err("the voxels are not a wall-parallel grid".into());
    }
    // Descending axes (a SPEC `0.5:-0.5:11`) are walked in ascending order.
    let rev_x = nx > 1 && at(nx - 1, 0, 0)[0] < at(0, 0, 0)[0];
    let rev_y = ny > 1 && at(0, ny - 1, 0)[1] < at(0, 0, 0)[1];
    let ix_of = |i: usize| if rev_x { nx - 1 - i } else { i };
    let iy_of = |i: usize| if rev_y { ny - 1 - i } else { i };
    let vx: Vec<f64> = (0..nx).map(|i| at(ix_of(i), 0, 0)[0] as f64).collect();
    let vy: Vec<f64> = (0..ny).map(|i| at(0, iy_of(i), 0)[1] as f64).collect();
    let vz: Vec<f64> = (0..nz).map(|i| at(0, 0, i)[2] as f64).collect();
    for a in [&vx, &vy] {
        if a.len() > 1 && lattice(a.iter().copied(), tol).is_none_or(|l| l.n != a.len()) {
            return Err("the voxel axes are not regular".into());
        }
    }
    let mapx = axis_map(&g.x, &vx, tol, "x")?;
    let mapy = axis_map(&g.y, &vy, tol, "y")?;
    let nvx = mapx.phases.iter().map(|p| p.1).max().unwrap_or(1);
    let nvy = mapy.phases.iter().map(|p| p.1).max().unwrap_or(1);
    let mx = fft_len(g.x.n + nvx - 1);
    let my = fft_len(g.y.n + nvy - 1);
    let (rx, ry) = (mapx.phases.len(), mapy.phases.len());
    // Depth-major, then x phase, then y phase; each sub-grid's outputs made in parallel.
    let subgrids: Vec<SubGrid> = (0..nz * rx * ry)
        .into_par_iter()
        .map(|k| {
            let (iz, fx_, fy_) = (k / (rx * ry), (k / ry) % rx, k % ry);
            let ((dx, cx), (dy, cy)) = (mapx.phases[fx_], mapy.phases[fy_]);
            let mut outputs = Vec::with_capacity(cx * cy);
            for i in 0..cx {
                for j in 0..cy {
                    let v = (ix_of(i * rx + fx_) * ny + iy_of(j * ry + fy_)) * nz + iz;
                    outputs.push(((i * my + j) as u32, v as u32));
                }
            }
            SubGrid {
                dz: vz[iz] - g.z,
                dx,
                dy,
                cx,
                cy,
                outputs,
            }
        })
        .collect();
    Ok(Layout {
        mx,
        my,
        nsx: g.x.n,
        nsy: g.y.n,
        px: mapx.pitch,
        py: mapy.pitch,
        rows_out: nvx,
        cell: g.index.iter().map(|&(i, j)| i * my + j).collect(),
        subgrids,
    })
}

#[cfg(test)]
mod tests {
    use super::fft_len;

    /// The smallest 3-smooth-times-power-of-two length, checked by brute force.
    #[test]
    fn fft_lengths() {
        let smooth = |mut m: usize| {
            while m.is_multiple_of(2) {
                m /= 2;
            }
            while m.is_multiple_of(3) {
                m /= 3;
            }
            m == 1
        };
        for n in 1..2000 {
            let want = (n..).find(|&m| smooth(m)).unwrap();
            assert_eq!(fft_len(n), want, "n = {n}");
        }
        assert_eq!(fft_len(174), 192);
        assert_eq!(fft_len(127), 128);
    }
}
