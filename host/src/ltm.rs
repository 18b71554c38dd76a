//! High-level LTM probes over a capture, streamed row by row through the kernel and
//! multi-threaded with rayon (DESIGN §A.5, §B.3).
//!
//! | call | computes | passes over the data |
//! |---|---|---|
//! | [`direct`] | diagonal `T(x_v, x_v)` over a volume (Eqs. 11–12) | 1 |
//! | [`column()`] | `T(x_a, ·)` with [`ColumnGate`] two-bounce (Eq. 14), higher-order (Eq. 18) or none, optionally restricted to a shell `r0 ≤ |x_a − x_b| < r1` | 1 |
//! | [`indirect`] | in-focus indirect light (Eqs. 15–17): Γ from the diagonal, then `Σ_{a∈Γ} T(a, b)` over Γ-masked pairs with `r0 ≤ |x_a − x_b| < r1` | 2 |
//!
//! Threads: the diagonal and the higher-order column split the voxels into chunks, each with
//! its own kernel probe, and every row's band spectra (computed once) are pushed into all
//! chunks in parallel; factorised columns accumulate per row in one probe (cheap) and image
//! the voxels in parallel at the end; the indirect sum keeps one factorised column per focus
//! `a ∈ Γ`, pushed in parallel. Memory never grows with the number of laser rows.

use crate::capture::{Capture, Geometry, RowSource};
use crate::error::{Error, Result};
use crate::fast::{BandDft, Lookup, Planar, planar};
use crate::volume::Volume;
use indicatif::{ProgressBar, ProgressStyle};
use num_complex::{Complex32, Complex64};
use rayon::prelude::*;
use std::sync::Mutex;
use std::time::Instant;
use vltm_kernel::{
    Config, Gate, Legs, Params, Point, Probe, Report, Row, RowBuffer, Scan, Target, Weights,
};

/// Virtual wave and weighting options shared by every probe (the CLI's common flags).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wave {
    /// Virtual wavelength λ (m); `None` = [`default_wavelength`] of the capture.
    pub wavelength: Option<f64>,
    /// Gate std σ (m); `None` = 2λ/3.
    pub sigma: Option<f64>,
    /// Leg weights: the paper's `1/d` or y-tal's none.
    pub weights: Weights,
    /// Band half-width m in units of 1/σ.
    pub band_half_width: f64,
    /// Divide each laser row by the physical laser's falloff `cos θ / d²` to its spot.
    pub compensate_laser: bool,
    /// For Gaussian-gated columns and in-focus indirect light: widen the virtual DFT period
    /// ([`Params::margin`]) so that every path time of the probed elements is alias-free,
    /// i.e. paths outside the capture's window contribute nothing (DESIGN §B.2.2) instead of
    /// wrapping around (default true). The factorised column cannot zero single paths as the
    /// diagonal does; this buys the same result with a larger band (`J ∝ N`).
    pub auto_margin: bool,
}

impl Default for Wave {
    fn default() -> Self {
        Self {
            wavelength: None,
            sigma: None,
            weights: Weights::Inv,
            band_half_width: 5.0,
            compensate_laser: false,
            auto_margin: true,
        }
    }
}

/// Aperture pitch of a grid (the coarser of its two axes; 0 for a single point).
fn pitch(pts: &[Point], shape: [usize; 2]) -> f32 {
    let d = |a: Point, b: Point| ((0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f32>()).sqrt();
    let px = if shape[0] > 1 {
        d(pts[0], pts[shape[1]])
    } else {
        0.0
    };
    let py = if shape[1] > 1 { d(pts[0], pts[1]) } else { 0.0 };
    px.max(py)
}

/// Default virtual wavelength: twice the coarser aperture pitch (the sampling limit of the
/// virtual lens), and at least 6 time bins (so the band stays below Nyquist).
pub fn default_wavelength(g: &Geometry) -> f64 {
    let p = pitch(&g.lasers, g.laser_shape).max(pitch(&g.spads, g.spad_shape)) as f64;
    (2.0 * p).max(6.0 * g.dt)
}

impl Wave {
    /// The kernel configuration for a capture.
    ///
    /// # Errors
    /// [`Error::Config`] naming the rejected parameter.
    pub fn config(&self, g: &Geometry) -> Result<Config> {
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
        let (d1, d4) = legs(g, &cfg);
        let span = |pts: &[Point], legs: &[f64], v: &Point| {
            pts.iter()
                .zip(legs)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (p, d)| {
                    let x = f64::from(dist(*p, *v)) + d;
                    (a.min(x), b.max(x))
                })
        };
        let proj: Vec<(f64, f64)> = foci.iter().map(|a| span(&g.lasers, &d1, a)).collect();
        let cam: Vec<(f64, f64)> = voxels.iter().map(|b| span(&g.spads, &d4, b)).collect();
        let (lo, hi) = foci
            .par_iter()
            .zip(&proj)
            .map(|(a, p)| {
                voxels.iter().zip(&cam).fold(
                    (f64::INFINITY, f64::NEG_INFINITY),
                    |(lo, hi), (b, c)| {
                        let d_ab = f64::from(dist(*a, *b));
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

/// The device legs `d1_l`, `d4_s` of every laser and SPAD spot (0 without legs in time).
fn legs(g: &Geometry, cfg: &Config) -> (Vec<f64>, Vec<f64>) {
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

/// How the voxel sums of the diagonal and of Gaussian columns are evaluated (the CLI's
/// `--path`). All paths compute the same numbers (see `tests/proptest_fast.rs` for the
/// tolerances); they differ in cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Path {
    /// The cheapest applicable path by the flop model of DESIGN §B.8: for the diagonal the
    /// least of planar (when the SPADs form a regular grid and the volume is a wall-parallel
    /// grid whose pitch divides the SPAD pitch), lookup (not confocal) and band; for
    /// Gaussian-gated columns planar or band.
    #[default]
    Auto,
    /// The kernel's band sum per (voxel, SPAD) (DESIGN §B.2.3): any geometry, every probe.
    Band,
    /// The planar FFT convolution ([`crate::fast::planar`]) for the diagonal and
    /// Gaussian-gated columns; an error if it does not apply (another geometry, another gate).
    Planar,
    /// Diagonal only: the gated baseband + cubic lookup ([`crate::fast::lookup`]), any
    /// non-confocal geometry; an error for columns and confocal captures.
    Lookup,
}

impl Path {
    /// The path's name as the CLI's `--path` spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Band => "band",
            Self::Planar => "planar",
            Self::Lookup => "lookup",
        }
    }
}

/// Execution options.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Exec {
    /// Show a progress bar on stderr (hidden anyway when stderr is not a terminal).
    pub progress: bool,
    /// Evaluation path.
    pub path: Path,
}

/// Result of a probe: intensities per voxel (volume order) and the kernel's counters.
#[derive(Clone, Debug, PartialEq)]
pub struct Output {
    /// `|A|²` per voxel.
    pub values: Vec<f32>,
    /// Rows, non-finite samples, aliased voxels.
    pub report: Report,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// The kernel configuration used (λ, σ, J…).
    pub config: Config,
    /// The evaluation path that computed the voxel sums (never [`Path::Auto`]).
    pub path: Path,
}

/// The physical laser's falloff to spot `x_l`: `cos θ / d²` with `d = |laser_xyz − x_l|` and
/// θ the angle to the wall normal (y-tal `compensate_laser_cos_dsqr`).
pub fn laser_falloff(g: &Geometry, x_l: Point) -> f64 {
    let v: [f64; 3] = core::array::from_fn(|i| g.laser_origin[i] - x_l[i] as f64);
    let d2 = v.iter().map(|c| c * c).sum::<f64>();
    (v[2].abs() / d2.sqrt()) / d2
}

/// What every pass needs: the kernel configuration and the user's options.
#[derive(Clone, Copy)]
struct Job<'a> {
    cfg: &'a Config,
    wave: &'a Wave,
    exec: Exec,
}

/// Streams every row of `src` through `push` with the row's spectra (computed once per row).
fn drive(
    src: &mut dyn RowSource,
    job: Job<'_>,
    label: &str,
    mut push: impl FnMut(&Scan<'_>, &Row<'_, f32>) -> Result<()>,
) -> Result<()> {
    let Job { cfg, wave, exec } = job;
    let g = src.geometry().clone();
    check_laser_falloff(&g, wave)?;
    let dft = BandDft::new(cfg);
    let mut clean = Vec::new();
    let ks = g.spads_per_row();
    let mut tables = if g.confocal {
        Vec::new()
    } else {
        vec![0.0f32; Scan::tables_len(cfg, ks)]
    };
    let mut buf = vec![0.0f32; RowBuffer::len(cfg, ks)];
    let mut hist = Vec::new();
    let bar = progress_bar(exec, g.lasers.len(), label);
    let fixed: Option<Scan<'_>> = if g.confocal {
        None
    } else {
        Some(Scan::new(cfg, &g.spads, &mut tables)?)
    };
    let mut confocal_tables = if g.confocal {
        vec![0.0f32; Scan::tables_len(cfg, 1)]
    } else {
        Vec::new()
    };
    for l in 0..g.lasers.len() {
        let x_l = src.read_row(l, &mut hist)?;
        if wave.compensate_laser {
            let k = (1.0 / laser_falloff(&g, x_l)) as f32;
            hist.iter_mut().for_each(|h| *h *= k);
        }
        let spad = [x_l];
        let per_row;
        let scan = match &fixed {
            Some(s) => s,
            None => {
                per_row = Scan::new(cfg, &spad, &mut confocal_tables)?;
                &per_row
            }
        };
        let mut rows = RowBuffer::new(scan, &mut buf)?;
        let row = load_row(&mut rows, scan, &dft, x_l, &hist, &mut clean)?;
        push(scan, &row)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(())
}

/// Stage 1 of one row through the host's matrix product ([`BandDft`]); non-finite samples
/// are zeroed in a copy (`clean`) for the product and counted by the kernel.
fn load_row<'r>(
    rows: &'r mut RowBuffer<'_>,
    scan: &Scan<'_>,
    dft: &BandDft,
    x_l: Point,
    hist: &'r [f32],
    clean: &mut Vec<f32>,
) -> Result<Row<'r, f32>> {
    let data: &[f32] = if hist.iter().all(|x| x.is_finite()) {
        hist
    } else {
        clean.clear();
        clean.extend(hist.iter().map(|&x| if x.is_finite() { x } else { 0.0 }));
        clean
    };
    Ok(rows.load_with(scan, x_l, hist, |band, ungated| {
        dft.apply(data, band, ungated);
    })?)
}

/// Reads rows in batches and hands each to one of `workers` in parallel (one worker per
/// thread, each with its own row buffer), so stage 1 and the per-row probe work use every
/// core. Memory: `2·threads` rows of histograms, never the whole capture.
fn drive_rows<W: Send>(
    src: &mut dyn RowSource,
    job: Job<'_>,
    scan: &Scan<'_>,
    label: &str,
    workers: Vec<W>,
    work: impl Fn(&mut W, &Row<'_, f32>) -> Result<()> + Sync,
) -> Result<Vec<W>> {
    let Job { cfg, wave, exec } = job;
    let g = src.geometry().clone();
    check_laser_falloff(&g, wave)?;
    let ks = g.spads_per_row();
    let dft = BandDft::new(cfg);
    // (worker, row buffer, copy of a row with non-finite samples zeroed)
    type Slot<W> = Mutex<(W, Vec<f32>, Vec<f32>)>;
    let slots: Vec<Slot<W>> = workers
        .into_iter()
        .map(|w| Mutex::new((w, vec![0.0f32; RowBuffer::len(cfg, ks)], Vec::new())))
        .collect();
    let n_slots = slots.len().max(1);
    let bar = progress_bar(exec, g.lasers.len(), label);
    let batch = 2 * rayon::current_num_threads();
    let mut rows: Vec<(Point, Vec<f32>)> = Vec::new();
    for start in (0..g.lasers.len()).step_by(batch) {
        let end = (start + batch).min(g.lasers.len());
        rows.resize_with(end - start, || ([0.0; 3], Vec::new()));
        for (l, (x, hist)) in (start..end).zip(rows.iter_mut()) {
            *x = src.read_row(l, hist)?;
            if wave.compensate_laser {
                let k = (1.0 / laser_falloff(&g, *x)) as f32;
                hist.iter_mut().for_each(|h| *h *= k);
            }
        }
        rows.par_iter().try_for_each(|(x_l, hist)| {
            let i = rayon::current_thread_index().unwrap_or(0) % n_slots;
            let mut slot = slots[i].lock().unwrap_or_else(|e| e.into_inner());
            let (w, buf, clean) = &mut *slot;
            let mut rb = RowBuffer::new(scan, buf)?;
            let row = load_row(&mut rb, scan, &dft, *x_l, hist, clean)?;
            work(w, &row)
        })?;
        bar.inc((end - start) as u64);
    }
    bar.finish_and_clear();
    Ok(slots
        .into_iter()
        .map(|m| m.into_inner().unwrap_or_else(|e| e.into_inner()).0)
        .collect())
}

fn check_laser_falloff(g: &Geometry, wave: &Wave) -> Result<()> {
    if wave.compensate_laser {
        let f = laser_falloff(g, g.lasers[0]);
        if !(f.is_finite() && f > 0.0) {
            return Err(Error::arg(
                "--compensate-laser",
                "laser_xyz lies in the wall plane: cos θ / d² is 0",
            ));
        }
    }
    Ok(())
}

/// A progress bar over `n` rows on stderr (hidden unless `exec.progress`; indicatif also hides
/// it when stderr is not a terminal).
pub(crate) fn progress_bar(exec: Exec, n: usize, label: &str) -> ProgressBar {
    let bar = if exec.progress {
        ProgressBar::new(n as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} rows, {eta} left")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message(label.to_string());
    bar
}

/// Splits `voxels` into chunks for the thread pool.
fn chunk_len(n: usize) -> usize {
    n.div_ceil(4 * rayon::current_num_threads()).max(64)
}

/// Element-wise probes (diagonal, higher-order column) over voxel chunks in parallel.
fn elementwise(
    src: &mut dyn RowSource,
    job: Job<'_>,
    target: Target,
    gate: Gate,
    voxels: &[Point],
    label: &str,
) -> Result<(Vec<f64>, Report)> {
    let cfg = job.cfg;
    let ks = src.geometry().spads_per_row();
    let cl = chunk_len(voxels.len());
    let chunks: Vec<&[Point]> = voxels.chunks(cl).collect();
    let mut states: Vec<Vec<f64>> = chunks
        .iter()
        .map(|c| vec![0.0; Probe::state_len(cfg, target, gate, c.len(), ks)])
        .collect();
    // The probes need a Scan only for validation of sizes; build them on the first row.
    let mut probes: Vec<Probe<'_>> = Vec::new();
    let mut state_iter = Some(states.iter_mut());
    drive(src, job, label, |scan, row| {
        if let Some(it) = state_iter.take() {
            probes = chunks
                .iter()
                .zip(it)
                .map(|(c, s)| Probe::new(scan, target, gate, c, s))
                .collect::<Result<_, _>>()?;
        }
        probes
            .par_iter_mut()
            .try_for_each(|p| p.push_row(scan, row))?;
        Ok(())
    })?;
    let mut out = vec![0.0f64; voxels.len()];
    let mut report = Report::default();
    let g = src.geometry().clone();
    let ks_pts = if g.confocal {
        vec![g.lasers[0]]
    } else {
        g.spads.clone()
    };
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, &ks_pts, &mut tables)?;
    for (p, o) in probes.iter().zip(out.chunks_mut(cl)) {
        let r = p.finish(&scan, o)?;
        report = Report {
            non_finite: report.non_finite.max(r.non_finite),
            dropped: report.dropped.max(r.dropped),
            aliased: report.aliased + r.aliased,
            ..r
        };
    }
    Ok((out, report))
}

/// Direct light: the diagonal over `volume` (Eqs. 11–12), on the path chosen by
/// [`Exec::path`] (the planar FFT convolution when it applies and is cheaper, else the
/// kernel's band sum).
///
/// # Errors
/// Configuration, read and kernel errors; [`Error::Argument`] (`--path`) when the planar
/// path is forced and does not apply.
pub fn direct(src: &mut dyn RowSource, volume: &Volume, wave: &Wave, exec: Exec) -> Result<Output> {
    let t = Instant::now();
    let cfg = wave.config(src.geometry())?;
    let job = Job {
        cfg: &cfg,
        wave,
        exec,
    };
    let g = src.geometry();
    if g.confocal && exec.path == Path::Lookup {
        return Err(Error::arg(
            "--path",
            "the lookup path does not apply to a confocal capture (use band)",
        ));
    }
    let band_cost = band_flops(g, &cfg, volume.len());
    let lookup_cost = (!g.confocal).then(|| {
        let l = Lookup::new(&cfg).grid_len() as f64;
        let ks = g.spads_per_row() as f64;
        // One complex inverse FFT per SPAD, then E0 + 16 flops per (voxel, SPAD) (§B.8).
        ks * 5.0 * l * l.log2() + volume.len() as f64 * ks * 76.0
    });
    // Planar competes with the cheaper of band and lookup under `Auto`.
    let rival = lookup_cost.map_or(band_cost, |l| l.min(band_cost));
    if let Some(planar) = choose_planar(g, &cfg, volume, exec.path, PlanarUse::Diagonal, rival)? {
        let (values, report) = direct_planar(src, job, volume, &planar)?;
        return Ok(Output {
            values,
            report,
            seconds: t.elapsed().as_secs_f64(),
            config: cfg,
            path: Path::Planar,
        });
    }
    if exec.path == Path::Lookup
        || (exec.path == Path::Auto && lookup_cost.is_some_and(|l| l < band_cost))
    {
        let (values, report) = direct_lookup(src, job, volume)?;
        return Ok(Output {
            values,
            report,
            seconds: t.elapsed().as_secs_f64(),
            config: cfg,
            path: Path::Lookup,
        });
    }
    let (v, report) = elementwise(
        src,
        job,
        Target::Diagonal,
        Gate::Gaussian,
        &volume.points,
        "direct",
    )?;
    Ok(Output {
        values: v.iter().map(|&x| x as f32).collect(),
        report,
        seconds: t.elapsed().as_secs_f64(),
        config: cfg,
        path: Path::Band,
    })
}

/// What the planar convolution would be used for (its cost differs).
#[derive(Clone, Copy, PartialEq, Eq)]
enum PlanarUse {
    /// Per row, for the diagonal.
    Diagonal,
    /// Once, to image a factorised column.
    Column,
}

/// Flops per row of the kernel's band sum over `n_voxels` (DESIGN §B.8: `Kv·Ks·(14J + E0)`).
fn band_flops(g: &Geometry, cfg: &Config, n_voxels: usize) -> f64 {
    n_voxels as f64 * g.spads_per_row() as f64 * (14.0 * cfg.bins() as f64 + 60.0)
}

/// The planar convolution for this probe, if [`Exec::path`] allows it, it applies and (for
/// [`Path::Auto`]) it costs fewer flops than `rival`, the cheapest other path (DESIGN §B.8
/// cost model, per row for the diagonal, once for a column's imaging).
fn choose_planar(
    g: &Geometry,
    cfg: &Config,
    volume: &Volume,
    path: Path,
    usage: PlanarUse,
    rival: f64,
) -> Result<Option<Planar>> {
    if matches!(path, Path::Band | Path::Lookup) {
        return Ok(None);
    }
    let why = if g.confocal {
        Err("a confocal capture has no SPAD grid".to_string())
    } else if volume.axes.is_none() {
        Err("the volume is a point list, not a grid".to_string())
    } else {
        Ok(())
    };
    let planar = why.and_then(|()| Planar::new(cfg, &g.spads, &volume.points, volume.shape));
    match (planar, path) {
        (Err(e), Path::Planar) => Err(Error::arg(
            "--path",
            format!("the planar FFT path does not apply: {e}"),
        )),
        (Err(_), _) => Ok(None),
        (Ok(p), Path::Planar) => Ok(Some(p)),
        (Ok(p), _) => {
            let (mx, my, slices) = p.shape();
            let m = (mx * my) as f64;
            let j = cfg.bins() as f64;
            // Complex FFTs of M points, 5·M·log₂M (§B.8), pruned inverse ones about half that.
            let f = 5.0 * m * m.log2();
            let per_row =
                j * (f + slices as f64 * (6.0 * m + 0.75 * f)) + volume.len() as f64 * 8.0 * j;
            // The column images once; its table costs `slices·J` forward FFTs.
            let planar = match usage {
                PlanarUse::Diagonal => per_row,
                PlanarUse::Column => per_row + slices as f64 * j * f,
            };
            Ok((planar < rival).then_some(p))
        }
    }
}

/// Voxels that have some (laser, SPAD) path outside the guard interval: the band path zeroes
/// those paths, the convolution cannot, so these voxels are evaluated on the band path.
fn outside_guard(g: &Geometry, cfg: &Config, voxels: &[Point]) -> Vec<bool> {
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

fn dist64(a: &Point, b: &[f64; 3]) -> f64 {
    (0..3)
        .map(|i| (a[i] as f64 - b[i]).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// The diagonal by the baseband lookup, rows in parallel (one scratch and accumulator per
/// thread). The lookup applies the guard itself.
fn direct_lookup(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
) -> Result<(Vec<f32>, Report)> {
    let cfg = job.cfg;
    let g = src.geometry().clone();
    let ks = g.spads.len();
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, &g.spads, &mut tables)?;
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
    let workers = drive_rows(src, job, &scan, "direct", workers, |(s, acc, r), row| {
        lookup.apply(&scan, row, pts, s, acc);
        r.rows += 1;
        r.non_finite += u64::from(row.non_finite());
        Ok(())
    })?;
    let mut acc = vec![Complex64::new(0.0, 0.0); volume.len()];
    let mut report = Report::default();
    for (_, a, r) in workers {
        for (x, y) in acc.iter_mut().zip(&a) {
            *x += y;
        }
        report.rows += r.rows;
        report.non_finite += r.non_finite;
    }
    Ok((acc.iter().map(|a| a.norm_sqr() as f32).collect(), report))
}

/// Per-thread state of the planar diagonal.
struct DiagWorker<'a> {
    scratch: planar::Scratch,
    acc: Vec<Complex64>,
    fallback: Option<Probe<'a>>,
    rows: u64,
    non_finite: u64,
}

/// The diagonal by the planar FFT convolution, rows in parallel; voxels with paths outside
/// the guard on the kernel's band path.
fn direct_planar(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
    planar: &Planar,
) -> Result<(Vec<f32>, Report)> {
    let cfg = job.cfg;
    let g = src.geometry().clone();
    let skip = outside_guard(&g, cfg, &volume.points);
    let fb_idx: Vec<usize> = (0..skip.len()).filter(|&i| skip[i]).collect();
    let fb_pts: Vec<Point> = fb_idx.iter().map(|&i| volume.points[i]).collect();
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
                &fb_pts,
                st,
            )?)
        };
        workers.push(DiagWorker {
            scratch: planar.scratch(),
            acc: vec![Complex64::new(0.0, 0.0); volume.len()],
            fallback,
            rows: 0,
            non_finite: 0,
        });
    }
    let pts = &volume.points;
    let workers = drive_rows(src, job, &scan, "direct", workers, |w, row| {
        let laser = row.laser();
        planar.apply(
            row.band(),
            pts,
            |v| {
                let d = dist(laser, *v);
                (d, cfg.weight(d))
            },
            &skip,
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
    let mut acc = vec![Complex64::new(0.0, 0.0); volume.len()];
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
    let mut values: Vec<f32> = acc.iter().map(|a| a.norm_sqr() as f32).collect();
    if let Some(m) = merged {
        let mut out = vec![0.0f64; fb_pts.len()];
        m.finish(&scan, &mut out)?;
        for (&i, v) in fb_idx.iter().zip(out) {
            values[i] = v as f32;
        }
    }
    Ok((values, report))
}

/// The time gate of a column (the CLI's `--gate`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColumnGate {
    /// 4-vertex Gaussian gate (Eq. 14): first-order indirect light from `x_a`.
    TwoBounce,
    /// The late gate (Eq. 18): higher-order indirect light.
    HigherOrder,
    /// No gate (the paper's Fig. 6 control).
    None,
}

/// A distance shell `r0 ≤ |x_a − x_b| < r1` (m) (near / middle / far decompositions).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shell {
    /// Inner radius (inclusive).
    pub r0: f32,
    /// Outer radius (exclusive).
    pub r1: f32,
}

impl Shell {
    /// Everything.
    pub const ALL: Self = Self {
        r0: 0.0,
        r1: f32::INFINITY,
    };

    /// Parses `R0:R1` (metres; `R1` may be `inf`).
    ///
    /// # Errors
    /// [`Error::Argument`] (`--shell`) unless `0 ≤ R0 < R1`.
    pub fn parse(s: &str) -> Result<Self> {
        let bad = || {
            Error::arg(
                "--shell",
                format!("expected R0:R1 with 0 <= R0 < R1 in metres, found `{s}`"),
            )
        };
        let (a, b) = s.split_once(':').ok_or_else(bad)?;
        let r0: f32 = a.trim().parse().map_err(|_| bad())?;
        let r1: f32 = b.trim().parse().map_err(|_| bad())?;
        if !(r0 >= 0.0 && r1 > r0) || r0.is_nan() {
            return Err(bad());
        }
        Ok(Self { r0, r1 })
    }

    /// Whether `d` lies in the shell.
    pub fn contains(&self, d: f32) -> bool {
        d >= self.r0 && d < self.r1
    }
}

fn dist(a: Point, b: Point) -> f32 {
    ((0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f32>()).sqrt()
}

/// Checks that a focus point is in front of the wall.
///
/// # Errors
/// [`Error::Argument`] (`--focus`) for z ≤ 0 or non-finite coordinates.
pub fn check_focus(a: Point) -> Result<()> {
    if a.iter().all(|c| c.is_finite()) && a[2] > 0.0 {
        Ok(())
    } else {
        Err(Error::arg(
            "--focus",
            format!("{a:?} is on or behind the wall (need z > 0)"),
        ))
    }
}

/// A column `T(x_a, ·)` over `volume`, with elements outside `shell` set to 0.
///
/// # Errors
/// Focus on or behind the wall, configuration, read and kernel errors; [`Error::Argument`]
/// (`--path`) when a path is forced that does not evaluate this column (`lookup`; `planar`
/// with a gate other than two-bounce or where the convolution does not apply).
pub fn column(
    src: &mut dyn RowSource,
    focus: Point,
    volume: &Volume,
    gate: ColumnGate,
    shell: Shell,
    wave: &Wave,
    exec: Exec,
) -> Result<Output> {
    check_focus(focus)?;
    match (exec.path, gate) {
        (Path::Lookup, _) => {
            return Err(Error::arg(
                "--path",
                "the lookup path evaluates the diagonal only (use auto, band or planar for columns)",
            ));
        }
        (Path::Planar, ColumnGate::HigherOrder | ColumnGate::None) => {
            return Err(Error::arg(
                "--path",
                "the planar path images Gaussian-gated (two-bounce) columns only (use auto or band)",
            ));
        }
        _ => {}
    }
    let t = Instant::now();
    let cfg = if gate == ColumnGate::TwoBounce {
        wave.column_config(src.geometry(), &[focus], &volume.points)?
    } else {
        wave.config(src.geometry())?
    };
    let target = Target::Column(focus);
    let (mut v, report, path) = match gate {
        ColumnGate::HigherOrder => {
            let (v, r) = elementwise(
                src,
                Job {
                    cfg: &cfg,
                    wave,
                    exec,
                },
                target,
                Gate::HigherOrder,
                &volume.points,
                "column",
            )?;
            (v, r, Path::Band)
        }
        ColumnGate::TwoBounce | ColumnGate::None => {
            let kgate = if gate == ColumnGate::None {
                Gate::None
            } else {
                Gate::Gaussian
            };
            single_column(
                src,
                Job {
                    cfg: &cfg,
                    wave,
                    exec,
                },
                focus,
                kgate,
                volume,
            )?
        }
    };
    for (x, p) in v.iter_mut().zip(&volume.points) {
        if !shell.contains(dist(focus, *p)) {
            *x = 0.0;
        }
    }
    Ok(Output {
        values: v.iter().map(|&x| x as f32).collect(),
        report,
        seconds: t.elapsed().as_secs_f64(),
        config: cfg,
        path,
    })
}

/// One factorised column, rows in parallel (one probe per thread, merged), imaged over the
/// volume by the planar convolution (Gaussian gate, when it applies) or the kernel; with the
/// path that imaged it.
fn single_column(
    src: &mut dyn RowSource,
    job: Job<'_>,
    focus: Point,
    gate: Gate,
    volume: &Volume,
) -> Result<(Vec<f64>, Report, Path)> {
    let cfg = job.cfg;
    let g = src.geometry().clone();
    if g.confocal {
        return Err(Error::arg(
            "column",
            "a confocal capture has no separate camera aperture: columns need a SPAD grid",
        ));
    }
    let planar = if gate == Gate::Gaussian {
        let rival = band_flops(&g, cfg, volume.len());
        choose_planar(&g, cfg, volume, job.exec.path, PlanarUse::Column, rival)?
    } else {
        None
    };
    let ks = g.spads.len();
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, &g.spads, &mut tables)?;
    let target = Target::Column(focus);
    let n_state = Probe::state_len(cfg, target, gate, 0, ks);
    let nw = rayon::current_num_threads().max(1);
    let mut states: Vec<Vec<f64>> = (0..nw).map(|_| vec![0.0; n_state]).collect();
    let probes = states
        .iter_mut()
        .map(|st| Probe::new(&scan, target, gate, &[], st))
        .collect::<Result<Vec<_>, _>>()?;
    let probes = drive_rows(src, job, &scan, "column", probes, |p, row| {
        Ok(p.push_row(&scan, row)?)
    })?;
    let mut it = probes.into_iter();
    let Some(mut p) = it.next() else {
        return Ok((vec![0.0; volume.len()], Report::default(), Path::Band));
    };
    for q in it {
        p.merge(&q)?;
    }
    let voxels = &volume.points;
    if let (Some(planar), Some((u, legs))) = (planar, p.column_spectra()) {
        let u32s: Vec<Complex32> = u
            .iter()
            .map(|z| Complex32::new(z.re as f32, z.im as f32))
            .collect();
        let skip = vec![false; voxels.len()];
        // One pass over the slices (milliseconds; the rows were the parallel part).
        let mut acc = vec![Complex64::new(0.0, 0.0); voxels.len()];
        let mut scratch = planar.scratch();
        planar.apply(
            &u32s,
            voxels,
            |b| (dist(focus, *b), 1.0),
            &skip,
            &mut scratch,
            &mut acc,
        );
        let aliased = column_aliased(&scan, focus, voxels, legs);
        let out = acc.iter().map(|a| a.norm_sqr()).collect();
        return Ok((
            out,
            Report {
                aliased,
                ..p.report()
            },
            Path::Planar,
        ));
    }
    let cl = chunk_len(voxels.len());
    let mut out = vec![0.0f64; voxels.len()];
    let reports = voxels
        .par_chunks(cl)
        .zip(out.par_chunks_mut(cl))
        .map(|(v, o)| p.image(&scan, v, o))
        .collect::<Result<Vec<_>, _>>()?;
    let aliased = reports.iter().map(|r| r.aliased).sum();
    Ok((
        out,
        Report {
            aliased,
            ..p.report()
        },
        Path::Band,
    ))
}

/// The kernel's alias count of a factorised column (voxels whose path times
/// `d1 + d_la + d_ab + d_bs + d4 − t0` leave [`Config::alias_free`]), for columns imaged on
/// the host.
fn column_aliased(scan: &Scan<'_>, a: Point, voxels: &[Point], legs: (f64, f64)) -> usize {
    let cfg = scan.config();
    let (af_lo, af_hi) = cfg.alias_free();
    if legs.0 > legs.1 {
        return 0;
    }
    voxels
        .par_iter()
        .filter(|b| {
            let d_ab = dist(a, **b);
            let (lo, hi) = scan.spads().iter().zip(scan.sensor_legs()).fold(
                (f64::INFINITY, f64::NEG_INFINITY),
                |(lo, hi), (sp, d4)| {
                    let x = (d_ab + dist(**b, *sp) + d4) as f64;
                    (lo.min(x), hi.max(x))
                },
            );
            legs.0 + lo - cfg.t0() < af_lo || legs.1 + hi - cfg.t0() > af_hi
        })
        .count()
}

/// One factorised column per focus, accumulated in one pass, each imaged over `voxels`.
fn factorised_columns(
    src: &mut dyn RowSource,
    job: Job<'_>,
    foci: &[Point],
    gate: Gate,
    voxels: &[Point],
    label: &str,
) -> Result<Vec<(Vec<f64>, Report)>> {
    let cfg = job.cfg;
    let g = src.geometry().clone();
    if g.confocal {
        return Err(Error::arg(
            "column",
            "a confocal capture has no separate camera aperture: columns need a SPAD grid",
        ));
    }
    let ks = g.spads_per_row();
    let n_state = Probe::state_len(cfg, Target::Column(foci[0]), gate, 0, ks);
    let mut states: Vec<Vec<f64>> = foci.iter().map(|_| vec![0.0; n_state]).collect();
    let mut probes: Vec<Probe<'_>> = Vec::new();
    let mut state_iter = Some(states.iter_mut());
    drive(src, job, label, |scan, row| {
        if let Some(it) = state_iter.take() {
            probes = foci
                .iter()
                .zip(it)
                .map(|(a, s)| Probe::new(scan, Target::Column(*a), gate, &[], s))
                .collect::<Result<_, _>>()?;
        }
        probes
            .par_iter_mut()
            .try_for_each(|p| p.push_row(scan, row))?;
        Ok(())
    })?;
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, &g.spads, &mut tables)?;
    let cl = chunk_len(voxels.len());
    probes
        .iter()
        .map(|p| {
            let mut out = vec![0.0f64; voxels.len()];
            let reports = voxels
                .par_chunks(cl)
                .zip(out.par_chunks_mut(cl))
                .map(|(v, o)| p.image(&scan, v, o))
                .collect::<Result<Vec<_>, _>>()?;
            let aliased = reports.iter().map(|r| r.aliased).sum();
            Ok((
                out,
                Report {
                    aliased,
                    ..p.report()
                },
            ))
        })
        .collect()
}

/// Options of the in-focus indirect sum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IndirectOptions {
    /// Relative threshold ε: Γ = {v : I_d(v) > ε·max I_d} (default 0.1).
    pub epsilon: f32,
    /// Pair distances accumulated: `r0 ≤ |x_a − x_b| < r1`; `r0` default 1.5σ (DESIGN §B.3.4).
    pub shell: Option<Shell>,
    /// Largest accumulator memory accepted (bytes) (default 8 GiB).
    pub max_bytes: usize,
}

impl Default for IndirectOptions {
    fn default() -> Self {
        Self {
            epsilon: 0.1,
            shell: None,
            max_bytes: 8 << 30,
        }
    }
}

/// Result of [`indirect`].
#[derive(Clone, Debug, PartialEq)]
pub struct IndirectOutput {
    /// In-focus indirect light `I_i(b)` (0 outside Γ).
    pub values: Vec<f32>,
    /// The direct light `I_d` of pass 1.
    pub direct: Vec<f32>,
    /// Γ membership per voxel.
    pub gamma: Vec<bool>,
    /// The pair shell used.
    pub shell: Shell,
    /// Counters of pass 2.
    pub report: Report,
    /// Wall-clock seconds for both passes.
    pub seconds: f64,
}

/// Γ = {v : I_d(v) > ε·max I_d} (Eq. 15 with a relative threshold); empty if the maximum is
/// not positive or not finite.
pub fn gamma_mask(direct: &[f32], epsilon: f32) -> Vec<bool> {
    let max = direct.iter().copied().fold(0.0f32, f32::max);
    direct
        .iter()
        .map(|&v| max.is_finite() && max > 0.0 && v > epsilon * max)
        .collect()
}

/// In-focus indirect light (Eqs. 15–17): pass 1 the diagonal, Γ = {I_d > ε·max}, pass 2
/// one factorised column per `a ∈ Γ`, and `I_i(b) = Σ_{a∈Γ, a≠b, r0≤|a−b|<r1} T(a, b)` for
/// `b ∈ Γ`. Reads the source twice.
///
/// # Errors
/// ε out of range, Γ too large for `max_bytes`, configuration, read and kernel errors.
pub fn indirect(
    src: &mut dyn RowSource,
    volume: &Volume,
    opts: &IndirectOptions,
    wave: &Wave,
    exec: Exec,
) -> Result<IndirectOutput> {
    if !(opts.epsilon >= 0.0 && opts.epsilon < 1.0) {
        return Err(Error::arg(
            "--epsilon",
            format!("expected 0 <= E < 1, found {}", opts.epsilon),
        ));
    }
    let t = Instant::now();
    let d = direct(src, volume, wave, exec)?;
    let gamma = gamma_mask(&d.values, opts.epsilon);
    let mut out = indirect_over(src, volume, &gamma, opts, wave, exec)?;
    out.direct = d.values;
    out.seconds = t.elapsed().as_secs_f64();
    Ok(out)
}

/// Pass 2 of [`indirect`] for a given Γ (e.g. from a direct-light image computed once and
/// reused for several captures, such as a scene and its direct-only control).
/// `IndirectOutput::direct` is left empty.
///
/// # Errors
/// Γ of the wrong length or too large for `max_bytes`, configuration, read and kernel errors.
pub fn indirect_over(
    src: &mut dyn RowSource,
    volume: &Volume,
    gamma: &[bool],
    opts: &IndirectOptions,
    wave: &Wave,
    exec: Exec,
) -> Result<IndirectOutput> {
    let t = Instant::now();
    if gamma.len() != volume.len() {
        return Err(Error::arg(
            "gamma",
            format!("expected {} flags, found {}", volume.len(), gamma.len()),
        ));
    }
    let idx: Vec<usize> = (0..gamma.len()).filter(|&i| gamma[i]).collect();
    let pts: Vec<Point> = idx.iter().map(|&i| volume.points[i]).collect();
    let cfg = wave.column_config(src.geometry(), &pts, &pts)?;
    let shell = opts.shell.unwrap_or(Shell {
        r0: 1.5 * cfg.sigma() as f32,
        r1: f32::INFINITY,
    });
    let mut values = vec![0.0f32; volume.len()];
    let mut report = Report::default();
    if !idx.is_empty() {
        let ks = src.geometry().spads_per_row();
        let bytes = idx.len()
            * Probe::state_bytes(&cfg, Target::Column([0.0, 0.0, 1.0]), Gate::Gaussian, 0, ks);
        if bytes > opts.max_bytes {
            return Err(Error::arg(
                "--epsilon",
                format!(
                    "Γ has {} voxels and needs {:.1} GB of accumulators; raise --epsilon",
                    idx.len(),
                    bytes as f64 / 1e9
                ),
            ));
        }
        let cols = factorised_columns(
            src,
            Job {
                cfg: &cfg,
                wave,
                exec,
            },
            &pts,
            Gate::Gaussian,
            &pts,
            "indirect",
        )?;
        let mut sum = vec![0.0f64; pts.len()];
        for (ai, (col, r)) in cols.iter().enumerate() {
            report = *r;
            for (bi, t) in col.iter().enumerate() {
                if ai != bi && shell.contains(dist(pts[ai], pts[bi])) {
                    sum[bi] += t;
                }
            }
        }
        for (&i, s) in idx.iter().zip(sum) {
            values[i] = s as f32;
        }
    }
    Ok(IndirectOutput {
        values,
        direct: Vec::new(),
        gamma: gamma.to_vec(),
        shell,
        report,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// Swaps the roles of lasers and SPADs by reciprocity (DESIGN §B.3.7): the SPAD array becomes
/// the virtual projector and the laser grid the camera, `T_swap(a, b) = T(b, a)`. Needs the
/// capture in memory (`Kl·Ks·Nt` values).
///
/// # Errors
/// [`Error::Argument`] for confocal captures (nothing to swap).
pub fn swap_roles(c: &Capture) -> Result<Capture> {
    let g = &c.geometry;
    if g.confocal {
        return Err(Error::arg(
            "--swap-roles",
            "a confocal capture has nothing to swap",
        ));
    }
    let (kl, ks, nt) = (g.lasers.len(), g.spads.len(), g.nt);
    let mut data = vec![0.0f32; c.data.len()];
    for l in 0..kl {
        for s in 0..ks {
            data[(s * kl + l) * nt..(s * kl + l + 1) * nt]
                .copy_from_slice(&c.data[(l * ks + s) * nt..(l * ks + s + 1) * nt]);
        }
    }
    let geometry = Geometry {
        lasers: g.spads.clone(),
        laser_shape: g.spad_shape,
        spads: g.lasers.clone(),
        spad_shape: g.laser_shape,
        laser_origin: g.sensor_origin,
        sensor_origin: g.laser_origin,
        ..g.clone()
    };
    Ok(Capture { geometry, data })
}
