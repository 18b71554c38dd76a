//! Running a probe: the command line's `direct`, `column`, `indirect`, `matrix`, `relight`
//! and `row` with all their options, in one entry point ([`run`]) that mirrors what the
//! command line does (same library calls in the same order, so the volumes are the same bit
//! for bit).

use crate::capture::{NativeCapture, prep_of};
use crate::job::Job;
use crate::leak::{
    apply_mask, auto_windows, column_mask, corrected, fallback_warning, falloff_of,
    surface_model,
};
use crate::options::{column_gate, diagonal_gate, shell_of, wave_of};
use crate::partial::{NativePartial, counters, report};
use crate::volume::{NativeVolume, points_of};
use crate::{arg, py_err};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use vltm::exec::{EvalPath, Exec};
use vltm::io::RowSource;
use vltm::io::prep::{PrepReport, with_prep};
use vltm::probe::{
    self, ColumnGate, Gamma, IndirectOptions, LeakCorrected, LeakOptions, Partial, Pattern, Shell,
    Task, Wave, partial,
};
use vltm_kernel::Point;

/// A finished probe.
pub(crate) struct Done {
    /// The main output (for shells: the whole column or the first shell's sum).
    pub(crate) out: probe::Output,
    /// Several volumes of one run (near, middle, far), if asked for.
    pub(crate) parts: Option<Vec<Vec<f32>>>,
    pub(crate) amplitudes: Option<Vec<num_complex::Complex64>>,
    pub(crate) explained: Option<f64>,
    pub(crate) gamma: Option<Vec<bool>>,
    pub(crate) direct: Option<Vec<f32>>,
    pub(crate) passes: Option<usize>,
    pub(crate) prep: Option<PrepReport>,
    /// The leak correction that ran: `gate` (the windows) or `model`.
    pub(crate) leak: Option<&'static str>,
    /// `leak_correct="auto"`: the windows' adjacency it chose by.
    pub(crate) adjacency: Option<f64>,
    /// Warnings beside the preprocessing's (a surface model not used, and why).
    pub(crate) warnings: Vec<String>,
}

impl Done {
    pub(crate) fn of(out: probe::Output) -> Self {
        Self {
            out,
            parts: None,
            amplitudes: None,
            explained: None,
            gamma: None,
            direct: None,
            passes: None,
            prep: None,
            leak: None,
            adjacency: None,
            warnings: Vec::new(),
        }
    }
}

/// What a probe call returns: finished arrays, a matrix, or a partial state.
#[allow(clippy::large_enum_variant)] // one per call, moved once
enum Outcome {
    Done(Done),
    Matrix(probe::Matrix),
    Part(Box<Partial>),
}

/// Runs a probe: `kind` is direct, column, indirect, matrix (`from_points` × the volume),
/// relight (`pattern` (n, 4) foci and weights, or `pattern_spec`) or row; `rows` makes it
/// partial. Options as the command line's (flags spelled as keywords).
#[pyfunction]
#[pyo3(signature = (capture, volume, kind, *, focus=None, gate="two-bounce", shell=None,
    shells=None, epsilon=0.1, direct=None, mask_epsilon=None, leak_correct=false,
    leak_model=false, leak_auto=false, leak_epsilon=0.1, wavelength=None, sigma=None, weights="inv", band=5.0,
    compensate_laser=false, crop=true, path="auto", swap_roles=false, t_min=None, t_max=None, rebin=1,
    background=None, rows=None, amplitudes=false, from_points=None, pattern=None,
    pattern_spec=None))]
#[allow(clippy::too_many_arguments)]
fn run<'py>(
    py: Python<'py>,
    capture: PyRef<'py, NativeCapture>,
    volume: PyRef<'py, NativeVolume>,
    kind: &str,
    focus: Option<[f32; 3]>,
    gate: &str,
    shell: Option<(f32, f32)>,
    shells: Option<&str>,
    epsilon: f32,
    direct: Option<PyReadonlyArray1<'py, f32>>,
    mask_epsilon: Option<f32>,
    leak_correct: bool,
    leak_model: bool,
    leak_auto: bool,
    leak_epsilon: f32,
    wavelength: Option<f64>,
    sigma: Option<f64>,
    weights: &str,
    band: f64,
    compensate_laser: bool,
    crop: bool,
    path: &str,
    swap_roles: bool,
    t_min: Option<&str>,
    t_max: Option<&str>,
    rebin: usize,
    background: Option<&str>,
    rows: Option<(usize, usize)>,
    amplitudes: bool,
    from_points: Option<PyReadonlyArray2<'py, f32>>,
    pattern: Option<PyReadonlyArray2<'py, f64>>,
    pattern_spec: Option<&str>,
) -> PyResult<Py<PyAny>> {
    let (wave, epath) = wave_of(
        wavelength,
        sigma,
        weights,
        band,
        compensate_laser,
        crop,
        path,
    )?;
    let prep = prep_of(t_min, t_max, rebin, background)?;
    let shell = shell_of("shell", shell)?;
    let cuts = shells.map(Shell::parse_cuts).transpose().map_err(py_err)?;
    if cuts.is_some() && shell.is_some() {
        return Err(arg(
            "shells",
            "cannot be used with shell (or min_separation)",
        ));
    }
    if rows.is_some() && prep.is_some() {
        return Err(arg(
            "rows",
            "partial states do not record preprocessing yet: run without t_min/t_max/rebin/background",
        ));
    }
    let vol = &volume.volume;
    let direct: Option<Vec<f32>> = direct.map(|d| d.as_array().iter().copied().collect());
    let need_focus = || -> PyResult<Point> {
        let a = focus.ok_or_else(|| arg("focus", "this probe needs a focus (x, y, z)"))?;
        probe::check_focus(a).map_err(py_err)?;
        Ok(a)
    };
    let no_part = |what: &str| -> PyResult<()> {
        if rows.is_some() {
            return Err(arg(
                "rows",
                format!("{what} has no partial states: run it over all rows"),
            ));
        }
        Ok(())
    };
    let job = match kind {
        "direct" => {
            let gate = diagonal_gate(gate)?;
            if gate != ColumnGate::TwoBounce {
                if rows.is_some() {
                    return Err(arg(
                        "rows",
                        "partial states hold the Gaussian-gated diagonal (direct light) only",
                    ));
                }
                if amplitudes {
                    return Err(arg(
                        "amplitudes",
                        "complex amplitudes exist for the Gaussian-gated diagonal (direct light) only",
                    ));
                }
            }
            Job::Direct { gate }
        }
        "column" => {
            let focus = need_focus()?;
            let gate = column_gate(gate)?;
            let extra = cuts.is_some() || mask_epsilon.is_some();
            if rows.is_some() && extra {
                return Err(arg(
                    "rows",
                    "a partial column takes shell, not shells or mask_epsilon (apply them to the merged volume)",
                ));
            }
            if rows.is_some() && leak_correct {
                return Err(arg(
                    "rows",
                    "a partial column cannot be leak-corrected (its Γ needs the direct light of the whole capture): pass leak_correct=False, or run the column over all rows",
                ));
            }
            if amplitudes && extra {
                return Err(arg(
                    "amplitudes",
                    "complex amplitudes come with a column without shells or mask_epsilon",
                ));
            }
            Job::Column {
                focus,
                gate,
                shell: shell.unwrap_or(Shell::ALL),
                shells: cuts,
                mask_epsilon,
                leak_epsilon: leak_correct.then_some(leak_epsilon),
            }
        }
        "indirect" => {
            Gamma::check_epsilon(epsilon, "epsilon").map_err(py_err)?;
            let opts = IndirectOptions {
                epsilon,
                shell,
                gate: column_gate(gate)?,
                leak: leak_correct.then(LeakOptions::default),
                ..IndirectOptions::default()
            };
            if let Some(d) = &direct
                && d.len() != vol.len()
            {
                return Err(arg(
                    "direct",
                    format!(
                        "expected {} values (the volume's voxels), found {}",
                        vol.len(),
                        d.len()
                    ),
                ));
            }
            if rows.is_some() {
                if leak_correct && (leak_model || leak_auto) {
                    return Err(arg(
                        "rows",
                        "the surface model (which leak_correct=\"auto\" may choose) is fitted to the whole capture: a partial in-focus sum takes leak_correct=\"gate\" (or False)",
                    ));
                }
                if direct.is_none() {
                    return Err(arg(
                        "direct",
                        "in-focus indirect light over a part of the rows needs Γ: pass direct=, the finished direct light over the same volume and options",
                    ));
                }
                if cuts.is_some() || opts.gate != ColumnGate::TwoBounce {
                    return Err(arg(
                        "rows",
                        "a partial in-focus sum takes the two-bounce gate and one shell",
                    ));
                }
            }
            if amplitudes {
                return Err(arg(
                    "amplitudes",
                    "in-focus indirect light is imaged as intensities",
                ));
            }
            Job::Indirect {
                opts,
                shells: cuts,
                direct,
            }
        }
        "matrix" => Job::Matrix {
            from: match &from_points {
                Some(a) => points_of(a, "from_")?,
                None => return Err(arg("from_", "a matrix needs its foci (from_)")),
            },
        },
        "relight" => {
            no_part("relighting")?;
            let pattern = match (&pattern, pattern_spec) {
                (_, Some(s)) => Pattern::parse(s).map_err(py_err)?,
                (Some(a), None) => {
                    let v = a.as_array();
                    if v.shape()[1] != 4 {
                        return Err(arg(
                            "pattern",
                            format!("expected (n, 4) foci and weights, found {:?}", v.shape()),
                        ));
                    }
                    let pts: Vec<(Point, f64)> = v
                        .rows()
                        .into_iter()
                        .map(|r| ([r[0] as f32, r[1] as f32, r[2] as f32], r[3]))
                        .collect();
                    Pattern::new(&pts).map_err(py_err)?
                }
                (None, None) => return Err(arg("pattern", "relighting needs a pattern")),
            };
            Job::Relight {
                pattern,
                leak_epsilon: leak_correct.then_some(leak_epsilon),
            }
        }
        "row" => {
            no_part("a row")?;
            let focus = need_focus()?;
            if swap_roles {
                return Err(arg(
                    "swap_roles",
                    "`row` is the transposed column already (use column with swap_roles=True for the in-memory transpose)",
                ));
            }
            Job::Row {
                focus,
                leak_epsilon: leak_correct.then_some(leak_epsilon),
            }
        }
        k => return Err(arg("kind", format!("unknown probe `{k}`"))),
    };
    if amplitudes && matches!(job, Job::Row { .. } | Job::Matrix { .. }) {
        return Err(arg(
            "amplitudes",
            "not offered for this probe (a matrix always has them)",
        ));
    }
    let cap: &NativeCapture = &capture;
    let exec = Exec {
        path: epath,
        ..Exec::default()
    };
    let model = leak_correct && (leak_model || leak_auto);
    let auto = leak_correct && leak_auto;
    let outcome = py
        .detach(|| {
            compute(
                cap,
                vol,
                job,
                &wave,
                exec,
                prep,
                swap_roles,
                rows,
                amplitudes,
                (model, auto),
            )
        })
        .map_err(py_err)?;
    match outcome {
        Outcome::Part(p) => Ok(Py::new(py, NativePartial(*p))?.into_any()),
        Outcome::Matrix(m) => {
            let rep = counters(py, &m.report, m.seconds, &m.config)?;
            rep.set_item("passes", m.passes)?;
            rep.set_item("path", "band")?;
            let t = (
                m.intensities().into_pyarray(py),
                m.amplitudes.into_pyarray(py),
                rep,
            );
            Ok(t.into_pyobject(py)?.into_any().unbind())
        }
        Outcome::Done(d) => {
            let rep = report(py, &d.out)?;
            extras(py, &rep, &d)?;
            let values = match d.parts {
                Some(parts) => parts.concat(),
                None => d.out.values,
            };
            let amps = d.amplitudes.map(|a| a.into_pyarray(py));
            let t = (values.into_pyarray(py), amps, rep);
            Ok(t.into_pyobject(py)?.into_any().unbind())
        }
    }
}

/// What a run adds to its report: leak correction, Γ and `I_d`, passes, preprocessing.
fn extras(py: Python<'_>, rep: &Bound<'_, PyDict>, d: &Done) -> PyResult<()> {
    if let Some(e) = d.explained {
        rep.set_item("explained", e)?;
    }
    if let Some(g) = &d.gamma {
        rep.set_item("gamma", g.clone().into_pyarray(py))?;
    }
    if let Some(v) = &d.direct {
        rep.set_item("direct", v.clone().into_pyarray(py))?;
    }
    if let Some(p) = d.passes {
        rep.set_item("passes", p)?;
    }
    if let Some(l) = d.leak {
        rep.set_item("leak_correct", l)?;
    }
    if let Some(a) = d.adjacency {
        rep.set_item("adjacency", a)?;
    }
    let mut warnings = Vec::new();
    if let Some(p) = &d.prep {
        rep.set_item("preprocessing", &p.summary)?;
        let s = &p.stats;
        let st = PyDict::new(py);
        st.set_item("histograms", s.histograms)?;
        st.set_item("empty", s.empty)?;
        st.set_item("counts_in", s.counts_in)?;
        st.set_item("counts_out", s.counts_out)?;
        rep.set_item("preprocessing_stats", st)?;
        warnings.extend(p.warning.clone());
    }
    warnings.extend(d.warnings.iter().cloned());
    if !warnings.is_empty() {
        rep.set_item("warnings", warnings)?;
    }
    Ok(())
}

/// The probe itself, without the GIL: the command line's calls, in its order.
#[allow(clippy::too_many_arguments)]
fn compute(
    cap: &NativeCapture,
    vol: &vltm::volume::Volume,
    job: Job,
    wave: &Wave,
    exec: Exec<'_>,
    prep: Option<vltm::io::prep::Prep>,
    swap_roles: bool,
    rows: Option<(usize, usize)>,
    amplitudes: bool,
    (model, auto): (bool, bool),
) -> vltm::Result<Outcome> {
    // `leak_correct="model"`: whether the capture holds the laser's falloff.
    let falloff = if model && job.leaks() {
        Some(falloff_of(cap)?)
    } else {
        None
    };
    let mut src = cap.load(swap_roles)?;
    if let (Job::Matrix { from }, None) = (&job, rows) {
        let m = probe::matrix(&mut *src, from, &vol.points, wave, exec)?;
        return Ok(Outcome::Matrix(m));
    }
    if rows.is_some() || amplitudes {
        let task = match &job {
            Job::Direct { .. } => Some(Task::Direct),
            Job::Column {
                focus, gate, shell, ..
            } => Some(Task::Column {
                focus: *focus,
                gate: *gate,
                shell: *shell,
            }),
            Job::Indirect { opts, direct, .. } => direct.as_ref().map(|d| Task::Indirect {
                gamma: probe::gamma_mask(d, opts.epsilon),
                shell: opts.shell,
                leak: opts.leak.is_some(),
            }),
            Job::Matrix { from } => Some(Task::Matrix { from: from.clone() }),
            Job::Relight { .. } | Job::Row { .. } => None,
        };
        if let Some(task) = task {
            let sigma = wave.config(src.geometry())?.sigma();
            let n = src.geometry().lasers.len();
            let r = rows.map_or(0..n, |(a, b)| a..b);
            let (bytes, name) = (cap.file_bytes(), cap.name());
            // A whole-scan column's amplitudes with the leak correction: the corrected rows.
            let leak = match &job {
                Job::Column {
                    leak_epsilon: Some(le),
                    ..
                } if rows.is_none() => Some(*le),
                _ => None,
            };
            let mut warnings = Vec::new();
            let mut adjacency = None;
            let ((p, explained, used), prep) = with_prep(
                prep,
                &mut *src,
                &vol.points,
                sigma,
                |s| -> vltm::Result<_> {
                    match leak {
                        Some(le) => {
                            if let Job::Column { focus, gate, .. } = &job {
                                probe::check_column(s.geometry(), *focus, vol, *gate, wave, exec)?;
                            }
                            // `auto`: the windows first, the model where they cut through light.
                            let mut gate = None;
                            let mut falloff = falloff;
                            if auto {
                                let g = probe::fit_over_volume(
                                    s,
                                    vol,
                                    le,
                                    wave,
                                    &LeakOptions::default(),
                                    exec,
                                )?;
                                adjacency = g.adjacency;
                                falloff = falloff.filter(|_| g.auto_prefers_model());
                                gate = Some(g);
                            }
                            if let Some(falloff) = falloff {
                                match surface_model(s, wave, falloff, exec)? {
                                    Ok(m) => {
                                        let p = partial::accumulate(
                                            &mut m.subtracted(s),
                                            bytes,
                                            &name,
                                            vol,
                                            &task,
                                            wave,
                                            exec,
                                            r,
                                        )?;
                                        return Ok((p, Some(m.explained), Some("model")));
                                    }
                                    Err(reason) => warnings.push(fallback_warning(&reason)),
                                }
                            }
                            let model = match gate {
                                Some(g) => g,
                                None => probe::fit_over_volume(
                                    s,
                                    vol,
                                    le,
                                    wave,
                                    &LeakOptions::default(),
                                    exec,
                                )?,
                            };
                            let mut lc = LeakCorrected::new(s, &model);
                            let p = partial::accumulate(
                                &mut lc, bytes, &name, vol, &task, wave, exec, r,
                            )?;
                            Ok((p, Some(model.explained), Some("gate")))
                        }
                        None => Ok((
                            partial::accumulate(s, bytes, &name, vol, &task, wave, exec, r)?,
                            None,
                            None,
                        )),
                    }
                },
                |_| {},
            )?;
            if rows.is_some() {
                return Ok(Outcome::Part(Box::new(p)));
            }
            let f = p.finish_with(true)?;
            let mut d = Done::of(f.output);
            d.amplitudes = f.amplitudes;
            d.explained = f.explained.or(explained);
            d.prep = prep;
            d.leak = used;
            d.adjacency = adjacency;
            d.warnings = warnings;
            return Ok(Outcome::Done(d));
        }
    }
    let sigma = wave.config(src.geometry())?.sigma();
    let (mut d, prep) = with_prep(
        prep,
        &mut *src,
        &vol.points,
        sigma,
        |rows| whole_pass(rows, vol, job, wave, exec, (falloff, auto)),
        |_| {},
    )?;
    d.prep = prep;
    Ok(Outcome::Done(d))
}

/// A whole-capture run on the (preprocessed) rows; with `falloff` (`leak_correct="model"`),
/// on the rows minus the surface model, Γ (of `indirect` and of a column's `mask_epsilon`)
/// still from the rows themselves, or, when the model is not used, with the windows and the
/// reason as a warning.
fn whole_pass(
    rows: &mut dyn RowSource,
    vol: &vltm::volume::Volume,
    job: Job,
    wave: &Wave,
    exec: Exec<'_>,
    (falloff, auto): (Option<bool>, bool),
) -> vltm::Result<Done> {
    let leaks = job.leaks();
    let Some(falloff) = falloff.filter(|_| leaks) else {
        let mut d = one_pass(rows, vol, job, wave, exec)?;
        d.leak = leaks.then_some("gate");
        return Ok(d);
    };
    // Bad input is refused before the model's passes.
    match &job {
        Job::Column { focus, gate, .. } => {
            probe::check_column(rows.geometry(), *focus, vol, *gate, wave, exec)?
        }
        Job::Relight { pattern, .. } => probe::check_relight(rows.geometry(), pattern, vol, wave)?,
        Job::Row { focus, .. } => probe::check_row(rows.geometry(), *focus, vol, wave)?,
        _ => {}
    }
    // Γ from the capture's own direct light (the capture minus the model has little).
    let (mut job, mut mask) = (job, None);
    match &mut job {
        Job::Indirect { opts, direct, .. } if direct.is_none() => {
            let (_, d) = Gamma::measure(rows, vol, opts.epsilon, "epsilon", wave, exec)?;
            *direct = Some(d.values);
        }
        Job::Column { mask_epsilon, .. } => {
            if let Some(e) = mask_epsilon.take() {
                mask = Some(column_mask(rows, vol, e, wave, exec)?);
            }
        }
        _ => {}
    }
    // `auto`: the windows' pass first; the model only where they cut through light.
    let windows = if auto {
        auto_windows(rows, vol, &job, wave, exec)?
    } else {
        None
    };
    let adjacency = windows.as_ref().and_then(|w| w.adjacency);
    let model = if auto && !windows.is_some_and(|w| w.auto_prefers_model()) {
        Err(None)
    } else {
        surface_model(rows, wave, falloff, exec)?.map_err(Some)
    };
    let mut d = match model {
        Ok(m) => {
            let mut d = one_pass(&mut m.subtracted(rows), vol, job.without_leak(), wave, exec)?;
            d.explained = Some(m.explained);
            d.leak = Some("model");
            d
        }
        Err(reason) => {
            let mut d = one_pass(rows, vol, job, wave, exec)?;
            d.leak = Some("gate");
            d.warnings.extend(reason.map(|r| fallback_warning(&r)));
            d
        }
    };
    d.adjacency = adjacency;
    if let Some(m) = mask {
        apply_mask(&mut d.out.values, &m);
        d.parts.iter_mut().flatten().for_each(|p| apply_mask(p, &m));
        d.gamma = Some(m);
    }
    Ok(d)
}

/// A whole-capture run on the (preprocessed) rows.
fn one_pass(
    rows: &mut dyn RowSource,
    vol: &vltm::volume::Volume,
    job: Job,
    wave: &Wave,
    exec: Exec<'_>,
) -> vltm::Result<Done> {
    match job {
        Job::Direct { gate } => Ok(Done::of(probe::diagonal(rows, vol, gate, wave, exec)?)),
        Job::Column {
            focus,
            gate,
            shell,
            shells,
            mask_epsilon,
            leak_epsilon,
        } => {
            // Bad input is refused before the extra passes (Γ of the mask, the leak fit).
            probe::check_column(rows.geometry(), focus, vol, gate, wave, exec)?;
            let mask = mask_epsilon
                .map(|e| column_mask(rows, vol, e, wave, exec))
                .transpose()?;
            let mut explained = None;
            let mut o = match leak_epsilon {
                Some(le) => {
                    let model =
                        probe::fit_over_volume(rows, vol, le, wave, &LeakOptions::default(), exec)?;
                    explained = Some(model.explained);
                    let mut lc = LeakCorrected::new(rows, &model);
                    probe::column(&mut lc, focus, vol, gate, shell, wave, exec)?
                }
                None => probe::column(rows, focus, vol, gate, shell, wave, exec)?,
            };
            if let Some(m) = &mask {
                apply_mask(&mut o.values, m);
            }
            let parts = shells.map(|cuts| {
                cuts.iter()
                    .map(|sh| sh.cut(focus, &o.values, &vol.points))
                    .collect()
            });
            let mut d = Done::of(o);
            d.parts = parts;
            d.explained = explained;
            d.gamma = mask;
            Ok(d)
        }
        Job::Indirect {
            opts,
            shells,
            direct,
        } => {
            let t = std::time::Instant::now();
            let (gamma, direct) = match direct {
                Some(d) => (Gamma::of(&d, opts.epsilon, "epsilon")?, d),
                None => {
                    let (g, d) = Gamma::measure(rows, vol, opts.epsilon, "epsilon", wave, exec)?;
                    (g, d.values)
                }
            };
            let gamma = gamma.non_empty("epsilon")?.mask;
            // The report records the configuration pass 2 ran on (its band and DFT length
            // cover every Γ pair), as the command line's summary line does.
            let (values, parts, report, explained, config) = match shells {
                None => {
                    let o = probe::indirect_over(rows, vol, &gamma, &opts, wave, exec)?;
                    (o.values, None, o.report, o.explained, o.config)
                }
                Some(cuts) => {
                    let p = probe::indirect_shells(rows, vol, &gamma, &opts, &cuts, wave, exec)?;
                    let (s, r) = (p.sums, p.report);
                    let total: Vec<f32> = (0..vol.len())
                        .map(|i| s.iter().map(|v| v[i]).sum::<f32>())
                        .collect();
                    (total, Some(s), r, None, p.config)
                }
            };
            let mut d = Done::of(probe::Output {
                values,
                report,
                seconds: t.elapsed().as_secs_f64(),
                config,
                path: EvalPath::Band,
                crop: None,
                aligned: None,
            });
            d.parts = parts;
            d.explained = explained;
            d.gamma = Some(gamma);
            d.direct = Some(direct);
            Ok(d)
        }
        Job::Relight {
            pattern,
            leak_epsilon,
        } => {
            probe::check_relight(rows.geometry(), &pattern, vol, wave)?;
            let (r, explained) = corrected(rows, vol, leak_epsilon, wave, exec, |src| {
                probe::relight(src, &pattern, vol, wave, exec)
            })?;
            let mut d = Done::of(r.output);
            d.amplitudes = Some(r.amplitudes);
            d.passes = Some(r.passes);
            d.explained = explained;
            Ok(d)
        }
        Job::Row {
            focus,
            leak_epsilon,
        } => {
            probe::check_row(rows.geometry(), focus, vol, wave)?;
            let (o, explained) = corrected(rows, vol, leak_epsilon, wave, exec, |src| {
                probe::row(src, focus, vol, wave, exec)
            })?;
            let mut d = Done::of(o);
            d.explained = explained;
            Ok(d)
        }
        Job::Matrix { .. } => Err(vltm::Error::arg(
            "kind",
            "a matrix is run over all rows above",
        )),
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(run, m)?)?;
    Ok(())
}
