//! Partial states (a probe's accumulators over some laser rows), their merging, and the
//! report dicts every result carries.

use crate::py_err;
use crate::volume::flat_points;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::path::Path;
use vltm::probe::{self, Partial};

/// A probe's accumulator state over some rows of a capture (see `vltm.Partial`).
#[pyclass(name = "NativePartial", module = "vltm._native", frozen)]
pub(crate) struct NativePartial(pub(crate) Partial);

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
    /// The column's focus, if the state is a column's.
    fn focus(&self) -> Option<[f32; 3]> {
        self.0.focus()
    }
    /// Finishes the state: (intensities float32 1-D, amplitudes complex128 1-D or None,
    /// shape, report dict, voxel points float32 1-D, whether they are a grid); `amplitudes`: also image a two-bounce column's amplitudes.
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
        let grid = f.volume.axes.is_some();
        let t = (
            f.output.values.into_pyarray(py),
            f.amplitudes.map(|a| a.into_pyarray(py)),
            (s[0], s[1], s[2]),
            rep,
            flat_points(&f.volume.points).into_pyarray(py),
            grid,
        );
        t.into_pyobject(py).map(|t| t.into_any())
    }
}

/// The report dict of a probe's output: counters, time, configuration, evaluation path.
pub(crate) fn report<'py>(py: Python<'py>, o: &probe::Output) -> PyResult<Bound<'py, PyDict>> {
    let d = counters(py, &o.report, o.seconds, &o.config)?;
    d.set_item("path", o.path.name())?;
    // The part of the time axis kept (the command line's `<probe>: time axis cropped to bins
    // a..b of n` line); None when the whole axis was used (`crop=False`, or nothing to drop).
    d.set_item("crop", o.crop.map(|c| c.to_string()))?;
    d.set_item("crop_bins", o.crop.map(|c| (c.start, c.end, c.nt)))?;
    Ok(d)
}

/// The counters every probe reports, its time and its configuration, as a dict.
pub(crate) fn counters<'py>(
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

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NativePartial>()?;
    m.add_function(wrap_pyfunction!(partial_from_bytes, m)?)?;
    m.add_function(wrap_pyfunction!(merge, m)?)?;
    m.add_function(wrap_pyfunction!(merge_bytes, m)?)?;
    Ok(())
}
