//! Direct light: the diagonal `T(x_v, x_v)` (Eqs. 11–12) on the cheapest applicable path
//! (planar FFT convolution, baseband lookup or the kernel's band sum).

mod confocal;
mod cosine;
mod phasor_path;

use phasor_path::{PHASOR_COST, direct_phasor, phasor_flops, phasor_plan};

use crate::budget;
use crate::error::{Error, Result};
use crate::exec::{Exec, Path};
use crate::io::capture::{Geometry, RowSource};
use crate::probe::crop::{Crop, Reach, with_crop};
use crate::probe::drive::*;
use crate::probe::fast::aligned::fast_hint;
use crate::probe::fast::resample::Resample;
use crate::probe::fast::{Confocal, Lookup, Phasor, Planar, planar};
use crate::probe::wave::*;
use crate::volume::Volume;
use num_complex::Complex64;
use rayon::prelude::*;
use std::time::Instant;
use vltm_kernel::{Config, Gate, Point, Probe, Report, Scan, Target};

/// Direct light: the diagonal over `volume` (Eqs. 11–12), on the path chosen by
/// [`Exec::path`] (the planar FFT convolution when it applies and is cheaper, else the
/// kernel's band sum).
///
/// # Errors
/// Configuration, read and kernel errors; [`Error::Argument`] (`path`) when the planar
/// path is forced and does not apply.
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
    let aligned = if a.support.is_some() {
        a.support.clone()
    } else {
        (a.path != Path::Planar && volume.axes.is_some())
            .then(|| fast_hint(src.geometry(), volume, config.wavelength()))
            .flatten()
    };
    Ok(Output {
        values,
        report: a.report,
        seconds: t.elapsed().as_secs_f64(),
        config,
        path: a.path,
        crop: a.crop,
        aligned,
    })
}

/// Complex accumulators per voxel (`T = |A|²`), the counters and the path that made them.
#[derive(Clone, Debug)]
pub(super) struct Amplitudes {
    pub(super) acc: Vec<Complex64>,
    pub(super) report: Report,
    pub(super) path: Path,
    /// The part of the time axis kept.
    pub(super) crop: Option<Crop>,
    /// When the FFT path computed an off-lattice grid on a support grid and resampled it
    /// ([`crate::probe::resample`]): the support grid's `--volume` SPEC.
    pub(super) support: Option<String>,
}

impl Amplitudes {
    /// Amplitudes of the whole time axis (the crop is set by the caller that made it).
    fn new(acc: Vec<Complex64>, report: Report, path: Path, support: Option<String>) -> Self {
        Self {
            acc,
            report,
            path,
            crop: None,
            support,
        }
    }
}

/// The accumulators of [`direct`] over the source's rows ([`RowSource::rows`]), with the
/// configuration (of the time axis cropped to the voxels' reach, `crop`).
pub(super) fn direct_acc(
    src: &mut dyn RowSource,
    volume: &Volume,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<(Amplitudes, Config)> {
    if wave.cosine {
        // The kernel runs the distance weights; `cosine` multiplies each row by the wall
        // cosines (refused before any pass where it does not apply).
        cosine::check(src.geometry(), exec.path)?;
        return direct_acc_with(src, volume, &wave.without_cosine(), exec, true);
    }
    direct_acc_with(src, volume, wave, exec, false)
}

/// [`direct_acc`] with the distance-only `wave`, and the wall cosines per row under `cosine`.
fn direct_acc_with(
    src: &mut dyn RowSource,
    volume: &Volume,
    wave: &Wave,
    exec: Exec<'_>,
    cosine: bool,
) -> Result<(Amplitudes, Config)> {
    let base = wave.config(src.geometry())?;
    crate::probe::window::window_rule(
        src.geometry(),
        &base,
        None,
        &volume.points,
        crate::probe::wave::ColumnGate::TwoBounce,
        exec,
    )?;
    let reach = Reach {
        foci: None,
        voxels: &volume.points,
        late: false,
    };
    with_crop(src, wave, exec, reach, |src, exec, crop| {
        let (mut a, cfg) = direct_acc_on(src, volume, wave, exec, cosine)?;
        a.crop = crop;
        Ok((a, cfg))
    })
}

/// [`direct_acc`] on the (cropped) source.
fn direct_acc_on(
    src: &mut dyn RowSource,
    volume: &Volume,
    wave: &Wave,
    exec: Exec<'_>,
    cosine: bool,
) -> Result<(Amplitudes, Config)> {
    let cfg = wave.config(src.geometry())?;
    check_memory(
        src.geometry(),
        &cfg,
        budget::bytes(volume.len(), 32),
        "direct light",
    )?;
    let job = Job {
        cfg: &cfg,
        wave,
        exec,
    };
    if cosine {
        let note = "cos weights (the wall's cosine per leg)".to_string();
        let (acc, report, path) = with_note(job, note, |job| {
            let plan = lookup_plan(src.geometry(), job.cfg, volume.len());
            cosine::direct(src, job, volume, &plan)
        })?;
        return Ok((Amplitudes::new(acc, report, path, None), cfg));
    }
    let g = src.geometry();
    let rows = g.lasers.len() as f64;
    // The phasor path: planned when forced (its errors name why it does not apply) or, under
    // `Auto`, when it applies and fits the budget.
    let ph = match exec.path {
        Path::Phasor => Some(phasor_plan(g, &cfg, volume.len())?),
        Path::Auto => phasor_plan(g, &cfg, volume.len())
            .ok()
            .filter(|(_, plan)| plan.fits()),
        _ => None,
    };
    let ph_cost = ph.as_ref().map_or(f64::INFINITY, |(p, _)| {
        phasor_flops(g, &cfg, p, volume.len())
    });
    // Off the wall's lattice: the FFT path on a support grid, resampled, when it applies and
    // is cheaper than the rivals (whole-scan flops).
    let rival = if g.confocal {
        confocal::band_total(g, &cfg, volume.len()).min(confocal::lookup_flops(
            g,
            &cfg,
            volume.len(),
        ))
    } else {
        let band = band_flops(g, &cfg, volume.len());
        let lookup = lookup_plan(g, &cfg, volume.len())
            .fits()
            .then(|| lookup_row_flops(g, &cfg, volume.len()));
        lookup.map_or(band, |l| l.min(band)) * rows
    };
    // Against the FFT paths the phasor path's flops count at its measured rate.
    let rival = rival.min(PHASOR_COST * ph_cost);
    if let Some((rs, engine)) = choose_resampled(g, &cfg, volume, exec.path, rival)? {
        let (acc, report) = direct_resampled(src, job, volume, &rs, engine)?;
        return Ok((
            Amplitudes::new(acc, report, Path::Planar, Some(rs.support_spec())),
            cfg,
        ));
    }
    if g.confocal {
        let (acc, report, path) = direct_confocal(src, job, volume, ph.as_ref(), ph_cost)?;
        return Ok((Amplitudes::new(acc, report, path, None), cfg));
    }
    let band_cost = band_flops(g, &cfg, volume.len());
    // The lookup competes only when its grid fits the budget (at large σ its carrier and
    // tables grow with N; the band sum then runs in bounded memory).
    let lookup_fits = lookup_plan(g, &cfg, volume.len()).fits();
    let lookup_cost = lookup_fits.then(|| lookup_row_flops(g, &cfg, volume.len()));
    // Planar competes with the cheapest of band, lookup and phasor under `Auto`.
    let rival = lookup_cost.map_or(band_cost, |l| l.min(band_cost));
    let ph_wins = ph_cost < rival * rows;
    let rival = rival.min(PHASOR_COST * ph_cost / rows);
    let (acc, report, path) = if let Some(planar) = choose_planar(
        (!g.confocal).then_some(&g.spads[..]),
        &cfg,
        volume,
        exec.path,
        PlanarUse::Diagonal,
        rival,
    )? {
        let (acc, report) = with_note(job, path_note(g, volume, &cfg, Path::Planar), |job| {
            direct_planar(src, job, volume, &planar)
        })?;
        (acc, report, Path::Planar)
    } else if let Some((p, plan)) = ph.as_ref().filter(|_| exec.path == Path::Phasor || ph_wins) {
        let (acc, report) = with_note(job, path_note(g, volume, &cfg, Path::Phasor), |job| {
            direct_phasor(src, job, volume, p, plan)
        })?;
        (acc, report, Path::Phasor)
    } else if exec.path == Path::Lookup
        || (exec.path == Path::Auto && lookup_cost.is_some_and(|l| l < band_cost))
    {
        let (acc, report) = with_note(job, path_note(g, volume, &cfg, Path::Lookup), |job| {
            direct_lookup(src, job, volume)
        })?;
        (acc, report, Path::Lookup)
    } else {
        let (acc, report) = with_note(job, path_note(g, volume, &cfg, Path::Band), |job| {
            elementwise(
                src,
                job,
                Target::Diagonal,
                Gate::Gaussian,
                &volume.points,
                "direct",
            )
        })?;
        (acc, report, Path::Band)
    };
    Ok((Amplitudes::new(acc, report, path, None), cfg))
}

/// Direct light of a confocal capture: the confocal convolution on a regular wall grid
/// with a fitting voxel grid, else the lookup (irregular wall points, point lists) or the
/// band sum, whichever the flop model finds cheaper (or [`Exec::path`] forces).
fn direct_confocal(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
    ph: Option<&(Phasor, budget::Plan)>,
    ph_cost: f64,
) -> Result<(Vec<Complex64>, Report, Path)> {
    let g = src.geometry();
    let cfg = job.cfg;
    let band = confocal::band_total(g, cfg, volume.len());
    let lookup = confocal::lookup_flops(g, cfg, volume.len());
    let lookup_fits = lookup_plan(g, cfg, volume.len()).fits();
    let rival = band.min(lookup).min(PHASOR_COST * ph_cost);
    let conv = confocal::choose(g, cfg, volume, job.exec.path, rival)?;
    let ph_wins = ph_cost < band && (ph_cost < lookup || !lookup_fits);
    let (values, report, path) = if let Some(c) = conv {
        let (v, r) = with_note(job, path_note(g, volume, cfg, Path::Planar), |job| {
            confocal::direct_convolution(src, job, volume, c)
        })?;
        (v, r, Path::Planar)
    } else if let Some((p, plan)) = ph.filter(|_| job.exec.path == Path::Phasor || ph_wins) {
        let (v, r) = with_note(job, path_note(g, volume, cfg, Path::Phasor), |job| {
            direct_phasor(src, job, volume, p, plan)
        })?;
        (v, r, Path::Phasor)
    } else if job.exec.path == Path::Lookup
        || (job.exec.path == Path::Auto && lookup < band && lookup_fits)
    {
        let (v, r) = with_note(job, path_note(g, volume, cfg, Path::Lookup), |job| {
            direct_lookup(src, job, volume)
        })?;
        (v, r, Path::Lookup)
    } else {
        let (v, r) = with_note(job, path_note(g, volume, cfg, Path::Band), |job| {
            elementwise(
                src,
                job,
                Target::Diagonal,
                Gate::Gaussian,
                &volume.points,
                "direct",
            )
        })?;
        (v, r, Path::Band)
    };
    Ok((values, report, path))
}

/// What the planar convolution would be used for (its cost differs).
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum PlanarUse {
    /// Per row, for the diagonal.
    Diagonal,
    /// Once, to image a factorised column.
    Column,
}

/// The planar convolution for this probe, if [`Exec::path`] allows it, it applies and (for
/// [`Path::Auto`]) it costs fewer flops than `rival`, the cheapest other path (by the
/// cost model, per row for the diagonal, once for a column's imaging). `spads`: the SPAD
/// spots, `None` for a confocal capture.
pub(super) fn choose_planar(
    spads: Option<&[Point]>,
    cfg: &Config,
    volume: &Volume,
    path: Path,
    usage: PlanarUse,
    rival: f64,
) -> Result<Option<Planar>> {
    if matches!(path, Path::Band | Path::Lookup | Path::Phasor) {
        return Ok(None);
    }
    let planar = match spads {
        None => Err("a confocal capture has no SPAD grid".to_string()),
        Some(_) if volume.axes.is_none() => {
            Err("the volume is a point list, not a grid".to_string())
        }
        Some(sp) => Planar::new(cfg, sp, &volume.points, volume.shape),
    };
    match (planar, path) {
        (Err(e), Path::Planar) => Err(Error::arg(
            "path",
            format!("the planar FFT path does not apply: {e}"),
        )),
        (Err(_), _) => Ok(None),
        (Ok(p), Path::Planar) => Ok(Some(p)),
        (Ok(p), _) => {
            let planar = planar_flops(p.shape(), cfg, volume.len(), usage);
            Ok((planar < rival).then_some(p))
        }
    }
}

/// Voxels that have some (laser, SPAD) path outside the guard interval: the band path zeroes
/// those paths, the convolution cannot, so these voxels are evaluated on the band path.
pub(super) fn outside_guard(g: &Geometry, cfg: &Config, voxels: &[Point]) -> Vec<bool> {
    let (d1, d4) = legs(g, cfg);
    let (lo, hi) = cfg.guard();
    let range = |pts: &[Point], legs: &[f64], v: &Point| {
        pts.iter()
            .zip(legs)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (p, d)| {
                let x = dist(*p, *v) as f64 + d;
                (a.min(x), b.max(x))
            })
    };
    voxels
        .par_iter()
        .map(|v| {
            let (l0, l1) = range(&g.lasers, &d1, v);
            let (s0, s1) = range(&g.spads, &d4, v);
            // A margin of 1e-4·σ for the f32 path lengths of the kernel.
            let m = 1e-4 * cfg.sigma();
            l0 + s0 - cfg.t0() < lo + m || l1 + s1 - cfg.t0() > hi - m
        })
        .collect()
}

/// The diagonal's accumulators by the baseband lookup, rows in parallel (one scratch and
/// accumulator per thread). The lookup applies the guard itself.
pub(super) fn direct_lookup(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
) -> Result<(Vec<Complex64>, Report)> {
    let cfg = job.cfg;
    let g = src.geometry().clone();
    lookup_plan(&g, cfg, volume.len()).check(|| pass_name(&g, cfg, "direct light (lookup)"))?;
    let ks = g.spads_per_row();
    // Confocal captures: `drive_rows` re-points this scan at each row's own spot
    // (`Scan::with_spads`, its tables shared).
    let spads = if g.confocal { &g.spads[..1] } else { &g.spads };
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, spads, &mut tables)?;
    let lookup = Lookup::new(cfg);
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

/// What the diagonal holds at once on the lookup path: the pass's tables and row buffers
/// ([`memory_plan`]) and the lookup's grid and per-thread scratch.
pub(super) fn lookup_plan(g: &Geometry, cfg: &Config, n_voxels: usize) -> budget::Plan {
    let mut plan = memory_plan(g, cfg, budget::bytes(n_voxels, 32), "direct light");
    let threads = rayon::current_num_threads().max(1);
    Lookup::add_to_plan(cfg, g.spads_per_row(), n_voxels, threads, &mut plan);
    plan
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
) -> Result<(Vec<Complex64>, Report)> {
    let skip = outside_guard(src.geometry(), job.cfg, &volume.points);
    let fb_idx: Vec<usize> = (0..skip.len()).filter(|&i| skip[i]).collect();
    let fb_pts: Vec<Point> = fb_idx.iter().map(|&i| volume.points[i]).collect();
    let (mut acc, fb_acc, report) = planar_core(src, job, &volume.points, planar, &skip, &fb_pts)?;
    for (&i, a) in fb_idx.iter().zip(fb_acc) {
        acc[i] = a;
    }
    Ok((acc, report))
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
            scratch: planar.scratch(),
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
                let d = dist(laser, *v);
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

/// Flops of the planar convolution of FFT size `(Mx, My)` over `slices` sub-grids of
/// `n_voxels` voxels (cost model): per row for the diagonal, once for a column's
/// imaging.
fn planar_flops(
    (mx, my, slices): (usize, usize, usize),
    cfg: &Config,
    n_voxels: usize,
    usage: PlanarUse,
) -> f64 {
    let m = (mx * my) as f64;
    let j = cfg.bins() as f64;
    // Complex FFTs of M points, 5·M·log₂M (§B.8), pruned inverse ones about half that.
    let f = 5.0 * m * m.log2();
    let per_row = j * (f + slices as f64 * (6.0 * m + 0.75 * f)) + n_voxels as f64 * 8.0 * j;
    // The column images once; its table costs `slices·J` forward FFTs.
    match usage {
        PlanarUse::Diagonal => per_row,
        PlanarUse::Column => per_row + slices as f64 * j * f,
    }
}

/// Flops of the lookup diagonal per row: one complex inverse FFT per SPAD, then `E0 + 16`
/// flops per (voxel, SPAD) (§B.8).
fn lookup_row_flops(g: &Geometry, cfg: &Config, n_voxels: usize) -> f64 {
    let l = Lookup::plan_len(cfg) as f64;
    let ks = g.spads_per_row() as f64;
    ks * 5.0 * l * l.log2() + n_voxels as f64 * ks * 76.0
}

/// The FFT engine of a resampled volume: the planar convolution per row, or the confocal one.
enum Engine {
    Planar(Box<Planar>),
    Confocal(Box<Confocal>),
}

/// The resampled FFT path ([`crate::probe::resample`]) for `volume`: `None` when it is not the
/// one to take — a forced band or lookup path, a point list, a volume on the wall's lattice
/// (the exact FFT path's case) or, under [`Path::Auto`], when resampling does not apply, its
/// buffers do not fit the budget or it costs more than `rival` (flops of the whole scan).
///
/// # Errors
/// With the planar path forced: [`Error::Argument`] (`path`) naming why neither the exact nor
/// the resampled FFT path applies; [`Error::Memory`] naming the largest buffer when the
/// support grid's do not fit the budget.
fn choose_resampled(
    g: &Geometry,
    cfg: &Config,
    volume: &Volume,
    path: Path,
    rival: f64,
) -> Result<Option<(Resample, Engine)>> {
    // A paired scan (laser and SPAD apart) has no FFT path, exact or resampled: the
    // confocal path's choice names why.
    if matches!(path, Path::Band | Path::Lookup | Path::Phasor)
        || volume.axes.is_none()
        || g.paired_apart()
    {
        return Ok(None);
    }
    let _t = crate::timings::section("planning: FFT path", crate::timings::Kind::Serial);
    let wall = if g.confocal { &g.lasers } else { &g.spads };
    let tol = 1e-5 * cfg.wavelength();
    let exact = match planar::layout(wall, &volume.points, volume.shape, tol) {
        Ok(_) => return Ok(None),
        Err(e) => e,
    };
    let forced = path == Path::Planar;
    let fail = |why: String| -> Result<Option<(Resample, Engine)>> {
        if forced {
            Err(Error::arg(
                "path",
                format!(
                    "the planar FFT path does not apply: {exact}; nor on a resampled grid: {why}"
                ),
            ))
        } else {
            Ok(None)
        }
    };
    let rs = match Resample::new(g, cfg, volume) {
        Ok(r) => r,
        Err(e) => return fail(e),
    };
    let sup = &rs.support;
    let lay = match planar::layout(wall, &sup.points, sup.shape, tol) {
        Ok(l) => l,
        Err(e) => return fail(e),
    };
    let (mx, my, slices) = lay.size();
    let (m, j) = (mx * my, cfg.bins());
    let threads = rayon::current_num_threads().max(1);
    let [sx, sy, nz] = sup.shape;
    let mut plan = budget::Plan::new();
    if g.confocal {
        // Twice with transposed twins (the wall spectra and their transpose).
        let copies = if crate::probe::fast::confocal::twins(&lay, 1e-6 * cfg.wavelength())
            .iter()
            .any(Option::is_some)
        {
            2
        } else {
            1
        };
        plan.add(
            format!("the support grid's wall spectra ({copies} × {j} × {mx} × {my} complex f32)"),
            budget::bytes(j, 8 * copies).saturating_mul(m as u128),
        )
        .add(
            format!("the support grid's amplitudes ({sx} × {sy} × {nz})"),
            budget::bytes(sup.len(), 16),
        );
    } else {
        plan.add(
            format!("the support grid's kernel table ({slices} × {j} × {mx} × {my} complex f32)"),
            budget::bytes(slices, 8)
                .saturating_mul(j as u128)
                .saturating_mul(m as u128),
        )
        .add(
            format!("{threads} planar scratch buffers (3 × {j} × {mx} × {my} complex f32 each)"),
            budget::bytes(threads, 24)
                .saturating_mul(j as u128)
                .saturating_mul(m as u128),
        )
        .add(
            format!("{threads} support-grid accumulators ({sx} × {sy} × {nz} each)"),
            budget::bytes(threads, 16).saturating_mul(sup.len() as u128),
        );
    }
    plan.add(
        "the resampling's intermediate and output",
        budget::bytes(sx * volume.shape[1] * nz + volume.len(), 16),
    );
    if let Err(e) = plan.check(|| {
        format!(
            "direct light on the FFT path over the support grid {} (resampled to the volume)",
            rs.support_spec()
        )
    }) {
        return if forced { Err(e) } else { Ok(None) };
    }
    let engine = if g.confocal {
        let c = match Confocal::with_layout(cfg, lay) {
            Ok(c) => c,
            Err(e) => return fail(e),
        };
        if !forced && c.flops() + rs.flops() >= rival {
            return Ok(None);
        }
        Engine::Confocal(Box::new(c))
    } else {
        let rows = g.lasers.len() as f64;
        let cost = planar_flops((mx, my, slices), cfg, sup.len(), PlanarUse::Diagonal) * rows;
        if !forced && cost + rs.flops() >= rival {
            return Ok(None);
        }
        match Planar::new(cfg, &g.spads, &sup.points, sup.shape) {
            Ok(p) => Engine::Planar(Box::new(p)),
            Err(e) => return fail(e),
        }
    };
    Ok(Some((rs, engine)))
}

/// The diagonal over `volume` by the FFT path on the support grid of `rs`, resampled; the
/// asked voxels with a path outside the guard on the band path (their exact band sums).
fn direct_resampled(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
    rs: &Resample,
    engine: Engine,
) -> Result<(Vec<Complex64>, Report)> {
    let note = format!("path planar, resampled from $volume {}", rs.support_spec());
    with_note(job, note, |job| {
        direct_resampled_on(src, job, volume, rs, engine)
    })
}

/// [`direct_resampled`] with its progress label set.
fn direct_resampled_on(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
    rs: &Resample,
    engine: Engine,
) -> Result<(Vec<Complex64>, Report)> {
    let g = src.geometry().clone();
    let cfg = job.cfg;
    let sup = &rs.support;
    let none = vec![false; sup.len()];
    // A confocal capture whose rows share one leg offset (wall-to-wall time axes): the guard
    // in the convolution's kernel, as on the aligned path, no band-path voxels.
    let (legs1, legs4) = legs(&g, cfg);
    let offsets: Vec<f32> = legs1
        .iter()
        .zip(&legs4)
        .map(|(a, b)| (a + b - cfg.t0()) as f32)
        .collect();
    let uniform = offsets.iter().all(|&x| x == offsets[0]);
    let engine = match engine {
        Engine::Confocal(c) if uniform => Engine::Confocal(Box::new((*c).with_guard(offsets[0]))),
        e => e,
    };
    let outside = match &engine {
        Engine::Planar(_) => outside_guard(&g, cfg, &volume.points),
        Engine::Confocal(_) if uniform => vec![false; volume.len()],
        Engine::Confocal(_) => confocal::outside_guard(&g, cfg, &volume.points),
    };
    let fb_idx: Vec<usize> = (0..outside.len()).filter(|&i| outside[i]).collect();
    let fb_pts: Vec<Point> = fb_idx.iter().map(|&i| volume.points[i]).collect();
    let (sup_acc, fb_acc, report) = match &engine {
        Engine::Planar(p) => planar_core(src, job, &sup.points, p, &none, &fb_pts)?,
        Engine::Confocal(c) => confocal::convolution_core(src, job, c, &none, &fb_pts)?,
    };
    let _t = crate::timings::section("resampling", crate::timings::Kind::Parallel);
    let mut acc = rs.apply(&sup_acc);
    drop(_t);
    for (&i, a) in fb_idx.iter().zip(fb_acc) {
        acc[i] = a;
    }
    Ok((acc, report))
}

/// Runs `f` with `job`'s progress labels carrying `note` (`direct (path lookup; …)`).
fn with_note<T>(job: Job<'_>, note: String, f: impl FnOnce(Job<'_>) -> Result<T>) -> Result<T> {
    let labelled = job
        .exec
        .progress
        .map(|p| crate::probe::crop::Labelled { inner: p, note });
    f(Job {
        exec: Exec {
            progress: labelled.as_ref().map(|l| l as &dyn crate::exec::Progress),
            ..job.exec
        },
        ..job
    })
}

/// The progress note of the diagonal's path: `path planar`, or for a slower path on a grid
/// the aligned `--volume` the FFT path would take.
fn path_note(g: &Geometry, volume: &Volume, cfg: &Config, path: Path) -> String {
    let hint = (path != Path::Planar && volume.axes.is_some())
        .then(|| fast_hint(g, volume, cfg.wavelength()))
        .flatten();
    match hint {
        Some(v) => format!("path {}; the FFT path would take $volume {v}", path.name()),
        None => format!("path {}", path.name()),
    }
}
