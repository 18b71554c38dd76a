//! Voxel sets: a grid from a SPEC or a list of points.

use crate::{arg, py_err};
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use vltm::volume::Volume;
use vltm_kernel::Point;

/// A voxel set: a grid from a SPEC or a list of points.
#[pyclass(name = "Volume", module = "vltm._native", frozen)]
#[derive(Clone)]
pub(crate) struct NativeVolume {
    pub(crate) volume: Volume,
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
        flat_points(&self.volume.points).into_pyarray(py)
    }
    fn __len__(&self) -> usize {
        self.volume.len()
    }
}

/// Points as flat `f32` (x, y, z per point).
pub(crate) fn flat_points(p: &[Point]) -> Vec<f32> {
    p.iter().flatten().copied().collect()
}

/// `(n, 3)` float32 points from NumPy.
pub(crate) fn points_of(a: &PyReadonlyArray2<'_, f32>, what: &str) -> PyResult<Vec<Point>> {
    let v = a.as_array();
    if v.shape()[1] != 3 {
        return Err(arg(
            what,
            format!("expected (n, 3) points, found {:?}", v.shape()),
        ));
    }
    Ok(v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
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
    let pts = points_of(&points, "volume")?;
    Ok(NativeVolume {
        volume: Volume::points(pts).map_err(py_err)?,
        spec: None,
    })
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NativeVolume>()?;
    m.add_function(wrap_pyfunction!(volume_from_spec, m)?)?;
    m.add_function(wrap_pyfunction!(volume_from_points, m)?)?;
    Ok(())
}
