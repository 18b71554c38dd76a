//! Writing `.npz` captures: compressed or stored, one `.npy` member per array, all or nothing.

use crate::atomic::Transaction;
use crate::budget;
use crate::error::{Error, Result};
use crate::io::capture::Capture;
use ndarray::{Array, IxDyn};
use ndarray_npy::NpzWriter;
use std::fs::File;
use std::path::Path;

/// Writes `c` as a compressed `.npz` capture.
///
/// # Errors
/// [`Error::Io`] if the file cannot be written.
pub fn write(c: &Capture, path: &Path) -> Result<()> {
    write_with(c, path, true)
}

/// Writes `c` as a `.npz` capture, deflated or stored (`compress = false`: 3–4× larger
/// for simulated captures, read ~10× faster).
///
/// # Errors
/// [`Error::Io`] if the file cannot be written.
pub fn write_with(c: &Capture, path: &Path, compress: bool) -> Result<()> {
    let mut t = Transaction::new();
    stage(&mut t, c, path, compress)?;
    t.commit()
}

/// [`write_with`] as one file of a [`Transaction`] (written on its commit, all or nothing with
/// the transaction's other files).
///
/// # Errors
/// As [`write_with`].
pub fn stage(t: &mut Transaction, c: &Capture, path: &Path, compress: bool) -> Result<()> {
    t.stage(path, |file| write_to(c, file, path, compress))
}

/// Encodes `c` into `file` (`path` names it in errors). The first I/O error is latched: the
/// zip writer sees success from then on, so it never fails again while dropped, and the error
/// is returned once the archive is finished.
fn write_to(c: &Capture, file: &mut File, path: &Path, compress: bool) -> Result<()> {
    let g = &c.geometry;
    let latch = Latch {
        inner: file,
        error: None,
    };
    let mut w = NpzWriter::new_with_options(latch, member_options(compress, 0));
    let npz = |e: ndarray_npy::WriteNpzError| Error::io(path, std::io::Error::other(e.to_string()));
    let [lx, ly] = g.laser_shape;
    let [sx, sy] = g.spad_shape;
    let h_shape: Vec<usize> = if g.confocal {
        vec![lx, ly, g.nt]
    } else {
        vec![lx, ly, sx, sy, g.nt]
    };
    let arr = |shape: Vec<usize>, v: Vec<f32>| {
        Array::from_shape_vec(IxDyn(&shape), v).expect("shape checked by Capture::new")
    };
    let pts = |p: &[vltm_kernel::Point]| p.iter().flatten().copied().collect::<Vec<f32>>();
    // A view of the capture's buffer: writing holds no second copy of H.
    let h = ndarray::ArrayView::from_shape(IxDyn(&h_shape), &c.data)
        .expect("shape checked by Capture::new");
    let h_bytes = budget::bytes(c.data.len(), 4);
    w.add_array_with_options("H", &h, member_options(compress, h_bytes))
        .map_err(npz)?;
    w.add_array("laser_grid_xyz", &arr(vec![lx, ly, 3], pts(&g.lasers)))
        .map_err(npz)?;
    w.add_array("sensor_grid_xyz", &arr(vec![sx, sy, 3], pts(&g.spads)))
        .map_err(npz)?;
    // Normals only where the relay surface has some that are not +z (the default).
    if !g.normals.lasers.is_empty() {
        w.add_array(
            "laser_grid_normals",
            &arr(vec![lx, ly, 3], pts(&g.normals.lasers)),
        )
        .map_err(npz)?;
    }
    if !g.normals.spads.is_empty() {
        w.add_array(
            "sensor_grid_normals",
            &arr(vec![sx, sy, 3], pts(&g.normals.spads)),
        )
        .map_err(npz)?;
    }
    w.add_array("laser_xyz", &ndarray::arr1(&g.laser_origin))
        .map_err(npz)?;
    w.add_array("sensor_xyz", &ndarray::arr1(&g.sensor_origin))
        .map_err(npz)?;
    w.add_array("delta_t", &ndarray::arr0(g.dt)).map_err(npz)?;
    w.add_array("t_start", &ndarray::arr0(g.t0)).map_err(npz)?;
    w.add_array(
        "t_accounts_first_and_last_bounces",
        &ndarray::arr0(u8::from(g.legs_in_time)),
    )
    .map_err(npz)?;
    w.add_array("confocal", &ndarray::arr0(u8::from(g.confocal)))
        .map_err(npz)?;
    let latch = w.finish().map_err(npz)?;
    if let Some(e) = latch.error {
        return Err(Error::io(path, e));
    }
    Ok(())
}

/// The zip options of a member of `bytes` bytes: deflated or stored, with ZIP64 sizes
/// (`large_file`) when the member or its `.npy` header could pass 4 GiB — the zip writer
/// refuses such a member otherwise ("Large file option has not been set"), which made
/// captures of more than 4 GiB unwritable. NumPy and vltm's reader read ZIP64 members.
fn member_options(compress: bool, bytes: u128) -> zip::write::SimpleFileOptions {
    let method = if compress {
        zip::CompressionMethod::Deflated
    } else {
        zip::CompressionMethod::Stored
    };
    // Room for the `.npy` header (at most a few hundred bytes).
    let large = bytes.saturating_add(1 << 16) >= u128::from(u32::MAX);
    zip::write::SimpleFileOptions::default()
        .compression_method(method)
        .large_file(large)
}

/// A writer that remembers its first error and reports success from then on (see
/// [`write_to`]).
struct Latch<'f> {
    inner: &'f mut File,
    error: Option<std::io::Error>,
}

impl std::io::Write for Latch<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.error.is_none()
            && let Err(e) = self.inner.write_all(buf)
        {
            self.error = Some(e);
        }
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        if self.error.is_none()
            && let Err(e) = self.inner.flush()
        {
            self.error = Some(e);
        }
        Ok(())
    }
}

impl std::io::Seek for Latch<'_> {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        // Seeks are needed to patch headers; a failed one is latched like a failed write.
        match self.inner.seek(pos) {
            Ok(p) => Ok(p),
            Err(e) => {
                let p = self.inner.stream_position().unwrap_or(0);
                self.error.get_or_insert(e);
                Ok(p)
            }
        }
    }
}
