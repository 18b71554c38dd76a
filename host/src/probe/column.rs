//! Columns `T(x_a, ·)` (Eqs. 13–14, 18): two-bounce, higher-order or un-gated, optionally cut
//! to a distance [`Shell`]; the factorised column accumulation shared with the in-focus
//! indirect sum; the diagonal under the same three gates ([`diagonal`]).

use super::crop::{Crop, Reach, with_crop};
use super::direct::direct;
use super::drive::*;
use super::gate::ColumnGate;
use super::output::{Output, check_finite, intensities};
use super::plan;
use super::wave::*;
use crate::budget;
use crate::error::{Error, Result};
use crate::exec::{EvalPath, Exec, Pass, chunk_len};
use crate::io::capture::{Geometry, RowSource};
use crate::probe::fast::Planar;
use crate::volume::Volume;
use num_complex::{Complex32, Complex64};
use rayon::prelude::*;
use std::time::Instant;
use vltm_kernel::geometry::dist;
use vltm_kernel::{Gate, Point, Probe, Report, Scan, Target, cis_turns, geometry};

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
    /// [`Error::Argument`] (`shell`) unless `0 ≤ R0 < R1`.
    pub fn parse(s: &str) -> Result<Self> {
        let bad = || {
            Error::arg(
                "shell",
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

    /// The names of the three shells of [`Shell::cuts`], in order.
    pub const CUT_NAMES: [&'static str; 3] = ["near", "middle", "far"];

    /// Near `[0, r1)`, middle `[r1, r2)` and far `[r2, ∞)`.
    ///
    /// # Errors
    /// [`Error::Argument`] (`shells`) unless `0 < r1 < r2 < ∞`.
    pub fn cuts(r1: f32, r2: f32) -> Result<[Self; 3]> {
        if !(r1 > 0.0 && r2 > r1 && r2.is_finite()) {
            return Err(Error::arg(
                "shells",
                format!("expected 0 < R1 < R2 in metres, found {r1}, {r2}"),
            ));
        }
        Ok([
            Self { r0: 0.0, r1 },
            Self { r0: r1, r1: r2 },
            Self {
                r0: r2,
                r1: f32::INFINITY,
            },
        ])
    }

    /// Parses `R1,R2` (metres, `0 < R1 < R2`) into [`Shell::cuts`].
    ///
    /// # Errors
    /// [`Error::Argument`] (`shells`) for anything else.
    pub fn parse_cuts(s: &str) -> Result<[Self; 3]> {
        let bad = || {
            Error::arg(
                "shells",
                format!("expected R1,R2 with 0 < R1 < R2 in metres, found `{s}`"),
            )
        };
        let (a, b) = s.split_once(',').ok_or_else(bad)?;
        let r1: f32 = a.trim().parse().map_err(|_| bad())?;
        let r2: f32 = b.trim().parse().map_err(|_| bad())?;
        Self::cuts(r1, r2).map_err(|_| bad())
    }

    /// `values` over `points` with every voxel outside the shell around `a` set to 0 (one
    /// shell of a column `T(x_a, ·)`).
    pub fn cut(&self, a: Point, values: &[f32], points: &[Point]) -> Vec<f32> {
        values
            .iter()
            .zip(points)
            .map(|(&x, p)| if self.contains(dist(&a, p)) { x } else { 0.0 })
            .collect()
    }
}

/// The diagonal under another gate: `none` (the monochromatic phasor, paper Fig. 6: direct
/// light plus everything else that reaches `x_v`'s focus at any time) or `higher-order`
/// (Eq. 18's late gate on the 3-vertex time: light that leaves `x_v`'s focus and returns to
/// it later, i.e. paths `x_l → x_v → … → x_v → x_s`); [`ColumnGate::TwoBounce`] is
/// [`direct`] itself. Kernel band path, element-wise (`Kv·Ks·E0` per row un-gated,
/// `Kv·Ks·(E0 + 7R)` higher-order).
///
/// # Errors
/// As [`direct`]; [`Error::Argument`] (`path`) when a fast path is forced for a gate other
/// than the Gaussian one.
pub fn diagonal(
    src: &mut dyn RowSource,
    volume: &Volume,
    gate: ColumnGate,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<Output> {
    let kgate = match gate {
        ColumnGate::TwoBounce => return direct(src, volume, wave, exec),
        ColumnGate::HigherOrder => Gate::HigherOrder,
        ColumnGate::None => Gate::None,
    };
    wave.refuse_cosine("the un-gated and higher-order diagonals")?;
    let path = plan::other_gates(exec.path)?;
    let t = Instant::now();
    let base = wave.config(src.geometry())?;
    super::window::window_rule(src.geometry(), &base, None, &volume.points, gate, exec)?;
    // The late gate counts light after the path: only the start of the axis is cropped.
    let reach = Reach {
        foci: None,
        voxels: &volume.points,
        late: true,
    };
    let wave_crop = Wave {
        crop: wave.crop && kgate == Gate::HigherOrder,
        ..*wave
    };
    let (v, report, cfg, crop) = with_crop(src, &wave_crop, exec, reach, |src, exec, crop| {
        let cfg = wave.config(src.geometry())?;
        let job = Job {
            cfg: &cfg,
            wave,
            exec,
        };
        let (v, r) = elementwise(src, job, Target::Diagonal, kgate, &volume.points, "direct")?;
        Ok((v, r, cfg, crop))
    })?;
    let values = intensities(&v);
    check_finite(&values, &volume.points, "the diagonal")?;
    Ok(Output {
        values,
        report,
        seconds: t.elapsed().as_secs_f64(),
        config: cfg,
        path,
        crop,
        aligned: None,
    })
}

/// Checks that a focus point is in front of the wall.
///
/// # Errors
/// [`Error::Argument`] (`focus`) for z ≤ 0 or non-finite coordinates.
pub fn check_focus(a: Point) -> Result<()> {
    if a.iter().all(|c| c.is_finite()) && a[2] > 0.0 {
        Ok(())
    } else {
        Err(Error::arg(
            "focus",
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
    exec: Exec<'_>,
) -> Result<Output> {
    wave.refuse_cosine("`column`")?;
    let t = Instant::now();
    let (state, cfg, crop) = column_acc(src, focus, volume, gate, wave, exec, false)?;
    let spads = src.geometry().spads.clone();
    let (values, report, path, _) = state.finish(&cfg, &spads, focus, volume, shell, false)?;
    check_finite(&values, &volume.points, "column")?;
    Ok(Output {
        values,
        report,
        seconds: t.elapsed().as_secs_f64(),
        config: cfg,
        path,
        crop,
        aligned: None,
    })
}

/// The accumulated state of a column before imaging.
pub(super) enum ColumnState {
    /// Element-wise (higher-order gate): the complex accumulator of every voxel.
    Voxels(Vec<Complex64>, Report),
    /// A factorised column (two-bounce or un-gated): the kernel probe's state (`f64` pairs),
    /// its counters and projector leg range, the gate, and the path that images it (the
    /// planar convolution, when already prepared).
    Factorised {
        state: Vec<f64>,
        report: Report,
        legs: (f64, f64),
        gate: Gate,
        path: EvalPath,
        planar: Option<Box<Planar>>,
    },
}

/// The accumulators of [`column()`] over the source's rows ([`RowSource::rows`]), with the
/// configuration (of the time axis cropped to the paths' reach) and the crop. `defer`: leave
/// the choice of the imaging path under [`EvalPath::Auto`] to `ColumnState::finish` (the path is
/// then recorded as `Auto`).
/// The checks [`column()`] makes before it reads a row: the focus, the lens weights, the
/// evaluation path for the gate, a SPAD grid for the factorised gates, and the capture's
/// window. A front end that runs another pass first (the leak correction's Γ) calls it to
/// refuse bad input before any work.
///
/// # Errors
/// As [`column()`]'s argument errors.
pub fn check_column(
    g: &Geometry,
    focus: Point,
    volume: &Volume,
    gate: ColumnGate,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<()> {
    wave.refuse_cosine("`column`")?;
    check_focus(focus)?;
    plan::check_column(exec.path, gate)?;
    if gate != ColumnGate::HigherOrder {
        g.need_spad_grid("column", "columns need")?;
    }
    let base = wave.config(g)?;
    // Quiet: the column itself warns about a partial coverage.
    let quiet = Exec {
        progress: None,
        ..exec
    };
    super::window::window_rule(g, &base, Some(&[focus]), &volume.points, gate, quiet).map(|_| ())
}

pub(super) fn column_acc(
    src: &mut dyn RowSource,
    focus: Point,
    volume: &Volume,
    gate: ColumnGate,
    wave: &Wave,
    exec: Exec<'_>,
    defer: bool,
) -> Result<(ColumnState, vltm_kernel::Config, Option<Crop>)> {
    check_focus(focus)?;
    plan::check_column(exec.path, gate)?;
    let base = wave.config(src.geometry())?;
    let foci = [focus];
    super::window::window_rule(
        src.geometry(),
        &base,
        Some(&foci),
        &volume.points,
        gate,
        exec,
    )?;
    if gate == ColumnGate::None {
        let (state, cfg) = column_acc_on(src, focus, volume, gate, wave, exec, defer)?;
        return Ok((state, cfg, None));
    }
    let after = gate == ColumnGate::HigherOrder;
    let reach = Reach {
        foci: Some(&foci),
        voxels: &volume.points,
        late: after,
    };
    with_crop(src, wave, exec, reach, |src, exec, crop| {
        let (state, cfg) = column_acc_on(src, focus, volume, gate, wave, exec, defer)?;
        Ok((state, cfg, crop))
    })
}

/// [`column_acc`] on the (cropped) source.
fn column_acc_on(
    src: &mut dyn RowSource,
    focus: Point,
    volume: &Volume,
    gate: ColumnGate,
    wave: &Wave,
    exec: Exec<'_>,
    defer: bool,
) -> Result<(ColumnState, vltm_kernel::Config)> {
    let cfg = if gate == ColumnGate::TwoBounce {
        wave.column_config(src.geometry(), &[focus], &volume.points)?
    } else {
        wave.config(src.geometry())?
    };
    check_memory(
        src.geometry(),
        &cfg,
        budget::bytes(volume.len(), 32),
        "the column",
    )?;
    let job = Job {
        cfg: &cfg,
        wave,
        exec,
    };
    let state = match gate {
        ColumnGate::HigherOrder => {
            let (acc, r) = elementwise(
                src,
                job,
                Target::Column(focus),
                Gate::HigherOrder,
                &volume.points,
                "column",
            )?;
            ColumnState::Voxels(acc, r)
        }
        ColumnGate::TwoBounce | ColumnGate::None => {
            let kgate = if gate == ColumnGate::None {
                Gate::None
            } else {
                Gate::Gaussian
            };
            let g = src.geometry();
            g.need_spad_grid("column", "columns need")?;
            // Deferred under `Auto` (parts of a split scan): `finish` decides.
            let (path, planar) = plan::column(&g.spads, &cfg, volume, exec.path, kgate, defer)?;
            let (state, report, legs) = single_column(src, job, focus, kgate)?;
            ColumnState::Factorised {
                state,
                report,
                legs,
                gate: kgate,
                path,
                planar: planar.map(Box::new),
            }
        }
    };
    Ok((state, cfg))
}

/// A finished column: intensities (0 outside the shell), counters, the path that imaged it,
/// and the complex amplitudes when asked for (`T = |A|²`; two-bounce and higher-order gates).
pub(super) type ColumnImage = (Vec<f32>, Report, EvalPath, Option<Vec<Complex64>>);

impl ColumnState {
    /// The column's intensities over `volume` (0 outside `shell`), the counters and the
    /// path that imaged it. `spads` are the capture's SPAD spots. `amps`: also the complex
    /// amplitudes (0 outside `shell`), for the two-bounce and higher-order gates (`None` for
    /// the un-gated column, which has no time gate to give a phase reference).
    ///
    /// # Errors
    /// A planar path that no longer applies; kernel errors.
    pub(super) fn finish(
        &self,
        cfg: &vltm_kernel::Config,
        spads: &[Point],
        focus: Point,
        volume: &Volume,
        shell: Shell,
        amps: bool,
    ) -> Result<ColumnImage> {
        let (mut v, report, path, mut amplitudes) = match self {
            Self::Voxels(acc, r) => (
                intensities(acc),
                *r,
                EvalPath::Band,
                amps.then(|| acc.clone()),
            ),
            Self::Factorised {
                state,
                report,
                legs,
                gate,
                path,
                planar,
            } => {
                // A column whose path was deferred (or read from a state): the planner decides.
                let rebuilt;
                let planar = match planar {
                    Some(p) => Some(p.as_ref()),
                    None => {
                        rebuilt = plan::column_imaging(spads, cfg, volume, *path, *gate)?;
                        rebuilt.as_ref()
                    }
                };
                let mut state = state.clone();
                let (v, r, p, a) = image_column(
                    cfg, spads, focus, *gate, &mut state, *report, *legs, volume, planar, amps,
                )?;
                (v.iter().map(|&x| x as f32).collect(), r, p, a)
            }
        };
        for (i, p) in volume.points.iter().enumerate() {
            if !shell.contains(dist(&focus, p)) {
                v[i] = 0.0;
                if let Some(a) = &mut amplitudes {
                    a[i] = Complex64::new(0.0, 0.0);
                }
            }
        }
        Ok((v, report, path, amplitudes))
    }
}

/// One factorised column's accumulators, rows in parallel (one probe per thread, merged):
/// the probe state, its counters and projector leg range.
pub(super) fn single_column(
    src: &mut dyn RowSource,
    job: Job<'_>,
    focus: Point,
    gate: Gate,
) -> Result<(Vec<f64>, Report, (f64, f64))> {
    let cfg = job.cfg;
    let g = src.geometry().clone();
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
    let probes = drive_rows(src, job, &scan, "column", probes, |p, _, row| {
        Ok(p.push_row(&scan, row)?)
    })?;
    let mut it = probes.into_iter();
    let Some(mut p) = it.next() else {
        return Ok((
            vec![0.0; n_state],
            Report::default(),
            (f64::INFINITY, f64::NEG_INFINITY),
        ));
    };
    for q in it {
        p.merge(&q)?;
    }
    let state = p.accumulators().iter().flat_map(|z| [z.re, z.im]).collect();
    Ok((state, p.report(), p.leg_range()))
}

/// A column probe imaged over `voxels` in parallel chunks: the intensities and the probe's
/// counters with the aliased paths of every chunk summed.
fn image_chunks(p: &Probe<'_>, scan: &Scan<'_>, voxels: &[Point]) -> Result<(Vec<f64>, Report)> {
    let cl = chunk_len(voxels.len());
    let mut out = vec![0.0f64; voxels.len()];
    let reports = voxels
        .par_chunks(cl)
        .zip(out.par_chunks_mut(cl))
        .map(|(v, o)| p.image(scan, v, o))
        .collect::<Result<Vec<_>, _>>()?;
    let aliased = reports.iter().map(|r| r.aliased).sum();
    Ok((
        out,
        Report {
            aliased,
            ..p.report()
        },
    ))
}

/// What [`image_column`] returns: intensities, counters, path, amplitudes if asked for.
type Imaged = (Vec<f64>, Report, EvalPath, Option<Vec<Complex64>>);

/// Images a factorised column from its state over the volume by the planar convolution
/// (when given: Gaussian gate over a grid) or the kernel; with the path that imaged it and,
/// with `amps` and the Gaussian gate, the complex amplitudes (the planar path's own, or
/// [`column_amplitudes`] beside the kernel's image).
#[allow(clippy::too_many_arguments)]
pub(super) fn image_column(
    cfg: &vltm_kernel::Config,
    spads: &[Point],
    focus: Point,
    gate: Gate,
    state: &mut [f64],
    report: Report,
    legs: (f64, f64),
    volume: &Volume,
    planar: Option<&Planar>,
    amps: bool,
) -> Result<Imaged> {
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, spads.len())];
    let scan = Scan::new(cfg, spads, &mut tables)?;
    let p = Probe::resume(&scan, Target::Column(focus), gate, &[], state, report, legs)?;
    let voxels = &volume.points;
    if let (Some(planar), Some((u, legs))) = (planar, p.column_spectra()) {
        let u32s: Vec<Complex32> = u
            .iter()
            .map(|z| Complex32::new(z.re as f32, z.im as f32))
            .collect();
        let _t = crate::timings::section("imaging the column", crate::timings::Kind::Parallel);
        let skip = vec![false; voxels.len()];
        // One pass over the slices, the slices in parallel (bit-identical to one thread's).
        let mut acc = vec![Complex64::new(0.0, 0.0); voxels.len()];
        planar.apply_parallel(&u32s, voxels, |b| (dist(&focus, b), 1.0), &skip, &mut acc);
        let aliased = column_aliased(&scan, focus, voxels, legs);
        let out = acc.iter().map(|a| a.norm_sqr()).collect();
        return Ok((
            out,
            Report {
                aliased,
                ..p.report()
            },
            EvalPath::Planar,
            amps.then_some(acc),
        ));
    }
    let (out, r) = image_chunks(&p, &scan, voxels)?;
    let amplitudes = (amps && gate == Gate::Gaussian).then(|| {
        let cl = chunk_len(voxels.len());
        let mut a = vec![Complex64::new(0.0, 0.0); voxels.len()];
        voxels
            .par_chunks(cl)
            .zip(a.par_chunks_mut(cl))
            .for_each(|(v, o)| column_amplitudes(&p, &scan, focus, v, o));
        a
    });
    Ok((out, r, EvalPath::Band, amplitudes))
}

/// Complex amplitudes of a factorised Gaussian column probe at `voxels`: `out[i] =
/// A(x_a, voxels[i])`, with exactly the arithmetic of the kernel's `Probe::image` (so that
/// `|out[i]|²` is its intensity). Nothing is written for probes of other kinds.
pub(super) fn column_amplitudes(
    p: &Probe<'_>,
    scan: &Scan<'_>,
    focus: Point,
    voxels: &[Point],
    out: &mut [Complex64],
) {
    let Some((u, _)) = p.column_spectra() else {
        return;
    };
    let cfg = scan.config();
    let j = cfg.bins().max(1);
    let span = cfg.span();
    let (klo, inv) = ((cfg.k_lo() as f64 / span) as f32, (1.0 / span) as f32);
    for (o, b) in out.iter_mut().zip(voxels) {
        let d_ab = dist(&focus, b);
        let mut sum = Complex64::new(0.0, 0.0);
        for (sp, us) in scan.spads().iter().zip(u.chunks_exact(j)) {
            let d_bs = dist(b, sp);
            let tau = d_ab + d_bs;
            let mut ph = cis_turns(klo * tau);
            let step = cis_turns(inv * tau);
            let mut z = Complex64::new(0.0, 0.0);
            for x in us {
                z += *x * Complex64::new(f64::from(ph.re), f64::from(ph.im));
                ph *= step;
            }
            sum += z * f64::from(cfg.weight(d_bs));
        }
        *o = sum;
    }
}

/// The kernel's alias count of a factorised column (voxels whose path times
/// `d1 + d_la + d_ab + d_bs + d4 − t0` leave [`Config::alias_free`]), for columns imaged on
/// the host.
pub(super) fn column_aliased(
    scan: &Scan<'_>,
    a: Point,
    voxels: &[Point],
    legs: (f64, f64),
) -> usize {
    let window = geometry::alias_window(scan.config());
    voxels
        .par_iter()
        .filter(|b| {
            let d_ab = dist(&a, b);
            let paths = scan
                .spads()
                .iter()
                .zip(scan.sensor_legs())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |r, (sp, d4)| {
                    geometry::widen(r, f64::from(d_ab + dist(b, sp) + d4))
                });
            geometry::leaves_window(window, legs, paths)
        })
        .count()
}

/// Factorised columns, one per focus, accumulated in one pass: their states one after
/// the other (`n_state` each), the counters (the same rows for all) and each column's
/// projector leg range.
#[derive(Clone, Debug)]
pub(super) struct Columns {
    pub(super) state: Vec<f64>,
    pub(super) report: Report,
    pub(super) legs: Vec<(f64, f64)>,
}

/// One factorised column per focus, accumulated in one pass over the source's rows.
pub(super) fn factorised_columns(
    src: &mut dyn RowSource,
    job: Job<'_>,
    foci: &[Point],
    gate: Gate,
    label: &str,
) -> Result<Columns> {
    let cfg = job.cfg;
    let g = src.geometry().clone();
    g.need_spad_grid("column", "columns need")?;
    let ks = g.spads_per_row();
    let n_state = Probe::state_len(cfg, Target::Column(foci[0]), gate, 0, ks);
    let mut state = vec![0.0f64; n_state * foci.len()];
    let probes = drive_probes(
        src,
        job,
        label,
        state.chunks_mut(n_state.max(1)),
        |scan, k, s| Probe::new(scan, Target::Column(foci[k]), gate, &[], s),
    )?;
    let report = probes.first().map(Probe::report).unwrap_or_default();
    let mut legs: Vec<(f64, f64)> = probes.iter().map(Probe::leg_range).collect();
    legs.resize(foci.len(), (f64::INFINITY, f64::NEG_INFINITY));
    drop(probes);
    Ok(Columns {
        state,
        report,
        legs,
    })
}

impl Columns {
    /// Images every column over `voxels` (`spads`: the capture's SPAD spots): per focus the
    /// intensities and the counters; the foci imaged go to `exec`'s progress as the stage
    /// `<label>: columns`.
    ///
    /// # Errors
    /// Kernel errors (sizes).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn image(
        &mut self,
        cfg: &vltm_kernel::Config,
        spads: &[Point],
        foci: &[Point],
        gate: Gate,
        voxels: &[Point],
        exec: Exec<'_>,
        label: &str,
    ) -> Result<Vec<(Vec<f64>, Report)>> {
        let ks = spads.len();
        let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
        let scan = Scan::new(cfg, spads, &mut tables)?;
        let n_state = Probe::state_len(cfg, Target::Column(foci[0]), gate, 0, ks);
        let report = self.report;
        // In parallel over the foci (and within a focus over chunks of voxels): a column
        // over few voxels is one chunk.
        let _t = crate::timings::section("imaging columns", crate::timings::Kind::Parallel);
        let bar = Pass::start(exec, &format!("{label}: columns"), foci.len());
        self.state
            .par_chunks_mut(n_state.max(1))
            .zip(foci.par_iter())
            .zip(self.legs.par_iter())
            .map(|((st, a), legs)| {
                let p = Probe::resume(&scan, Target::Column(*a), gate, &[], st, report, *legs)?;
                let imaged = image_chunks(&p, &scan, voxels);
                bar.advance(1);
                imaged
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shells_parse_and_cut() {
        let s = Shell::parse_cuts("0.2, 0.5").unwrap();
        assert_eq!(
            (s[0].r0, s[0].r1, s[1].r0, s[1].r1, s[2].r0),
            (0.0, 0.2, 0.2, 0.5, 0.5)
        );
        assert!(s[2].r1.is_infinite());
        for bad in ["0.5,0.2", "0,1", "1", "a,b", "0.1,inf"] {
            let e = Shell::parse_cuts(bad).unwrap_err().to_string();
            assert!(e.starts_with("argument `shells`"), "{e}");
            assert!(e.ends_with(&format!("found `{bad}`")), "{e}");
        }
        let pts = [[0.0, 0.0, 1.0], [0.0, 0.0, 1.3], [0.0, 0.0, 2.0]];
        let v = [1.0, 2.0, 3.0];
        let f = [0.0, 0.0, 1.0];
        assert_eq!(s[0].cut(f, &v, &pts), [1.0, 0.0, 0.0]);
        assert_eq!(s[1].cut(f, &v, &pts), [0.0, 2.0, 0.0]);
        assert_eq!(s[2].cut(f, &v, &pts), [0.0, 0.0, 3.0]);
        assert_eq!(Shell::CUT_NAMES, ["near", "middle", "far"]);
    }
}
