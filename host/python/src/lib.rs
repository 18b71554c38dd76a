//! `vltm._native`: the Rust side of the Python package. Thin typed entry points over the
//! vltm library; argument normalisation, docstrings of the public API and the Dask layer live
//! in the Python package (`vltm/__init__.py`, `vltm/dask.py`).
//!
//! Probes: direct light, columns (with complex amplitudes of two-bounce and higher-order
//! columns on request), in-focus indirect light (leak-corrected or not) and the matrix
//! between two voxel sets; each over all rows, or over a row range as a partial state.
//!
//! Every call that runs a probe releases the GIL (`Python::detach`) while Rust works; inputs
//! are copied out of NumPy before, outputs handed to NumPy after. Errors become
//! `vltm.ArgumentError` (a `ValueError`: bad arguments, the CLI's exit code 2) or
//! `vltm.DataError` (an `OSError`: unreadable or bad data, exit code 1) carrying the
//! library's one-line message.

use numpy::{IntoPyArray, PyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use vltm::exec::{Exec, Path as EvalPath};
use vltm::io::{self, Capture, Geometry, RowSource};
use vltm::probe::{
    self, ColumnGate, IndirectOptions, LeakOptions, Partial, Shell, Task, Wave, partial,
};
use vltm::volume::Volume;
use vltm_kernel::{Point, Weights};

/// The Python exception for a library error: `vltm.ArgumentError` or `vltm.DataError`.
fn py_err(e: vltm::Error) -> PyErr {
    let usage = e.is_usage();
    let msg = e.to_string().replace('\n', " ");
    Python::attach(|py| {
        let class = if usage { "ArgumentError" } else { "DataError" };
        match py
            .import("vltm._errors")
            .and_then(|m| m.getattr(class))
            .and_then(|c| c.call1((msg.clone(),)))
        {
            Ok(obj) => PyErr::from_value(obj),
            Err(_) => PyException::new_err(msg),
        }
    })
}

fn arg(name: &str, msg: impl ToString) -> PyErr {
    py_err(vltm::Error::arg(name, msg))
}

/// Where a capture's rows come from.
enum Store {
    /// A file, opened (and streamed) by every call; never read whole into memory unless its
    /// format needs it (compressed `.npz`).
    File { path: PathBuf, bytes: u64 },
    /// Arrays given from Python.
    Memory(Arc<Capture>),
}

/// A capture: a file vltm reads, or arrays (`Capture.from_arrays`).
#[pyclass(name = "NativeCapture", module = "vltm._native", frozen)]
struct NativeCapture {
    store: Store,
    geometry: Geometry,
}

impl NativeCapture {
    fn source(&self) -> vltm::Result<Box<dyn RowSource + '_>> {
        match &self.store {
            Store::File { path, .. } => io::open_source(path),
            Store::Memory(c) => Ok(Box::new(MemSource(c))),
        }
    }

    fn file_bytes(&self) -> u64 {
        match &self.store {
            Store::File { bytes, .. } => *bytes,
            Store::Memory(_) => 0,
        }
    }

    fn name(&self) -> String {
        match &self.store {
            Store::File { path, .. } => path
                .file_name()
                .map_or_else(String::new, |f| f.to_string_lossy().into_owned()),
            Store::Memory(_) => "<arrays>".into(),
        }
    }
}

/// An in-memory capture as a row source, borrowed.
struct MemSource<'a>(&'a Capture);

impl RowSource for MemSource<'_> {
    fn geometry(&self) -> &Geometry {
        &self.0.geometry
    }
    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> vltm::Result<Point> {
        let c = self.0;
        let g = &c.geometry;
        let n = g.spads_per_row() * g.nt;
        let x = *g
            .lasers
            .get(l)
            .ok_or_else(|| vltm::Error::arg("row", format!("row {l} does not exist")))?;
        out.clear();
        out.extend_from_slice(&c.data[l * n..(l + 1) * n]);
        Ok(x)
    }
}

#[pymethods]
impl NativeCapture {
    /// The capture's dimensions, geometry and time axis as a dict.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let g = &self.geometry;
        let d = PyDict::new(py);
        match &self.store {
            Store::File { path, bytes } => {
                d.set_item("path", path.to_string_lossy().into_owned())?;
                d.set_item("file_bytes", *bytes)?;
            }
            Store::Memory(_) => d.set_item("path", py.None())?,
        }
        d.set_item("lasers", g.lasers.len())?;
        d.set_item("laser_shape", (g.laser_shape[0], g.laser_shape[1]))?;
        d.set_item("spads", g.spads.len())?;
        d.set_item("spad_shape", (g.spad_shape[0], g.spad_shape[1]))?;
        d.set_item("spads_per_row", g.spads_per_row())?;
        d.set_item("confocal", g.confocal)?;
        d.set_item("nt", g.nt)?;
        d.set_item("delta_t", g.dt)?;
        d.set_item("t_start", g.t0)?;
        d.set_item("laser_xyz", g.laser_origin.to_vec())?;
        d.set_item("sensor_xyz", g.sensor_origin.to_vec())?;
        d.set_item("t_accounts_first_and_last_bounces", g.legs_in_time)?;
        d.set_item("default_wavelength", probe::default_wavelength(g))?;
        Ok(d)
    }

    /// Laser spots, (lasers, 3) float32.
    fn laser_points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        self.geometry
            .lasers
            .iter()
            .flatten()
            .copied()
            .collect::<Vec<_>>()
            .into_pyarray(py)
    }

    /// SPAD spots, (spads, 3) float32.
    fn spad_points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        self.geometry
            .spads
            .iter()
            .flatten()
            .copied()
            .collect::<Vec<_>>()
            .into_pyarray(py)
    }
}

/// Opens a capture file (any format vltm reads); reads its geometry only.
#[pyfunction]
fn open_capture(py: Python<'_>, path: PathBuf) -> PyResult<NativeCapture> {
    let (geometry, bytes) = py
        .detach(|| -> vltm::Result<_> {
            let g = io::open_source(&path)?.geometry().clone();
            let bytes = std::fs::metadata(&path)
                .map_err(|e| vltm::Error::io(&path, e))?
                .len();
            Ok((g, bytes))
        })
        .map_err(py_err)?;
    Ok(NativeCapture {
        store: Store::File { path, bytes },
        geometry,
    })
}

/// A capture from arrays: `h` as (rows, spads_per_row, nt) float32, spots as (n, 3).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn capture_from_arrays(
    py: Python<'_>,
    h: PyReadonlyArray3<'_, f32>,
    lasers: PyReadonlyArray2<'_, f32>,
    laser_shape: (usize, usize),
    spads: PyReadonlyArray2<'_, f32>,
    spad_shape: (usize, usize),
    delta_t: f64,
    t_start: f64,
    laser_xyz: [f64; 3],
    sensor_xyz: [f64; 3],
    legs_in_time: bool,
    confocal: bool,
) -> PyResult<NativeCapture> {
    let pts = |a: &PyReadonlyArray2<'_, f32>, what: &str| -> PyResult<Vec<Point>> {
        let v = a.as_array();
        if v.shape()[1] != 3 {
            return Err(arg(
                what,
                format!("expected (n, 3) points, found {:?}", v.shape()),
            ));
        }
        Ok(v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
    };
    let lasers = pts(&lasers, "laser_grid_xyz")?;
    let spads = pts(&spads, "sensor_grid_xyz")?;
    let hv = h.as_array();
    let nt = hv.shape()[2];
    let data: Vec<f32> = hv.iter().copied().collect();
    let geometry = Geometry {
        lasers,
        laser_shape: [laser_shape.0, laser_shape.1],
        spads,
        spad_shape: [spad_shape.0, spad_shape.1],
        laser_origin: laser_xyz,
        sensor_origin: sensor_xyz,
        legs_in_time,
        confocal,
        nt,
        dt: delta_t,
        t0: t_start,
    };
    let c = py
        .detach(|| Capture::new(geometry, data, Path::new("H")))
        .map_err(py_err)?;
    let geometry = c.geometry.clone();
    Ok(NativeCapture {
        store: Store::Memory(Arc::new(c)),
        geometry,
    })
}

/// A voxel set: a grid from a SPEC or a list of points.
#[pyclass(name = "Volume", module = "vltm._native", frozen)]
#[derive(Clone)]
struct NativeVolume {
    volume: Volume,
    spec: Option<String>,
}

#[pymethods]
impl NativeVolume {
    /// Grid shape (nx, ny, nz); (n, 1, 1) for a point list.
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        let s = self.volume.shape;
        (s[0], s[1], s[2])
    }
    /// Whether the volume is a grid (from a SPEC).
    #[getter]
    fn is_grid(&self) -> bool {
        self.volume.axes.is_some()
    }
    /// The SPEC it was parsed from, if any.
    #[getter]
    fn spec(&self) -> Option<String> {
        self.spec.clone()
    }
    /// The voxel centres, flat float32 (x, y, z per voxel, C order over the shape).
    fn flat_points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        self.volume
            .points
            .iter()
            .flatten()
            .copied()
            .collect::<Vec<_>>()
            .into_pyarray(py)
    }
    fn __len__(&self) -> usize {
        self.volume.len()
    }
}

/// Parses a volume SPEC (`x0:x1:nx,y0:y1:ny,z0:z1:nz` or `x,y,z;x,y,z`).
#[pyfunction]
fn volume_from_spec(spec: &str) -> PyResult<NativeVolume> {
    Ok(NativeVolume {
        volume: Volume::parse(spec).map_err(py_err)?,
        spec: Some(spec.to_string()),
    })
}

/// A point-list volume from (n, 3) float32 points.
#[pyfunction]
fn volume_from_points(points: PyReadonlyArray2<'_, f32>) -> PyResult<NativeVolume> {
    let v = points.as_array();
    if v.shape()[1] != 3 {
        return Err(arg(
            "volume",
            format!("expected (..., 3) points, found {:?}", v.shape()),
        ));
    }
    let pts = v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect();
    Ok(NativeVolume {
        volume: Volume::points(pts).map_err(py_err)?,
        spec: None,
    })
}

/// A probe's accumulator state over some rows of a capture (see `vltm.Partial`).
#[pyclass(name = "NativePartial", module = "vltm._native", frozen)]
struct NativePartial(Partial);

#[pymethods]
impl NativePartial {
    /// The state in vltm's binary partial format (what `--partial` writes).
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        let b = py.detach(|| self.0.to_bytes());
        PyBytes::new(py, &b)
    }
    /// Row ranges held, as (start, stop) pairs.
    fn rows(&self) -> Vec<(usize, usize)> {
        self.0.rows().iter().map(|r| (r.start, r.end)).collect()
    }
    /// Laser rows of the whole scan.
    fn total_rows(&self) -> usize {
        self.0.total_rows()
    }
    /// `direct`, `column`, `indirect` or `matrix`.
    fn kind(&self) -> String {
        self.0.kind().to_string()
    }
    /// Whether the rows cover the scan.
    fn is_complete(&self) -> bool {
        self.0.is_complete()
    }
    /// Size of the serialised state in bytes.
    fn nbytes(&self) -> usize {
        self.0.byte_len()
    }
    /// Finishes the state: (intensities float32 1-D, amplitudes complex128 1-D or None,
    /// shape, report dict); `amplitudes`: also image a two-bounce column's amplitudes.
    /// A matrix state finishes into (intensities float32 1-D, amplitudes complex64 1-D,
    /// (n_from, n_to), report dict, from points float32 1-D, to points float32 1-D).
    #[pyo3(signature = (amplitudes=false))]
    fn finish<'py>(&self, py: Python<'py>, amplitudes: bool) -> PyResult<Bound<'py, PyAny>> {
        let f = py
            .detach(|| self.0.finish_with(amplitudes))
            .map_err(py_err)?;
        let rep = report(py, &f.output)?;
        if let Some(e) = f.explained {
            rep.set_item("explained", e)?;
        }
        if let Some(m) = f.matrix {
            let from = flat_points(self.0.from_points()).into_pyarray(py);
            let to = flat_points(&f.volume.points).into_pyarray(py);
            rep.set_item("aliased", m.report.aliased)?;
            let t = (
                m.intensities().into_pyarray(py),
                m.amplitudes.into_pyarray(py),
                (m.n_from, m.n_to),
                rep,
                from,
                to,
            );
            return t.into_pyobject(py).map(|t| t.into_any());
        }
        let s = f.volume.shape;
        let t = (
            f.output.values.into_pyarray(py),
            f.amplitudes.map(|a| a.into_pyarray(py)),
            (s[0], s[1], s[2]),
            rep,
        );
        t.into_pyobject(py).map(|t| t.into_any())
    }
}

/// Points as flat `f32` (x, y, z per point).
fn flat_points(p: &[Point]) -> Vec<f32> {
    p.iter().flatten().copied().collect()
}

/// `(n, 3)` float32 points from NumPy.
fn points_of(a: &PyReadonlyArray2<'_, f32>, what: &str) -> PyResult<Vec<Point>> {
    let v = a.as_array();
    if v.shape()[1] != 3 {
        return Err(arg(
            what,
            format!("expected (n, 3) points, found {:?}", v.shape()),
        ));
    }
    Ok(v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// Reads a partial state from bytes.
#[pyfunction]
fn partial_from_bytes(py: Python<'_>, data: &[u8]) -> PyResult<NativePartial> {
    let p = py
        .detach(|| Partial::from_bytes(data, Path::new("<bytes>")))
        .map_err(py_err)?;
    Ok(NativePartial(p))
}

/// Merges partial states by addition.
#[pyfunction]
fn merge(py: Python<'_>, parts: Vec<PyRef<'_, NativePartial>>) -> PyResult<NativePartial> {
    let parts: Vec<Partial> = parts.iter().map(|p| p.0.clone()).collect();
    let names: Vec<String> = (0..parts.len()).map(|i| format!("part {i}")).collect();
    let m = py
        .detach(|| Partial::merge(parts, &names))
        .map_err(py_err)?;
    Ok(NativePartial(m))
}

/// Merges serialised partial states (bytes) into serialised state: the Dask reduction.
#[pyfunction]
fn merge_bytes<'py>(py: Python<'py>, parts: Vec<Vec<u8>>) -> PyResult<Bound<'py, PyBytes>> {
    let b = py
        .detach(|| -> vltm::Result<Vec<u8>> {
            let names: Vec<String> = (0..parts.len()).map(|i| format!("part {i}")).collect();
            let read = parts
                .iter()
                .map(|b| Partial::from_bytes(b, Path::new("<bytes>")))
                .collect::<vltm::Result<Vec<_>>>()?;
            Ok(Partial::merge(read, &names)?.to_bytes())
        })
        .map_err(py_err)?;
    Ok(PyBytes::new(py, &b))
}

/// Γ = {v : I_d(v) > ε·max I_d}, as vltm computes it.
#[pyfunction]
fn gamma_mask(direct: Vec<f32>, epsilon: f32) -> Vec<bool> {
    probe::gamma_mask(&direct, epsilon)
}

fn report<'py>(py: Python<'py>, o: &probe::Output) -> PyResult<Bound<'py, PyDict>> {
    let d = counters(py, &o.report, o.seconds, &o.config)?;
    d.set_item("path", o.path.name())?;
    Ok(d)
}

/// The counters every probe reports, its time and its configuration, as a dict.
fn counters<'py>(
    py: Python<'py>,
    r: &vltm_kernel::Report,
    seconds: f64,
    config: &vltm_kernel::Config,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("rows", r.rows)?;
    d.set_item("non_finite", r.non_finite)?;
    d.set_item("dropped", r.dropped)?;
    d.set_item("aliased", r.aliased)?;
    d.set_item("seconds", seconds)?;
    d.set_item("wavelength", config.wavelength())?;
    d.set_item("sigma", config.sigma())?;
    d.set_item("bins", config.bins())?;
    Ok(d)
}

/// The counters of a matrix as a dict (those of [`report`], and `passes`).
fn matrix_report<'py>(py: Python<'py>, m: &probe::Matrix) -> PyResult<Bound<'py, PyDict>> {
    let d = counters(py, &m.report, m.seconds, &m.config)?;
    d.set_item("passes", m.passes)?;
    d.set_item("path", "band")?;
    Ok(d)
}

/// The options every probe shares, from Python keywords.
#[derive(Clone, Copy)]
struct Opts {
    wave: Wave,
    path: EvalPath,
}

fn opts(
    wavelength: Option<f64>,
    sigma: Option<f64>,
    weights: &str,
    band: f64,
    compensate_laser: bool,
    path: &str,
) -> PyResult<Opts> {
    let weights = match weights {
        "inv" => Weights::Inv,
        "one" => Weights::One,
        w => return Err(arg("weights", format!("expected inv or one, found `{w}`"))),
    };
    let path = match path {
        "auto" => EvalPath::Auto,
        "band" => EvalPath::Band,
        "planar" => EvalPath::Planar,
        "lookup" => EvalPath::Lookup,
        p => {
            return Err(arg(
                "path",
                format!("expected auto, band, planar or lookup, found `{p}`"),
            ));
        }
    };
    Ok(Opts {
        wave: Wave {
            wavelength,
            sigma,
            weights,
            band_half_width: band,
            compensate_laser,
            auto_margin: true,
            crop: true,
        },
        path,
    })
}

fn shell_of(shell: Option<(f32, f32)>) -> PyResult<Option<Shell>> {
    match shell {
        None => Ok(None),
        Some((r0, r1)) if r0 >= 0.0 && r1 > r0 => Ok(Some(Shell { r0, r1 })),
        Some((r0, r1)) => Err(arg(
            "shell",
            format!("expected (r0, r1) with 0 <= r0 < r1 in metres, found ({r0}, {r1})"),
        )),
    }
}

/// What a probe call returns: finished arrays, or a partial state.
#[allow(clippy::large_enum_variant)] // one per call, moved once
enum Outcome {
    /// Intensities, amplitudes, and the fraction the leak correction removed.
    Done(
        probe::Output,
        Option<Vec<num_complex::Complex64>>,
        Option<f64>,
    ),
    Matrix(probe::Matrix),
    Part(Box<Partial>),
}

/// Runs a probe: `kind` is direct, column, indirect or matrix (`from_points` × the
/// volume); `rows` makes it partial.
#[pyfunction]
#[pyo3(signature = (capture, volume, kind, *, focus=None, gate="two-bounce", shell=None,
    epsilon=0.1, direct=None, wavelength=None, sigma=None, weights="inv", band=5.0,
    compensate_laser=false, path="auto", rows=None, amplitudes=false, leak_correct=false,
    from_points=None))]
#[allow(clippy::too_many_arguments)]
fn run<'py>(
    py: Python<'py>,
    capture: PyRef<'py, NativeCapture>,
    volume: PyRef<'py, NativeVolume>,
    kind: &str,
    focus: Option<[f32; 3]>,
    gate: &str,
    shell: Option<(f32, f32)>,
    epsilon: f32,
    direct: Option<Vec<f32>>,
    wavelength: Option<f64>,
    sigma: Option<f64>,
    weights: &str,
    band: f64,
    compensate_laser: bool,
    path: &str,
    rows: Option<(usize, usize)>,
    amplitudes: bool,
    leak_correct: bool,
    from_points: Option<PyReadonlyArray2<'py, f32>>,
) -> PyResult<Py<PyAny>> {
    let o = opts(wavelength, sigma, weights, band, compensate_laser, path)?;
    let shell = shell_of(shell)?;
    if !(0.0..1.0).contains(&epsilon) {
        return Err(arg(
            "epsilon",
            format!("expected 0 <= E < 1, found {epsilon}"),
        ));
    }
    let task = match kind {
        "direct" => Task::Direct,
        "column" => Task::Column {
            focus: focus.ok_or_else(|| arg("focus", "a column needs a focus (x, y, z)"))?,
            gate: match gate {
                "two-bounce" => ColumnGate::TwoBounce,
                "higher-order" => ColumnGate::HigherOrder,
                "none" => ColumnGate::None,
                g => {
                    return Err(arg(
                        "gate",
                        format!("expected two-bounce, higher-order or none, found `{g}`"),
                    ));
                }
            },
            shell: shell.unwrap_or(Shell::ALL),
        },
        "indirect" => Task::Indirect {
            gamma: match &direct {
                Some(d) if d.len() != volume.volume.len() => {
                    return Err(arg(
                        "direct",
                        format!(
                            "expected {} values (the volume's voxels), found {}",
                            volume.volume.len(),
                            d.len()
                        ),
                    ));
                }
                Some(d) => probe::gamma_mask(d, epsilon),
                None if rows.is_some() || amplitudes => {
                    return Err(arg(
                        "direct",
                        "in-focus indirect light over a part of the rows needs Γ: pass direct=, the finished direct light over the same volume and options",
                    ));
                }
                None => Vec::new(),
            },
            shell,
            leak: leak_correct,
        },
        "matrix" => Task::Matrix {
            from: match &from_points {
                Some(a) => points_of(a, "from_")?,
                None => return Err(arg("from_", "a matrix needs its foci (from_)")),
            },
        },
        k => return Err(arg("kind", format!("unknown probe `{k}`"))),
    };
    let cap: &NativeCapture = &capture;
    let vol = &volume.volume;
    let exec = Exec {
        path: o.path,
        ..Exec::default()
    };
    let outcome = py
        .detach(|| -> vltm::Result<Outcome> {
            let mut src = cap.source()?;
            if let (Task::Matrix { from }, None) = (&task, rows) {
                let m = probe::matrix(&mut *src, from, &vol.points, &o.wave, exec)?;
                return Ok(Outcome::Matrix(m));
            }
            if rows.is_some() || amplitudes {
                let n = src.geometry().lasers.len();
                let r = rows.map_or(0..n, |(a, b)| a..b);
                let p = partial::accumulate(
                    &mut *src,
                    cap.file_bytes(),
                    &cap.name(),
                    vol,
                    &task,
                    &o.wave,
                    exec,
                    r,
                )?;
                if rows.is_some() {
                    return Ok(Outcome::Part(Box::new(p)));
                }
                let f = p.finish_with(true)?;
                return Ok(Outcome::Done(f.output, f.amplitudes, f.explained));
            }
            let mut explained = None;
            let out = match &task {
                Task::Direct => probe::direct(&mut *src, vol, &o.wave, exec)?,
                Task::Column { focus, gate, shell } => {
                    probe::column(&mut *src, *focus, vol, *gate, *shell, &o.wave, exec)?
                }
                Task::Indirect { gamma, shell, leak } => {
                    let io = IndirectOptions {
                        epsilon,
                        shell: *shell,
                        leak: leak.then(LeakOptions::default),
                        ..IndirectOptions::default()
                    };
                    let r = if direct.is_some() {
                        probe::indirect_over(&mut *src, vol, gamma, &io, &o.wave, exec)?
                    } else {
                        probe::indirect(&mut *src, vol, &io, &o.wave, exec)?
                    };
                    let config = o.wave.config(src.geometry())?;
                    explained = r.explained;
                    probe::Output {
                        values: r.values,
                        report: r.report,
                        seconds: r.seconds,
                        config,
                        path: EvalPath::Band,
                        crop: None,
                        aligned: None,
                    }
                }
                Task::Matrix { .. } => {
                    return Err(vltm::Error::arg("kind", "a matrix is run above"));
                }
            };
            Ok(Outcome::Done(out, None, explained))
        })
        .map_err(py_err)?;
    match outcome {
        Outcome::Part(p) => Ok(Py::new(py, NativePartial(*p))?.into_any()),
        Outcome::Matrix(m) => {
            let rep = matrix_report(py, &m)?;
            let t = (
                m.intensities().into_pyarray(py),
                m.amplitudes.into_pyarray(py),
                rep,
            );
            Ok(t.into_pyobject(py)?.into_any().unbind())
        }
        Outcome::Done(out, amps, explained) => {
            let rep = report(py, &out)?;
            if let Some(e) = explained {
                rep.set_item("explained", e)?;
            }
            let values = out.values.into_pyarray(py);
            let amps = amps.map(|a| a.into_pyarray(py));
            Ok((values, amps, rep).into_pyobject(py)?.into_any().unbind())
        }
    }
}

/// Sets the number of worker threads (once per process, before the first probe).
#[pyfunction]
fn set_threads(n: usize) -> PyResult<()> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build_global()
        .map_err(|e| {
            arg(
                "threads",
                format!("the thread pool is already running ({e})"),
            )
        })
}

/// The extension module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NativeCapture>()?;
    m.add_class::<NativeVolume>()?;
    m.add_class::<NativePartial>()?;
    m.add_function(wrap_pyfunction!(open_capture, m)?)?;
    m.add_function(wrap_pyfunction!(capture_from_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(volume_from_spec, m)?)?;
    m.add_function(wrap_pyfunction!(volume_from_points, m)?)?;
    m.add_function(wrap_pyfunction!(partial_from_bytes, m)?)?;
    m.add_function(wrap_pyfunction!(merge, m)?)?;
    m.add_function(wrap_pyfunction!(merge_bytes, m)?)?;
    m.add_function(wrap_pyfunction!(gamma_mask, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(set_threads, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
