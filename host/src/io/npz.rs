//! vltm's own `.npz` capture format: written compressed or stored, read whole, and streamed
//! row by row from a stored (uncompressed) archive.
//!
//! Keys of vltm's `.npz` capture format (names follow y-tal's HDF5 fields).
//!
//! | key | dtype, shape | meaning |
//! |---|---|---|
//! | `H` | f32 `(Lx, Ly, Sx, Sy, Nt)`, or `(Lx, Ly, Nt)` if confocal | histograms, time last |
//! | `laser_grid_xyz` | f32 `(Lx, Ly, 3)` | laser spots |
//! | `sensor_grid_xyz` | f32 `(Sx, Sy, 3)` | SPAD spots |
//! | `laser_xyz`, `sensor_xyz` | f64 `(3,)` | device positions |
//! | `delta_t`, `t_start` | f64 `()` | bin width, time of bin 0 (m) |
//! | `t_accounts_first_and_last_bounces`, `confocal` | u8 `()` | flags |
//! | `laser_grid_normals`, `sensor_grid_normals` (optional) | f32 `(Lx, Ly, 3)`, `(Sx, Sy, 3)` | relay-surface normals at the spots (absent: +z; written only when some normal is not +z) |
//!
//! `confocal = 1` means one histogram per row: a **paired** scan, row `l` lit at
//! `laser_grid_xyz[l]` and seen at `sensor_grid_xyz[l]` (the two grids have one shape; a
//! confocal capture when they are equal). vltm writes paired captures in this layout.
//!
//! **Per-histogram paired form** (what a user writes with numpy for a galvo-scanned or
//! arbitrary scan; recognised by `laser_xyz` of shape `(K, 3)` and no `laser_grid_xyz`):
//!
//! | key | dtype, shape | meaning |
//! |---|---|---|
//! | `H` | f32 `(K, Nt)` | histogram `k`, time last |
//! | `laser_xyz`, `sensor_xyz` | f32 or f64 `(K, 3)` | the laser and SPAD spot of histogram `k` (m) |
//! | `delta_t`, `t_start` | f64 `()` | bin width, time of bin 0 (m) |
//! | `laser_normals`, `sensor_normals` (optional) | f32 or f64 `(K, 3)` | relay-surface normals at the spots (absent: +z): checked (finite, non-zero length), used by `--compensate-laser` and `--weights cos` |
//! | `laser_origin`, `sensor_origin` (optional) | f64 `(3,)` | device positions (default the origin) |
//! | `t_accounts_first_and_last_bounces` (optional) | u8 `()` | device legs in the time axis (needs both origins) |
//!
//! Every field is checked before anything is read into the capture: lists of different
//! lengths, NaN or infinite points and zero-length normals are one-line errors naming the key.

use crate::atomic::Transaction;
use crate::budget;
use crate::error::{Error, Result};
use crate::io::capture::{Capture, Geometry, Normals, RowSource, check_row};
use ndarray::{Array, ArrayD, IxDyn};
use ndarray_npy::{NpzReader, NpzWriter, ReadableElement};
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

fn get<T: ReadableElement>(r: &mut NpzReader<File>, path: &Path, key: &str) -> Result<ArrayD<T>> {
    r.by_name::<ndarray::OwnedRepr<T>, IxDyn>(key).map_err(|e| {
        Error::format(
            path,
            key,
            "a readable array of the documented dtype",
            e.to_string(),
        )
    })
}

fn scalar<T: ReadableElement + Copy>(r: &mut NpzReader<File>, path: &Path, key: &str) -> Result<T> {
    let a = get::<T>(r, path, key)?;
    a.iter()
        .next()
        .copied()
        .filter(|_| a.len() == 1)
        .ok_or_else(|| Error::format(path, key, "a scalar", format!("shape {:?}", a.shape())))
}

fn grid(
    r: &mut NpzReader<File>,
    path: &Path,
    key: &str,
) -> Result<(Vec<vltm_kernel::Point>, [usize; 2])> {
    let a = get::<f32>(r, path, key)?;
    let s = a.shape().to_vec();
    if s.len() != 3 || s[2] != 3 {
        return Err(Error::format(
            path,
            key,
            "shape (nx, ny, 3)",
            format!("{s:?}"),
        ));
    }
    let v: Vec<f32> = a.iter().copied().collect();
    Ok((
        v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        [s[0], s[1]],
    ))
}

/// The optional normals of vltm's grid layout: `(nx, ny, 3)` of the grid's shape, or empty
/// when the key is absent (+z). Their values are checked by [`Geometry::validate`].
fn grid_normals(
    r: &mut NpzReader<File>,
    path: &Path,
    key: &str,
    shape: [usize; 2],
) -> Result<Vec<vltm_kernel::Point>> {
    let names = r
        .names()
        .map_err(|e| Error::format(path, "(archive)", "a NumPy .npz archive", e.to_string()))?;
    if !names.iter().any(|n| n.trim_end_matches(".npy") == key) {
        return Ok(Vec::new());
    }
    let (n, s) = grid(r, path, key)?;
    if s != shape {
        return Err(Error::format(
            path,
            key,
            format!("shape ({}, {}, 3): one normal per spot", shape[0], shape[1]),
            format!("({}, {}, 3)", s[0], s[1]),
        ));
    }
    Ok(n)
}

fn xyz(r: &mut NpzReader<File>, path: &Path, key: &str) -> Result<[f64; 3]> {
    let a = get::<f64>(r, path, key)?;
    let v: Vec<f64> = a.iter().copied().collect();
    <[f64; 3]>::try_from(v.as_slice())
        .map_err(|_| Error::format(path, key, "3 coordinates", format!("shape {:?}", a.shape())))
}

/// Largest `.npy` header read (bytes); numpy writes under 4 KiB.
const MAX_NPY_HEADER: u64 = 1 << 16;

/// The header length and the offset of the header text from the 12 first bytes of a `.npy`
/// member (magic already checked or not: a wrong version is an error).
fn npy_prefix(pre: &[u8; 12]) -> std::result::Result<(u64, u64), String> {
    if &pre[..6] != b"\x93NUMPY" {
        return Err("no NUMPY magic".into());
    }
    match pre[6] {
        1 => Ok((u64::from(u16::from_le_bytes([pre[8], pre[9]])), 10)),
        2 | 3 => Ok((
            u64::from(u32::from_le_bytes([pre[8], pre[9], pre[10], pre[11]])),
            12,
        )),
        v => Err(format!("version {v}")),
    }
}

/// The `shape` tuple of a `.npy` header dictionary (spaces removed).
fn npy_shape(header: &str) -> Option<Vec<usize>> {
    header
        .split_once("'shape':(")
        .and_then(|(_, r)| r.split_once(')'))
        .and_then(|(t, _)| {
            t.split(',')
                .filter(|x| !x.is_empty())
                .map(|x| x.parse::<usize>().ok())
                .collect()
        })
}

/// Bytes per element of a `.npy` `descr` such as `'<f4'` (1 for anything unrecognised: the
/// array reader rejects it later).
fn npy_item_size(header: &str) -> u128 {
    header
        .split_once("'descr':'")
        .and_then(|(_, r)| r.split_once('\''))
        .and_then(|(d, _)| {
            d.trim_start_matches(['<', '>', '|', '='])
                .get(1..)?
                .parse()
                .ok()
        })
        .unwrap_or(1)
}

/// Checks every member's `.npy` header before any array is read: the header is at most
/// 64 KiB and the array its shape claims fits the memory budget (alone, and all members
/// together). The NumPy reader sizes its buffer from the header, so a header claiming 10¹²
/// values would otherwise abort the process.
///
/// # Errors
/// [`Error::Format`] for an unreadable archive or header, [`Error::Memory`] naming the
/// member and the size its header claims.
fn check_members(path: &Path) -> Result<()> {
    use std::io::Read;
    let archive = |e: zip::result::ZipError| {
        Error::format(path, "(archive)", "a NumPy .npz archive", e.to_string())
    };
    let f = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut z = zip::ZipArchive::new(f).map_err(archive)?;
    let mut total = 0u128;
    for i in 0..z.len() {
        let mut e = z.by_index(i).map_err(archive)?;
        let name = e.name().trim_end_matches(".npy").to_string();
        let bad = |expected: &str, found: String| Error::format(path, &name, expected, found);
        let mut pre = [0u8; 12];
        if e.read_exact(&mut pre).is_err() {
            // Too short for a .npy header: the array reader names it if it is needed.
            continue;
        }
        let (hlen, skip) = npy_prefix(&pre).map_err(|m| bad("a .npy array", m))?;
        if hlen > MAX_NPY_HEADER {
            return Err(bad("a .npy header under 64 KiB", format!("{hlen} bytes")));
        }
        let mut header = pre[skip as usize..].to_vec();
        header.resize(hlen as usize, 0);
        let have = (12 - skip).min(hlen) as usize;
        e.read_exact(&mut header[have..])
            .map_err(|err| bad("a complete .npy header", err.to_string()))?;
        let header = String::from_utf8_lossy(&header).replace(' ', "");
        let Some(shape) = npy_shape(&header) else {
            return Err(bad("a shape tuple in the .npy header", header));
        };
        let n = shape
            .iter()
            .try_fold(1u128, |a, &x| a.checked_mul(x as u128))
            .unwrap_or(u128::MAX);
        let bytes = n.saturating_mul(npy_item_size(&header));
        let what = || {
            format!(
                "{name} of {} values claimed by {}'s header",
                budget::count(n),
                path.display()
            )
        };
        // The archive records each member's uncompressed size: data that cannot be there is
        // a truncated member, refused before the reader allocates the claimed array (a claim
        // over the budget is refused by the budget, below).
        let room = u128::from(e.size()).saturating_sub(u128::from(skip + hlen));
        if bytes > room && bytes <= u128::from(budget::get()) {
            return Err(bad(
                &format!("{bytes} bytes of data as its header claims"),
                format!("{room} bytes in the archive (truncated)"),
            ));
        }
        budget::check(what, bytes)?;
        total = total.saturating_add(bytes);
    }
    budget::check(
        || format!("the arrays claimed by {}'s headers", path.display()),
        total,
    )
}

/// A `(K, 3)` array of points stored as f64 or f32 (`None` when the key is absent).
fn points(r: &mut NpzReader<File>, path: &Path, key: &str) -> Result<Option<Vec<[f64; 3]>>> {
    let names = r
        .names()
        .map_err(|e| Error::format(path, "(archive)", "a NumPy .npz archive", e.to_string()))?;
    if !names.iter().any(|n| n.trim_end_matches(".npy") == key) {
        return Ok(None);
    }
    let (v, shape): (Vec<f64>, Vec<usize>) = match r.by_name::<ndarray::OwnedRepr<f64>, IxDyn>(key)
    {
        Ok(a) => (a.iter().copied().collect(), a.shape().to_vec()),
        Err(_) => {
            let a = get::<f32>(r, path, key)?;
            (
                a.iter().map(|&x| f64::from(x)).collect(),
                a.shape().to_vec(),
            )
        }
    };
    if shape.len() != 2 || shape[1] != 3 {
        return Err(Error::format(
            path,
            key,
            "shape (K, 3): one point per histogram",
            format!("{shape:?}"),
        ));
    }
    let pts: Vec<[f64; 3]> = v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    if let Some(i) = pts.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::format(
            path,
            key,
            "finite coordinates",
            format!("{:?} at index {i}", pts[i]),
        ));
    }
    Ok(Some(pts))
}

/// Whether the archive is in the per-histogram paired form (module docs).
fn per_histogram(r: &mut NpzReader<File>, path: &Path) -> Result<bool> {
    let names = r
        .names()
        .map_err(|e| Error::format(path, "(archive)", "a NumPy .npz archive", e.to_string()))?;
    let has = |k: &str| names.iter().any(|n| n.trim_end_matches(".npy") == k);
    Ok(!has("laser_grid_xyz") && has("laser_xyz") && has("sensor_xyz"))
}

/// The geometry of a per-histogram paired archive whose `H` has shape `s` (module docs).
fn paired_geometry(r: &mut NpzReader<File>, path: &Path, s: &[usize]) -> Result<Geometry> {
    let need = |key: &str, p: Option<Vec<[f64; 3]>>| {
        p.ok_or_else(|| Error::format(path, key, "a (K, 3) array", "nothing"))
    };
    let lasers = need("laser_xyz", points(r, path, "laser_xyz")?)?;
    let spads = need("sensor_xyz", points(r, path, "sensor_xyz")?)?;
    if spads.len() != lasers.len() {
        return Err(Error::format(
            path,
            "sensor_xyz",
            format!(
                "one SPAD point per laser point (laser_xyz has {})",
                lasers.len()
            ),
            format!("{} points", spads.len()),
        ));
    }
    if s.len() != 2 || s[0] != lasers.len() {
        return Err(Error::format(
            path,
            "H",
            format!("shape ({}, Nt): one histogram per pair", lasers.len()),
            format!("{s:?}"),
        ));
    }
    let mut normals = [Vec::new(), Vec::new()];
    for (key, out) in ["laser_normals", "sensor_normals"]
        .into_iter()
        .zip(&mut normals)
    {
        if let Some(n) = points(r, path, key)? {
            if n.len() != lasers.len() {
                return Err(Error::format(
                    path,
                    key,
                    format!("{} normals, one per pair", lasers.len()),
                    n.len(),
                ));
            }
            if let Some(i) = n
                .iter()
                .position(|v| v.iter().map(|c| c * c).sum::<f64>() <= 0.0)
            {
                return Err(Error::format(
                    path,
                    key,
                    "normals of non-zero length",
                    format!("{:?} at index {i}", n[i]),
                ));
            }
            *out = n;
        }
    }
    let names = r
        .names()
        .map_err(|e| Error::format(path, "(archive)", "a NumPy .npz archive", e.to_string()))?;
    let has = |k: &str| names.iter().any(|n| n.trim_end_matches(".npy") == k);
    let origin = |r: &mut NpzReader<File>, key: &str| -> Result<[f64; 3]> {
        if has(key) {
            let o = xyz(r, path, key)?;
            if !o.iter().all(|c| c.is_finite()) {
                return Err(Error::format(
                    path,
                    key,
                    "finite coordinates",
                    format!("{o:?}"),
                ));
            }
            Ok(o)
        } else {
            Ok([0.0; 3])
        }
    };
    let legs_in_time = has("t_accounts_first_and_last_bounces")
        && scalar::<u8>(r, path, "t_accounts_first_and_last_bounces")? != 0;
    if legs_in_time && !(has("laser_origin") && has("sensor_origin")) {
        return Err(Error::format(
            path,
            "t_accounts_first_and_last_bounces",
            "laser_origin and sensor_origin (the device legs need the device positions)",
            "1 without them",
        ));
    }
    let f32s = |p: &[[f64; 3]]| -> Vec<vltm_kernel::Point> {
        p.iter()
            .map(|q| [q[0] as f32, q[1] as f32, q[2] as f32])
            .collect()
    };
    let k = lasers.len();
    let g = Geometry {
        lasers: f32s(&lasers),
        laser_shape: [k, 1],
        spads: f32s(&spads),
        spad_shape: [k, 1],
        laser_origin: origin(r, "laser_origin")?,
        sensor_origin: origin(r, "sensor_origin")?,
        legs_in_time,
        confocal: true,
        nt: s[1],
        dt: scalar::<f64>(r, path, "delta_t")?,
        t0: scalar::<f64>(r, path, "t_start")?,
        normals: Normals::from_lists(f32s(&normals[0]), f32s(&normals[1])),
    };
    g.validate(path)?;
    Ok(g)
}

/// The geometry of an archive whose `H` has shape `s` (checked against the grids), in
/// vltm's layout or the per-histogram paired form (module docs).
fn geometry(r: &mut NpzReader<File>, path: &Path, s: &[usize]) -> Result<Geometry> {
    if per_histogram(r, path)? {
        return paired_geometry(r, path, s);
    }
    let (lasers, laser_shape) = grid(r, path, "laser_grid_xyz")?;
    let (spads, spad_shape) = grid(r, path, "sensor_grid_xyz")?;
    let confocal = scalar::<u8>(r, path, "confocal")? != 0;
    let want: Vec<usize> = if confocal {
        vec![laser_shape[0], laser_shape[1]]
    } else {
        vec![laser_shape[0], laser_shape[1], spad_shape[0], spad_shape[1]]
    };
    if s.len() != want.len() + 1 || s[..want.len()] != want[..] {
        return Err(Error::format(
            path,
            "H",
            format!("shape {want:?} + (Nt,)"),
            format!("{s:?}"),
        ));
    }
    let g = Geometry {
        lasers,
        laser_shape,
        spads,
        spad_shape,
        laser_origin: xyz(r, path, "laser_xyz")?,
        sensor_origin: xyz(r, path, "sensor_xyz")?,
        legs_in_time: scalar::<u8>(r, path, "t_accounts_first_and_last_bounces")? != 0,
        confocal,
        nt: s[s.len() - 1],
        dt: scalar::<f64>(r, path, "delta_t")?,
        t0: scalar::<f64>(r, path, "t_start")?,
        normals: Normals::from_lists(
            grid_normals(r, path, "laser_grid_normals", laser_shape)?,
            grid_normals(r, path, "sensor_grid_normals", spad_shape)?,
        ),
    };
    g.validate(path)?;
    Ok(g)
}

/// An uncompressed `.npz` capture (`vltm simulate --uncompressed`, `numpy.savez`) read
/// **row by row** straight from the file: memory O(Ks·Nt) whatever the number of rows,
/// and no decoding of the whole `H` before the first row is processed.
///
/// Integrity: the archive's CRC-32 of `H` is checked as the rows are read. Rows read in order
/// (as every probe reads them) are hashed on the way, at no extra I/O; reading the last row
/// completes the check, and a mismatch is an error on that row, so no pass over the whole
/// capture ends with corrupted data unnoticed. A pass that skips around is checked by one
/// extra sequential read of the entry when its last row is requested.
#[derive(Debug)]
pub struct Stream {
    path: std::path::PathBuf,
    geometry: Geometry,
    file: File,
    /// Byte offset of `H[0, …]` in the file.
    start: u64,
    bytes: Vec<u8>,
    crc: Crc,
}

/// The CRC-32 check of the stored `H.npy` entry, computed as rows are read (see
/// [`Stream`]'s [`RowSource::read_row`]).
#[derive(Debug)]
struct Crc {
    /// The entry's first byte (its `.npy` header) and its length in the file.
    entry: (u64, u64),
    /// The CRC-32 the archive records for the entry.
    expected: u32,
    /// Running hash of the entry's bytes `entry.0 .. hashed_to`.
    hasher: crc32fast::Hasher,
    hashed_to: u64,
    /// Set once the whole entry matched.
    verified: bool,
}

/// Opens `path` as a [`Stream`] if its `H` is stored uncompressed as little-endian
/// C-order `f32` (`Ok(None)` otherwise: read it with [`read`]).
///
/// # Errors
/// [`Error::Io`], or [`Error::Format`] for a malformed archive, field or a truncated `H`.
pub fn open_stream(path: &Path) -> Result<Option<Stream>> {
    use std::io::{Read, Seek, SeekFrom};
    let io = |e: std::io::Error| Error::io(path, e);
    let bad = |what: &str, found: String| Error::format(path, "H", what.to_string(), found);
    let f = File::open(path).map_err(io)?;
    let mut z = zip::ZipArchive::new(f)
        .map_err(|e| Error::format(path, "(archive)", "a NumPy .npz archive", e.to_string()))?;
    let (data_start, len, crc32) = match z.by_name("H.npy") {
        Ok(e) if e.compression() == zip::CompressionMethod::Stored => {
            (e.data_start(), e.size(), e.crc32())
        }
        Ok(_) => return Ok(None),
        Err(e) => return Err(bad("an array H", e.to_string())),
    };
    let mut file = z.into_inner();
    file.seek(SeekFrom::Start(data_start)).map_err(io)?;
    let mut pre = [0u8; 12];
    file.read_exact(&mut pre).map_err(io)?;
    let (hlen, skip) = npy_prefix(&pre).map_err(|e| bad(".npy version 1-3", e))?;
    if hlen > MAX_NPY_HEADER {
        return Err(bad("a .npy header under 64 KiB", format!("{hlen} bytes")));
    }
    file.seek(SeekFrom::Start(data_start + skip)).map_err(io)?;
    let mut header = vec![0u8; hlen as usize];
    file.read_exact(&mut header).map_err(io)?;
    let header = String::from_utf8_lossy(&header).replace(' ', "");
    if !header.contains("'descr':'<f4'") || !header.contains("'fortran_order':False") {
        return Ok(None);
    }
    let shape = npy_shape(&header)
        .ok_or_else(|| bad("a shape tuple in the .npy header", header.clone()))?;
    let start = data_start + skip + hlen;
    let need = shape
        .iter()
        .try_fold(4u64, |a, &x| a.checked_mul(x as u64))
        .and_then(|b| b.checked_add(start));
    // Exactly the shape's bytes, as `read` (and NumPy) require: a truncated entry, or one
    // with bytes after its data, is refused by every command alike.
    if need != Some(data_start + len) {
        let have = (data_start + len).saturating_sub(start);
        let what = if need.is_some_and(|end| end < data_start + len) {
            "extra bytes after the data"
        } else {
            "truncated"
        };
        return Err(bad(
            &format!(
                "{} bytes of f32 data",
                need.map_or("more than 2^64".into(), |e| (e - start).to_string())
            ),
            format!("{have} bytes ({what})"),
        ));
    }
    check_members(path)?;
    let mut r = NpzReader::new(File::open(path).map_err(io)?)
        .map_err(|e| Error::format(path, "(archive)", "a NumPy .npz archive", e.to_string()))?;
    let geometry = geometry(&mut r, path, &shape)?;
    // Hash the entry's .npy header now; rows are hashed as they are read.
    let mut hasher = crc32fast::Hasher::new();
    let mut head = vec![
        0u8;
        usize::try_from(start - data_start)
            .map_err(|_| bad("a small header", String::new()))?
    ];
    file.seek(SeekFrom::Start(data_start)).map_err(io)?;
    file.read_exact(&mut head).map_err(io)?;
    hasher.update(&head);
    Ok(Some(Stream {
        path: path.to_path_buf(),
        geometry,
        file,
        start,
        bytes: Vec::new(),
        crc: Crc {
            entry: (data_start, len),
            expected: crc32,
            hasher,
            hashed_to: start,
            verified: false,
        },
    }))
}

impl Stream {
    /// Completes the CRC-32 check of `H` from `hashed_to` to the end of the entry.
    fn finish_crc(&mut self) -> Result<()> {
        use std::io::{Read, Seek, SeekFrom};
        let (first, len) = self.crc.entry;
        let end = first + len;
        let io = |e: std::io::Error| Error::io(&self.path, e);
        self.file
            .seek(SeekFrom::Start(self.crc.hashed_to))
            .map_err(io)?;
        let mut buf = vec![0u8; 1 << 20];
        let mut left = end.saturating_sub(self.crc.hashed_to);
        while left > 0 {
            let k = left.min(buf.len() as u64) as usize;
            self.file.read_exact(&mut buf[..k]).map_err(io)?;
            self.crc.hasher.update(&buf[..k]);
            left -= k as u64;
        }
        self.crc.hashed_to = end;
        let got = self.crc.hasher.clone().finalize();
        if got != self.crc.expected {
            return Err(Error::format(
                &self.path,
                "H",
                format!("CRC-32 {:08x} as the archive records", self.crc.expected),
                format!("{got:08x}: the file is corrupted"),
            ));
        }
        self.crc.verified = true;
        Ok(())
    }
}

impl RowSource for Stream {
    fn geometry(&self) -> &Geometry {
        &self.geometry
    }
    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<vltm_kernel::Point> {
        use std::io::{Read, Seek, SeekFrom};
        let g = &self.geometry;
        let n = g.spads_per_row() * g.nt;
        check_row(l, g.lasers.len())?;
        let x = g.lasers[l];
        self.bytes.resize(4 * n, 0);
        let offset = self.start + (4 * n * l) as u64;
        self.file
            .seek(SeekFrom::Start(offset))
            .and_then(|_| self.file.read_exact(&mut self.bytes))
            .map_err(|e| Error::io(&self.path, e))?;
        if !self.crc.verified {
            if self.crc.hashed_to == offset {
                self.crc.hasher.update(&self.bytes);
                self.crc.hashed_to += self.bytes.len() as u64;
            }
            if l + 1 == g.lasers.len() {
                self.finish_crc()?;
            }
        }
        out.clear();
        out.extend(
            self.bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        );
        Ok(x)
    }

    /// The rows of a batch by positional reads in parallel (one per row); the entry's
    /// CRC-32 is still checked, each row hashed on its own thread and the hashes combined in
    /// row order.
    #[cfg(unix)]
    fn read_rows(
        &mut self,
        first: usize,
        out: &mut [(vltm_kernel::Point, Vec<f32>)],
    ) -> Result<()> {
        use rayon::prelude::*;
        use std::os::unix::fs::FileExt;
        let g = &self.geometry;
        let n = g.spads_per_row() * g.nt;
        if out.is_empty() {
            return Ok(());
        }
        check_row(first, g.lasers.len())?;
        check_row(first + out.len() - 1, g.lasers.len())?;
        let hash = !self.crc.verified;
        let (file, path, start) = (&self.file, &self.path, self.start);
        let hashes = out
            .par_iter_mut()
            .enumerate()
            .map(|(i, (x, h))| {
                let l = first + i;
                // Straight into the row's buffer (kept from the batch before: no fill, no
                // copy), the stored little-endian bytes hashed as read.
                h.resize(n, 0.0);
                let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut h[..]);
                file.read_exact_at(bytes, start + (4 * n * l) as u64)
                    .map_err(|e| Error::io(path, e))?;
                let hs = hash.then(|| {
                    let mut hs = crc32fast::Hasher::new();
                    hs.update(bytes);
                    hs
                });
                if cfg!(target_endian = "big") {
                    h.iter_mut()
                        .for_each(|v| *v = f32::from_bits(v.to_bits().swap_bytes()));
                }
                *x = g.lasers[l];
                Ok(hs)
            })
            .collect::<Result<Vec<_>>>()?;
        if hash {
            if self.crc.hashed_to == start + (4 * n * first) as u64 {
                for hs in hashes.iter().flatten() {
                    self.crc.hasher.combine(hs);
                }
                self.crc.hashed_to += (4 * n * out.len()) as u64;
            }
            if first + out.len() == g.lasers.len() {
                self.finish_crc()?;
            }
        }
        Ok(())
    }

    #[cfg(unix)]
    fn reads_in_parallel(&self) -> bool {
        true
    }
}

/// Reads a `.npz` capture written by [`write()`] (or by numpy with the same keys).
///
/// # Errors
/// [`Error::Io`] if unreadable, [`Error::Format`] naming the key for a missing or
/// malformed field.
pub fn read(path: &Path) -> Result<Capture> {
    check_members(path)?;
    let f = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut r = NpzReader::new(f)
        .map_err(|e| Error::format(path, "(archive)", "a NumPy .npz archive", e.to_string()))?;
    let h = get::<f32>(&mut r, path, "H")?;
    let geometry = geometry(&mut r, path, h.shape())?;
    // A C-order array is already `[Kl][Ks][Nt]`: take its buffer (iterating an `IxDyn`
    // array element by element costs ~0.5 s per 50 M values).
    let data = if h.is_standard_layout() {
        match h.into_raw_vec_and_offset() {
            (v, None | Some(0)) => v,
            (v, Some(o)) => v[o..].to_vec(),
        }
    } else {
        h.iter().copied().collect()
    };
    Capture::new(geometry, data, path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::capture::RowSource;
    use std::path::PathBuf;

    fn fixture() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fixtures/two_patches.npz")
    }

    /// A per-histogram paired archive as numpy writes it (`np.savez(H=..., laser_xyz=...,
    /// sensor_xyz=..., ...)`), with `edit` applied to the arrays first.
    fn write_paired(p: &Path, edit: impl FnOnce(&mut Vec<(&'static str, ArrayD<f64>)>)) {
        let k = 5;
        let nt = 7;
        let pts = |dx: f64, dz: f64| {
            ArrayD::from_shape_fn(IxDyn(&[k, 3]), move |i| match i[1] {
                0 => 0.1 * i[0] as f64 + dx,
                1 => -0.05,
                _ => dz * (i[0] % 2) as f64,
            })
        };
        let mut arrays: Vec<(&'static str, ArrayD<f64>)> = vec![
            ("laser_xyz", pts(0.0, 0.03)),
            ("sensor_xyz", pts(0.02, -0.04)),
            (
                "laser_normals",
                ArrayD::from_shape_fn(IxDyn(&[k, 3]), |i| f64::from(u8::from(i[1] == 2))),
            ),
            ("delta_t", ndarray::arr0(0.01).into_dyn()),
            ("t_start", ndarray::arr0(0.5).into_dyn()),
        ];
        edit(&mut arrays);
        let mut w = NpzWriter::new(File::create(p).unwrap());
        let h = ArrayD::from_shape_fn(IxDyn(&[k, nt]), |i| (i[0] * 100 + i[1]) as f32);
        w.add_array("H", &h).unwrap();
        for (name, a) in &arrays {
            if name.starts_with("t_accounts") {
                w.add_array(*name, &a.mapv(|x| x as u8)).unwrap();
            } else {
                w.add_array(*name, a).unwrap();
            }
        }
        w.finish().unwrap();
    }

    /// The per-histogram paired form reads as a paired geometry (row `l` = pair `l`, its own
    /// laser and SPAD spot, on a relay surface that is not flat), in memory and streamed;
    /// vltm's own layout writes and reads it back unchanged.
    #[test]
    fn paired_per_histogram_form() {
        let dir = std::env::temp_dir().join(format!("vltm-paired-npz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("paired.npz");
        write_paired(&p, |_| {});
        let c = read(&p).unwrap();
        let g = &c.geometry;
        assert!(g.confocal && g.paired_apart());
        assert_eq!((g.lasers.len(), g.spads.len(), g.nt), (5, 5, 7));
        assert_eq!(g.lasers[3], [0.3, -0.05, 0.03]);
        assert_eq!(g.spads[3], [0.32, -0.05, -0.04]);
        assert_eq!((g.dt, g.t0, g.legs_in_time), (0.01, 0.5, false));
        assert_eq!(c.row(3), &[300.0, 301.0, 302.0, 303.0, 304.0, 305.0, 306.0]);
        let mut s = open_stream(&p).unwrap().expect("stored H streams");
        let mut row = Vec::new();
        assert_eq!(s.read_row(3, &mut row).unwrap(), g.lasers[3]);
        assert_eq!(row, c.row(3));
        // vltm's layout: confocal = 1 with two different grids of one shape.
        let q = dir.join("vltm.npz");
        write(&c, &q).unwrap();
        assert_eq!(read(&q).unwrap(), c);
        let _ = std::fs::remove_dir_all(dir);
    }

    /// Per-pair normals (`laser_normals`, `sensor_normals`) that are not all +z are kept per
    /// point in the geometry (all-+z ones are the flat default), and vltm's layout writes them
    /// as `laser_grid_normals` / `sensor_grid_normals` and reads them back unchanged; a NaN
    /// normal is a one-line error naming its key.
    #[test]
    fn paired_normals_are_kept_and_written() {
        let dir = std::env::temp_dir().join(format!("vltm-paired-nrm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("paired.npz");
        let tilt = |a: f64| {
            ArrayD::from_shape_fn(IxDyn(&[5, 3]), move |i| match i[1] {
                0 => a * i[0] as f64,
                1 => 0.0,
                _ => 1.0,
            })
        };
        write_paired(&p, |a| {
            a.retain(|(n, _)| *n != "laser_normals");
            a.push(("laser_normals", tilt(0.1)));
            a.push(("sensor_normals", tilt(-0.2)));
        });
        let c = read(&p).unwrap();
        let g = &c.geometry;
        assert_eq!(g.normals.lasers[3], [0.3f32, 0.0, 1.0]);
        assert_eq!(g.normals.spads[3], [-0.6f32, 0.0, 1.0]);
        assert!(g.not_flat().is_some());
        let q = dir.join("vltm.npz");
        write(&c, &q).unwrap();
        assert_eq!(read(&q).unwrap(), c);
        // The layout without normals (+z) reads back with none, as before.
        write_paired(&p, |_| {});
        assert!(read(&p).unwrap().geometry.normals.flat());
        write_paired(&p, |a| {
            a.retain(|(n, _)| *n != "laser_normals");
            let mut t = tilt(0.1);
            t[&[1usize, 2][..]] = f64::NAN;
            a.push(("sensor_normals", t));
        });
        let e = read(&p).unwrap_err().to_string();
        assert!(e.contains("sensor_normals") && !e.contains('\n'), "{e}");
        let _ = std::fs::remove_dir_all(dir);
    }

    /// Bad paired input: one line naming the key, for lists of different lengths, NaN points,
    /// zero-length normals, an H that does not hold one histogram per pair, and legs in time
    /// without device positions.
    #[test]
    fn paired_bad_input_names_the_key() {
        let dir = std::env::temp_dir().join(format!("vltm-paired-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let set = |a: &mut Vec<(&'static str, ArrayD<f64>)>, k: &'static str, v: ArrayD<f64>| {
            a.retain(|(n, _)| *n != k);
            a.push((k, v));
        };
        type Edit = Box<dyn Fn(&mut Vec<(&'static str, ArrayD<f64>)>)>;
        let cases: Vec<(&str, Edit, &str)> = vec![
            (
                "lengths",
                Box::new(move |a| set(a, "sensor_xyz", ArrayD::zeros(IxDyn(&[4, 3])))),
                "sensor_xyz",
            ),
            (
                "nan",
                Box::new(move |a| {
                    let mut l = a.iter().find(|(n, _)| *n == "laser_xyz").unwrap().1.clone();
                    l[&[2usize, 1][..]] = f64::NAN;
                    set(a, "laser_xyz", l);
                }),
                "laser_xyz",
            ),
            (
                "normal",
                Box::new(move |a| set(a, "laser_normals", ArrayD::zeros(IxDyn(&[5, 3])))),
                "laser_normals",
            ),
            (
                "shape",
                Box::new(move |a| set(a, "laser_xyz", ArrayD::zeros(IxDyn(&[5, 2])))),
                "laser_xyz",
            ),
            (
                "legs",
                Box::new(move |a| {
                    set(
                        a,
                        "t_accounts_first_and_last_bounces",
                        ndarray::arr0(1.0).into_dyn(),
                    );
                }),
                "t_accounts_first_and_last_bounces",
            ),
        ];
        for (name, edit, key) in cases {
            let p = dir.join(format!("{name}.npz"));
            write_paired(&p, |a| edit(a));
            let e = read(&p).unwrap_err();
            let msg = e.to_string();
            assert!(
                matches!(&e, Error::Format { field, .. } if field == key),
                "{name}: {msg}"
            );
            assert!(!msg.contains('\n'), "{name}: {msg}");
        }
        let _ = std::fs::remove_dir_all(dir);
    }

    /// An uncompressed archive streams the same rows as the in-memory reader; a compressed
    /// one is not streamed; a truncated one is rejected by name.
    #[test]
    fn npz_stream_equals_read() {
        let c = read(&fixture()).unwrap();
        assert!(open_stream(&fixture()).unwrap().is_none(), "compressed");
        let dir = std::env::temp_dir().join(format!("vltm-stream-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("c.npz");
        write_with(&c, &p, false).unwrap();
        let mut s = open_stream(&p).unwrap().expect("stored H streams");
        assert_eq!(s.geometry(), &c.geometry);
        let mut row = Vec::new();
        for l in [0, 17, c.geometry.lasers.len() - 1] {
            let x = s.read_row(l, &mut row).unwrap();
            assert_eq!(x, c.geometry.lasers[l]);
            assert_eq!(row.as_slice(), c.row(l));
        }
        assert!(s.read_row(c.geometry.lasers.len(), &mut row).is_err());
        // Cut the file inside H: the archive or H is reported, never a short row.
        let bytes = std::fs::read(&p).unwrap();
        let t = dir.join("t.npz");
        std::fs::write(&t, &bytes[..bytes.len() / 2]).unwrap();
        let e = open_stream(&t).and_then(|s| s.ok_or(crate::Error::arg("x", "none")));
        assert!(e.is_err(), "truncated archive accepted");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A flipped byte inside the stored `H` is caught by the CRC-32, whether the rows are read
    /// in order or skipping around; the intact file passes both ways, and a second pass too.
    #[test]
    fn streamed_rows_are_crc_checked() {
        let c = read(&fixture()).unwrap();
        let dir = std::env::temp_dir().join(format!("vltm-crc-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("c.npz");
        write_with(&c, &p, false).unwrap();
        let kl = c.geometry.lasers.len();
        let pass = |path: &Path, order: &[usize]| -> Result<()> {
            let mut s = open_stream(path)?.expect("stored");
            let mut row = Vec::new();
            for &l in order {
                s.read_row(l, &mut row)?;
            }
            Ok(())
        };
        let in_order: Vec<usize> = (0..kl).chain(0..kl).collect();
        let skipping: Vec<usize> = (0..kl).rev().collect();
        pass(&p, &in_order).unwrap();
        pass(&p, &skipping).unwrap();
        let mut bytes = std::fs::read(&p).unwrap();
        // A byte in the middle of H (H is the first and by far the largest member).
        let at = bytes.len() / 3;
        bytes[at] ^= 0x40;
        let bad = dir.join("bad.npz");
        std::fs::write(&bad, &bytes).unwrap();
        for order in [&in_order, &skipping] {
            let e = pass(&bad, order).unwrap_err().to_string();
            assert!(e.contains("CRC-32") && e.contains("bad.npz"), "{e}");
        }
        // In batches (parallel positional reads): the same rows; the flipped byte caught.
        let batches = |path: &Path, batch: usize| -> Result<Vec<f32>> {
            let mut s = open_stream(path)?.expect("stored");
            let mut all = Vec::new();
            let mut rows: Vec<(vltm_kernel::Point, Vec<f32>)> = Vec::new();
            for start in (0..kl).step_by(batch) {
                rows.resize_with((start + batch).min(kl) - start, || ([0.0; 3], Vec::new()));
                s.read_rows(start, &mut rows)?;
                for (i, (x, h)) in rows.iter().enumerate() {
                    assert_eq!(*x, c.geometry.lasers[start + i]);
                    all.extend_from_slice(h);
                }
            }
            Ok(all)
        };
        for batch in [1, 3, 8, kl] {
            assert_eq!(batches(&p, batch).unwrap(), c.data, "batch {batch}");
            let e = batches(&bad, batch).unwrap_err().to_string();
            assert!(e.contains("CRC-32") && e.contains("bad.npz"), "{e}");
        }
        let mut s = open_stream(&p).unwrap().expect("stored");
        let mut two = vec![([0.0; 3], Vec::new()); 2];
        assert!(s.read_rows(kl - 1, &mut two).is_err(), "a row past the end");
        std::fs::remove_dir_all(&dir).ok();
    }
}
