//! The hidden surfaces as surfels: points, normals, areas and the cluster (object) each belongs
//! to; from a direct-light volume ([`Surfels::from_direct`]) or given ([`Surfels::new`]).

use crate::error::{Error, Result};
use crate::volume::Volume;

/// Hidden surfaces sampled as small Lambertian patches (surfels), in the capture's frame
/// (metres; relay wall at its spots' z, hidden scene at larger z).
#[derive(Clone, Debug, PartialEq)]
pub struct Surfels {
    /// Centres (m).
    pub points: Vec<[f64; 3]>,
    /// Unit normals, pointing out of the surface (a surfel lit from the side its normal
    /// points to).
    pub normals: Vec<[f64; 3]>,
    /// Areas (m²).
    pub areas: Vec<f64>,
    /// Cluster (object) index of each surfel, `0..clusters`: each cluster gets its own
    /// reflectance, and per histogram its own gain and delay.
    pub cluster: Vec<usize>,
    /// Number of clusters.
    pub clusters: usize,
    /// Surfels that move and scale together when the geometry is refined
    /// ([`super::refine`]): one range per column of [`Surfels::from_direct`]; empty for
    /// surfels given whole ([`Surfels::new`]).
    pub patches: Vec<std::ops::Range<usize>>,
}

impl Surfels {
    /// Surfels from their parts, checked: equal lengths, finite points, unit normals, positive
    /// areas, cluster indices dense from 0, at least one surfel.
    ///
    /// # Errors
    /// [`Error::Argument`] naming `surfels` for any of the above.
    pub fn new(
        points: Vec<[f64; 3]>,
        normals: Vec<[f64; 3]>,
        areas: Vec<f64>,
        cluster: Vec<usize>,
    ) -> Result<Self> {
        let n = points.len();
        if n == 0 {
            return Err(Error::arg("surfels", "no surfel: nothing to render"));
        }
        if normals.len() != n || areas.len() != n || cluster.len() != n {
            return Err(Error::arg(
                "surfels",
                format!(
                    "{n} points but {} normals, {} areas and {} cluster indices",
                    normals.len(),
                    areas.len(),
                    cluster.len()
                ),
            ));
        }
        if let Some(i) = points.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
            return Err(Error::arg("surfels", format!("point {i} is not finite")));
        }
        if let Some(i) = normals
            .iter()
            .position(|v| ((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() - 1.0).abs() > 1e-6)
        {
            return Err(Error::arg(
                "surfels",
                format!("normal {i} is not a unit vector"),
            ));
        }
        if let Some(i) = areas.iter().position(|a| !(a.is_finite() && *a > 0.0)) {
            return Err(Error::arg("surfels", format!("area {i} is not positive")));
        }
        let clusters = cluster.iter().max().map_or(0, |m| m + 1);
        let mut seen = vec![false; clusters];
        cluster.iter().for_each(|&c| seen[c] = true);
        if let Some(c) = seen.iter().position(|s| !s) {
            return Err(Error::arg("surfels", format!("cluster {c} has no surfel")));
        }
        Ok(Self {
            points,
            normals,
            areas,
            cluster,
            clusters,
            patches: Vec::new(),
        })
    }

    /// Number of surfels.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether there is no surfel (never, for a value built by [`Surfels::new`]).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Total area per cluster (m²).
    pub fn cluster_areas(&self) -> Vec<f64> {
        let mut a = vec![0.0; self.clusters];
        for (&c, &x) in self.cluster.iter().zip(&self.areas) {
            a[c] += x;
        }
        a
    }

    /// The surfaces seen in a direct-light volume (a grid, `values` its `|T(x_v, x_v)|` in C
    /// order): per lateral column `(x, y)` whose brightest voxel exceeds `epsilon × max`, the
    /// depth of that voxel refined by a parabola through it and its two neighbours in z; the
    /// normal from the depth map's gradient (central differences over kept neighbours), turned
    /// toward the wall; `sub × sub` surfels per column on that tangent plane, each with its
    /// share of the column's area projected on the plane. Neighbouring columns whose depths
    /// differ by less than `2·max(Δx, Δz)` belong to the same cluster (4-connected).
    ///
    /// The depth is what the phasor-field image resolves (a fraction of its envelope σ along
    /// z); the lateral extent is blurred by about λ/2: the surfels reach beyond the true
    /// edges. [`super::SynthModel::fit`] absorbs the rest in its reflectances, gains and delays.
    ///
    /// # Errors
    /// [`Error::Argument`]: `volume` not a grid with at least 3 depths (`volume`), `values`
    /// of another length or not finite, `epsilon` outside `(0, 1)`, no light above it, a
    /// surface at or behind `wall_z` (`surfels`).
    pub fn from_direct(
        volume: &Volume,
        values: &[f32],
        epsilon: f32,
        sub: usize,
        wall_z: f64,
    ) -> Result<Self> {
        let Some(axes) = volume.axes else {
            return Err(Error::arg(
                "volume",
                "surfels from the direct light need a grid volume (x, y and z ranges)",
            ));
        };
        let [nx, ny, nz] = volume.shape;
        if nz < 3 {
            return Err(Error::arg(
                "volume",
                "surfels from the direct light need at least 3 depths along z",
            ));
        }
        if values.len() != volume.points.len() {
            return Err(Error::arg(
                "volume",
                format!("{} values for {} voxels", values.len(), volume.points.len()),
            ));
        }
        if values.iter().any(|v| !v.is_finite()) {
            return Err(Error::arg(
                "volume",
                "the direct light holds non-finite values",
            ));
        }
        if !(epsilon > 0.0 && epsilon < 1.0) {
            return Err(Error::arg("epsilon", "must lie in (0, 1)"));
        }
        let step = |i: usize, n: usize| {
            if n > 1 {
                f64::from(axes[i][1] - axes[i][0]) / (n - 1) as f64
            } else {
                0.0
            }
        };
        let (hx, hy, hz) = (step(0, nx), step(1, ny), step(2, nz));
        let z0 = f64::from(axes[2][0]);
        let peak = values.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        if peak <= 0.0 {
            return Err(Error::arg("volume", "the direct light is zero everywhere"));
        }
        let floor = epsilon * peak;
        // Depth per kept column.
        let mut depth: Vec<Option<f64>> = vec![None; nx * ny];
        for i in 0..nx {
            for j in 0..ny {
                let col = &values[(i * ny + j) * nz..(i * ny + j + 1) * nz];
                let (k, m) = col
                    .iter()
                    .enumerate()
                    .fold((0, 0.0f32), |(bk, bm), (k, v)| {
                        if v.abs() > bm { (k, v.abs()) } else { (bk, bm) }
                    });
                if m <= floor {
                    continue;
                }
                let off = if k > 0 && k + 1 < nz {
                    let (a, b, c) = (
                        f64::from(col[k - 1].abs()),
                        f64::from(m),
                        f64::from(col[k + 1].abs()),
                    );
                    let den = a - 2.0 * b + c;
                    if den < 0.0 {
                        (0.5 * (a - c) / den).clamp(-0.5, 0.5)
                    } else {
                        0.0
                    }
                } else {
                    0.0
                };
                depth[i * ny + j] = Some(z0 + (k as f64 + off) * hz);
            }
        }
        let at = |i: isize, j: isize| -> Option<f64> {
            (i >= 0 && j >= 0 && (i as usize) < nx && (j as usize) < ny)
                .then(|| depth[i as usize * ny + j as usize])
                .flatten()
        };
        let slope = |a: Option<f64>, c: f64, b: Option<f64>, h: f64| match (a, b) {
            _ if h == 0.0 => 0.0,
            (Some(a), Some(b)) => (b - a) / (2.0 * h),
            (Some(a), None) => (c - a) / h,
            (None, Some(b)) => (b - c) / h,
            (None, None) => 0.0,
        };
        let jump = 2.0 * hx.max(hy).max(hz);
        // Clusters: 4-connected kept columns with close depths.
        let mut label = vec![usize::MAX; nx * ny];
        let mut clusters = 0;
        for start in 0..nx * ny {
            if depth[start].is_none() || label[start] != usize::MAX {
                continue;
            }
            label[start] = clusters;
            let mut stack = vec![start];
            while let Some(c) = stack.pop() {
                let (i, j) = ((c / ny) as isize, (c % ny) as isize);
                let zc = depth[c].unwrap_or(0.0);
                for (di, dj) in [(-1, 0), (1, 0), (0, -1), (0, 1)] {
                    if let Some(z) = at(i + di, j + dj) {
                        let n = (i + di) as usize * ny + (j + dj) as usize;
                        if label[n] == usize::MAX && (z - zc).abs() < jump {
                            label[n] = clusters;
                            stack.push(n);
                        }
                    }
                }
            }
            clusters += 1;
        }
        let sub = sub.max(1);
        let (mut points, mut normals, mut areas, mut cluster, mut patches) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for i in 0..nx {
            for j in 0..ny {
                let Some(z) = depth[i * ny + j] else { continue };
                if z <= wall_z {
                    return Err(Error::arg(
                        "surfels",
                        format!(
                            "a surface at z = {z:.3} m lies at or behind the wall (z = {wall_z:.3} m)"
                        ),
                    ));
                }
                let (ii, jj) = (i as isize, j as isize);
                let gx = slope(at(ii - 1, jj), z, at(ii + 1, jj), hx);
                let gy = slope(at(ii, jj - 1), z, at(ii, jj + 1), hy);
                let len = (gx * gx + gy * gy + 1.0).sqrt();
                let n = [gx / len, gy / len, -1.0 / len];
                let x0 = f64::from(axes[0][0]) + i as f64 * hx;
                let y0 = f64::from(axes[1][0]) + j as f64 * hy;
                let first = points.len();
                let a = hx.max(f64::EPSILON) * hy.max(f64::EPSILON) * len / (sub * sub) as f64;
                for u in 0..sub {
                    for v in 0..sub {
                        let du = ((u as f64 + 0.5) / sub as f64 - 0.5) * hx;
                        let dv = ((v as f64 + 0.5) / sub as f64 - 0.5) * hy;
                        points.push([x0 + du, y0 + dv, z + gx * du + gy * dv]);
                        normals.push(n);
                        areas.push(a);
                        cluster.push(label[i * ny + j]);
                    }
                }
                patches.push(first..points.len());
            }
        }
        let mut out = Self::new(points, normals, areas, cluster)?;
        out.patches = patches;
        Ok(out)
    }
}
