//! The capture model: geometry, time axis and row access.
//!
//! A capture holds `H[l][s][n]`: laser spot `l`, SPAD spot `s`, time bin `n` at path length
//! `t0 + n·Δt` (metres, the point-sample convention). The kernel is fed one
//! laser row at a time through [`RowSource`].

use crate::error::{Error, Result};
use vltm_kernel::Point;

/// Where the lasers and SPADs are and how the time axis is defined.
#[derive(Clone, Debug, PartialEq)]
pub struct Geometry {
    /// Laser spots on the wall (z = 0), C order over `laser_shape`.
    pub lasers: Vec<Point>,
    /// Grid shape of the laser spots `[nx, ny]` (`[K, 1]` for a list).
    pub laser_shape: [usize; 2],
    /// SPAD spots on the wall, C order over `spad_shape`.
    pub spads: Vec<Point>,
    /// Grid shape of the SPAD spots `[nx, ny]` (`[16, 1]` for a 1-D array, `[1, 1]` single).
    pub spad_shape: [usize; 2],
    /// Position of the laser device (y-tal `laser_xyz`) (m).
    pub laser_origin: [f64; 3],
    /// Position of the sensor device (y-tal `sensor_xyz`) (m).
    pub sensor_origin: [f64; 3],
    /// Whether the time axis includes the device legs (y-tal
    /// `t_accounts_first_and_last_bounces`).
    pub legs_in_time: bool,
    /// One histogram per row (a **paired** scan, y-tal's `is_laser_paired_to_sensor()`): row
    /// `l` holds one histogram, for the laser spot `lasers[l]` and the SPAD spot `spads[l]`
    /// (the two lists have the same length). A **confocal** capture is the paired scan whose
    /// points coincide (`spads == lasers`, [`Geometry::coincident`]); a galvo-scanned
    /// non-confocal or "arbitrary scanning" capture has them apart, on a relay surface that
    /// need not be flat. (The field keeps its historical name: every paired scan, confocal
    /// or not, sets it.)
    pub confocal: bool,
    /// Bins per histogram.
    pub nt: usize,
    /// Bin width (m of path).
    pub dt: f64,
    /// Path length of bin 0 (m).
    pub t0: f64,
    /// Relay-surface normals at the laser and SPAD spots ([`Normals`]; empty lists: the flat
    /// wall's +z at every spot, the convention of formats that carry none).
    pub normals: Normals,
}

/// Relay-surface normals at the spots of a [`Geometry`]: directions of any non-zero length
/// ([`Geometry::laser_normal`] normalises), pointing toward the hidden scene (+z on the
/// wall z = 0). An empty list means +z at every spot of that list (formats
/// without normals, and every file whose normals are all +z); otherwise one normal per spot,
/// in the order of [`Geometry::lasers`] / [`Geometry::spads`]. Only the sign-free direction
/// enters vltm's cosines (`|v·n|`), so a file whose normals point away from the scene reads
/// the same.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Normals {
    /// One normal per laser spot, or empty (+z).
    pub lasers: Vec<Point>,
    /// One normal per SPAD spot, or empty (+z).
    pub spads: Vec<Point>,
}

/// The flat wall's normal, +z (toward the hidden scene).
pub const WALL_NORMAL: [f64; 3] = [0.0, 0.0, 1.0];

impl Normals {
    /// Normals read from a file: kept only where some normal is not +z (to within 1e-6 of
    /// the unit vector after normalising), so that a file of +z normals is the flat default.
    pub fn from_lists(lasers: Vec<Point>, spads: Vec<Point>) -> Self {
        let keep = |v: Vec<Point>| {
            let flat = v.iter().all(|n| {
                let u = unit(n);
                u.is_some_and(|u| (u[2].abs() - 1.0).abs() < 1e-6)
            });
            if flat { Vec::new() } else { v }
        };
        Self {
            lasers: keep(lasers),
            spads: keep(spads),
        }
    }

    /// Whether every normal is +z (both lists empty).
    pub fn flat(&self) -> bool {
        self.lasers.is_empty() && self.spads.is_empty()
    }
}

/// `n/|n|` in `f64`, `None` for a zero-length or non-finite `n`.
pub fn unit(n: &Point) -> Option<[f64; 3]> {
    let v = n.map(f64::from);
    let len = v.iter().map(|c| c * c).sum::<f64>().sqrt();
    (len.is_finite() && len > 0.0).then(|| v.map(|c| c / len))
}

/// `|cos θ|` between the leg from wall point `x` to `v` and the unit normal `n` at `x`:
/// `|n·(v − x)| / |v − x|` (1 when `v = x`: a voxel on the wall is not attenuated).
pub fn wall_cosine(x: Point, n: [f64; 3], v: Point) -> f64 {
    let d: [f64; 3] = core::array::from_fn(|i| f64::from(v[i]) - f64::from(x[i]));
    let len = d.iter().map(|c| c * c).sum::<f64>().sqrt();
    if len > 0.0 {
        (d[0] * n[0] + d[1] * n[1] + d[2] * n[2]).abs() / len
    } else {
        1.0
    }
}

impl Geometry {
    /// The physical laser's falloff to spot `x_l`: `cos θ / d²` with `d = |laser_xyz − x_l|`
    /// and θ the angle to the wall normal +z (y-tal `compensate_laser_cos_dsqr` on a flat
    /// wall). [`Geometry::laser_falloff_at`] takes the spot's own normal.
    pub fn laser_falloff(&self, x_l: Point) -> f64 {
        self.falloff(x_l, WALL_NORMAL)
    }

    /// The physical laser's falloff to laser spot `l` with the spot's own normal `n`
    /// ([`Geometry::laser_normal`]): `|v·n| / d³` with `v = laser_xyz − x_l`, `d = |v|` (y-tal
    /// `compensate_laser_cos_dsqr`, which takes `laser_grid_normals`; the same as
    /// [`Geometry::laser_falloff`] on a flat wall). `l` must be a laser row.
    pub fn laser_falloff_at(&self, l: usize) -> f64 {
        self.falloff(self.lasers[l], self.laser_normal(l))
    }

    /// The physical laser's falloff `|v·n| / d³` to wall point `x_l` with unit normal `n`
    /// (`v = laser_xyz − x_l`, `d = |v|`).
    pub fn falloff(&self, x_l: Point, n: [f64; 3]) -> f64 {
        let v: [f64; 3] = core::array::from_fn(|i| self.laser_origin[i] - f64::from(x_l[i]));
        let d2 = v.iter().map(|c| c * c).sum::<f64>();
        let dot = v[0] * n[0] + v[1] * n[1] + v[2] * n[2];
        (dot.abs() / d2.sqrt()) / d2
    }

    /// The unit normal at laser spot `l` (+z where the capture has none). `l` must be a laser
    /// index.
    pub fn laser_normal(&self, l: usize) -> [f64; 3] {
        self.normals
            .lasers
            .get(l)
            .and_then(unit)
            .unwrap_or(WALL_NORMAL)
    }

    /// The unit normal at SPAD spot `s` (+z where the capture has none).
    pub fn spad_normal(&self, s: usize) -> [f64; 3] {
        self.normals
            .spads
            .get(s)
            .and_then(unit)
            .unwrap_or(WALL_NORMAL)
    }

    /// Whether the relay surface is a flat wall z = const with normal ±z at every spot: what
    /// the FFT paths (planar, confocal, resampled) assume. `None` when it is; otherwise why
    /// not, in words for an error or `vltm info` (the z span, or the normals that tilt).
    pub fn not_flat(&self) -> Option<String> {
        let (lo, hi) = self
            .lasers
            .iter()
            .chain(&self.spads)
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), p| {
                (a.min(p[2]), b.max(p[2]))
            });
        if hi - lo > 1e-6 * (1.0 + lo.abs().max(hi.abs())) {
            return Some(format!(
                "the relay surface is not flat (z spans {:.4} m)",
                hi - lo
            ));
        }
        let tilt = |ns: &[Point]| {
            ns.iter()
                .filter_map(unit)
                .map(|u| u[2].abs().clamp(0.0, 1.0).acos())
                .fold(0.0f64, f64::max)
        };
        let t = tilt(&self.normals.lasers).max(tilt(&self.normals.spads));
        (t > 1e-3).then(|| {
            format!(
                "the relay surface's normals are not +z (tilted up to {:.1}°)",
                t.to_degrees()
            )
        })
    }

    /// Number of SPAD histograms in each row (1 for paired and confocal captures).
    pub fn spads_per_row(&self) -> usize {
        if self.confocal { 1 } else { self.spads.len() }
    }

    /// A paired scan whose laser and SPAD points coincide: a confocal capture in the strict
    /// sense (the confocal FFT convolution applies only then). `false` for grid scans.
    pub fn coincident(&self) -> bool {
        self.confocal && self.spads == self.lasers
    }

    /// A paired scan with laser and SPAD points apart (one histogram per row,
    /// [`Geometry::confocal`], not [`Geometry::coincident`]).
    pub fn paired_apart(&self) -> bool {
        self.confocal && !self.coincident()
    }

    /// The SPAD spots of row `l`: `spads[l..l + 1]` for a paired (or confocal) scan, every
    /// SPAD for a grid scan. `l` must be a row index.
    pub fn row_spads(&self, l: usize) -> &[Point] {
        if self.confocal {
            &self.spads[l..l + 1]
        } else {
            &self.spads
        }
    }

    /// Refuses a probe that needs a SPAD grid seen from every laser row (columns, rows, the
    /// matrix: their factorised sums run over `laser × SPAD` grids) on a
    /// paired or confocal capture. `what` names the probe's output (`"columns"`), `arg` the
    /// argument of the error.
    ///
    /// # Errors
    /// [`Error::Argument`] `arg` with one line that says why.
    pub fn need_spad_grid(&self, arg: &str, what: &str) -> Result<()> {
        if self.coincident() {
            Err(Error::arg(
                arg,
                format!("a confocal capture has no separate camera aperture: {what} a SPAD grid"),
            ))
        } else if self.confocal {
            Err(Error::arg(
                arg,
                format!(
                    "a paired scan has one SPAD per laser spot, not a camera aperture shared by \
                     every laser spot: {what} a SPAD grid (their sums factorise over laser × SPAD \
                     grids); `direct` images paired scans"
                ),
            ))
        } else {
            Ok(())
        }
    }

    /// The kind of scan in words, for messages: `"confocal"`, `"paired (laser and SPAD
    /// points apart)"` or `"laser grid × SPAD grid"`.
    pub fn scan_kind(&self) -> &'static str {
        if self.coincident() {
            "confocal"
        } else if self.confocal {
            "paired (laser and SPAD points apart)"
        } else {
            "laser grid × SPAD grid"
        }
    }

    /// Checks shapes and values: grid sizes match, positions finite, normals (where given) one
    /// per spot, finite and of non-zero length, Δt > 0, Nt > 0.
    ///
    /// # Errors
    /// [`Error::Format`] naming `what` (the file) and the field.
    pub fn validate(&self, what: &std::path::Path) -> Result<()> {
        let shape = |s: [usize; 2]| s[0] * s[1];
        if self.lasers.is_empty() || shape(self.laser_shape) != self.lasers.len() {
            return Err(Error::format(
                what,
                "laser_grid",
                format!("{} laser spots", shape(self.laser_shape)),
                self.lasers.len(),
            ));
        }
        if self.spads.is_empty() || shape(self.spad_shape) != self.spads.len() {
            return Err(Error::format(
                what,
                "sensor_grid",
                format!("{} SPAD spots", shape(self.spad_shape)),
                self.spads.len(),
            ));
        }
        if self.confocal && self.spads.len() != self.lasers.len() {
            return Err(Error::format(
                what,
                "sensor_grid",
                format!(
                    "one SPAD point per laser point (a paired scan: {} laser points)",
                    self.lasers.len()
                ),
                format!("{} SPAD points", self.spads.len()),
            ));
        }
        for (name, pts) in [("laser_grid", &self.lasers), ("sensor_grid", &self.spads)] {
            if let Some(i) = pts.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
                return Err(Error::format(
                    what,
                    name,
                    "finite coordinates",
                    format!("{:?} at index {i}", pts[i]),
                ));
            }
        }
        for (name, ns, pts) in [
            ("laser_grid_normals", &self.normals.lasers, &self.lasers),
            ("sensor_grid_normals", &self.normals.spads, &self.spads),
        ] {
            if !ns.is_empty() && ns.len() != pts.len() {
                return Err(Error::format(
                    what,
                    name,
                    format!("{} normals, one per spot", pts.len()),
                    ns.len(),
                ));
            }
            if let Some(i) = ns.iter().position(|n| unit(n).is_none()) {
                return Err(Error::format(
                    what,
                    name,
                    "finite normals of non-zero length",
                    format!("{:?} at index {i}", ns[i]),
                ));
            }
        }
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(Error::format(
                what,
                "delta_t",
                "a finite value > 0",
                self.dt,
            ));
        }
        if !self.t0.is_finite() {
            return Err(Error::format(what, "t_start", "a finite value", self.t0));
        }
        // Path lengths are squared and multiplied on the way: keep the time axis at a size
        // where that stays exact enough and finite (1e9 m of path is 3 s of light).
        let end = self.t0.abs() + self.dt * self.nt as f64;
        if end.is_nan() || end > MAX_PATH {
            return Err(Error::format(
                what,
                "delta_t",
                format!("a time axis within {MAX_PATH:e} m of path (|t_start| + Nt·delta_t)"),
                format!("{} + {} × {}", self.t0.abs(), self.nt, self.dt),
            ));
        }
        if self.nt == 0 {
            return Err(Error::format(what, "H", "at least one time bin", 0));
        }
        Ok(())
    }
}

/// Longest path length a time axis may reach, `|t0| + Nt·Δt` (m): 1e9 m, 3 s of light.
pub const MAX_PATH: f64 = 1e9;

/// A source of laser rows: the kernel's input. Implemented by in-memory captures, file
/// readers that stream by row, and the simulator.
pub trait RowSource {
    /// The capture's geometry.
    fn geometry(&self) -> &Geometry;
    /// Writes the histograms of laser row `l` into `out` (resized to
    /// `spads_per_row·Nt`, SPAD-major) and returns the laser spot.
    ///
    /// # Errors
    /// I/O or format errors of the underlying file.
    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point>;

    /// Reads the rows `first..first + out.len()` into `out` (laser spot and histograms per
    /// row, as [`RowSource::read_row`]): the probes read a batch of rows per pool of threads
    /// this way. By default one after the other; an uncompressed `.npz` reads them in parallel
    /// by positional reads, a capture in memory copies them in parallel, a gzip-chunked tal
    /// file inflates its chunks on the pool's threads (ahead, in a background reader), and the
    /// wrappers that crop or correct rows do their per-row work in parallel, so that reading
    /// keeps up with many threads.
    ///
    /// # Errors
    /// As [`RowSource::read_row`].
    fn read_rows(&mut self, first: usize, out: &mut [(Point, Vec<f32>)]) -> Result<()> {
        for (l, (x, h)) in (first..).zip(out.iter_mut()) {
            *x = self.read_row(l, h)?;
        }
        Ok(())
    }

    /// Whether [`RowSource::read_rows`] reads a batch on several threads (for the section
    /// timings of [`crate::timings`]).
    fn reads_in_parallel(&self) -> bool {
        false
    }

    /// The laser rows a probe streams from this source: all of them unless the source is a
    /// [`RowRange`] (a part of a scan split by rows).
    fn rows(&self) -> std::ops::Range<usize> {
        0..self.geometry().lasers.len()
    }

    /// The rows in scan order as an iterator of `(laser spot, histograms of all SPADs)`
    /// (`spads_per_row·Nt` values, SPAD-major), read one at a time: the shape in which the
    /// kernel takes a scan. Each item owns its histograms; [`RowSource::read_row`] reuses a
    /// buffer instead (what the high-level probes do).
    ///
    /// ```
    /// use vltm::io::{self, RowSource};
    /// let mut c = io::open(std::path::Path::new("../fixtures/two_patches_single.npz"))?;
    /// let per_row = c.geometry.spads_per_row() * c.geometry.nt;
    /// let mut n = 0;
    /// for row in c.iter_rows() {
    ///     let (laser, histograms) = row?;
    ///     assert_eq!((laser[2], histograms.len()), (0.0, per_row)); // a spot on the wall
    ///     n += 1;
    /// }
    /// assert_eq!(n, 64);
    /// # Ok::<(), vltm::Error>(())
    /// ```
    fn iter_rows(&mut self) -> Rows<'_, Self>
    where
        Self: Sized,
    {
        Rows { src: self, next: 0 }
    }
}

/// The laser rows `start..end` of another source: probes stream only these rows (a part of a
/// scan split by rows across processes); the geometry stays the whole capture's, so every
/// derived parameter (default λ, margins, guards) is the same as for the whole scan.
pub struct RowRange<'a> {
    src: &'a mut dyn RowSource,
    rows: std::ops::Range<usize>,
}

impl<'a> RowRange<'a> {
    /// The rows `rows` of `src`.
    ///
    /// # Errors
    /// [`Error::Argument`] (`rows`) unless `start <= end <= ` the number of laser rows.
    pub fn new(src: &'a mut dyn RowSource, rows: std::ops::Range<usize>) -> Result<Self> {
        let n = src.geometry().lasers.len();
        if rows.start > rows.end || rows.end > n {
            return Err(Error::arg(
                "rows",
                format!(
                    "rows {}:{} do not lie in the capture's {n} laser rows (need A <= B <= {n})",
                    rows.start, rows.end
                ),
            ));
        }
        Ok(Self { src, rows })
    }
}

impl RowSource for RowRange<'_> {
    fn geometry(&self) -> &Geometry {
        self.src.geometry()
    }
    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        if !self.rows.contains(&l) {
            return Err(Error::arg(
                "row",
                format!(
                    "row {l} lies outside the rows {}:{} of this part",
                    self.rows.start, self.rows.end
                ),
            ));
        }
        self.src.read_row(l, out)
    }
    fn read_rows(&mut self, first: usize, out: &mut [(Point, Vec<f32>)]) -> Result<()> {
        for l in [first, first + out.len().max(1) - 1] {
            if !self.rows.contains(&l) {
                return Err(Error::arg(
                    "row",
                    format!(
                        "row {l} lies outside the rows {}:{} of this part",
                        self.rows.start, self.rows.end
                    ),
                ));
            }
        }
        self.src.read_rows(first, out)
    }
    fn reads_in_parallel(&self) -> bool {
        self.src.reads_in_parallel()
    }
    fn rows(&self) -> std::ops::Range<usize> {
        self.rows.clone()
    }
}

impl std::fmt::Debug for RowRange<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RowRange")
            .field("rows", &self.rows)
            .finish()
    }
}

/// Iterator over the rows of a [`RowSource`] ([`RowSource::iter_rows`]).
#[derive(Debug)]
pub struct Rows<'a, S: RowSource> {
    src: &'a mut S,
    next: usize,
}

impl<S: RowSource> Iterator for Rows<'_, S> {
    type Item = Result<(Point, Vec<f32>)>;

    fn next(&mut self) -> Option<Self::Item> {
        let l = self.next;
        if l >= self.src.geometry().lasers.len() {
            return None;
        }
        self.next += 1;
        let mut out = Vec::new();
        Some(self.src.read_row(l, &mut out).map(|p| (p, out)))
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.src.geometry().lasers.len().saturating_sub(self.next);
        (n, Some(n))
    }
}

/// A capture held in memory: geometry plus `H` as `f32`, `[Kl][spads_per_row][Nt]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Capture {
    /// Geometry and time axis.
    pub geometry: Geometry,
    /// Histograms, laser-major then SPAD then time.
    pub data: Vec<f32>,
}

impl Capture {
    /// Builds a capture, checking that `data` has `Kl·spads_per_row·Nt` values.
    ///
    /// # Errors
    /// [`Error::Format`] for a size mismatch (`what` names the origin).
    pub fn new(geometry: Geometry, data: Vec<f32>, what: &std::path::Path) -> Result<Self> {
        geometry.validate(what)?;
        let want = geometry.lasers.len() * geometry.spads_per_row() * geometry.nt;
        if data.len() != want {
            return Err(Error::format(
                what,
                "H",
                format!("{want} values"),
                data.len(),
            ));
        }
        Ok(Self { geometry, data })
    }

    /// The histograms of laser row `l`.
    pub fn row(&self, l: usize) -> &[f32] {
        let n = self.geometry.spads_per_row() * self.geometry.nt;
        &self.data[l * n..(l + 1) * n]
    }
}

/// Checks a laser row index against a capture of `rows` rows: the one check and the one
/// message of every [`RowSource::read_row`].
///
/// # Errors
/// [`Error::Argument`] (`row`) for `l >= rows`.
pub fn check_row(l: usize, rows: usize) -> Result<()> {
    if l < rows {
        Ok(())
    } else {
        Err(Error::arg(
            "row",
            format!("laser row {l} is out of range: the capture has {rows} rows (0..{rows})"),
        ))
    }
}

impl RowSource for Capture {
    fn geometry(&self) -> &Geometry {
        &self.geometry
    }
    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        check_row(l, self.geometry.lasers.len())?;
        out.clear();
        out.extend_from_slice(self.row(l));
        Ok(self.geometry.lasers[l])
    }
    /// The rows of a batch copied out of memory in parallel (one row per task).
    fn read_rows(&mut self, first: usize, out: &mut [(Point, Vec<f32>)]) -> Result<()> {
        use rayon::prelude::*;
        if out.is_empty() {
            return Ok(());
        }
        let rows = self.geometry.lasers.len();
        check_row(first, rows)?;
        check_row(first + out.len().max(1) - 1, rows)?;
        let this = &*self;
        out.par_iter_mut().enumerate().for_each(|(i, (x, h))| {
            h.clear();
            h.extend_from_slice(this.row(first + i));
            *x = this.geometry.lasers[first + i];
        });
        Ok(())
    }
    fn reads_in_parallel(&self) -> bool {
        true
    }
}

/// Every row of `src` read into memory, as the capture `name`.
///
/// # Errors
/// Read errors; the capture's own checks ([`Capture::new`]).
pub fn read_all(src: &mut dyn RowSource, name: &std::path::Path) -> Result<Capture> {
    let g = src.geometry().clone();
    let mut data = Vec::new();
    let mut row = Vec::new();
    for l in 0..g.lasers.len() {
        src.read_row(l, &mut row)?;
        data.extend_from_slice(&row);
    }
    Capture::new(g, data, name)
}

/// `src` with the roles of lasers and SPADs swapped (`--swap-roles`): every row read into
/// memory ([`read_all`]), then [`swap_roles`]. Memory: twice the capture (`Kl·Ks·Nt` f32).
///
/// # Errors
/// As [`read_all`] and [`swap_roles`].
pub fn swapped(src: &mut dyn RowSource, name: &std::path::Path) -> Result<Capture> {
    swap_roles(&read_all(src, name)?)
}

/// Swaps the roles of lasers and SPADs by reciprocity: the SPAD array becomes
/// the virtual projector and the laser grid the camera, `T_swap(a, b) = T(b, a)`. Needs the
/// capture in memory (`Kl·Ks·Nt` values).
///
/// A paired scan (one laser and one SPAD spot per row, apart) swaps its two lists of spots
/// (and their normals and the two devices): the histograms stay where they are, row `k` now
/// has the laser at the old SPAD spot `S_k` and the SPAD at `L_k`.
///
/// # Errors
/// [`Error::Argument`] for confocal captures (laser and SPAD at the same spots: nothing to
/// swap).
pub fn swap_roles(c: &Capture) -> Result<Capture> {
    let g = &c.geometry;
    let swapped = |g: &Geometry| Geometry {
        lasers: g.spads.clone(),
        laser_shape: g.spad_shape,
        spads: g.lasers.clone(),
        spad_shape: g.laser_shape,
        laser_origin: g.sensor_origin,
        sensor_origin: g.laser_origin,
        normals: Normals {
            lasers: g.normals.spads.clone(),
            spads: g.normals.lasers.clone(),
        },
        ..g.clone()
    };
    if g.coincident() {
        return Err(Error::arg(
            "swap_roles",
            "a confocal capture has nothing to swap (its laser and SPAD spots coincide)",
        ));
    }
    if g.confocal {
        return Ok(Capture {
            geometry: swapped(g),
            data: c.data.clone(),
        });
    }
    let (kl, ks, nt) = (g.lasers.len(), g.spads.len(), g.nt);
    let mut data = vec![0.0f32; c.data.len()];
    for l in 0..kl {
        for s in 0..ks {
            data[(s * kl + l) * nt..(s * kl + l + 1) * nt]
                .copy_from_slice(&c.data[(l * ks + s) * nt..(l * ks + s + 1) * nt]);
        }
    }
    Ok(Capture {
        geometry: swapped(g),
        data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An out-of-range row is an error with the one message of every reader, not a panic
    /// (the in-memory capture sliced its data and panicked).
    #[test]
    fn read_row_out_of_range_is_an_error() {
        let lasers = vec![[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]];
        let g = Geometry {
            spads: lasers.clone(),
            lasers,
            laser_shape: [2, 1],
            spad_shape: [2, 1],
            laser_origin: [0.0; 3],
            sensor_origin: [0.0; 3],
            legs_in_time: false,
            confocal: true,
            nt: 3,
            dt: 0.01,
            t0: 0.0,
            normals: Normals::default(),
        };
        let mut c = Capture::new(g, vec![1.0; 6], std::path::Path::new("t")).unwrap();
        let mut row = Vec::new();
        assert_eq!(c.read_row(1, &mut row).unwrap(), [0.1, 0.0, 0.0]);
        assert_eq!(row, [1.0; 3]);
        let e = c.read_row(2, &mut row).unwrap_err();
        assert_eq!(e.to_string(), check_row(2, 2).unwrap_err().to_string());
        assert_eq!(
            e.to_string(),
            "argument `row`: laser row 2 is out of range: the capture has 2 rows (0..2)"
        );
        assert!(check_row(1, 2).is_ok());
    }

    /// A source read whole is the capture its file holds; `swapped` is that capture with
    /// its roles swapped.
    #[test]
    fn a_source_read_whole_and_swapped() {
        let path = std::path::Path::new("../fixtures/two_patches.npz");
        let c = crate::io::open(path).unwrap();
        let whole = read_all(&mut *crate::io::open_source(path).unwrap(), path).unwrap();
        assert_eq!((&whole.geometry, &whole.data), (&c.geometry, &c.data));
        let s = swapped(&mut *crate::io::open_source(path).unwrap(), path).unwrap();
        let want = swap_roles(&c).unwrap();
        assert_eq!((&s.geometry, &s.data), (&want.geometry, &want.data));
    }
}
