//! Columns `T(x_a, ·)` (Eqs. 13–14, 18): two-bounce, higher-order or un-gated, optionally cut
//! to a distance [`Shell`]; the factorised column accumulation shared with the in-focus
//! indirect sum.

use super::direct::*;
use super::drive::*;
use super::wave::*;
use crate::error::{Error, Result};
use crate::exec::{Exec, Path, chunk_len};
use crate::io::capture::RowSource;
use crate::volume::Volume;
use num_complex::{Complex32, Complex64};
use rayon::prelude::*;
use std::time::Instant;
use vltm_kernel::{Gate, Point, Probe, Report, Scan, Target};

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
    exec: Exec<'_>,
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
pub(super) fn single_column(
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
    let probes = drive_rows(src, job, &scan, "column", probes, |p, _, row| {
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
pub(super) fn column_aliased(
    scan: &Scan<'_>,
    a: Point,
    voxels: &[Point],
    legs: (f64, f64),
) -> usize {
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
pub(super) fn factorised_columns(
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
