//! A probe run over a part of the rows, kept as a [`Partial`].

use crate::error::{Error, Result};
use crate::exec::{EvalPath, Exec};
use crate::io::capture::{RowRange, RowSource};
use crate::probe::column::{ColumnState, Columns, Shell, column_acc, factorised_columns};
use crate::probe::crop::{self, Reach};
use crate::probe::direct::direct_acc;
use crate::probe::drive::Job;
use crate::probe::gate::ColumnGate;
use crate::probe::leak::{DirectModel, GateEnergy, LeakCorrected, LeakOptions, cell_radius};
use crate::probe::matrix::matrix_acc;
use crate::probe::wave::Wave;
use crate::volume::Volume;
use std::ops::Range;
use vltm_kernel::{Gate, Point, Report};

use super::head::*;
use super::names::*;
use super::part::{Partial, Task};

/// Runs `task` over the laser rows `rows` of `src` and returns its accumulator state.
/// `file_bytes` is the capture file's size (0 for a capture made in memory or a stream whose
/// final size is not known yet: it then matches any size when parts merge) and
/// `capture_name` its name (recorded, not compared). Every parameter is derived from the whole
/// capture's geometry, exactly as one pass over all rows derives it.
///
/// # Errors
/// [`Error::Argument`] (`rows`) for rows outside the scan; the probe's own errors.
#[allow(clippy::too_many_arguments)]
pub fn accumulate(
    src: &mut dyn RowSource,
    file_bytes: u64,
    capture_name: &str,
    volume: &Volume,
    task: &Task,
    wave: &Wave,
    exec: Exec<'_>,
    rows: Range<usize>,
) -> Result<Partial> {
    wave.refuse_cosine("a scan split by rows (`$rows`)")?;
    let g = src.geometry().clone();
    let mut part = RowRange::new(src, rows.clone())?;
    let mut legs = Vec::new();
    let mut spads = Vec::new();
    let mut energy = GateEnergy::default();
    let (cfg, acc, report, path, focus, gate, shell, gamma) = match task {
        Task::Direct => {
            let (a, cfg) = direct_acc(&mut part, volume, wave, exec)?;
            let acc = flat(&a.acc);
            (cfg, acc, a.report, a.path, None, None, None, None)
        }
        Task::Column { focus, gate, shell } => {
            let (state, cfg, _) = column_acc(&mut part, *focus, volume, *gate, wave, exec, true)?;
            let (acc, report, path) = match state {
                ColumnState::Voxels(acc, r) => (flat(&acc), r, EvalPath::Band),
                ColumnState::Factorised {
                    state,
                    report,
                    legs: l,
                    path,
                    ..
                } => {
                    legs.push(leg_head(l));
                    spads.clone_from(&g.spads);
                    (state, report, path)
                }
            };
            let sh = Some(shell_head(*shell));
            (cfg, acc, report, path, Some(*focus), Some(*gate), sh, None)
        }
        Task::Indirect { gamma, shell, leak } => {
            if gamma.len() != volume.len() {
                return Err(Error::arg(
                    "gamma",
                    format!("expected {} flags, found {}", volume.len(), gamma.len()),
                ));
            }
            let idx: Vec<usize> = (0..gamma.len()).filter(|&i| gamma[i]).collect();
            let pts: Vec<Point> = idx.iter().map(|&i| volume.points[i]).collect();
            // The window rule on the volume's diagonal, as a whole `indirect` applies it.
            let base = wave.config(&g)?;
            crate::probe::window::window_coverage(
                &g,
                &base,
                None,
                &volume.points,
                ColumnGate::TwoBounce,
            )?;
            // The time axis cropped to the Γ pairs' reach, as `indirect` crops it.
            let reach = Reach {
                foci: Some(&pts),
                voxels: &pts,
                late: false,
            };
            let bins = crop::bins(&g, wave, reach)?;
            let cfg = wave.column_config(&crop::cropped_geometry(&g, &bins), &pts, &pts)?;
            let shell = shell.unwrap_or(Shell {
                r0: 1.5 * cfg.sigma() as f32,
                r1: f32::INFINITY,
            });
            let job = Job {
                cfg: &cfg,
                wave,
                exec,
            };
            let cols = match (pts.is_empty(), leak) {
                (true, true) => {
                    return Err(Error::arg(
                        "leak_correct",
                        "Γ is empty: no voxel has direct light above ε·max (no direct return in the window for this volume?)",
                    ));
                }
                (true, false) => Columns {
                    state: Vec::new(),
                    report: Report::default(),
                    legs: Vec::new(),
                },
                (false, true) => {
                    let lo = LeakOptions::default();
                    let model = DirectModel::gate(&g, &pts, cell_radius(volume), wave, &lo)?;
                    let mut lc = LeakCorrected::measuring(&mut part, &model);
                    let c = crop::on_bins(&mut lc, bins, |s| {
                        factorised_columns(s, job, &pts, Gate::Gaussian, "indirect")
                    })?;
                    energy = lc.energy().unwrap_or_default();
                    c
                }
                (false, false) => crop::on_bins(&mut part, bins, |s| {
                    factorised_columns(s, job, &pts, Gate::Gaussian, "indirect")
                })?,
            };
            legs = cols.legs.iter().copied().map(leg_head).collect();
            spads.clone_from(&g.spads);
            let sh = Some(shell_head(shell));
            (
                cfg,
                cols.state,
                cols.report,
                EvalPath::Band,
                None,
                None,
                sh,
                Some(idx),
            )
        }
        Task::Matrix { from } => {
            let (cols, cfg) = matrix_acc(&mut part, from, &volume.points, wave, exec)?;
            legs = cols.legs.iter().copied().map(leg_head).collect();
            spads.clone_from(&g.spads);
            (
                cfg,
                cols.state,
                cols.report,
                EvalPath::Band,
                None,
                None,
                None,
                None,
            )
        }
    };
    let (kind, from, leak) = match task {
        Task::Direct => ("direct", Vec::new(), false),
        Task::Column { .. } => ("column", Vec::new(), false),
        Task::Indirect { leak, .. } => ("indirect", Vec::new(), *leak),
        Task::Matrix { from } => ("matrix", from.clone(), false),
    };
    let points = if volume.axes.is_some() {
        Vec::new()
    } else {
        volume.points.clone()
    };
    let head = Head {
        capture: Identity {
            file_bytes,
            lasers: g.lasers.len(),
            laser_shape: g.laser_shape,
            spads: g.spads.len(),
            spad_shape: g.spad_shape,
            nt: g.nt,
            dt: g.dt,
            t0: g.t0,
            confocal: g.confocal,
            legs_in_time: g.legs_in_time,
            geometry_fnv64: geometry_hash(&g),
        },
        probe: ProbeHead {
            kind: kind.into(),
            path: path.name().into(),
            wave: WaveHead {
                wavelength: wave.wavelength,
                sigma: wave.sigma,
                weights: weights_name(wave.weights).into(),
                band_half_width: wave.band_half_width,
                compensate_laser: wave.compensate_laser,
                auto_margin: wave.auto_margin,
            },
            config: config_head(&cfg),
            volume: VolumeHead {
                shape: volume.shape,
                axes: volume.axes,
                points_fnv64: format!("{:016x}", fnv(point_bytes(&volume.points))),
            },
            focus,
            gate: gate.map(|g| gate_name(g).into()),
            shell,
            gamma,
            leak,
        },
        rows: if rows.is_empty() {
            Vec::new()
        } else {
            vec![[rows.start, rows.end]]
        },
        report: Counters {
            rows: report.rows,
            non_finite: report.non_finite,
            dropped: report.dropped,
            leak_total: energy.total,
            leak_cut: energy.cut,
        },
        legs,
        n_spads: spads.len(),
        n_points: points.len(),
        n_from: from.len(),
        n_acc: acc.len(),
        crc32: String::new(),
        capture_name: capture_name.into(),
    };
    Ok(Partial {
        head,
        spads,
        points,
        from,
        acc,
    })
}
