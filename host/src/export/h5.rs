//! HDF5 output of result volumes, written in pure Rust (`hdf5-pure`: no system HDF5 library,
//! no Python), for tools that read HDF5 rather than `.npy` (h5py, MATLAB `h5read`, y-tal users).
//!
//! A file written by [`write_volume`] holds, at its root:
//!
//! | object | type, shape | content |
//! |---|---|---|
//! | dataset `intensity` | f32 `(nx, ny, nz)` (C order) | the probe's intensities `|A|²`, as the `.npy` output (point lists: `(K, 1, 1)`) |
//! | dataset `volume_xyz` | f32 `(nx, ny, nz, 3)` | voxel centres in metres (y-tal's `volume_format` `X_Y_Z_3`) |
//! | attribute `probe` | string | `direct`, `column`, `indirect`, … |
//! | attribute `wavelength`, `sigma` | f64 | virtual wavelength λ and gate σ (m of optical path) |
//! | attribute `band_half_width` | f64 | m (band `|ν − Ω| ≤ m/σ`) |
//! | attribute `weights` | string | `inv` (the paper's 1/d per leg) or `one` (y-tal's) |
//! | attribute `focus` | f64 `[3]` | x_a of a column (absent otherwise) |
//! | attribute `capture` | string | the input file, as given |
//! | attribute `vltm_version` | string | the writing vltm's version |
//!
//! ```python
//! import h5py; f = h5py.File("direct.h5"); I = f["intensity"][()]; xyz = f["volume_xyz"][()]
//! ```
//!
//! [`stage_matrix`] writes the LTM between two voxel sets (`vltm matrix`): datasets `re`,
//! `im`, `intensity` of shape `(n_from, n_to)`, `from_xyz`, `to_xyz`, the same attributes and
//! the matrix's own (how the sets were given, ε, the DFT size).
//!
//! [`read_volume`] reads `intensity` back (with the pure-Rust reader that reads captures).
//! Memory: the file is assembled in memory (about 16 bytes per voxel) and written at once.

use std::path::Path;

use hdf5_pure::{AttrValue, FileBuilder};
use hdf5_reader::Hdf5File;
use vltm_kernel::num_complex::Complex32;
use vltm_kernel::{Config, Point, Weights};

use crate::atomic::Transaction;
use crate::error::{Error, Result};
use crate::volume::Volume;

/// What produced a volume: recorded as attributes next to the data.
#[derive(Clone, Debug)]
pub struct Provenance<'a> {
    /// Probe name (`direct`, `column`, …).
    pub probe: &'a str,
    /// The probes' configuration (λ, σ, m, weights).
    pub config: &'a Config,
    /// The projector focus x_a of a column.
    pub focus: Option<Point>,
    /// The capture file, as given.
    pub capture: &'a Path,
}

/// Writes `values` (one per voxel of `volume`, C order) and the voxel centres to the HDF5 file
/// `path`, with `meta` as attributes (layout in the module docs).
///
/// # Errors
/// [`Error::Argument`] (`values`) if `values` does not hold one value per voxel;
/// [`Error::Format`] if the HDF5 encoder refuses the data; [`Error::Io`] if the file cannot
/// be written.
pub fn write_volume(
    path: impl AsRef<Path>,
    values: &[f32],
    volume: &Volume,
    meta: &Provenance<'_>,
) -> Result<()> {
    let mut t = Transaction::new();
    stage_volume(&mut t, path.as_ref(), values, volume, meta)?;
    t.commit()
}

/// [`write_volume`] as one file of a [`Transaction`] (written on its commit).
///
/// # Errors
/// As [`write_volume`].
pub fn stage_volume(
    t: &mut Transaction,
    path: &Path,
    values: &[f32],
    volume: &Volume,
    meta: &Provenance<'_>,
) -> Result<()> {
    if values.len() != volume.len() {
        return Err(Error::arg(
            "values",
            format!(
                "expected one value per voxel ({}), found {}",
                volume.len(),
                values.len()
            ),
        ));
    }
    let shape: Vec<u64> = volume.shape.iter().map(|&d| d as u64).collect();
    let xyz: Vec<f32> = volume.points.iter().flatten().copied().collect();
    let mut b = FileBuilder::new();
    b.create_dataset("intensity")
        .with_f32_data(values)
        .with_shape(&shape);
    b.create_dataset("volume_xyz")
        .with_f32_data(&xyz)
        .with_shape(&[shape[0], shape[1], shape[2], 3]);
    set_provenance(&mut b, meta);
    let bytes = b
        .finish()
        .map_err(|e| Error::format(path, "(file)", "an encodable HDF5 volume", e))?;
    t.stage(path, |f| {
        std::io::Write::write_all(f, &bytes).map_err(|e| Error::io(path, e))
    })
}

/// The attributes of [`Provenance`] (table in the module docs).
fn set_provenance(b: &mut FileBuilder, meta: &Provenance<'_>) {
    let cfg = meta.config;
    b.set_attr("probe", AttrValue::String(meta.probe.to_string()));
    b.set_attr("wavelength", AttrValue::F64(cfg.wavelength()));
    b.set_attr("sigma", AttrValue::F64(cfg.sigma()));
    b.set_attr(
        "band_half_width",
        AttrValue::F64(cfg.params().band_half_width),
    );
    let weights = match cfg.params().weights {
        Weights::Inv => "inv",
        Weights::One => "one",
    };
    b.set_attr("weights", AttrValue::String(weights.to_string()));
    if let Some(a) = meta.focus {
        b.set_attr(
            "focus",
            AttrValue::F64Array(a.iter().map(|&c| f64::from(c)).collect()),
        );
    }
    b.set_attr(
        "capture",
        AttrValue::String(meta.capture.display().to_string()),
    );
    b.set_attr(
        "vltm_version",
        AttrValue::String(env!("CARGO_PKG_VERSION").to_string()),
    );
}

/// LTM elements between two voxel sets, for [`stage_matrix`].
#[derive(Clone, Debug)]
pub struct MatrixData<'a> {
    /// Amplitudes `A(from[i], to[k])` at `i·to.len() + k`.
    pub amplitudes: &'a [Complex32],
    /// The projector foci `x_a` (rows).
    pub from: &'a [Point],
    /// The imaged voxels `x_b` (columns).
    pub to: &'a [Point],
    /// Further attributes: numbers (λ-independent settings such as ε, the DFT size).
    pub numbers: &'a [(&'a str, f64)],
    /// Further attributes: strings (how `from` and `to` were given, the gate).
    pub texts: &'a [(&'a str, String)],
}

/// Writes a matrix of LTM elements as one file of a [`Transaction`]: datasets `re`, `im`
/// (f32 amplitudes) and `intensity` (f32 `|A|²`), each of shape `(n_from, n_to)`, `from_xyz`
/// `(n_from, 3)` and `to_xyz` `(n_to, 3)` in metres, the [`Provenance`] attributes and
/// `m.numbers`, `m.texts`. Memory: the three `f32` planes and their encoded copy (24 bytes
/// per element) beside the caller's amplitudes.
///
/// # Errors
/// [`Error::Argument`] (`values`) if the amplitudes are not `n_from × n_to`;
/// [`Error::Format`] if the HDF5 encoder refuses the data.
pub fn stage_matrix(
    t: &mut Transaction,
    path: &Path,
    m: &MatrixData<'_>,
    meta: &Provenance<'_>,
) -> Result<()> {
    let (nf, nt) = (m.from.len(), m.to.len());
    if m.amplitudes.len() != nf * nt {
        return Err(Error::arg(
            "values",
            format!(
                "expected {nf} x {nt} amplitudes, found {}",
                m.amplitudes.len()
            ),
        ));
    }
    let shape = [nf as u64, nt as u64];
    let mut b = FileBuilder::new();
    {
        let re: Vec<f32> = m.amplitudes.iter().map(|z| z.re).collect();
        b.create_dataset("re").with_f32_data(&re).with_shape(&shape);
    }
    {
        let im: Vec<f32> = m.amplitudes.iter().map(|z| z.im).collect();
        b.create_dataset("im").with_f32_data(&im).with_shape(&shape);
    }
    {
        let int: Vec<f32> = m
            .amplitudes
            .iter()
            .map(|z| {
                let (re, im) = (f64::from(z.re), f64::from(z.im));
                (re * re + im * im) as f32
            })
            .collect();
        b.create_dataset("intensity")
            .with_f32_data(&int)
            .with_shape(&shape);
    }
    for (name, pts) in [("from_xyz", m.from), ("to_xyz", m.to)] {
        let xyz: Vec<f32> = pts.iter().flatten().copied().collect();
        b.create_dataset(name)
            .with_f32_data(&xyz)
            .with_shape(&[pts.len() as u64, 3]);
    }
    set_provenance(&mut b, meta);
    for (k, v) in m.numbers {
        b.set_attr(k, AttrValue::F64(*v));
    }
    for (k, v) in m.texts {
        b.set_attr(k, AttrValue::String(v.clone()));
    }
    let bytes = b
        .finish()
        .map_err(|e| Error::format(path, "(file)", "an encodable HDF5 matrix", e))?;
    t.stage(path, |f| {
        std::io::Write::write_all(f, &bytes).map_err(|e| Error::io(path, e))
    })
}

/// Reads an `f32` dataset of a vltm HDF5 file: values in C order and the shape.
///
/// # Errors
/// [`Error::Io`] / [`Error::Format`] if the file cannot be read, has no such f32 dataset,
/// or its size does not match its shape.
pub fn read_f32_dataset(path: impl AsRef<Path>, name: &str) -> Result<(Vec<f32>, Vec<usize>)> {
    let path = path.as_ref();
    let h5 = |field: &str, e: hdf5_reader::error::Error| {
        Error::format(path, field, "a vltm HDF5 file", e)
    };
    let file = Hdf5File::open(path).map_err(|e| h5("(file)", e))?;
    let ds = file.dataset(name).map_err(|e| h5(name, e))?;
    let shape: Vec<usize> = ds.shape().iter().map(|&d| d as usize).collect();
    let raw = ds.read_raw_bytes().map_err(|e| h5(name, e))?;
    let n = shape.iter().product::<usize>();
    if raw.len() != 4 * n {
        return Err(Error::format(
            path,
            name,
            format!("{n} f32 values (shape {shape:?})"),
            format!("{} bytes", raw.len()),
        ));
    }
    let v = raw
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Ok((v, shape))
}

/// Reads the `intensity` dataset of a file written by [`write_volume`]: values in C order and
/// the shape.
///
/// # Errors
/// [`Error::Io`] / [`Error::Format`] if the file cannot be read, has no f32 `intensity`
/// dataset, or its size does not match its shape.
pub fn read_volume(path: impl AsRef<Path>) -> Result<(Vec<f32>, Vec<usize>)> {
    read_f32_dataset(path, "intensity")
}

#[cfg(test)]
mod tests {
    use super::*;
    use vltm_kernel::Params;

    #[test]
    fn volume_round_trip_with_attributes() {
        let vol = Volume::parse("-0.5:0.5:3,0:0.2:2,0.5:1:4").unwrap();
        let values: Vec<f32> = (0..vol.len()).map(|i| i as f32 * 0.5 - 1.0).collect();
        let cfg = Config::try_new(&Params::new(0.2, 100, 0.01)).unwrap();
        let path = std::env::temp_dir().join(format!("vltm-h5-{}.h5", std::process::id()));
        let meta = Provenance {
            probe: "column",
            config: &cfg,
            focus: Some([0.1, 0.0, 0.7]),
            capture: Path::new("c.npz"),
        };
        write_volume(&path, &values, &vol, &meta).unwrap();
        let (back, shape) = read_volume(&path).unwrap();
        assert_eq!(shape, vec![3, 2, 4]);
        assert_eq!(back, values);
        let f = Hdf5File::open(&path).unwrap();
        let xyz = f.dataset("volume_xyz").unwrap();
        assert_eq!(xyz.shape(), &[3, 2, 4, 3]);
        let raw = xyz.read_raw_bytes().unwrap();
        let last: Vec<f32> = raw[raw.len() - 12..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        assert_eq!(last, vol.points[vol.len() - 1].to_vec());
        let _ = std::fs::remove_file(&path);
        // Wrong value count: an argument error, nothing written.
        let err = write_volume(&path, &values[1..], &vol, &meta).unwrap_err();
        assert!(err.to_string().contains("values"), "{err}");
        assert!(!path.exists());
    }

    #[test]
    fn reading_a_non_volume_is_a_format_error() {
        let path = std::env::temp_dir().join(format!("vltm-h5-bad-{}.h5", std::process::id()));
        std::fs::write(&path, b"not an HDF5 file").unwrap();
        let err = read_volume(&path).unwrap_err();
        assert!(err.to_string().contains("vltm-h5-bad"), "{err}");
        let _ = std::fs::remove_file(&path);
    }
}
