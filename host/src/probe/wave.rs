//! The virtual wave and weighting options every probe shares ([`Wave`]: λ, σ, lens weights,
//! band, laser compensation, automatic margin), the kernel configuration they give, and the
//! device legs of the capture's spots under it (`legs`). Lengths are metres of optical path.

use crate::error::Result;
use crate::io::capture::Geometry;
use rayon::prelude::*;
use vltm_kernel::geometry::{dist, dist64, pitch};
use vltm_kernel::{Config, Legs, Params, Point, Weights};

/// Virtual wave and weighting options shared by every probe (the CLI's common flags).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wave {
    /// Virtual wavelength λ (m); `None` = [`default_wavelength`] of the capture.
    pub wavelength: Option<f64>,
    /// Gate std σ (m); `None` = 2λ/3.
    pub sigma: Option<f64>,
    /// Leg weights: the paper's `1/d` or y-tal's none.
    pub weights: Weights,
    /// The Lambertian cosine at the wall point of each leg (`--weights cos`): each leg's
    /// weight `w(d)` ([`Wave::weights`]) times `|cos θ| = |n·(x_v − x)|/|x_v − x|` with `n` the
    /// relay surface's normal at the wall point `x` ([`Geometry::laser_normal`],
    /// [`Geometry::spad_normal`]; +z where the capture has none). Default false (distance-only
    /// weights, what every figure and the y-tal parity use). Computed by
    /// [`direct`](crate::probe::direct) on paired and confocal scans (one SPAD per row), on
    /// the band and lookup paths; every other probe and path refuses it in one line.
    pub cosine: bool,
    /// Band half-width m in units of 1/σ.
    pub band_half_width: f64,
    /// Divide each laser row by the physical laser's falloff `cos θ / d²` to its spot.
    pub compensate_laser: bool,
    /// For Gaussian-gated columns and in-focus indirect light: widen the virtual DFT period
    /// ([`Params::margin`]) so that every path time of the probed elements is alias-free,
    /// i.e. paths outside the capture's window contribute nothing instead of
    /// wrapping around (default true). The factorised column cannot zero single paths as the
    /// diagonal does; this buys the same result with a larger band (`J ∝ N`).
    pub auto_margin: bool,
    /// Crop the time axis to the window the probed voxels can reach before the band
    /// transform (default true; `crate::probe`'s crop: the results agree within the gate's
    /// tail, the cost falls with the crop).
    pub crop: bool,
}

impl Default for Wave {
    fn default() -> Self {
        Self {
            wavelength: None,
            sigma: None,
            weights: Weights::Inv,
            cosine: false,
            band_half_width: 5.0,
            compensate_laser: false,
            auto_margin: true,
            crop: true,
        }
    }
}

/// The smallest band half-width [`Wave::check`] accepts (units of 1/σ; truncation error
/// ≈ erfc(1/√2) = 0.32).
pub const MIN_BAND: f64 = 1.0;
/// The largest band half-width [`Wave::check`] accepts (units of 1/σ; beyond it the
/// truncation error is below f64's precision and the band only costs time).
pub const MAX_BAND: f64 = 20.0;

/// The longest `wavelength` or `sigma` [`Wave::check`] accepts: 1000 km of path.
pub const MAX_LENGTH: f64 = 1e6;

/// Default virtual wavelength: twice the coarser aperture pitch (the sampling limit of the
/// virtual lens), and at least 6 time bins (so the band stays below Nyquist).
pub fn default_wavelength(g: &Geometry) -> f64 {
    let p = pitch(&g.lasers, g.laser_shape).max(pitch(&g.spads, g.spad_shape)) as f64;
    (2.0 * p).max(6.0 * g.dt)
}

impl Wave {
    /// Refuses [`Wave::cosine`] in a probe that does not compute it (`probe` names it): every
    /// probe but [`direct`](crate::probe::direct).
    ///
    /// # Errors
    /// [`Error::Argument`](crate::Error::Argument) (`weights`) with one line that says why.
    pub fn refuse_cosine(&self, probe: &str) -> Result<()> {
        if self.cosine {
            return Err(crate::error::Error::arg(
                "weights",
                format!(
                    "`cos` weights (the wall's cosine per leg) are computed by `direct` only, \
                     on paired and confocal scans, not by {probe}: its sums factorise over the \
                     SPAD grid inside the kernel, where the per-point cosine does not fit"
                ),
            ));
        }
        Ok(())
    }

    /// The wave the kernel runs under [`Wave::cosine`]: the same options without the cosine
    /// (which the caller applies per row and voxel).
    pub fn without_cosine(&self) -> Self {
        Self {
            cosine: false,
            ..*self
        }
    }

    /// Refuses options that make no sense, with their valid range: the band half-width
    /// `band` in [1, 20] (`MIN_BAND`, `MAX_BAND`; units of 1/σ), a given `wavelength` from two
    /// time bins (`2·dt`, the Nyquist limit) and a given `sigma` from one time bin (`dt`), both
    /// at most `MAX_LENGTH` (1000 km; a longer wave overflows the kernel's sizes; the memory budget
    /// bounds the DFT period long before).
    ///
    /// # Errors
    /// [`Error::Argument`](crate::Error::Argument) naming the parameter and its range.
    pub fn check(&self, g: &Geometry) -> Result<()> {
        let m = self.band_half_width;
        if !(MIN_BAND..=MAX_BAND).contains(&m) {
            return Err(crate::error::Error::arg(
                "band",
                format!(
                    "expected {MIN_BAND} to {MAX_BAND} (the band's half-width in units of 1/σ; \
                     truncation error ≈ erfc(m/√2): 5 gives 5.7e-7), found {m}"
                ),
            ));
        }
        for (name, v, bins, least) in [
            (
                "wavelength",
                self.wavelength,
                2.0,
                "two time bins (the Nyquist limit)",
            ),
            ("sigma", self.sigma, 1.0, "one time bin"),
        ] {
            if let Some(v) = v {
                let lo = bins * g.dt;
                if !(v >= lo && v <= MAX_LENGTH) {
                    return Err(crate::error::Error::arg(
                        name,
                        format!(
                            "expected {lo} to {MAX_LENGTH} m of path (from {least} of {} m \
                             to 1000 km), found {v}",
                            g.dt
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The kernel configuration for a capture.
    ///
    /// # Errors
    /// [`Error::Config`](crate::Error::Config) naming the rejected parameter. (Under
    /// [`Wave::cosine`] the configuration has the distance weights; the cosines are the
    /// host's.)
    pub fn config(&self, g: &Geometry) -> Result<Config> {
        self.check(g)?;
        let lam = self.wavelength.unwrap_or_else(|| default_wavelength(g));
        let legs = if g.legs_in_time {
            Legs::FirstAndLast {
                laser_origin: g.laser_origin,
                sensor_origin: g.sensor_origin,
            }
        } else {
            Legs::WallToWall
        };
        let p = Params {
            sigma: self.sigma,
            band_half_width: self.band_half_width,
            t0: g.t0,
            legs,
            weights: self.weights,
            ..Params::new(lam, g.nt, g.dt)
        };
        Ok(Config::try_new(&p)?)
    }

    /// The configuration for factorised Gaussian columns focused at `foci` and imaged over
    /// `voxels`: [`Wave::config`], with [`Params::margin`] widened (under
    /// [`Wave::auto_margin`]) until every path time `d1 + |x_l − x_a| + |x_a − x_b| +
    /// |x_b − x_s| + d4 − t0` lies in [`Config::alias_free`].
    ///
    /// # Errors
    /// As [`Wave::config`] (a margin so large that N overflows is a `SizeOverflow`).
    pub fn column_config(&self, g: &Geometry, foci: &[Point], voxels: &[Point]) -> Result<Config> {
        let cfg = self.config(g)?;
        if !self.auto_margin || foci.is_empty() || voxels.is_empty() {
            return Ok(cfg);
        }
        let _t = crate::timings::section("planning: time window", crate::timings::Kind::Parallel);
        let (d1, d4) = legs(g, &cfg);
        let proj: Vec<(f64, f64)> = foci.iter().map(|a| span(&g.lasers, &d1, a)).collect();
        let cam: Vec<(f64, f64)> = voxels.par_iter().map(|b| span(&g.spads, &d4, b)).collect();
        let (lo, hi) = foci
            .par_iter()
            .zip(&proj)
            .map(|(a, p)| {
                voxels.iter().zip(&cam).fold(
                    (f64::INFINITY, f64::NEG_INFINITY),
                    |(lo, hi), (b, c)| {
                        let d_ab = f64::from(dist(a, b));
                        (lo.min(p.0 + d_ab + c.0), hi.max(p.1 + d_ab + c.1))
                    },
                )
            })
            .reduce(
                || (f64::INFINITY, f64::NEG_INFINITY),
                |x, y| (x.0.min(y.0), x.1.max(y.1)),
            );
        let (af_lo, af_hi) = cfg.alias_free();
        // 1e-4·σ for the f32 path lengths of the kernel, as the guard check of the diagonal.
        let slack = 1e-4 * cfg.sigma();
        let need = ((af_lo + slack) - (lo - g.t0))
            .max((hi - g.t0) - (af_hi - slack))
            .max(0.0);
        if need == 0.0 {
            return Ok(cfg);
        }
        Ok(Config::try_new(&Params {
            margin: need,
            ..*cfg.params()
        })?)
    }
}

/// The least and the largest `|p − v| + d` over the spots `pts` with their device legs `legs`
/// (m): the span of one leg's path lengths to `v`. In 8 independent lanes with branch-free
/// compares, so the loop vectorises (a `min`/`max` fold runs one scalar compare chain: 3 % of
/// an exhaustive `direct`); extremes do not depend on the order.
pub(super) fn span(pts: &[Point], legs: &[f64], v: &Point) -> (f64, f64) {
    const W: usize = 8;
    let (mut a, mut b) = ([f64::INFINITY; W], [f64::NEG_INFINITY; W]);
    let mut step = |k: usize, p: &Point, d: f64| {
        let x = f64::from(dist(p, v)) + d;
        a[k] = if x < a[k] { x } else { a[k] };
        b[k] = if x > b[k] { x } else { b[k] };
    };
    let (pc, dc) = (pts.chunks_exact(W), legs.chunks_exact(W));
    let (pr, dr) = (pc.remainder(), dc.remainder());
    for (p, d) in pc.zip(dc) {
        for k in 0..W {
            step(k, &p[k], d[k]);
        }
    }
    for (p, d) in pr.iter().zip(dr) {
        step(0, p, *d);
    }
    (
        a.iter().fold(f64::INFINITY, |m, &x| m.min(x)),
        b.iter().fold(f64::NEG_INFINITY, |m, &x| m.max(x)),
    )
}

/// The device legs `d1_l`, `d4_s` of every laser and SPAD spot (0 without legs in time).
pub(super) fn legs(g: &Geometry, cfg: &Config) -> (Vec<f64>, Vec<f64>) {
    let d1 = g
        .lasers
        .iter()
        .map(|l| match cfg.legs() {
            Legs::WallToWall => 0.0,
            Legs::FirstAndLast { laser_origin, .. } => dist64(l, &laser_origin),
        })
        .collect();
    let d4 = g
        .spads
        .iter()
        .map(|s| match cfg.legs() {
            Legs::WallToWall => 0.0,
            Legs::FirstAndLast { sensor_origin, .. } => dist64(s, &sensor_origin),
        })
        .collect();
    (d1, d4)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geometry() -> Geometry {
        Geometry {
            lasers: vec![[0.0, 0.0, 0.0], [0.2, 0.0, 0.0]],
            laser_shape: [2, 1],
            spads: vec![[0.1, 0.0, 0.0]],
            spad_shape: [1, 1],
            laser_origin: [0.0, 0.0, 0.5],
            sensor_origin: [0.0, 0.0, 0.5],
            legs_in_time: false,
            confocal: false,
            nt: 200,
            dt: 0.01,
            t0: 0.0,
            normals: Default::default(),
        }
    }

    /// Options out of range are refused naming the parameter and its range; the ends of the
    /// ranges are accepted.
    #[test]
    fn wave_options_have_ranges() {
        let g = geometry();
        let refused = |w: Wave, param: &str, range: &str| {
            let e = w.check(&g).unwrap_err();
            let line = e.to_string();
            assert!(
                line.starts_with(&format!("argument `{param}`")) && line.contains(range),
                "{line}"
            );
        };
        let band = |m| Wave {
            band_half_width: m,
            ..Wave::default()
        };
        for m in [1e-300, 0.5, 20.5, 1e300, f64::NAN, f64::INFINITY] {
            refused(band(m), "band", "1 to 20");
        }
        for m in [MIN_BAND, 5.0, MAX_BAND] {
            band(m).check(&g).unwrap();
        }
        let wl = |v| Wave {
            wavelength: Some(v),
            ..Wave::default()
        };
        for v in [1e-300, 0.019, 1.1e6, f64::NAN, -1.0, 1e300] {
            refused(wl(v), "wavelength", "0.02 to 1000000 m");
        }
        for v in [0.02, 1.0, 1e6] {
            wl(v).check(&g).unwrap();
        }
        let sigma = |v| Wave {
            sigma: Some(v),
            ..Wave::default()
        };
        for v in [0.0, 0.009, 1e9, f64::NAN] {
            refused(sigma(v), "sigma", "0.01 to 1000000 m");
        }
        sigma(0.01).check(&g).unwrap();
        // `config` applies the check.
        assert!(band(1e-300).config(&g).is_err());
    }
}
