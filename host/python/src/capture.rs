//! Captures: a file vltm streams, a file read into memory (`.mat` with its conventions), or
//! arrays; their geometry, summed transient, and the synthetic captures of `simulate`.

use crate::{arg, py_err};
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use vltm::atomic::Transaction;
use vltm::io::prep::{Prep, Prepared};
use vltm::io::{self, Capture, Geometry, RowSource};
use vltm::{info, probe};
use vltm_kernel::Point;

/// Where a capture's rows come from.
pub(crate) enum Store {
    /// A file, opened (and streamed) by every call; never read whole into memory unless its
    /// format needs it (compressed `.npz`).
    File { path: PathBuf, bytes: u64 },
    /// Rows in memory: a `.mat` file read with its conventions (`path`, `bytes` set), arrays
    /// given from Python or a simulated scene.
    Memory {
        capture: Arc<Capture>,
        path: Option<PathBuf>,
        bytes: u64,
        name: String,
    },
}

/// A capture: a file vltm reads, or arrays (`Capture.from_arrays`).
#[pyclass(name = "NativeCapture", module = "vltm._native", frozen)]
pub(crate) struct NativeCapture {
    pub(crate) store: Store,
    pub(crate) geometry: Geometry,
}

impl NativeCapture {
    /// The rows, as a source read by one probe.
    pub(crate) fn source(&self) -> vltm::Result<Box<dyn RowSource + '_>> {
        match &self.store {
            Store::File { path, .. } => io::open_source(path),
            Store::Memory { capture, .. } => Ok(Box::new(MemSource(capture))),
        }
    }

    /// The rows, with the lasers and SPADs swapped on request (read into memory then).
    pub(crate) fn load(&self, swap_roles: bool) -> vltm::Result<Box<dyn RowSource + '_>> {
        let mut src = self.source()?;
        if !swap_roles {
            return Ok(src);
        }
        Ok(Box::new(io::capture::swapped(
            &mut *src,
            Path::new(&self.name()),
        )?))
    }

    /// The file's size (what partial states record of a capture; 0 for arrays).
    pub(crate) fn file_bytes(&self) -> u64 {
        match &self.store {
            Store::File { bytes, .. } | Store::Memory { bytes, .. } => *bytes,
        }
    }

    /// The file's name (what partial states record of a capture).
    pub(crate) fn name(&self) -> String {
        match &self.store {
            Store::File { path, .. } => file_name(path),
            Store::Memory { name, .. } => name.clone(),
        }
    }
}

/// The kind of scan as `vltm info` names it: `"confocal"` (laser and SPAD at the same wall
/// point), `"paired"` (one laser and one SPAD spot per histogram, apart) or `"non-confocal"`
/// (a laser grid × a SPAD grid).
pub(crate) fn scan_name(g: &Geometry) -> &'static str {
    if g.coincident() {
        "confocal"
    } else if g.confocal {
        "paired"
    } else {
        "non-confocal"
    }
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map_or_else(String::new, |f| f.to_string_lossy().into_owned())
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

/// The preprocessing asked for (`--t-min`, `--t-max`, `--rebin`, `--background`), if any:
/// the command line's parsing and defaults.
pub(crate) fn prep_of(
    t_min: Option<&str>,
    t_max: Option<&str>,
    rebin: usize,
    background: Option<&str>,
) -> PyResult<Option<Prep>> {
    Prep::parse(t_min, t_max, rebin, background).map_err(py_err)
}

#[pymethods]
impl NativeCapture {
    /// The capture's dimensions, geometry and time axis as a dict.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let g = &self.geometry;
        let d = PyDict::new(py);
        match &self.store {
            Store::File { path, bytes }
            | Store::Memory {
                path: Some(path),
                bytes,
                ..
            } => {
                d.set_item("path", path.to_string_lossy().into_owned())?;
                d.set_item("file_bytes", *bytes)?;
            }
            Store::Memory { path: None, .. } => d.set_item("path", py.None())?,
        }
        d.set_item("lasers", g.lasers.len())?;
        d.set_item("laser_shape", (g.laser_shape[0], g.laser_shape[1]))?;
        d.set_item("spads", g.spads.len())?;
        d.set_item("spad_shape", (g.spad_shape[0], g.spad_shape[1]))?;
        d.set_item("spads_per_row", g.spads_per_row())?;
        // `confocal`: laser and SPAD at the same wall point (what a Python user means by
        // it); `paired`: one histogram per row, confocal or apart; `scan`: the kind as
        // `vltm info` names it.
        d.set_item("confocal", g.coincident())?;
        d.set_item("paired", g.confocal)?;
        d.set_item("scan", scan_name(g))?;
        d.set_item("nt", g.nt)?;
        d.set_item("delta_t", g.dt)?;
        d.set_item("t_start", g.t0)?;
        d.set_item("laser_xyz", g.laser_origin.to_vec())?;
        d.set_item("sensor_xyz", g.sensor_origin.to_vec())?;
        d.set_item("t_accounts_first_and_last_bounces", g.legs_in_time)?;
        d.set_item("normals", if g.normals.flat() { "+z" } else { "per point" })?;
        d.set_item(
            "relay",
            g.not_flat().unwrap_or_else(|| "planar".to_string()),
        )?;
        d.set_item("default_wavelength", probe::default_wavelength(g))?;
        Ok(d)
    }

    /// Laser spots, (lasers, 3) float32.
    fn laser_points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        crate::volume::flat_points(&self.geometry.lasers).into_pyarray(py)
    }

    /// SPAD spots, (spads, 3) float32.
    fn spad_points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        crate::volume::flat_points(&self.geometry.spads).into_pyarray(py)
    }

    /// The summed transient (`vltm info --png`): every histogram summed bin by bin after
    /// the preprocessing, as (counts float64 1-D, t0, dt, preprocessing summary or None,
    /// warning or None).
    #[pyo3(signature = (t_min=None, t_max=None, rebin=1, background=None))]
    #[allow(clippy::type_complexity)]
    fn transient<'py>(
        &self,
        py: Python<'py>,
        t_min: Option<&str>,
        t_max: Option<&str>,
        rebin: usize,
        background: Option<&str>,
    ) -> PyResult<(
        Bound<'py, PyArray1<f64>>,
        f64,
        f64,
        Option<String>,
        Option<String>,
    )> {
        let prep = prep_of(t_min, t_max, rebin, background)?;
        let (sum, t0, dt, summary, warning) = py
            .detach(|| -> vltm::Result<_> {
                let mut src = self.source()?;
                match prep {
                    Some(p) => {
                        let mut pr = Prepared::new(&mut *src, p, None)?;
                        let sum = info::summed(&mut pr)?;
                        let (t0, dt) = (pr.geometry().t0, pr.geometry().dt);
                        let r = vltm::io::prep::check(&pr)?;
                        Ok((sum, t0, dt, Some(r.summary), r.warning))
                    }
                    None => {
                        let sum = info::summed(&mut *src)?;
                        Ok((sum, self.geometry.t0, self.geometry.dt, None, None))
                    }
                }
            })
            .map_err(py_err)?;
        Ok((sum.into_pyarray(py), t0, dt, summary, warning))
    }

    /// Writes the capture as a vltm `.npz` (compressed unless `uncompressed`), and with
    /// `ptu` also as a synthetic PicoQuant T3 stream with its `.json` sidecar; all or nothing.
    #[pyo3(signature = (path, uncompressed=false, ptu=None))]
    fn save(
        &self,
        py: Python<'_>,
        path: PathBuf,
        uncompressed: bool,
        ptu: Option<PathBuf>,
    ) -> PyResult<()> {
        py.detach(|| -> vltm::Result<()> {
            let owned;
            let c: &Capture = match &self.store {
                Store::Memory { capture, .. } => capture,
                Store::File { path: p, .. } => {
                    owned = io::open(p)?;
                    &owned
                }
            };
            let mut t = Transaction::new();
            io::npz::stage(&mut t, c, &path, !uncompressed)?;
            if let Some(p) = &ptu {
                io::ptu::stage_t3(&mut t, c, p, &io::ptu::T3WriteOptions::default())?;
            }
            t.commit()
        })
        .map_err(py_err)
    }
}

/// Opens a capture file (any format vltm reads); reads its geometry only, except for `.mat`
/// files, read once into memory with their conventions overridden by `delta_t`, `t_start`,
/// `grid_width` (as `--delta-t`, `--t-start`, `--grid-width`; refused for other formats).
#[pyfunction]
#[pyo3(signature = (path, delta_t=None, t_start=None, grid_width=None))]
fn open_capture(
    py: Python<'_>,
    path: PathBuf,
    delta_t: Option<f64>,
    t_start: Option<f64>,
    grid_width: Option<f64>,
) -> PyResult<NativeCapture> {
    let mat = io::extension(&path).as_deref() == Some("mat");
    let options = io::mat::MatOptions {
        delta_t,
        t_start,
        grid_width,
    };
    if !mat {
        options.refuse().map_err(py_err)?;
    }
    let (store, geometry) = py
        .detach(|| -> vltm::Result<_> {
            let bytes = std::fs::metadata(&path)
                .map_err(|e| vltm::Error::io(&path, e))?
                .len();
            if mat {
                let c = io::mat::read(&path, &options)?.capture;
                let g = c.geometry.clone();
                let store = Store::Memory {
                    capture: Arc::new(c),
                    name: file_name(&path),
                    path: Some(path.clone()),
                    bytes,
                };
                return Ok((store, g));
            }
            let g = io::open_source(&path)?.geometry().clone();
            Ok((
                Store::File {
                    path: path.clone(),
                    bytes,
                },
                g,
            ))
        })
        .map_err(py_err)?;
    Ok(NativeCapture { store, geometry })
}

/// A capture from arrays: `h` as (rows, spads_per_row, nt) float32, spots as (n, 3), normals
/// (optional) as (n, 3) per list of spots.
#[pyfunction]
#[pyo3(signature = (h, lasers, laser_shape, spads, spad_shape, delta_t, t_start, laser_xyz, sensor_xyz, legs_in_time, confocal, laser_normals=None, sensor_normals=None))]
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
    laser_normals: Option<PyReadonlyArray2<'_, f32>>,
    sensor_normals: Option<PyReadonlyArray2<'_, f32>>,
) -> PyResult<NativeCapture> {
    let lasers = crate::volume::points_of(&lasers, "laser_grid_xyz")?;
    let spads = crate::volume::points_of(&spads, "sensor_grid_xyz")?;
    let normals = |a: Option<PyReadonlyArray2<'_, f32>>, name| -> PyResult<Vec<_>> {
        a.map_or(Ok(Vec::new()), |a| crate::volume::points_of(&a, name))
    };
    let normals = vltm::io::Normals::from_lists(
        normals(laser_normals, "laser_normals")?,
        normals(sensor_normals, "sensor_normals")?,
    );
    let hv = h.as_array();
    let nt = hv.shape()[2];
    vltm::budget::check(
        || {
            format!(
                "the capture's histograms ({} f32)",
                vltm::budget::count(hv.len() as u128)
            )
        },
        vltm::budget::bytes(hv.len(), 4),
    )
    .map_err(py_err)?;
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
        normals,
    };
    let c = py
        .detach(|| Capture::new(geometry, data, Path::new("H")))
        .map_err(py_err)?;
    let geometry = c.geometry.clone();
    Ok(NativeCapture {
        store: Store::Memory {
            capture: Arc::new(c),
            path: None,
            bytes: 0,
            name: "<arrays>".into(),
        },
        geometry,
    })
}

/// Renders a synthetic capture from a scene file (JSON), in memory (`vltm simulate`).
#[pyfunction]
fn simulate(py: Python<'_>, scene: PathBuf) -> PyResult<NativeCapture> {
    let c = py
        .detach(|| vltm::sim::Scene::load(&scene)?.render())
        .map_err(py_err)?;
    let geometry = c.geometry.clone();
    Ok(NativeCapture {
        store: Store::Memory {
            capture: Arc::new(c),
            path: None,
            bytes: 0,
            name: file_name(&scene),
        },
        geometry,
    })
}

/// `vltm info`'s layout text of a capture file, its warnings and the summed transient: the
/// library's `info::info` (the lines the command line prints), with `.mat` overrides
/// and preprocessing as `vltm info`'s options; `png` also draws the summed transient (as
/// `--png`, adding the command line's `wrote F` line); `volume` (a SPEC) is named in the
/// `fast paths` line as `--volume` is.
#[pyfunction]
#[pyo3(signature = (path, delta_t=None, t_start=None, grid_width=None, t_min=None, t_max=None,
    rebin=1, background=None, png=None, volume=None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn info_text<'py>(
    py: Python<'py>,
    path: PathBuf,
    delta_t: Option<f64>,
    t_start: Option<f64>,
    grid_width: Option<f64>,
    t_min: Option<&str>,
    t_max: Option<&str>,
    rebin: usize,
    background: Option<&str>,
    png: Option<PathBuf>,
    volume: Option<&str>,
) -> PyResult<(
    Vec<String>,
    Vec<String>,
    Bound<'py, PyArray1<f64>>,
    f64,
    f64,
)> {
    use vltm::info::Stream;
    let prep = prep_of(t_min, t_max, rebin, background)?;
    let volume = volume
        .map(vltm::volume::Volume::parse)
        .transpose()
        .map_err(py_err)?;
    let mat = io::mat::MatOptions {
        delta_t,
        t_start,
        grid_width,
    };
    if let Some(p) = &png
        && same_file(p, &path)
    {
        return Err(arg(
            "png",
            format!("{} is the capture itself: choose another file", p.display()),
        ));
    }
    let (lines, warnings, sum) = py
        .detach(|| -> vltm::Result<_> {
            let (mut lines, mut warnings) = (Vec::new(), Vec::new());
            let sum = vltm::info::info(&path, &mat, prep, volume.as_ref(), &mut |stream, line| {
                let line = vltm::error::respell(line, crate::param);
                match stream {
                    Stream::Out => lines.push(line),
                    Stream::Warning => warnings.push(line),
                }
            })?;
            if let Some(p) = &png {
                let t = vltm::export::figure::plot::Transient {
                    counts: &sum.counts,
                    t0: sum.t0,
                    dt: sum.dt,
                    title: format!("{}: summed transient", file_name(&path)),
                    shade: None,
                };
                let mut tr = Transaction::new();
                t.stage_png(&mut tr, p)?;
                tr.commit()?;
                lines.push(format!("wrote {}", p.display()));
            }
            Ok((lines, warnings, sum))
        })
        .map_err(py_err)?;
    let (t0, dt) = (sum.t0, sum.dt);
    Ok((lines, warnings, sum.counts.into_pyarray(py), t0, dt))
}

/// Whether two paths name the same file (an output must not replace its input).
fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}

/// The built-in demo (`vltm demo`): renders the demo scene, runs every probe on it, writes
/// the figures, volumes and `summary.txt` into `out`; returns the table.
#[pyfunction]
fn demo(py: Python<'_>, out: PathBuf) -> PyResult<String> {
    py.detach(|| vltm::demo::run(&out, None)).map_err(py_err)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NativeCapture>()?;
    m.add_function(wrap_pyfunction!(info_text, m)?)?;
    m.add_function(wrap_pyfunction!(demo, m)?)?;
    m.add_function(wrap_pyfunction!(open_capture, m)?)?;
    m.add_function(wrap_pyfunction!(capture_from_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    Ok(())
}
