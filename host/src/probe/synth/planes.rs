//! Planes from the direct-light image: the columns of [`Surfels::from_direct`] split into
//! planar groups per cluster, each group a [`Facet`] (a rectangle) to refine
//! ([`super::refine_facets`]), and the wavelength of the image to read them from.
//!
//! Per cluster, the columns' centres get a least-squares plane (the smallest principal axis).
//! A cluster whose RMS distance to it exceeds `split_tol` is split in two by `k`-planes (seeded
//! by the two most different column normals, then points assigned to the nearer plane), at
//! most twice (four facets per cluster), when that cuts the squared residual at least 4× and
//! the two planes meet at 35° or more (the depth map of one plane bends by up to about 25°
//! where the image blurs its edges). Groups of fewer than 4 columns are dropped. Each facet's
//! frame: normal toward the wall, `v` the in-plane direction of +y (of +x for a
//! near-horizontal facet), `u = v × n`; its extent the columns' projections widened by half
//! the column pitch.
//!
//! Cost: `O(columns²)` per cluster for the seeds, a few 3 × 3 eigenproblems. Memory: the
//! columns' centres and normals.

use super::facet::Facet;
use super::surfels::Surfels;
use super::vec3::{V3, dot, unit};
use crate::error::{Error, Result};
use crate::io::capture::Geometry;

/// Least-squares plane of `pts`: centroid, unit normal (smallest principal axis) and the
/// sum of squared distances.
fn plane(pts: &[V3]) -> (V3, V3, f64) {
    let m = pts.len().max(1) as f64;
    let c: V3 = core::array::from_fn(|i| pts.iter().map(|p| p[i]).sum::<f64>() / m);
    let mut cov = [[0.0f64; 3]; 3];
    for p in pts {
        let d: V3 = core::array::from_fn(|i| p[i] - c[i]);
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += d[i] * d[j];
            }
        }
    }
    let n = smallest_axis(cov);
    let ssr = pts
        .iter()
        .map(|p| dot(core::array::from_fn(|i| p[i] - c[i]), n).powi(2))
        .sum();
    (c, n, ssr)
}

/// Eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix (cyclic Jacobi).
fn smallest_axis(mut a: [[f64; 3]; 3]) -> V3 {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-30 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() <= 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in &mut a {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (rp, rq) = (a[p], a[q]);
            a[p] = core::array::from_fn(|k| c * rp[k] - s * rq[k]);
            a[q] = core::array::from_fn(|k| s * rp[k] + c * rq[k]);
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let k = (0..3)
        .min_by(|&i, &j| a[i][i].total_cmp(&a[j][j]))
        .unwrap_or(2);
    unit([v[0][k], v[1][k], v[2][k]])
}

/// The smallest angle between two planes of a split (degrees): the depth map of one plane
/// bends by up to about 25° at its edges where the phasor-field image blurs them.
const MIN_FOLD: f64 = 35.0;

/// The fewest columns a facet starts from: smaller groups are the image's side lobes and
/// noise more often than surfaces (a surface they miss is grown back from its neighbours').
const MIN_COLUMNS: usize = 4;

/// Splits the column set `idx` (centres `pts`, normals `nrm`) into at most `2^depth` planar
/// groups (module docs).
fn split(
    pts: &[V3],
    nrm: &[V3],
    idx: Vec<usize>,
    tol: f64,
    depth: usize,
    out: &mut Vec<Vec<usize>>,
) {
    let sub: Vec<V3> = idx.iter().map(|&i| pts[i]).collect();
    let (_, _, ssr) = plane(&sub);
    let rms = (ssr / idx.len().max(1) as f64).sqrt();
    if depth == 0 || idx.len() < 6 || rms <= tol {
        out.push(idx);
        return;
    }
    // Seeds: the two most different normals.
    let (mut sa, mut sb, mut worst) = (idx[0], idx[0], f64::INFINITY);
    for (x, &i) in idx.iter().enumerate() {
        for &j in &idx[x + 1..] {
            let d = dot(nrm[i], nrm[j]);
            if d < worst {
                (sa, sb, worst) = (i, j, d);
            }
        }
    }
    let mut side: Vec<bool> = idx
        .iter()
        .map(|&i| dot(nrm[i], nrm[sb]) > dot(nrm[i], nrm[sa]))
        .collect();
    let mut planes = [(pts[sa], nrm[sa]), (pts[sb], nrm[sb])];
    for _ in 0..10 {
        let groups: [Vec<V3>; 2] = [false, true].map(|s| {
            idx.iter()
                .zip(&side)
                .filter(|(_, x)| **x == s)
                .map(|(&i, _)| pts[i])
                .collect()
        });
        if groups.iter().any(|g| g.len() < 3) {
            out.push(idx);
            return;
        }
        for (k, g) in groups.iter().enumerate() {
            let (c, n, _) = plane(g);
            planes[k] = (c, n);
        }
        let dist = |p: V3, (c, n): (V3, V3)| dot(core::array::from_fn(|i| p[i] - c[i]), n).abs();
        let new: Vec<bool> = idx
            .iter()
            .map(|&i| dist(pts[i], planes[1]) < dist(pts[i], planes[0]))
            .collect();
        if new == side {
            break;
        }
        side = new;
    }
    let groups: [Vec<usize>; 2] = [false, true].map(|s| {
        idx.iter()
            .zip(&side)
            .filter(|(_, x)| **x == s)
            .map(|(&i, _)| i)
            .collect()
    });
    let ssr2: f64 = groups
        .iter()
        .map(|g| plane(&g.iter().map(|&i| pts[i]).collect::<Vec<_>>()).2)
        .sum();
    let fold = {
        let n0 = plane(&groups[0].iter().map(|&i| pts[i]).collect::<Vec<_>>()).1;
        let n1 = plane(&groups[1].iter().map(|&i| pts[i]).collect::<Vec<_>>()).1;
        dot(n0, n1).abs().clamp(0.0, 1.0).acos()
    };
    if groups.iter().any(|g| g.len() < 3) || ssr2 * 4.0 > ssr || fold < MIN_FOLD.to_radians() {
        out.push(idx);
        return;
    }
    for g in groups {
        split(pts, nrm, g, tol, depth - 1, out);
    }
}

/// Planar facets from the column patches of [`Surfels::from_direct`] (module docs): `split_tol`
/// the RMS distance (m) above which a cluster is split, `pitch` the column pitch (m) by half
/// of which the extents are widened.
///
/// # Errors
/// `surfels` without patches, or `split_tol`/`pitch` not positive and finite.
pub fn facets_from_surfels(s: &Surfels, split_tol: f64, pitch: f64) -> Result<Vec<Facet>> {
    if s.patches.is_empty() {
        return Err(Error::arg(
            "surfels",
            "facets need the column patches of Surfels::from_direct",
        ));
    }
    if !(split_tol.is_finite() && split_tol > 0.0) {
        return Err(Error::arg("split_tol", "must be positive and finite (m)"));
    }
    if !(pitch.is_finite() && pitch > 0.0) {
        return Err(Error::arg("pitch", "must be positive and finite (m)"));
    }
    let pts: Vec<V3> = s
        .patches
        .iter()
        .map(|r| {
            let m = r.len().max(1) as f64;
            core::array::from_fn(|x| r.clone().map(|k| s.points[k][x]).sum::<f64>() / m)
        })
        .collect();
    let nrm: Vec<V3> = s.patches.iter().map(|r| s.normals[r.start]).collect();
    let cl: Vec<usize> = s.patches.iter().map(|r| s.cluster[r.start]).collect();
    let mut out = Vec::new();
    for c in 0..s.clusters {
        let idx: Vec<usize> = (0..pts.len()).filter(|&i| cl[i] == c).collect();
        if idx.is_empty() {
            continue;
        }
        let mut groups = Vec::new();
        split(&pts, &nrm, idx, split_tol, 2, &mut groups);
        for g in groups {
            if g.len() < MIN_COLUMNS {
                continue;
            }
            let gp: Vec<V3> = g.iter().map(|&i| pts[i]).collect();
            let (centre, n) = if gp.len() >= 3 {
                let (c, n, _) = plane(&gp);
                (c, n)
            } else {
                (gp[0], nrm[g[0]])
            };
            let toward: V3 = core::array::from_fn(|x| g.iter().map(|&i| nrm[i][x]).sum());
            let mut f = Facet::framed(centre, n, toward, c);
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for p in &gp {
                let d: V3 = core::array::from_fn(|i| p[i] - centre[i]);
                for (k, axis) in [f.u, f.v].into_iter().enumerate() {
                    let x = dot(d, axis);
                    lo[k] = lo[k].min(x);
                    hi[k] = hi[k].max(x);
                }
            }
            let h = 0.5 * pitch;
            f.extent = [lo[0] - h, hi[0] + h, lo[1] - h, hi[1] + h];
            out.push(f);
        }
    }
    if out.is_empty() {
        return Err(Error::arg(
            "surfels",
            format!("no plane of {MIN_COLUMNS} columns or more in the direct light"),
        ));
    }
    Ok(out)
}

/// The wavelength (m) of the direct-light image that [`Surfels::from_direct`] reads planes
/// from: half the coarser of the laser and SPAD pitches (`None` for a single spot). Give the
/// image the default envelope `2λ/3`.
///
/// The default wavelength (twice the pitch) blurs depth along z too much to read a plane's
/// tilt from (10–35° off on the path-traced scenes); a wavelength of half the pitch sharpens
/// it (0.6–2.4° and 2–4 mm on `panel_figure`, before any refinement). A quarter pitch breaks
/// the surfaces into fragments: the lateral sampling of the wall no longer holds the wave.
pub fn geometry_wavelength(g: &Geometry) -> Option<f64> {
    let p = f64::from(
        vltm_kernel::geometry::pitch(&g.lasers, g.laser_shape)
            .max(vltm_kernel::geometry::pitch(&g.spads, g.spad_shape)),
    );
    (p > 0.0).then_some(0.5 * p)
}
