//! The direct-light model of a capture: built for the gate, or fitted (see the parent module).

use super::energy::GateEnergy;
use crate::error::{Error, Result};
use crate::exec::{Exec, Pass, row_batch};
use crate::io::capture::{Geometry, RowSource};
use crate::probe::wave::Wave;
use crate::timings::{self, Kind};
use num_complex::Complex64;
use rayon::prelude::*;
use std::time::Instant;
use vltm_kernel::Point;

use super::model::*;
use super::options::{AUTO_ADJACENCY, LeakMethod, LeakOptions};

/// The fitted direct-light model of a capture (see the module docs).
#[derive(Clone, Debug)]
pub struct DirectModel {
    geometry: Geometry,
    points: Vec<Point>,
    /// Fitted complex reflectance per point.
    pub rho: Vec<Complex64>,
    basis: Basis,
    /// Fraction of the demodulated capture's energy the model explains (fit), or of the
    /// capture's energy `Σ H²` in the zeroed windows (gate) (0..1).
    pub explained: f64,
    /// Half-width of the zeroed windows (gate method) (m of path).
    gate: Option<f64>,
    /// Gate method, once its pass has read the capture: of the energy the windows leave, the
    /// share within one window half-width of them ([`GateEnergy::adjacency`]).
    pub adjacency: Option<f64>,
    /// Wall-clock seconds of the fit.
    pub seconds: f64,
}

impl DirectModel {
    /// The carrier basis and voxel–SPAD tables over `points`, after the checks every method
    /// shares: `points` not empty, and some 3-vertex return inside the capture's window.
    fn check(g: &Geometry, points: &[Point], wave: &Wave) -> Result<(Basis, SpadTables)> {
        if points.is_empty() {
            return Err(Error::arg(
                "leak_correct",
                "Γ is empty: no voxel to fit the direct light at (lower $epsilon or check $volume)",
            ));
        }
        let basis = Basis::new(g, wave)?;
        let tab = SpadTables::new(g, points, &basis);
        let v_n = points.len();
        let any = (0..g.lasers.len()).into_par_iter().any(|l| {
            let lrow = laser_legs(g, &basis, points, l);
            row_spads(g, l).any(|s| {
                (0..v_n).any(|v| ret_any(g, &basis, &tab, &lrow, points, l, v, s).is_some())
            })
        });
        if !any {
            return Err(Error::arg(
                "leak_correct",
                format!(
                    "no direct (3-vertex) return of Γ's {v_n} voxels falls in the capture's window \
                     [{:.3}, {:.3}] m: there is no direct light to remove",
                    g.t0,
                    g.t0 + basis.window
                ),
            ));
        }
        Ok((basis, tab))
    }

    /// Whether `--leak-correct auto` tries the surface model after these windows: their
    /// [`DirectModel::adjacency`] is at least [`AUTO_ADJACENCY`] (not measured: no).
    pub fn auto_prefers_model(&self) -> bool {
        self.adjacency.is_some_and(|a| a >= AUTO_ADJACENCY)
    }

    /// The gate method's model ([`LeakMethod::Gate`]) without reading the capture: it uses
    /// the timing of the returns only, so each row is corrected on its own (a part of a scan
    /// split by rows is corrected exactly as in one pass). [`DirectModel::explained`] is 0
    /// until measured ([`GateEnergy`]).
    ///
    /// # Errors
    /// As [`DirectModel::fit`] before its pass over the data (empty `points`, no return in
    /// the window); configuration errors.
    pub fn gate(
        g: &Geometry,
        points: &[Point],
        cell: f64,
        wave: &Wave,
        opts: &LeakOptions,
    ) -> Result<Self> {
        let (basis, _) = Self::check(g, points, wave)?;
        Ok(Self {
            geometry: g.clone(),
            points: points.to_vec(),
            rho: Vec::new(),
            basis,
            explained: 0.0,
            gate: Some(opts.cells * cell + 3.0 * g.dt),
            adjacency: None,
            seconds: 0.0,
        })
    }

    /// Fits the model over the voxels `points` (Γ) to the capture `src` (one pass over the
    /// rows), with the carrier and envelope of `wave` on this capture.
    ///
    /// # Errors
    /// [`Error::Argument`] (`leak_correct`) when `points` is empty, when no 3-vertex return
    /// of any point falls in the capture's window, or when the capture holds no light at those
    /// returns; configuration and read errors.
    pub fn fit(
        src: &mut dyn RowSource,
        points: &[Point],
        cell: f64,
        wave: &Wave,
        opts: &LeakOptions,
        exec: Exec<'_>,
    ) -> Result<Self> {
        wave.refuse_cosine("the leak fit")?;
        let t = Instant::now();
        let g = src.geometry().clone();
        if opts.method == LeakMethod::Gate {
            let mut model = Self::gate(&g, points, cell, wave, opts)?;
            // One window half-width, in bins.
            let reach = model
                .gate
                .map_or(0, |w| (w / g.dt).ceil().max(1.0) as usize);
            let bar = Pass::start(exec, "leak gate", g.lasers.len());
            let mut energy = GateEnergy::default();
            // Batches of rows: read (in parallel where the source can), then each row's
            // windows cut and its energy measured in parallel, the energies added in row order.
            let batch = row_batch();
            let mut rows: Vec<(Point, Vec<f32>)> = Vec::new();
            for start in (0..g.lasers.len()).step_by(batch) {
                let end = (start + batch).min(g.lasers.len());
                rows.resize_with(end - start, || ([0.0; 3], Vec::new()));
                {
                    let kind = if src.reads_in_parallel() {
                        Kind::Parallel
                    } else {
                        Kind::Serial
                    };
                    let _t = timings::section("read rows", kind);
                    src.read_rows(start, &mut rows)?;
                }
                let _t = timings::section("leak windows", Kind::Parallel);
                let per_row: Vec<GateEnergy> = rows
                    .par_iter()
                    .enumerate()
                    .map(|(i, (_, row))| {
                        let mut kept = row.clone();
                        model.subtract_row(start + i, &mut kept);
                        let mut e = GateEnergy::default();
                        e.add_near(row, &kept, g.nt, reach);
                        e
                    })
                    .collect();
                for e in per_row {
                    energy.merge(&e);
                }
                bar.advance(end - start);
            }
            drop(bar);
            model.explained = energy.explained()?;
            model.adjacency = energy.adjacency();
            model.seconds = t.elapsed().as_secs_f64();
            return Ok(model);
        }
        let (basis, tab) = Self::check(&g, points, wave)?;
        let pts = points;
        let v_n = pts.len();
        let zero = Complex64::new(0.0, 0.0);
        // Pass over the data: rhs = Aᴴ b, energy = ‖b‖².
        let ks = g.spads_per_row();
        let bar = Pass::start(exec, "leak fit", g.lasers.len());
        let mut rhs = vec![zero; v_n];
        let mut energy = 0.0;
        let batch = row_batch();
        let mut rows: Vec<(usize, Vec<f32>)> = Vec::new();
        for start in (0..g.lasers.len()).step_by(batch) {
            let end = (start + batch).min(g.lasers.len());
            rows.resize_with(end - start, || (0, Vec::new()));
            for (l, (i, hist)) in (start..end).zip(rows.iter_mut()) {
                *i = l;
                src.read_row(l, hist)?;
            }
            let (y, e) = rows
                .par_iter()
                .fold(
                    || (vec![zero; v_n], 0.0, Work::new(&basis), Vec::new()),
                    |(mut y, mut e, mut work, mut b), (l, hist)| {
                        b.resize(ks * basis.nc, zero);
                        e += demodulate(&g, &basis, hist, &mut b);
                        apply_row(&g, &basis, &tab, pts, *l, &[], Some(&b), &mut work, &mut y);
                        (y, e, work, b)
                    },
                )
                .map(|(y, e, _, _)| (y, e))
                .reduce(
                    || (vec![zero; v_n], 0.0),
                    |(mut a, ea), (b, eb)| {
                        a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                        (a, ea + eb)
                    },
                );
            rhs.iter_mut().zip(&y).for_each(|(x, y)| *x += y);
            energy += e;
            bar.advance(end - start);
        }
        drop(bar);
        let project = |y: &mut [Complex64]| {
            if !opts.complex {
                y.iter_mut().for_each(|z| z.im = 0.0);
            }
        };
        project(&mut rhs);
        if energy.is_nan() || energy <= 0.0 || rhs.iter().all(|z| *z == zero) {
            return Err(Error::arg(
                "leak_correct",
                "the capture holds no light at the direct (3-vertex) return times of Γ's voxels: \
                 there is no direct light to remove",
            ));
        }
        let normal = |p: &[Complex64]| -> Vec<Complex64> {
            let mut y = (0..g.lasers.len())
                .into_par_iter()
                .fold(
                    || (vec![zero; v_n], Work::new(&basis)),
                    |(mut y, mut work), l| {
                        apply_row(&g, &basis, &tab, pts, l, p, None, &mut work, &mut y);
                        (y, work)
                    },
                )
                .map(|(y, _)| y)
                .reduce(
                    || vec![zero; v_n],
                    |mut a, b| {
                        a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                        a
                    },
                );
            project(&mut y);
            y
        };
        // CGNR from 0.
        let mut x = vec![zero; v_n];
        let mut r = rhs.clone();
        let mut p = r.clone();
        let mut rr = dot(&r, &r);
        let rr0 = rr;
        let bar = Pass::start(exec, "leak fit (iterations)", opts.iterations);
        for _ in 0..opts.iterations {
            if rr.is_nan() || rr <= 1e-30 * rr0 {
                break;
            }
            let q = normal(&p);
            let pq = dot(&p, &q);
            if pq.is_nan() || pq <= 0.0 {
                break;
            }
            let alpha = rr / pq;
            x.iter_mut().zip(&p).for_each(|(xi, pi)| *xi += alpha * pi);
            r.iter_mut().zip(&q).for_each(|(ri, qi)| *ri -= alpha * qi);
            let rr_new = dot(&r, &r);
            let beta = rr_new / rr;
            rr = rr_new;
            p.iter_mut()
                .zip(&r)
                .for_each(|(pi, ri)| *pi = ri + beta * *pi);
            bar.advance(1);
        }
        drop(bar);
        let nx = normal(&x);
        let resid = energy - 2.0 * dot(&x, &rhs) + dot(&x, &nx);
        Ok(Self {
            geometry: g,
            points: pts.to_vec(),
            rho: x,
            basis,
            explained: (1.0 - resid / energy).clamp(0.0, 1.0),
            gate: None,
            adjacency: None,
            seconds: t.elapsed().as_secs_f64(),
        })
    }

    /// The points the model scatters from.
    pub fn points(&self) -> &[Point] {
        &self.points
    }

    /// Renders the model's histograms of laser row `l` into `out` (`spads_per_row·Nt`,
    /// SPAD-major), **subtracting** them from what `out` holds.
    pub fn subtract_row(&self, l: usize, out: &mut [f32]) {
        let g = &self.geometry;
        let basis = &self.basis;
        let tab_row = laser_legs(g, basis, &self.points, l);
        let nt = g.nt;
        let sp = basis.sigma_p / g.dt; // bins
        let r = (4.0 * sp).ceil() as i64;
        let norm = 1.0 / (sp * (2.0 * std::f64::consts::PI).sqrt());
        let inv = 0.5 / (sp * sp);
        let rot = Complex64::from_polar(1.0, basis.omega * g.dt);
        let spads: Vec<usize> = row_spads(g, l).collect();
        if let Some(half) = self.gate {
            out.par_chunks_mut(nt).zip(spads).for_each(|(h, s)| {
                for (v, &(tl, _)) in tab_row.iter().enumerate() {
                    let (d, _) = leg(g.spads[s], self.points[v]);
                    let tau = tl + d + basis.d4[s];
                    let lo = ((tau - half) / g.dt).ceil().max(0.0);
                    let hi = ((tau + half) / g.dt).floor().min(nt as f64 - 1.0);
                    if lo <= hi {
                        h[lo as usize..=hi as usize]
                            .iter_mut()
                            .for_each(|x| *x = 0.0);
                    }
                }
            });
            return;
        }
        out.par_chunks_mut(nt).zip(spads).for_each(|(h, s)| {
            let mut acc = vec![0.0f64; nt];
            for (v, &rho) in self.rho.iter().enumerate() {
                if rho == Complex64::new(0.0, 0.0) {
                    continue;
                }
                let (tl, al) = tab_row[v];
                let (d, f) = leg(g.spads[s], self.points[v]);
                let ts = d + basis.d4[s];
                let a = al * f;
                let tau = tl + ts;
                if a == 0.0 || !(0.0..=basis.window).contains(&tau) {
                    continue;
                }
                let x = tau / g.dt;
                let n0 = x.round() as i64;
                let lo = (n0 - r).max(0);
                let hi = (n0 + r).min(nt as i64 - 1);
                if lo > hi {
                    continue;
                }
                // 2·a·Re[ρ e^{iω0(t_n − τ)}]·g(t_n − τ), g unit-sum sampled Gaussian.
                let mut z = 2.0
                    * a
                    * norm
                    * rho
                    * Complex64::from_polar(1.0, basis.omega * (lo as f64 - x) * g.dt);
                for n in lo..=hi {
                    let u = n as f64 - x;
                    acc[n as usize] += z.re * (-u * u * inv).exp();
                    z *= rot;
                }
            }
            for (o, a) in h.iter_mut().zip(&acc) {
                *o -= *a as f32;
            }
        });
    }
}
