//! MATLAB captures: MAT v5 files (zlib-compressed elements included, [`v5`]) and MAT v7.3
//! files (HDF5 underneath, [`v73`]), and the capture layouts vltm recognises in them.
//!
//! No crate is used for the format: `matfile` (0.5) reads numeric arrays only (no structs,
//! which the phasor-field layout needs) and decodes every variable whole; [`v5`] is a small
//! parser of the published format (MathWorks, *MAT-File Format*) that reads the headers of
//! all variables first (inflating only the first bytes of each compressed element), so that
//! an unknown layout is reported without decoding anything, and [`flate2`] inflates.
//!
//! # Layouts
//!
//! | layout | variables | capture |
//! |---|---|---|
//! | **Stanford confocal** (O'Toole et al. 2018, `cnlos_reconstruction.m`) | `rect_data` (N₁, N₂, T), any numeric class; `width` (scalar, m) | confocal, N₁×N₂ wall points |
//! | **phasor field** (Liu et al. 2019; y-tal `MAT_PHASOR_FIELDS`) | struct `dataset` with `data` (T, 1, L), `laserPos` (L×3 or 3×L), `cameraPos` (3), `laserOrigin`, `cameraOrigin` (3), `deltat`, `t0` (m) | L laser spots × one SPAD |
//!
//! Anything else is an [`Error::Format`] on `(layout)` listing the variables found (name,
//! dims, class).
//!
//! **Stanford conventions**, none of which the file records (`fixtures/real/README.md`,
//! from the authors' script), applied by default and each overridable ([`MatOptions`]):
//!
//! * bins of 4 ps: Δt = 4e-12 s · c = 1.19917 mm of path (`--delta-t`);
//! * t = 0 at the wall: the data are pre-rectified, bin 0 is light leaving the wall point and
//!   the laser and detector legs are excluded (`t0 = 0`, [`Geometry::legs_in_time`] false;
//!   `--t-start`);
//! * the confocal grid spans `[-width, width]²` (`--grid-width` sets the half-width): point
//!   `(i, j)` of `rect_data(i, j, :)` is at `x = -w + 2w·i/(N₁−1)`, `y = +w − 2w·j/(N₂−1)`
//!   (the second index runs **down**). Laser row `l = i·N₂ + j` (C order over `[N₁, N₂]`).
//!   The authors' script displays i across (increasing to the left) and j down;
//!   the exit sign's letters read upright and unmirrored in that display, i.e. as seen from the
//!   wall. With `y` down the second index, `(x, y, z)` is right-handed with y up and z into the
//!   hidden scene, and vltm's figures, drawn as seen from the wall (x increasing to the left,
//!   y up; `out::figure`), show the sign upright and reading EXIT; with `y = +2nd index` it
//!   was turned by 180°, a mirror image of the lab (docs/real-data.md, `tests/real.rs`);
//! * the device positions are not recorded; [`DEFAULT_LASER_ORIGIN`] is used, which
//!   only matters for `--compensate-laser` (the legs are not in the time axis).
//!
//! **Phasor-field conventions** follow y-tal's converter (`tal/io/format.py`): the file's
//! one camera and many laser positions are kept as they are (no swap needed: vltm's rows are
//! lasers), the time axis includes the device legs, `deltat` and `t0` are metres of path.
//!
//! # Memory
//!
//! A v5 variable is one zlib stream in MATLAB's column-major order, time slowest for
//! `rect_data`: no laser row is complete before the whole variable is inflated, so the
//! capture is read whole before the probes start. The reading itself is overlapped: a
//! background thread inflates and decodes `rect_data` 16 time samples at a time
//! ([`Mat5::stream_f32`], a queue of two chunks) while this thread transposes the samples
//! already decoded into the capture's rows (a blocked transpose, one cache line of a row per
//! wall point). Peak: the capture as f32 (4·N₁N₂T bytes, 33.6 MB for the 64×64×2048
//! captures) plus four chunks of 16·N₁N₂ values (about 1 MB), instead of the raw bytes, all
//! values and the capture at once. Measured on the Stanford captures (docs/performance.md, *Reading the `.mat`*):
//! reading was 42 % of the CPU time of a `vltm direct`; the overlap cut the peak resident
//! set by 12 MB (`direct`) and 30 MB (`info`). Every allocation is checked against
//! [`budget::check`] before it is made. v7.3 files and the phasor-field layout are read
//! whole (raw bytes, values, capture).

pub mod v5;
pub mod v73;

use crate::aperture::{DEFAULT_LASER_ORIGIN, DEFAULT_SENSOR_ORIGIN};
use crate::budget;
use crate::error::{Error, Result};
use crate::io::capture::{Capture, Geometry};
use std::path::Path;
use v5::{Class, Mat5, Value, Var};
use v73::Mat73;

/// The speed of light (m/s).
pub const C: f64 = 299_792_458.0;
/// The Stanford captures' bin width: 4 ps of path (m).
pub const STANFORD_DT: f64 = 4e-12 * C;

/// Overrides of conventions a file does not record.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MatOptions {
    /// Bin width in metres of path (`--delta-t`).
    pub delta_t: Option<f64>,
    /// Path length of bin 0 in metres (`--t-start`).
    pub t_start: Option<f64>,
    /// Half-width `w` of the confocal grid `[-w, w]²` in metres (`--grid-width`).
    pub grid_width: Option<f64>,
}

impl MatOptions {
    /// Refuses the overrides for a capture that is not a `.mat` file (other formats record
    /// their time axis and grid).
    ///
    /// # Errors
    /// [`Error::Argument`] naming the first override given (`delta_t`, `t_start`,
    /// `grid_width`).
    pub fn refuse(&self) -> Result<()> {
        for (set, arg) in [
            (self.delta_t.is_some(), "delta_t"),
            (self.t_start.is_some(), "t_start"),
            (self.grid_width.is_some(), "grid_width"),
        ] {
            if set {
                return Err(Error::arg(
                    arg,
                    "only for .mat captures (other formats record their time axis and grid)",
                ));
            }
        }
        Ok(())
    }
}

/// A layout vltm knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// `rect_data` + `width`.
    StanfordConfocal,
    /// struct `dataset`.
    PhasorField,
}

/// A capture read from a `.mat` file, with what was assumed.
#[derive(Debug)]
pub struct MatCapture {
    /// The capture.
    pub capture: Capture,
    /// The layout found.
    pub layout: Layout,
    /// `MAT v5` or `MAT v7.3 (HDF5)`.
    pub version: &'static str,
    /// The variables of the file (`name dims class`).
    pub variables: Vec<String>,
    /// One line per convention: its value and where it came from (file, default, option).
    pub conventions: Vec<String>,
}

/// The variables of a `.mat` file, either version.
enum File {
    V5(Mat5),
    V73(Mat73),
}

impl File {
    fn open(path: &Path) -> Result<Self> {
        let mut head = [0u8; 128];
        let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let n = std::io::Read::read(&mut f, &mut head).map_err(|e| Error::io(path, e))?;
        let text = String::from_utf8_lossy(&head[..n.min(20)]).into_owned();
        if text.starts_with("MATLAB 7.3") || head.starts_with(b"\x89HDF") {
            Ok(Self::V73(Mat73::open(path)?))
        } else if v5::is_v5(&head[..n]) {
            Ok(Self::V5(Mat5::open(path)?))
        } else {
            Err(Error::format(
                path,
                "(header)",
                "a MATLAB MAT-file (v5, v7 or v7.3)",
                if n < 128 {
                    format!("{n} bytes (truncated)")
                } else {
                    "another kind of file".into()
                },
            ))
        }
    }

    fn version(&self) -> &'static str {
        match self {
            Self::V5(_) => "MAT v5",
            Self::V73(_) => "MAT v7.3 (HDF5)",
        }
    }

    fn headers(&self) -> Result<Vec<Var>> {
        match self {
            Self::V5(m) => Ok(m.entries.iter().map(|e| e.header.clone()).collect()),
            Self::V73(m) => m.names.iter().map(|(n, _)| m.header(n)).collect(),
        }
    }

    fn read(&self, name: &str) -> Result<Var> {
        match self {
            Self::V5(m) => m.read(name),
            Self::V73(m) => m.read(name),
        }
    }
}

/// The variables of a `.mat` file as `name dims class`, headers only.
///
/// # Errors
/// As [`read`].
pub fn variables(path: &Path) -> Result<Vec<String>> {
    Ok(File::open(path)?
        .headers()?
        .iter()
        .map(Var::describe)
        .collect())
}

/// Reads a `.mat` capture of a known layout.
///
/// # Errors
/// [`Error::Format`] naming the file and the variable: an unknown layout (listing the
/// variables), wrong dimensions, non-numeric data, a truncated or corrupt stream;
/// [`Error::Memory`] over the budget; [`Error::Io`].
pub fn read(path: &Path, opts: &MatOptions) -> Result<MatCapture> {
    let file = File::open(path)?;
    let headers = file.headers()?;
    let variables: Vec<String> = headers.iter().map(Var::describe).collect();
    let has = |n: &str| headers.iter().any(|v| v.name == n);
    let (capture, layout, conventions) = if has("rect_data") && has("width") {
        let (c, conv) = stanford(path, &file, opts)?;
        (c, Layout::StanfordConfocal, conv)
    } else if has("dataset") {
        let (c, conv) = phasor_field(path, &file, opts)?;
        (c, Layout::PhasorField, conv)
    } else {
        return Err(Error::format(
            path,
            "(layout)",
            "a known .mat layout: rect_data + width (Stanford confocal) or struct dataset (phasor field)",
            format!(
                "variables: {}",
                if variables.is_empty() {
                    "none".to_string()
                } else {
                    variables.join(", ")
                }
            ),
        ));
    };
    Ok(MatCapture {
        capture,
        layout,
        version: file.version(),
        variables,
        conventions,
    })
}

/// Numeric values of a variable as f64 (small variables).
fn numbers(path: &Path, v: &Var) -> Result<Vec<f64>> {
    match &v.value {
        Value::F64(x) => Ok(x.clone()),
        Value::F32(x) => Ok(x.iter().map(|&a| f64::from(a)).collect()),
        _ => Err(non_numeric(path, v)),
    }
}

fn non_numeric(path: &Path, v: &Var) -> Error {
    Error::format(
        path,
        &v.name,
        "numeric values",
        format!("a {} array", v.class.name()),
    )
}

fn scalar(path: &Path, v: &Var, what: &str) -> Result<f64> {
    match numbers(path, v)?[..] {
        [x] if x.is_finite() => Ok(x),
        [x] => Err(Error::format(path, what, "a finite scalar", x)),
        _ => Err(Error::format(
            path,
            what,
            "a scalar",
            format!("dims {:?}", v.dims),
        )),
    }
}

/// A convention line: `name value (source)`.
fn conv(name: &str, value: String, source: &str) -> String {
    format!("{name:<12} {value} ({source})")
}

fn stanford(path: &Path, file: &File, o: &MatOptions) -> Result<(Capture, Vec<String>)> {
    let wv = file.read("width")?;
    let width = scalar(path, &wv, "width")?;
    let (w, w_src) = match o.grid_width {
        Some(g) => (g, "set by $grid_width"),
        None => (width, "the file's `width`"),
    };
    if !(w.is_finite() && w >= 0.0) {
        return Err(Error::format(path, "width", "a half-width >= 0 m", w));
    }
    // v5: the header now, the values streamed below; v7.3: read whole.
    let data = match file {
        File::V5(m) => m
            .header("rect_data")
            .cloned()
            .ok_or_else(|| Error::format(path, "rect_data", "a variable", "none"))?,
        File::V73(m) => m.read("rect_data")?,
    };
    let [n1, n2, nt] = match data.dims[..] {
        [a, b, t] if a > 0 && b > 0 && t > 0 => [a, b, t],
        [a, b] if a > 0 && b > 0 => [a, b, 1],
        _ => {
            return Err(Error::format(
                path,
                "rect_data",
                "dims (N1, N2, T) with no zero",
                format!("{:?}", data.dims),
            ));
        }
    };
    if !matches!(data.class, Class::Numeric(_)) {
        return Err(non_numeric(path, &data));
    }
    let (dt, dt_src) = match o.delta_t {
        Some(d) => (d, "set by $delta_t"),
        None => (STANFORD_DT, "assumed: 4 ps bins, the authors' convention"),
    };
    let (t0, t0_src) = match o.t_start {
        Some(t) => (t, "set by $t_start"),
        None => (0.0, "assumed: t = 0 at the wall, pre-rectified data"),
    };
    let kl = n1 * n2;
    let p = path.display().to_string();
    budget::check(
        || format!("{p}: the capture of rect_data"),
        budget::bytes(kl, 4).saturating_mul(nt as u128),
    )?;
    let coord = |k: usize, n: usize| {
        if n > 1 {
            -w + 2.0 * w * k as f64 / (n - 1) as f64
        } else {
            0.0
        }
    };
    let lasers: Vec<_> = (0..n1)
        .flat_map(|i| (0..n2).map(move |j| [coord(i, n1) as f32, -coord(j, n2) as f32, 0.0]))
        .collect();
    let geometry = Geometry {
        spads: lasers.clone(),
        lasers,
        laser_shape: [n1, n2],
        spad_shape: [n1, n2],
        laser_origin: DEFAULT_LASER_ORIGIN,
        sensor_origin: DEFAULT_SENSOR_ORIGIN,
        legs_in_time: false,
        confocal: true,
        nt,
        dt,
        t0,
        normals: Default::default(),
    };
    // rect_data(i, j, t) is at i + n1·(j + n2·t); the capture wants [(i·n2 + j)·nt + t].
    let mut h = vec![0.0f32; kl * nt];
    // A blocked transpose: 16 time samples (one cache line of the output row) per wall point,
    // the wall points in file order, so that reads and writes both stream. `v` holds time
    // samples `t0..` (all of them, or a chunk of whole samples).
    const TB: usize = 16;
    fn gather<T: Copy>(
        v: &[T],
        t0: usize,
        h: &mut [f32],
        [n1, n2, nt]: [usize; 3],
        f: impl Fn(T) -> f32,
    ) {
        let kl = n1 * n2;
        let end = (t0 + v.len() / kl.max(1)).min(nt);
        for b0 in (t0..end).step_by(TB) {
            let b1 = (b0 + TB).min(end);
            for j in 0..n2 {
                for i in 0..n1 {
                    let row = (i * n2 + j) * nt;
                    let src = i + n1 * j;
                    for (t, x) in h[row + b0..row + b1].iter_mut().enumerate() {
                        *x = f(v[src + kl * (b0 - t0 + t)]);
                    }
                }
            }
        }
    }
    match (&data.value, file) {
        (Value::F32(v), _) => gather(v, 0, &mut h, [n1, n2, nt], |x| x),
        (Value::F64(v), _) => gather(v, 0, &mut h, [n1, n2, nt], |x| x as f32),
        (Value::Skipped, File::V5(m)) => {
            // Inflated and decoded by a background thread, TB time samples at a time, while
            // this one transposes the samples already decoded (module docs, *Memory*).
            let rx = m.stream_f32("rect_data", TB * kl)?;
            let mut t0 = 0;
            for chunk in rx {
                let chunk = chunk?;
                if chunk.len() % kl != 0 || t0 + chunk.len() / kl > nt {
                    break;
                }
                gather(&chunk, t0, &mut h, [n1, n2, nt], |x| x);
                t0 += chunk.len() / kl;
            }
            if t0 != nt {
                return Err(Error::format(
                    path,
                    "rect_data",
                    format!("{} values", kl * nt),
                    format!("{} (the stream ended early)", t0 * kl),
                ));
            }
        }
        _ => return Err(non_numeric(path, &data)),
    }
    drop(data);
    let capture = Capture::new(geometry, h, path)?;
    let conventions = vec![
        conv(
            "layout",
            "Stanford confocal (rect_data + width)".into(),
            "recognised",
        ),
        conv(
            "grid",
            format!(
                "{n1}x{n2} confocal points over [-{w}, {w}]^2 m, x = 1st index (-w to w), y = 2nd (w down to -w)"
            ),
            w_src,
        ),
        conv("delta_t", format!("{dt} m of path"), dt_src),
        conv("t_start", format!("{t0} m"), t0_src),
        conv(
            "legs",
            "not in the time axis (wall to wall)".into(),
            "assumed: pre-rectified data",
        ),
        conv(
            "devices",
            format!("{DEFAULT_LASER_ORIGIN:?} m"),
            "not recorded: vltm's default, used only by $compensate_laser",
        ),
    ];
    Ok((capture, conventions))
}

fn phasor_field(path: &Path, file: &File, o: &MatOptions) -> Result<(Capture, Vec<String>)> {
    let ds = file.read("dataset")?;
    if ds.class != Class::Struct {
        return Err(Error::format(
            path,
            "dataset",
            "a struct (phasor-field layout)",
            format!("a {} array", ds.class.name()),
        ));
    }
    let field = |n: &str| {
        ds.field(n).ok_or_else(|| {
            Error::format(
                path,
                &format!("dataset.{n}"),
                "a field of this name (phasor-field layout)",
                "none",
            )
        })
    };
    let xyz = |n: &str| -> Result<[f64; 3]> {
        let v = numbers(path, field(n)?)?;
        <[f64; 3]>::try_from(v.as_slice())
            .ok()
            .filter(|p| p.iter().all(|c| c.is_finite()))
            .ok_or_else(|| {
                Error::format(
                    path,
                    &format!("dataset.{n}"),
                    "3 finite coordinates",
                    format!("{v:?}"),
                )
            })
    };
    let data = field("data")?;
    let (nt, nl) = match data.dims[..] {
        [t, 1, l] | [t, l] if t > 0 && l > 0 => (t, l),
        _ => {
            return Err(Error::format(
                path,
                "dataset.data",
                "dims (T, 1, L)",
                format!("{:?}", data.dims),
            ));
        }
    };
    let lp = field("laserPos")?;
    let lv = numbers(path, lp)?;
    let lasers: Vec<[f32; 3]> = match lp.dims[..] {
        // Column-major: a 3×L array holds each point's coordinates together.
        [3, l] if l == nl => lv
            .chunks_exact(3)
            .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
            .collect(),
        [l, 3] if l == nl => (0..nl)
            .map(|k| [lv[k] as f32, lv[k + nl] as f32, lv[k + 2 * nl] as f32])
            .collect(),
        _ => {
            return Err(Error::format(
                path,
                "dataset.laserPos",
                format!("dims ({nl}, 3) or (3, {nl}) to match data"),
                format!("{:?}", lp.dims),
            ));
        }
    };
    let cam = xyz("cameraPos")?;
    let laser_origin = xyz("laserOrigin")?;
    let sensor_origin = xyz("cameraOrigin")?;
    let (dt, dt_src) = match o.delta_t {
        Some(d) => (d, "set by $delta_t"),
        None => (
            scalar(path, field("deltat")?, "dataset.deltat")?,
            "the file's deltat",
        ),
    };
    let (t0, t0_src) = match o.t_start {
        Some(t) => (t, "set by $t_start"),
        None => (scalar(path, field("t0")?, "dataset.t0")?, "the file's t0"),
    };
    if o.grid_width.is_some() {
        return Err(Error::arg(
            "grid_width",
            "only for the Stanford confocal layout (this file stores its positions)",
        ));
    }
    let h: Vec<f32> = match &data.value {
        // data(t, 1, l) at t + nt·l: already laser-major.
        Value::F32(v) => v.clone(),
        Value::F64(v) => v.iter().map(|&x| x as f32).collect(),
        _ => return Err(non_numeric(path, data)),
    };
    let geometry = Geometry {
        lasers,
        laser_shape: [nl, 1],
        spads: vec![[cam[0] as f32, cam[1] as f32, cam[2] as f32]],
        spad_shape: [1, 1],
        laser_origin,
        sensor_origin,
        legs_in_time: true,
        confocal: false,
        nt,
        dt,
        t0,
        normals: Default::default(),
    };
    let capture = Capture::new(geometry, h, path)?;
    let conventions = vec![
        conv(
            "layout",
            "phasor field (struct dataset)".into(),
            "recognised",
        ),
        conv(
            "grid",
            format!("{nl} laser spots x 1 SPAD at {cam:?} m"),
            "the file's laserPos, cameraPos",
        ),
        conv("delta_t", format!("{dt} m of path"), dt_src),
        conv("t_start", format!("{t0} m"), t0_src),
        conv(
            "legs",
            "in the time axis".into(),
            "y-tal's MAT_PHASOR_FIELDS convention",
        ),
        conv(
            "devices",
            format!("laser {laser_origin:?}, camera {sensor_origin:?} m"),
            "the file's laserOrigin, cameraOrigin",
        ),
    ];
    Ok((capture, conventions))
}

#[cfg(test)]
mod tests;
