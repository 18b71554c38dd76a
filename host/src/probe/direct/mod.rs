//! Direct light: the diagonal `T(x_v, x_v)` (Eqs. 11–12) on the path the planner chose
//! ([`crate::probe::plan`]: planar or confocal FFT convolution, resampled or not, phasor,
//! baseband lookup or the kernel's band sum); this module carries the decision out.

mod confocal;
mod cosine;
mod phasor_path;

use phasor_path::direct_phasor;

use crate::budget;
use crate::error::Result;
use crate::exec::{EvalPath, Exec, Progress};
use crate::io::capture::{Geometry, RowSource};
use crate::probe::crop::{self, Crop, Labelled, Reach};
use crate::probe::drive::*;
use crate::probe::fast::resample::Resample;
use crate::probe::fast::{LookupDiagonal, Planar, planar};
use crate::probe::output::{Output, check_finite, intensities};
use crate::probe::plan::{self, Diagonal, Engine};
use crate::probe::wave::*;
use crate::volume::Volume;
use num_complex::Complex64;
use rayon::prelude::*;
use std::time::Instant;
use vltm_kernel::geometry::dist;
use vltm_kernel::{Config, Gate, Point, Probe, Report, Scan, Target};

/// Direct light: the diagonal over `volume` (Eqs. 11–12), on the path [`Exec::path`] forces
/// or, under [`EvalPath::Auto`], the cheapest that applies by the flop model (the planner's docs,
/// `probe::plan`).
///
/// # Errors
/// Configuration, read and kernel errors; [`Error::Argument`](crate::error::Error::Argument)
/// (`path`, `weights`) when a forced path or the `cos` weights do not apply;
/// [`Error::Memory`](crate::error::Error::Memory) when a forced path's buffers do not fit the
/// budget.
pub fn direct(
    src: &mut dyn RowSource,
    volume: &Volume,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<Output> {
    let t = Instant::now();
    let (a, config) = direct_acc(src, volume, wave, exec)?;
    let values = intensities(&a.acc);
    check_finite(&values, &volume.points, "direct light")?;
    Ok(Output {
        values,
        report: a.report,
        seconds: t.elapsed().as_secs_f64(),
        config,
        path: a.path,
        crop: a.crop,
        aligned: a.aligned,
    })
}

/// Complex accumulators per voxel (`T = |A|²`), the counters and the path that made them.
#[derive(Clone, Debug)]
pub(super) struct Amplitudes {
    pub(super) acc: Vec<Complex64>,
    pub(super) report: Report,
    pub(super) path: EvalPath,
    /// The part of the time axis kept.
    pub(super) crop: Option<Crop>,
    /// The grid the planner reports ([`Output::aligned`]): the support grid's `--volume` SPEC
    /// when the FFT path resampled an off-lattice grid ([`crate::probe::resample`]), or the
    /// aligned grid the FFT path would take when another path ran.
    pub(super) aligned: Option<String>,
}

impl Amplitudes {
    /// Amplitudes of the whole time axis (the crop is set by the caller that made it).
    fn new(acc: Vec<Complex64>, report: Report, path: EvalPath, aligned: Option<String>) -> Self {
        Self {
            acc,
            report,
            path,
            crop: None,
            aligned,
        }
    }
}

/// The accumulators of [`direct`] over the source's rows ([`RowSource::rows`]), with the
/// configuration (of the time axis cropped to the voxels' reach, `crop`, and, except on the
/// band path, with its DFT period shrunk to the voxels' paths).
pub(super) fn direct_acc(
    src: &mut dyn RowSource,
    volume: &Volume,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<(Amplitudes, Config)> {
    if wave.cosine {
        // The kernel runs the distance weights; `cosine` multiplies each row by the wall
        // cosines (refused before any pass where it does not apply).
        plan::check_cosine(src.geometry(), exec.path)?;
        return direct_acc_with(src, volume, &wave.without_cosine(), exec, true);
    }
    direct_acc_with(src, volume, wave, exec, false)
}

/// [`direct_acc`] with the distance-only `wave`, and the wall cosines per row under `cosine`:
/// the capture's configuration and device legs made once, the window checked, the time axis
/// cut to the voxels' reach (and, except on the band path, the DFT period shrunk to their
/// paths), then the planner's path carried out.
fn direct_acc_with(
    src: &mut dyn RowSource,
    volume: &Volume,
    wave: &Wave,
    exec: Exec<'_>,
    cosine: bool,
) -> Result<(Amplitudes, Config)> {
    let g = src.geometry();
    let base = wave.config(g)?;
    let legs = legs(g, &base);
    crate::probe::window::window_rule_with(
        g,
        &base,
        &legs,
        None,
        &volume.points,
        crate::probe::gate::ColumnGate::TwoBounce,
        exec,
    )?;
    let reach = Reach {
        foci: None,
        voxels: &volume.points,
        late: false,
    };
    let mut cut = crop::cut(src, wave.crop, &base, &legs, exec, reach)?;
    let (crop, cfg, shrunk) = (cut.crop, cut.cfg, cut.shrunk);
    let (src, exec) = cut.parts();
    let g = src.geometry();
    let plan = |cfg: &Config| {
        if cosine {
            plan::cosine(g, cfg, volume, exec.path)
        } else {
            plan::diagonal(g, cfg, volume, exec.path)
        }
    };
    // The shorter period on every path but the band path, which keeps the kernel's: the
    // firmware runs it, and its states merge with the host's (`crop` module docs).
    let (cfg, choice) = match shrunk.map(|t| plan(&t).map(|c| (t, c))).transpose()? {
        Some((t, c)) if !matches!(c.how, Diagonal::Band) => (t, c),
        _ => (cfg, plan(&cfg)?),
    };
    // The pass's progress labels carry the planner's note (`direct (path lookup; …)`).
    let noted = exec.progress.map(|p| Labelled {
        inner: p,
        note: choice.note,
    });
    let job = Job {
        cfg: &cfg,
        wave,
        exec: Exec {
            progress: noted.as_ref().map(|l| l as &dyn Progress),
            ..exec
        },
    };
    let (acc, report) = evaluate(src, job, volume, choice.how, &legs)?;
    let a = Amplitudes {
        crop,
        ..Amplitudes::new(acc, report, choice.path, choice.aligned)
    };
    Ok((a, cfg))
}

/// The diagonal's accumulators evaluated as the planner decided (`how`); `legs`: the device
/// legs `(d1, d4)` of the capture's spots.
fn evaluate(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
    how: Diagonal,
    legs: &(Vec<f64>, Vec<f64>),
) -> Result<(Vec<Complex64>, Report)> {
    match how {
        Diagonal::Resampled(rs, engine) => direct_resampled(src, job, volume, &rs, engine, legs),
        Diagonal::Planar(p) => direct_planar(src, job, volume, &p, legs),
        Diagonal::Convolution(c) => confocal::direct_convolution(src, job, volume, &c, legs),
        Diagonal::Phasor(p, plan) => direct_phasor(src, job, volume, &p, &plan),
        Diagonal::Lookup(plan) => direct_lookup(src, job, volume, &plan),
        Diagonal::Band => elementwise(
            src,
            job,
            Target::Diagonal,
            Gate::Gaussian,
            &volume.points,
            "direct",
        ),
        Diagonal::Cosine(lookup) => cosine::direct(src, job, volume, lookup.as_ref()),
    }
}

/// Voxels that have some (laser, SPAD) path outside the guard interval: the band path zeroes
/// those paths, the convolution cannot, so these voxels are evaluated on the band path.
pub(super) fn outside_guard(
    g: &Geometry,
    cfg: &Config,
    (d1, d4): &(Vec<f64>, Vec<f64>),
    voxels: &[Point],
) -> Vec<bool> {
    let (lo, hi) = cfg.guard();
    voxels
        .par_iter()
        .map(|v| {
            let (l0, l1) = span(&g.lasers, d1, v);
            let (s0, s1) = span(&g.spads, d4, v);
            // A margin of 1e-4·σ for the f32 path lengths of the kernel.
            let m = 1e-4 * cfg.sigma();
            l0 + s0 - cfg.t0() < lo + m || l1 + s1 - cfg.t0() > hi - m
        })
        .collect()
}

/// The diagonal's accumulators by the baseband lookup, rows in parallel (one scratch and
/// accumulator per thread; `plan`: what it holds, checked against the budget). The lookup
/// applies the guard itself.
pub(super) fn direct_lookup(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
    plan: &budget::Plan,
) -> Result<(Vec<Complex64>, Report)> {
    let cfg = job.cfg;
    let g = src.geometry().clone();
    plan.check(|| pass_name(&g, cfg, "direct light (lookup)"))?;
    let ks = g.spads_per_row();
    // Confocal captures: `drive_rows` re-points this scan at each row's own spot
    // (`Scan::with_spads`, its tables shared).
    let spads = if g.confocal { &g.spads[..1] } else { &g.spads };
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, spads, &mut tables)?;
    let lookup = LookupDiagonal::new(cfg);
    let nw = rayon::current_num_threads().max(1);
    let workers: Vec<_> = (0..nw)
        .map(|_| {
            (
                lookup.scratch(ks),
                vec![Complex64::new(0.0, 0.0); volume.len()],
                Report::default(),
            )
        })
        .collect();
    let pts = &volume.points;
    let workers = drive_rows(
        src,
        job,
        &scan,
        "direct",
        workers,
        |(s, acc, r), scan, row| {
            lookup.apply(scan, row, pts, s, acc);
            r.count_row(row);
            Ok(())
        },
    )?;
    let mut acc = vec![Complex64::new(0.0, 0.0); volume.len()];
    let mut report = Report::default();
    for (_, a, r) in workers {
        for (x, y) in acc.iter_mut().zip(&a) {
            *x += y;
        }
        report.add_part(&r);
    }
    Ok((acc, report))
}

/// Per-thread state of the planar diagonal.
pub(super) struct DiagWorker<'a> {
    scratch: planar::Scratch,
    acc: Vec<Complex64>,
    fallback: Option<Probe<'a>>,
    rows: u64,
    non_finite: u64,
}

/// The diagonal's accumulators by the planar FFT convolution, rows in parallel; voxels with
/// paths outside the guard on the kernel's band path.
pub(super) fn direct_planar(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
    planar: &Planar,
    legs: &(Vec<f64>, Vec<f64>),
) -> Result<(Vec<Complex64>, Report)> {
    let skip = outside_guard(src.geometry(), job.cfg, legs, &volume.points);
    with_band_fallback(&volume.points, &skip, |fb_pts| {
        planar_core(src, job, &volume.points, planar, &skip, fb_pts)
    })
}

/// The planar convolution over the voxels `pts` (its grid; those with `skip` left at 0) and
/// the band path's accumulators of the points `fb_pts`, in one pass over the rows.
pub(super) fn planar_core(
    src: &mut dyn RowSource,
    job: Job<'_>,
    pts: &[Point],
    planar: &Planar,
    skip: &[bool],
    fb_pts: &[Point],
) -> Result<(Vec<Complex64>, Vec<Complex64>, Report)> {
    let cfg = job.cfg;
    let g = src.geometry().clone();
    let ks = g.spads.len();
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, &g.spads, &mut tables)?;
    let nw = rayon::current_num_threads().max(1);
    let n_state = Probe::state_len(cfg, Target::Diagonal, Gate::Gaussian, fb_pts.len(), ks);
    let mut states: Vec<Vec<f64>> = (0..nw).map(|_| vec![0.0; n_state]).collect();
    let mut workers = Vec::with_capacity(nw);
    for st in &mut states {
        let fallback = if fb_pts.is_empty() {
            None
        } else {
            Some(Probe::new(
                &scan,
                Target::Diagonal,
                Gate::Gaussian,
                fb_pts,
                st,
            )?)
        };
        workers.push(DiagWorker {
            scratch: planar::Scratch::default(),
            acc: vec![Complex64::new(0.0, 0.0); pts.len()],
            fallback,
            rows: 0,
            non_finite: 0,
        });
    }
    let workers = drive_rows(src, job, &scan, "direct", workers, |w, _, row| {
        let laser = row.laser();
        planar.apply(
            row.band(),
            pts,
            |v| {
                let d = dist(&laser, v);
                (d, cfg.weight(d))
            },
            skip,
            &mut w.scratch,
            &mut w.acc,
        );
        if let Some(p) = &mut w.fallback {
            p.push_row(&scan, row)?;
        }
        w.rows += 1;
        w.non_finite += u64::from(row.non_finite());
        Ok(())
    })?;
    let mut acc = vec![Complex64::new(0.0, 0.0); pts.len()];
    let mut report = Report::default();
    let mut merged: Option<Probe<'_>> = None;
    for w in workers {
        for (a, b) in acc.iter_mut().zip(&w.acc) {
            *a += b;
        }
        report.rows += w.rows;
        report.non_finite += w.non_finite;
        if let Some(p) = w.fallback {
            match &mut merged {
                None => merged = Some(p),
                Some(m) => m.merge(&p)?,
            }
        }
    }
    let fb_acc = merged.map_or_else(Vec::new, |m| {
        m.accumulators()
            .iter()
            .take(fb_pts.len())
            .copied()
            .collect()
    });
    Ok((acc, fb_acc, report))
}

/// The diagonal over `volume` by the FFT path on the support grid of `rs`, resampled; the
/// asked voxels with a path outside the guard on the band path (their exact band sums).
fn direct_resampled(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
    rs: &Resample,
    engine: Engine,
    legs: &(Vec<f64>, Vec<f64>),
) -> Result<(Vec<Complex64>, Report)> {
    let g = src.geometry().clone();
    let cfg = job.cfg;
    let sup = &rs.support;
    let none = vec![false; sup.len()];
    // A confocal capture whose rows share one leg offset (wall-to-wall time axes): the guard
    // in the convolution's kernel, as on the aligned path, no band-path voxels.
    let guard = confocal::common_offset(cfg, legs);
    let outside = match (&engine, guard) {
        (Engine::Planar(_), _) => outside_guard(&g, cfg, legs, &volume.points),
        (Engine::Confocal(_), Some(_)) => vec![false; volume.len()],
        (Engine::Confocal(_), None) => confocal::outside_guard(&g, cfg, legs, &volume.points),
    };
    let fb_idx: Vec<usize> = (0..outside.len()).filter(|&i| outside[i]).collect();
    let fb_pts: Vec<Point> = fb_idx.iter().map(|&i| volume.points[i]).collect();
    let (sup_acc, fb_acc, report) = match &engine {
        Engine::Planar(p) => planar_core(src, job, &sup.points, p, &none, &fb_pts)?,
        Engine::Confocal(c) => {
            confocal::convolution_core(src, job, c, guard, &none, &fb_pts, legs)?
        }
    };
    let _t = crate::timings::section("resampling", crate::timings::Kind::Parallel);
    let mut acc = rs.apply(&sup_acc);
    drop(_t);
    for (&i, a) in fb_idx.iter().zip(fb_acc) {
        acc[i] = a;
    }
    Ok((acc, report))
}
