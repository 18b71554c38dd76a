//! Reading `.npz` captures: the members checked before anything is decoded, the geometry
//! (grids or per-histogram points, normals, device positions), the whole capture in memory.

use crate::budget;
use crate::error::{Error, Result};
use crate::io::capture::{Capture, Geometry, Normals};
use ndarray::{ArrayD, IxDyn};
use ndarray_npy::{NpzReader, ReadableElement};
use std::fs::File;
use std::path::Path;

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
pub(super) const MAX_NPY_HEADER: u64 = 1 << 16;

/// The header length and the offset of the header text from the 12 first bytes of a `.npy`
/// member (magic already checked or not: a wrong version is an error).
pub(super) fn npy_prefix(pre: &[u8; 12]) -> std::result::Result<(u64, u64), String> {
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
pub(super) fn npy_shape(header: &str) -> Option<Vec<usize>> {
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
pub(super) fn check_members(path: &Path) -> Result<()> {
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
pub(super) fn geometry(r: &mut NpzReader<File>, path: &Path, s: &[usize]) -> Result<Geometry> {
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

/// Reads a `.npz` capture written by [`write`](fn@super::write) (or by numpy with the same keys).
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
