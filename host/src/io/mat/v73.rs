//! MAT v7.3 files (`save -v7.3`): HDF5 with a 512-byte MATLAB user block, read through the
//! pure-Rust [`hdf5_reader`] (which finds the superblock after the user block).
//!
//! MATLAB stores an array of dims `(a, b, c)` as an HDF5 dataset of shape `(c, b, a)`: the
//! bytes are in MATLAB's column-major order, so reversing the HDF5 shape gives the MATLAB dims
//! and the values need no transposition. A struct is a group whose members are its fields.
//! Numeric datasets of any float or integer type are decoded as in [`super::v5`] (f32 above
//! [`F32_ABOVE`] elements, else f64); others (strings, references, cells) are listed by name
//! with no data.

use super::v5::{Class, F32_ABOVE, Value, Var};
use crate::budget;
use crate::error::{Error, Result};
use hdf5_reader::error::Error as H5Error;
use hdf5_reader::group::Group;
use hdf5_reader::{ByteOrder, Dataset, Datatype, Hdf5File};
use std::path::{Path, PathBuf};

/// An open MAT v7.3 file.
pub struct Mat73 {
    path: PathBuf,
    file: Hdf5File,
    /// Top-level variables: (name, is a group).
    pub names: Vec<(String, bool)>,
}

impl std::fmt::Debug for Mat73 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Mat73")
            .field("path", &self.path)
            .field("names", &self.names)
            .finish_non_exhaustive()
    }
}

fn h5(path: &Path, var: &str, e: H5Error) -> Error {
    match e {
        H5Error::Io(io) => Error::io(path, io),
        other => Error::format(path, var, "a readable MAT v7.3 (HDF5) variable", other),
    }
}

impl Mat73 {
    /// Opens the file and lists its top-level variables.
    ///
    /// # Errors
    /// [`Error::Format`] if the HDF5 structure cannot be parsed.
    pub fn open(path: &Path) -> Result<Self> {
        let file = Hdf5File::open(path).map_err(|e| h5(path, "(file)", e))?;
        let (groups, sets) = file
            .root_group()
            .and_then(|g| g.member_names())
            .map_err(|e| h5(path, "(root group)", e))?;
        // MATLAB's own bookkeeping group (`#refs#`) holds no variable.
        let names = sets
            .into_iter()
            .map(|n| (n, false))
            .chain(groups.into_iter().map(|n| (n, true)))
            .filter(|(n, _)| !n.starts_with('#'))
            .collect();
        Ok(Self {
            path: path.to_path_buf(),
            file,
            names,
        })
    }

    /// The header of a variable (dims and class), no data.
    ///
    /// # Errors
    /// As [`Mat73::read`].
    pub fn header(&self, name: &str) -> Result<Var> {
        self.var(name, false)
    }

    /// Reads a variable whole.
    ///
    /// # Errors
    /// [`Error::Format`] naming the variable; [`Error::Memory`] over the budget.
    pub fn read(&self, name: &str) -> Result<Var> {
        self.var(name, true)
    }

    fn var(&self, name: &str, full: bool) -> Result<Var> {
        let root = self
            .file
            .root_group()
            .map_err(|e| h5(&self.path, name, e))?;
        match self.names.iter().find(|(n, _)| n == name) {
            Some((_, true)) => {
                let g = root.group(name).map_err(|e| h5(&self.path, name, e))?;
                self.group(&g, name, full)
            }
            Some((_, false)) => {
                let d = root.dataset(name).map_err(|e| h5(&self.path, name, e))?;
                self.dataset(&d, name, name, full)
            }
            None => Err(Error::format(
                &self.path,
                name,
                "a variable of this name",
                "none",
            )),
        }
    }

    fn group(&self, g: &Group, name: &str, full: bool) -> Result<Var> {
        let (_, sets) = g.member_names().map_err(|e| h5(&self.path, name, e))?;
        let mut fields = Vec::new();
        if full {
            for f in &sets {
                let what = format!("{name}.{f}");
                let d = g.dataset(f).map_err(|e| h5(&self.path, &what, e))?;
                fields.push(self.dataset(&d, f, &what, true)?);
            }
        }
        Ok(Var {
            name: name.to_string(),
            class: Class::Struct,
            dims: vec![1, 1],
            value: Value::Struct(fields),
        })
    }

    fn dataset(&self, d: &Dataset, name: &str, what: &str, full: bool) -> Result<Var> {
        let mut dims: Vec<usize> = d
            .shape()
            .iter()
            .rev()
            .map(|&x| usize::try_from(x).unwrap_or(usize::MAX))
            .collect();
        while dims.len() < 2 {
            dims.push(1);
        }
        let numeric = match d.dtype() {
            Datatype::FloatingPoint { size, .. } => {
                Some(if *size == 4 { "single" } else { "double" })
            }
            Datatype::FixedPoint { .. } => Some("double"),
            _ => None,
        };
        let class = match numeric {
            Some(n) => Class::Numeric(n),
            None => Class::Object,
        };
        let mut var = Var {
            name: name.to_string(),
            class,
            dims,
            value: Value::Skipped,
        };
        if !full || numeric.is_none() {
            return Ok(var);
        }
        let count = var.len();
        let size = match d.dtype() {
            Datatype::FloatingPoint { size, .. } => usize::from(*size),
            Datatype::FixedPoint { size, .. } => usize::from(*size),
            _ => 0,
        };
        let path = self.path.display().to_string();
        budget::check(
            || format!("{path}: variable `{what}`"),
            budget::bytes(count, size as u128 + 8),
        )?;
        let raw = d.read_raw_bytes().map_err(|e| h5(&self.path, what, e))?;
        if raw.len() != count.saturating_mul(size) || !matches!(size, 1 | 2 | 4 | 8) {
            return Err(Error::format(
                &self.path,
                what,
                format!("{count} values of {size} bytes"),
                format!("{} bytes", raw.len()),
            ));
        }
        let it = raw.chunks_exact(size).map(|c| decode(c, d.dtype()));
        var.value = if count > F32_ABOVE {
            Value::F32(it.map(|x| x as f32).collect())
        } else {
            Value::F64(it.collect())
        };
        Ok(var)
    }
}

/// One element of a float or integer HDF5 datatype.
fn decode(c: &[u8], t: &Datatype) -> f64 {
    let n = c.len();
    let mut w = [0u8; 8];
    w[..n].copy_from_slice(c);
    let order = match t {
        Datatype::FloatingPoint { byte_order, .. } | Datatype::FixedPoint { byte_order, .. } => {
            *byte_order
        }
        _ => ByteOrder::LittleEndian,
    };
    if order == ByteOrder::BigEndian {
        w[..n].reverse();
    }
    match t {
        Datatype::FloatingPoint { size: 4, .. } => {
            f64::from(f32::from_le_bytes([w[0], w[1], w[2], w[3]]))
        }
        Datatype::FloatingPoint { .. } => f64::from_le_bytes(w),
        Datatype::FixedPoint { signed: true, .. } => {
            if w[n - 1] & 0x80 != 0 {
                w[n..].fill(0xFF);
            }
            i64::from_le_bytes(w) as f64
        }
        _ => u64::from_le_bytes(w) as f64,
    }
}
