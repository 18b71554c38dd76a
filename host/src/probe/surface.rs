//! A surface fitted to the direct light, and the image on it (`vltm surface`).
//!
//! A flat object seen at an angle — a sign, a chart — crosses several depth slices of a
//! wall-parallel volume, so no slice shows all of it and the maximum over depth mixes its
//! face with the blur in front of and behind it. [`surface`] finds the object's plane in the
//! direct light and images the light on that plane:
//!
//! 1. **Direct light over a slab** (a grid volume `nx × ny × nz` in front of the object, one
//!    pass of [`direct`](super::direct); on the wall's grid it takes the FFT path).
//! 2. **Depth per column**: for each `(x, y)`, the depth of its brightest voxel (the
//!    `nx × ny` depth map, [`Surface::depth`]).
//! 3. **A plane** `z = a + b·x + c·y` through the columns brighter than
//!    [`SurfaceOptions::floor`] × the slab's maximum, by least squares weighted by their
//!    brightness ([`Surface::plane`], with the fit's weighted RMS depth residual).
//! 4. **The image on the plane**: per column, [`SurfaceOptions::layers`] samples spread over
//!    [`SurfaceOptions::thickness`] along z around the plane, read from the slab by linear
//!    interpolation in z (the slab's voxels are the same sums, so no second pass is needed:
//!    along z the direct light varies on the scale of the virtual pulse σ, and slices a few
//!    millimetres apart sample it finely). Depths outside the slab are clamped to it and
//!    counted ([`Surface::outside`]).
//! 5. **Local contrast** (optional, [`SurfaceOptions::contrast`]): every sample divided by
//!    the front view (the maximum over the layers) blurred by a Gaussian of that many metres,
//!    so that strokes a few centimetres wide stand out where the object's brightness falls off
//!    towards its edges (a retro-reflective sign's does by half). The values are then ratios,
//!    not intensities.
//!
//! Units: metres; intensities are the direct light's `|A|²` (ratios after the contrast step).
//! Cost: one direct-light pass over the slab, then `O(nx·ny·(nz + layers))` and, for the
//! contrast, `O(nx·ny·r)` with `r` the blur's radius in grid steps. Memory: the slab's values
//! and the image, `4·nx·ny·(nz + layers)` bytes.

use vltm_kernel::Point;

use super::output::Output;
use super::wave::Wave;
use crate::error::{Error, Result};
use crate::exec::Exec;
use crate::io::capture::RowSource;
use crate::volume::Volume;

/// How [`surface`] fits the plane and samples the image on it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceOptions {
    /// Columns whose brightest voxel is below `floor` × the slab's maximum are left out of the
    /// plane fit (0 < floor < 1).
    pub floor: f32,
    /// Metres along z that the image's layers span around the plane (≥ 0).
    pub thickness: f32,
    /// Samples per column along z (1–64), evenly spaced over [`Self::thickness`].
    pub layers: usize,
    /// The local-contrast blur's standard deviation in metres (`None`: intensities as they
    /// are).
    pub contrast: Option<f32>,
}

impl Default for SurfaceOptions {
    fn default() -> Self {
        Self {
            floor: 0.25,
            thickness: 0.02,
            layers: 5,
            contrast: None,
        }
    }
}

impl SurfaceOptions {
    /// Checks every field once, naming it (`$floor`, `$thickness`, `$layers`, `$contrast`)
    /// and its valid range.
    pub fn check(&self) -> Result<()> {
        if !(self.floor.is_finite() && self.floor > 0.0 && self.floor < 1.0) {
            return Err(Error::arg(
                "floor",
                format!(
                    "{} is outside (0, 1) (a fraction of the maximum)",
                    self.floor
                ),
            ));
        }
        if !(self.thickness.is_finite() && (0.0..=1.0).contains(&self.thickness)) {
            return Err(Error::arg(
                "thickness",
                format!("{} m is outside [0, 1] m", self.thickness),
            ));
        }
        if !(1..=64).contains(&self.layers) {
            return Err(Error::arg(
                "layers",
                format!("{} is outside 1..=64", self.layers),
            ));
        }
        if let Some(s) = self.contrast
            && !(s.is_finite() && s > 0.0 && s <= 10.0)
        {
            return Err(Error::arg(
                "contrast",
                format!("{s} m is outside (0, 10] m (the blur's standard deviation)"),
            ));
        }
        Ok(())
    }

    /// The layers' offsets along z from the plane (metres), from `-thickness/2` to
    /// `+thickness/2`.
    pub fn offsets(&self) -> Vec<f32> {
        if self.layers == 1 {
            return vec![0.0];
        }
        let step = self.thickness / (self.layers - 1) as f32;
        (0..self.layers)
            .map(|k| -0.5 * self.thickness + step * k as f32)
            .collect()
    }
}

/// A plane fitted to the brightest depth of each column (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneFit {
    /// `[a, b, c]` of `z = a + b·x + c·y` (metres; b, c dimensionless).
    pub plane: [f64; 3],
    /// Columns that entered the fit.
    pub fitted: usize,
    /// The fit's brightness-weighted RMS depth residual (metres).
    pub rms: f64,
}

impl PlaneFit {
    /// The plane's depth at `(x, y)`.
    pub fn z_at(&self, x: f64, y: f64) -> f64 {
        let [a, b, c] = self.plane;
        a + b * x + c * y
    }
}

/// What [`surface`] returns.
#[derive(Clone, Debug)]
pub struct Surface {
    /// The fitted plane.
    pub fit: PlaneFit,
    /// The depth of each column's brightest voxel (metres), `nx × ny` in C order.
    pub depth: Vec<f32>,
    /// The image on the plane, `nx × ny × layers` in C order (see [`Surface::volume`]).
    pub image: Vec<f32>,
    /// The image's sample points: `(x, y, plane(x, y) + offset)`, shape `[nx, ny, layers]`,
    /// with axes whose z range is the plane's depth at the volume's centre ± half the
    /// thickness (for the figure's top view).
    pub volume: Volume,
    /// Samples whose depth fell outside the slab and were clamped to its nearest slice.
    pub outside: usize,
    /// The direct-light pass over the slab (its configuration, path, report and time; its
    /// values are the slab's intensities).
    pub slab: Output,
}

/// Fits the plane to a slab's direct light (`values` over the grid `slab`, C order): steps 2
/// and 3 of the module documentation. Returns the fit and the depth map.
pub fn fit_plane(slab: &Volume, values: &[f32], floor: f32) -> Result<(PlaneFit, Vec<f32>)> {
    let [nx, ny, nz] = slab.shape;
    if values.len() != nx * ny * nz || slab.points.len() != values.len() {
        return Err(Error::arg(
            "volume",
            format!(
                "{} values for a slab of {nx}x{ny}x{nz} voxels",
                values.len()
            ),
        ));
    }
    let top = values.iter().fold(0.0f32, |a, &b| a.max(b));
    if !(top.is_finite() && top > 0.0) {
        return Err(Error::arg(
            "volume",
            "no direct light in the slab (its maximum is 0): move the volume to the object",
        ));
    }
    let mut depth = Vec::with_capacity(nx * ny);
    let mut m = [[0.0f64; 4]; 3];
    let mut fitted = 0;
    let mut pts = Vec::new();
    for (col, vals) in values.chunks_exact(nz).enumerate() {
        let (k, v) =
            vals.iter().enumerate().fold(
                (0, f32::NEG_INFINITY),
                |a, (k, &v)| if v > a.1 { (k, v) } else { a },
            );
        let p = slab.points[col * nz + k];
        depth.push(p[2]);
        if v >= floor * top {
            let (x, y, z, w) = (
                f64::from(p[0]),
                f64::from(p[1]),
                f64::from(p[2]),
                f64::from(v / top),
            );
            let r = [1.0, x, y];
            for i in 0..3 {
                for j in 0..3 {
                    m[i][j] += w * r[i] * r[j];
                }
                m[i][3] += w * r[i] * z;
            }
            pts.push([x, y, z, w]);
            fitted += 1;
        }
    }
    let plane = solve3(m).ok_or_else(|| {
        Error::arg(
            "volume",
            format!(
                "no plane through the {fitted} columns brighter than {floor}·max (they lie on \
                 a line or are fewer than 3): widen the volume in x and y or lower --floor"
            ),
        )
    })?;
    let (mut r2, mut wsum) = (0.0, 0.0);
    for [x, y, z, w] in pts {
        let e = z - (plane[0] + plane[1] * x + plane[2] * y);
        r2 += w * e * e;
        wsum += w;
    }
    let rms = (r2 / wsum).sqrt();
    Ok((PlaneFit { plane, fitted, rms }, depth))
}

/// Gauss–Jordan elimination of a 3×3 system `[A | b]` with partial pivoting; `None` when it
/// is singular (relative to its scale).
fn solve3(mut m: [[f64; 4]; 3]) -> Option<[f64; 3]> {
    let scale = m
        .iter()
        .flat_map(|r| r[..3].iter())
        .fold(0.0f64, |a, &b| a.max(b.abs()));
    if scale.is_nan() || scale <= 0.0 {
        return None;
    }
    for c in 0..3 {
        let p = (c..3).max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs()))?;
        if m[p][c].abs() <= 1e-12 * scale {
            return None;
        }
        m.swap(c, p);
        let d = m[c][c];
        for v in &mut m[c] {
            *v /= d;
        }
        let pivot = m[c];
        for (r, row) in m.iter_mut().enumerate() {
            if r != c {
                let f = row[c];
                for (v, pv) in row.iter_mut().zip(pivot) {
                    *v -= f * pv;
                }
            }
        }
    }
    Some([m[0][3], m[1][3], m[2][3]])
}

/// Samples the slab's values (`values` over the grid `slab`) on the plane `fit` at the given
/// offsets along z (step 4 of the module documentation): returns the image
/// (`nx × ny × offsets.len()`, C order), its sample points and the count of samples clamped to
/// the slab.
pub fn sample_plane(
    slab: &Volume,
    values: &[f32],
    fit: &PlaneFit,
    offsets: &[f32],
) -> (Vec<f32>, Vec<Point>, usize) {
    let [nx, ny, nz] = slab.shape;
    let layers = offsets.len();
    let mut image = Vec::with_capacity(nx * ny * layers);
    let mut points = Vec::with_capacity(nx * ny * layers);
    let mut outside = 0;
    let z0 = f64::from(slab.points[0][2]);
    let dz = if nz > 1 {
        f64::from(slab.points[1][2]) - z0
    } else {
        0.0
    };
    for col in 0..nx * ny {
        let p = slab.points[col * nz];
        let vals = &values[col * nz..(col + 1) * nz];
        let zc = fit.z_at(f64::from(p[0]), f64::from(p[1]));
        for &o in offsets {
            let z = zc + f64::from(o);
            let u = if dz > 0.0 { (z - z0) / dz } else { 0.0 };
            let uc = u.clamp(0.0, (nz - 1) as f64);
            if uc != u {
                outside += 1;
            }
            let k = (uc.floor() as usize).min(nz.saturating_sub(2));
            let v = if nz == 1 {
                vals[0]
            } else {
                let f = (uc - k as f64) as f32;
                vals[k] * (1.0 - f) + vals[k + 1] * f
            };
            image.push(v);
            points.push([p[0], p[1], z as f32]);
        }
    }
    (image, points, outside)
}

/// Divides each sample by the front view (maximum over the layers) blurred by a Gaussian of
/// `sigma` metres (step 5), truncated at 3σ and renormalised at the edges; a floor of 1e-3 of
/// the blurred maximum keeps empty regions finite.
pub fn local_contrast(image: &[f32], shape: [usize; 3], pitch: [f32; 2], sigma: f32) -> Vec<f32> {
    let [nx, ny, layers] = shape;
    let front: Vec<f64> = image
        .chunks_exact(layers)
        .map(|c| f64::from(c.iter().fold(0.0f32, |a, &b| a.max(b))))
        .collect();
    let kernel = |pitch: f32| -> Vec<f64> {
        let s = if pitch > 0.0 {
            f64::from(sigma / pitch)
        } else {
            0.0
        };
        if s <= 0.0 {
            return vec![1.0];
        }
        let r = (3.0 * s).ceil() as isize;
        (-r..=r)
            .map(|d| (-((d * d) as f64) / (2.0 * s * s)).exp())
            .collect()
    };
    let (kx, ky) = (kernel(pitch[0]), kernel(pitch[1]));
    let pass = |src: &[f64], k: &[f64], along_x: bool| -> Vec<f64> {
        let r = (k.len() / 2) as isize;
        let mut out = vec![0.0; nx * ny];
        for ix in 0..nx {
            for iy in 0..ny {
                let (mut acc, mut wsum) = (0.0, 0.0);
                for (t, &kw) in k.iter().enumerate() {
                    let d = t as isize - r;
                    let (jx, jy) = if along_x {
                        (ix as isize + d, iy as isize)
                    } else {
                        (ix as isize, iy as isize + d)
                    };
                    if (0..nx as isize).contains(&jx) && (0..ny as isize).contains(&jy) {
                        acc += kw * src[jx as usize * ny + jy as usize];
                        wsum += kw;
                    }
                }
                out[ix * ny + iy] = acc / wsum;
            }
        }
        out
    };
    let blur = pass(&pass(&front, &kx, true), &ky, false);
    let floor = 1e-3 * blur.iter().fold(0.0f64, |a, &b| a.max(b));
    image
        .chunks_exact(layers)
        .zip(&blur)
        .flat_map(|(c, &b)| {
            let d = b.max(floor);
            c.iter().map(move |&v| {
                if d > 0.0 {
                    (f64::from(v) / d) as f32
                } else {
                    0.0
                }
            })
        })
        .collect()
}

/// Direct light on a plane fitted to it (see the module documentation): one direct-light pass
/// over the grid `slab` (with `nz ≥ 2` slices in front of and behind the object), the plane,
/// and the image on it.
pub fn surface(
    src: &mut dyn RowSource,
    slab: &Volume,
    wave: &Wave,
    opts: &SurfaceOptions,
    exec: Exec<'_>,
) -> Result<Surface> {
    opts.check()?;
    let Some(axes) = slab.axes else {
        return Err(Error::arg(
            "volume",
            "a surface needs a grid volume (x, y and z ranges), not a list of points",
        ));
    };
    let [nx, ny, nz] = slab.shape;
    if nz < 2 || nx < 2 || ny < 2 {
        return Err(Error::arg(
            "volume",
            format!(
                "a surface needs at least 2 voxels along each axis, from a slab in front of the \
                 object to behind it ({nx}x{ny}x{nz} given)"
            ),
        ));
    }
    let out = super::direct(src, slab, wave, exec)?;
    let (fit, depth) = fit_plane(slab, &out.values, opts.floor)?;
    let offsets = opts.offsets();
    let (mut image, points, outside) = sample_plane(slab, &out.values, &fit, &offsets);
    let shape = [nx, ny, offsets.len()];
    if let Some(s) = opts.contrast {
        let pitch = slab.pitch();
        image = local_contrast(&image, shape, [pitch[0], pitch[1]], s);
    }
    let cx = 0.5 * (f64::from(axes[0][0]) + f64::from(axes[0][1]));
    let cy = 0.5 * (f64::from(axes[1][0]) + f64::from(axes[1][1]));
    let zc = fit.z_at(cx, cy) as f32;
    let half = 0.5 * opts.thickness;
    let volume = Volume {
        points,
        shape,
        axes: Some([axes[0], axes[1], [zc - half, zc + half]]),
    };
    Ok(Surface {
        fit,
        depth,
        image,
        volume,
        outside,
        slab: out,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A slab whose brightest depth per column lies on a known plane, with a darker stripe
    /// (a "stroke") on it.
    fn synthetic(plane: [f64; 3]) -> (Volume, Vec<f32>) {
        let slab = Volume::grid([-0.2, -0.2, 0.5], [0.2, 0.2, 0.9], [21, 21, 81]).unwrap();
        let values = slab
            .points
            .iter()
            .map(|p| {
                let z = plane[0] + plane[1] * f64::from(p[0]) + plane[2] * f64::from(p[1]);
                let d = (f64::from(p[2]) - z) / 0.02;
                let stroke = if p[0].abs() < 0.03 { 0.4 } else { 1.0 };
                (stroke * (-0.5 * d * d).exp()) as f32
            })
            .collect();
        (slab, values)
    }

    #[test]
    fn the_plane_of_a_tilted_slab_is_found() {
        let truth = [0.7, 0.1, -0.05];
        let (slab, values) = synthetic(truth);
        let (fit, depth) = fit_plane(&slab, &values, 0.25).unwrap();
        for (a, b) in fit.plane.iter().zip(truth) {
            assert!((a - b).abs() < 3e-3, "{:?} vs {truth:?}", fit.plane);
        }
        assert!(fit.rms < 4e-3, "rms {}", fit.rms);
        assert_eq!(depth.len(), 21 * 21);
        assert_eq!(fit.fitted, 21 * 21);
        // The image on the plane: the stroke's columns are 0.4 of the others, in every layer
        // near the plane; a slice at the plane's mean depth would cut the stroke obliquely.
        let o = SurfaceOptions {
            thickness: 0.0,
            layers: 1,
            ..SurfaceOptions::default()
        };
        let (image, points, outside) = sample_plane(&slab, &values, &fit, &o.offsets());
        assert_eq!(outside, 0);
        for (v, p) in image.iter().zip(&points) {
            let want = if p[0].abs() < 0.03 { 0.4 } else { 1.0 };
            assert!((v - want).abs() < 0.02, "{v} at {p:?}");
        }
    }

    #[test]
    fn bad_options_and_degenerate_slabs_are_refused() {
        let bad = [
            SurfaceOptions {
                floor: 1.0,
                ..SurfaceOptions::default()
            },
            SurfaceOptions {
                thickness: f32::NAN,
                ..SurfaceOptions::default()
            },
            SurfaceOptions {
                layers: 0,
                ..SurfaceOptions::default()
            },
            SurfaceOptions {
                contrast: Some(0.0),
                ..SurfaceOptions::default()
            },
        ];
        for (o, name) in bad.iter().zip(["floor", "thickness", "layers", "contrast"]) {
            let e = o.check().unwrap_err().to_string();
            assert!(e.contains(name), "{e}");
        }
        let (slab, values) = synthetic([0.7, 0.0, 0.0]);
        let e = fit_plane(&slab, &vec![0.0; values.len()], 0.25).unwrap_err();
        assert!(e.to_string().contains("no direct light"), "{e}");
        // One bright column: no plane.
        let mut one = vec![0.0f32; values.len()];
        one[40] = 1.0;
        let e = fit_plane(&slab, &one, 0.25).unwrap_err();
        assert!(e.to_string().contains("no plane"), "{e}");
    }

    #[test]
    fn local_contrast_flattens_a_smooth_falloff() {
        // A bright square whose brightness falls off smoothly, with a dark stroke: after the
        // contrast step the stroke stands out by the same ratio at the edge as at the centre.
        let (nx, ny) = (40, 40);
        let mut img = vec![0.0f32; nx * ny];
        for ix in 0..nx {
            for iy in 0..ny {
                let (x, y) = (ix as f32 - 19.5, iy as f32 - 19.5);
                let fall = (-(x * x + y * y) / 800.0).exp();
                let stroke = if iy % 10 == 5 { 0.5 } else { 1.0 };
                img[ix * ny + iy] = fall * stroke;
            }
        }
        let out = local_contrast(&img, [nx, ny, 1], [0.01, 0.01], 0.03);
        let ratio = |ix: usize| out[ix * ny + 25] / out[ix * ny + 27];
        let (centre, edge) = (ratio(20), ratio(3));
        assert!(
            (centre - 0.5).abs() < 0.1 && (edge - 0.5).abs() < 0.1,
            "{centre} {edge}"
        );
        let lo = out.iter().fold(f32::INFINITY, |a, &b| a.min(b));
        let hi = out.iter().fold(0.0f32, |a, &b| a.max(b));
        assert!(lo > 0.2 && hi < 2.5, "{lo}..{hi}");
    }
}
