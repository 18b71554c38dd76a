//! Reading and checking the metadata datasets of an `HDF5_TAL` file: grids, scalars, flags
//! and numbers of any stored type, each error naming its dataset.

use crate::error::{Error, Result};
use hdf5_reader::error::Error as H5Error;
use hdf5_reader::{ByteOrder, Dataset, Datatype, Hdf5File};
use std::path::Path;
use vltm_kernel::Point;

/// The elements of an array in logical (C) order.
pub(super) fn into_vec<T: Clone>(a: ndarray::ArrayD<T>) -> Vec<T> {
    if a.is_standard_layout() {
        a.into_raw_vec_and_offset().0
    } else {
        a.iter().cloned().collect()
    }
}

pub(super) fn usize_of(d: u64) -> usize {
    usize::try_from(d).unwrap_or(usize::MAX)
}

/// numpy's `allclose` (rtol 1e-5, atol 1e-8) of two point lists of the same length.
pub(super) fn allclose(a: &[Point], b: &[Point]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(p, q)| {
            p.iter().zip(q).all(|(&x, &y)| {
                let (x, y) = (f64::from(x), f64::from(y));
                (x - y).abs() <= 1e-8 + 1e-5 * y.abs()
            })
        })
}

/// Wraps an `hdf5_reader` error: I/O stays I/O, anything else is a format error of `field`.
pub(super) fn h5_error(path: &Path, field: &str, e: H5Error) -> Error {
    match e {
        H5Error::Io(io) => Error::io(path, io),
        other => Error::format(path, field, "a readable HDF5_TAL field", other),
    }
}

/// A grid of points with its shape `[nx, ny]` (`[N, 1]` for an `N_3` list).
pub(super) struct Grid {
    pub(super) points: Vec<Point>,
    pub(super) shape: [usize; 2],
    /// Stored as `(X, Y, 3)`.
    pub(super) xy: bool,
    pub(super) field: &'static str,
}

impl Grid {
    /// Checks the grid against `H`'s two axes `want` and returns them as the grid shape.
    pub(super) fn fit(&self, path: &Path, want: [usize; 2]) -> Result<[usize; 2]> {
        let ok = if self.xy {
            self.shape == want
        } else {
            Some(self.points.len()) == want[0].checked_mul(want[1])
        };
        if !ok {
            let found = if self.xy {
                format!("shape ({}, {}, 3)", self.shape[0], self.shape[1])
            } else {
                format!("{} points", self.points.len())
            };
            return Err(Error::format(
                path,
                self.field,
                format!("a ({}, {}, 3) grid to match H", want[0], want[1]),
                found,
            ));
        }
        Ok(want)
    }

    /// Checks the grid holds `n` points (one `H` axis) and returns its own shape.
    pub(super) fn count(&self, path: &Path, n: usize) -> Result<[usize; 2]> {
        if self.points.len() != n {
            return Err(Error::format(
                path,
                self.field,
                format!("{n} points to match H"),
                self.points.len(),
            ));
        }
        Ok(self.shape)
    }
}

/// Typed access to the root datasets of one file.
pub(super) struct Fields<'a> {
    pub(super) path: &'a Path,
    pub(super) file: &'a Hdf5File,
    pub(super) names: &'a [String],
    /// The layout the file is read as (`HDF5_TAL`, `Z-NLOS`), for errors.
    pub(super) kind: &'static str,
}

impl Fields<'_> {
    pub(super) fn has(&self, name: &str) -> bool {
        self.names.iter().any(|n| n == name)
    }

    /// Whether `name` is a dataset with a null dataspace (no shape, no values): how h5py
    /// and y-tal's `write_capture` store a field that is `None` (`laser_grid_normals` of a
    /// capture without normals). False when absent or not null.
    pub(super) fn is_null(&self, name: &str) -> bool {
        self.has(name)
            && self
                .file
                .dataset(name)
                .is_ok_and(|ds| ds.ndim() == 0 && ds.num_elements().is_ok_and(|n| n == 0))
    }

    pub(super) fn dataset(&self, name: &str) -> Result<Dataset> {
        if !self.has(name) {
            return Err(Error::format(
                self.path,
                name,
                format!("a dataset of this name ({})", self.kind),
                "none",
            ));
        }
        self.file
            .dataset(name)
            .map_err(|e| h5_error(self.path, name, e))
    }

    /// All values of a numeric (float, integer or integer-enum) dataset as f64, with its shape
    /// and datatype.
    pub(super) fn numbers(&self, name: &str) -> Result<(Vec<f64>, Vec<usize>, Datatype)> {
        let ds = self.dataset(name)?;
        let shape: Vec<usize> = ds.shape().iter().map(|&d| usize_of(d)).collect();
        let dtype = ds.dtype().clone();
        let raw = ds
            .read_raw_bytes()
            .map_err(|e| h5_error(self.path, name, e))?;
        let v = decode_numbers(&raw, &dtype).ok_or_else(|| {
            Error::format(
                self.path,
                name,
                "numeric values",
                format!("{dtype:?} ({} bytes)", raw.len()),
            )
        })?;
        let n = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
        if n != Some(v.len()) {
            return Err(Error::format(
                self.path,
                name,
                format!("the values of shape {shape:?}"),
                format!("{} values", v.len()),
            ));
        }
        Ok((v, shape, dtype))
    }

    pub(super) fn float_scalar(&self, name: &str) -> Result<f64> {
        let (v, shape, _) = self.numbers(name)?;
        match v[..] {
            [x] => Ok(x),
            _ => Err(Error::format(
                self.path,
                name,
                "a scalar",
                format!("shape {shape:?}"),
            )),
        }
    }

    /// A one-element integer (or enum) dataset, with the enum member's name if it has one.
    pub(super) fn enum_scalar(&self, name: &str) -> Result<(i64, Option<String>)> {
        let (v, shape, dtype) = self.numbers(name)?;
        let x = match v[..] {
            [x] if x.fract() == 0.0 && x.abs() < 1e15 => x as i64,
            _ => {
                return Err(Error::format(
                    self.path,
                    name,
                    "one integer",
                    format!("{v:?} of shape {shape:?}"),
                ));
            }
        };
        let member = match &dtype {
            Datatype::Enum { base, members } => members
                .iter()
                .find(|m| decode_numbers(&m.value, base).as_deref() == Some(&[x as f64][..]))
                .map(|m| m.name.clone()),
            _ => None,
        };
        Ok((x, member))
    }

    pub(super) fn xyz(&self, name: &str) -> Result<[f64; 3]> {
        let (v, shape, _) = self.numbers(name)?;
        let p = <[f64; 3]>::try_from(v.as_slice()).map_err(|_| {
            Error::format(self.path, name, "3 coordinates", format!("shape {shape:?}"))
        })?;
        if !p.iter().all(|c| c.is_finite()) {
            return Err(Error::format(
                self.path,
                name,
                "finite coordinates",
                format!("{p:?}"),
            ));
        }
        Ok(p)
    }

    /// A grid `(X, Y, 3)` or `(N, 3)`, checked against its `*_grid_format` if present.
    pub(super) fn grid(&self, name: &'static str, format_name: &str) -> Result<Grid> {
        let (v, shape, _) = self.numbers(name)?;
        let (xy, dims) = match shape[..] {
            [nx, ny, 3] => (true, [nx, ny]),
            [n, 3] => (false, [n, 1]),
            _ => {
                return Err(Error::format(
                    self.path,
                    name,
                    "shape (X, Y, 3) or (N, 3)",
                    format!("{shape:?}"),
                ));
            }
        };
        if self.has(format_name) {
            let (g, member) = self.enum_scalar(format_name)?;
            let (want, want_name) = if xy { (2, "X_Y_3") } else { (1, "N_3") };
            if g != want || member.is_some_and(|m| m != want_name) {
                return Err(Error::format(
                    self.path,
                    format_name,
                    format!("{want} = {want_name} (tal GridFormat) for {name} of shape {shape:?}"),
                    g,
                ));
            }
        }
        Ok(Grid {
            points: v
                .chunks_exact(3)
                .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
                .collect(),
            shape: dims,
            xy,
            field: name,
        })
    }
}

/// Decodes the raw element bytes of a float, integer or integer-enum datatype to f64.
pub(super) fn decode_numbers(raw: &[u8], dtype: &Datatype) -> Option<Vec<f64>> {
    /// Little-endian words of `N` bytes.
    fn words<const N: usize>(raw: &[u8], order: ByteOrder) -> Option<Vec<[u8; N]>> {
        if !raw.len().is_multiple_of(N) {
            return None;
        }
        Some(
            raw.chunks_exact(N)
                .map(|c| {
                    let mut w = [0u8; N];
                    w.copy_from_slice(c);
                    if order == ByteOrder::BigEndian {
                        w.reverse();
                    }
                    w
                })
                .collect(),
        )
    }
    match dtype {
        &Datatype::FloatingPoint { size, byte_order } => match size {
            4 => words::<4>(raw, byte_order).map(|w| {
                w.into_iter()
                    .map(|b| f64::from(f32::from_le_bytes(b)))
                    .collect()
            }),
            8 => {
                words::<8>(raw, byte_order).map(|w| w.into_iter().map(f64::from_le_bytes).collect())
            }
            _ => None,
        },
        &Datatype::FixedPoint {
            size,
            signed,
            byte_order,
        } => {
            let size = usize::from(size);
            if !matches!(size, 1 | 2 | 4 | 8) || !raw.len().is_multiple_of(size) {
                return None;
            }
            Some(
                raw.chunks_exact(size)
                    .map(|c| {
                        let mut w = [0u8; 8];
                        w[..size].copy_from_slice(c);
                        if byte_order == ByteOrder::BigEndian {
                            w[..size].reverse();
                        }
                        if signed && w[size - 1] & 0x80 != 0 {
                            w[size..].fill(0xFF);
                        }
                        if signed {
                            i64::from_le_bytes(w) as f64
                        } else {
                            u64::from_le_bytes(w) as f64
                        }
                    })
                    .collect(),
            )
        }
        Datatype::Enum { base, .. } => decode_numbers(raw, base),
        _ => None,
    }
}

/// Element type of `H`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Elem {
    F32,
    F64,
}

impl Elem {
    /// The element type of dataset `field` of `path`.
    ///
    /// # Errors
    /// [`Error::Format`] naming `field` unless it holds float32 or float64 values.
    pub(super) fn of(h: &Dataset, path: &Path, field: &str) -> Result<Self> {
        match h.dtype() {
            Datatype::FloatingPoint { size: 4, .. } => Ok(Self::F32),
            Datatype::FloatingPoint { size: 8, .. } => Ok(Self::F64),
            other => Err(Error::format(
                path,
                field,
                "float32 or float64 values",
                format!("{other:?}"),
            )),
        }
    }
}
