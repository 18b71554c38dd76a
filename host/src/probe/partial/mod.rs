//! Partial accumulators: a probe run over a part of a scan's laser rows keeps its
//! accumulator state as a [`Partial`] instead of finishing it, so a scan can be split by rows
//! across processes and machines, the parts [merged](Partial::merge) by addition and the sum
//! [finished](Partial::finish) into the same volume as one pass (bit-identical where the
//! summation order is the same, else to float rounding).
//!
//! A part records the capture's identity (file size, dimensions, time axis, an FNV-1a hash
//! of the geometry) and the probe's kind and parameters (the user's wave options, the
//! resolved kernel configuration, the volume, focus, gate, shell, Γ, evaluation path);
//! merging parts that differ in any of them, or whose row ranges overlap, is an error, and so
//! is finishing a state whose rows do not cover the scan.
//!
//! # File format
//!
//! [`Partial::to_bytes`] writes the container of [`crate::io::state`] (magic `VLTMPART`,
//! version, JSON header, SPAD spots, volume points, a matrix's foci, the accumulators, a
//! CRC-32); the header holds the fields below.
//!
//! State per probe (`f64`): direct light `2·Kv`; higher-order column `2·Kv`; factorised
//! column (two-bounce) `2J(Ks+1)`, un-gated `2Ks`; in-focus indirect light `|Γ|·2J(Ks+1)`
//! (leak-corrected or not: the gate corrects each row from Γ and the geometry alone, and the
//! header sums the energy read and removed, `report.leak_total`/`leak_cut`); the matrix
//! `n_from·2J(Ks+1)` (one factorised column per focus, imaged over the `to` voxels when
//! finished).
//! Merging is one addition per `f64`; finishing costs what finishing one pass costs (the
//! imaging of factorised columns). Memory: the state, twice while merging two parts.

use super::column::{ColumnState, Columns, Shell, check_focus, column_acc, factorised_columns};
use super::crop::{self, Reach};
use super::direct::direct_acc;
use super::drive::{Job, intensities};
use super::gate::ColumnGate;
use super::indirect::indirect_sum;
use super::leak::{DirectModel, GateEnergy, LeakCorrected, LeakOptions, cell_radius};
use super::matrix::{Matrix, matrix_acc, matrix_of_columns};
use super::output::Output;
use super::wave::Wave;
use crate::error::{Error, Result};
use crate::exec::{Exec, Path};
use crate::io::capture::{RowRange, RowSource};
use crate::io::state;
use crate::volume::Volume;
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::time::Instant;
use vltm_kernel::{Config, Gate, Legs, Params, Point, Report};

mod names;
use names::*;

pub use crate::io::state::{MAGIC, VERSION};

/// Which probe a partial state accumulates.
#[derive(Clone, Debug, PartialEq)]
pub enum Task {
    /// Direct light (the diagonal, [`super::direct`]).
    Direct,
    /// A column ([`super::column()`]).
    Column {
        /// Focus `x_a` (m).
        focus: Point,
        /// Time gate.
        gate: ColumnGate,
        /// Distance shell kept when finished.
        shell: Shell,
    },
    /// Pass 2 of in-focus indirect light ([`super::indirect_over`]) for a given Γ (pass 1,
    /// the direct light that defines Γ, is a [`Task::Direct`] of its own).
    Indirect {
        /// Γ membership per voxel.
        gamma: Vec<bool>,
        /// Pair shell (`None`: `r0 = 1.5σ`).
        shell: Option<Shell>,
        /// Leak correction ([`super::LeakMethod::Gate`], default options) before the columns:
        /// the windows of Γ's direct returns zeroed row by row, as one pass does.
        leak: bool,
    },
    /// The two-bounce LTM between the foci `from` and the volume's voxels ([`super::matrix()`]).
    Matrix {
        /// Projector foci `x_a` (the matrix's rows, m).
        from: Vec<Point>,
    },
}

/// The capture's identity: parts of different captures do not merge.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Identity {
    file_bytes: u64,
    lasers: usize,
    laser_shape: [usize; 2],
    spads: usize,
    spad_shape: [usize; 2],
    nt: usize,
    dt: f64,
    t0: f64,
    confocal: bool,
    legs_in_time: bool,
    geometry_fnv64: String,
}

/// The first field in which `a` and `b` (serialised) differ, as `prefix.field: a vs b`
/// (nested objects down to the first differing leaf, `probe.wave.sigma: 0.08 vs null`),
/// skipping the top-level fields `skip` says match; `None` when none does.
fn first_difference<T: Serialize + PartialEq>(
    prefix: &str,
    a: &T,
    b: &T,
    skip: impl Fn(&str) -> bool,
) -> Option<String> {
    fn walk(
        path: &str,
        x: &serde_json::Value,
        y: &serde_json::Value,
        skip: &dyn Fn(&str) -> bool,
    ) -> Option<String> {
        use serde_json::Value::Object;
        match (x, y) {
            (Object(x), Object(y)) => x.iter().find_map(|(k, v)| {
                let w = y.get(k).unwrap_or(&serde_json::Value::Null);
                if skip(k) {
                    return None;
                }
                walk(&format!("{path}.{k}"), v, w, &|_| false)
            }),
            _ => (x != y).then(|| format!("{path}: {x} vs {y}")),
        }
    }
    match (serde_json::to_value(a), serde_json::to_value(b)) {
        (Ok(x), Ok(y)) => walk(prefix, &x, &y, &skip),
        _ => (a != b).then(|| prefix.to_string()),
    }
}

impl Identity {
    /// The first field in which `b` is another capture than `self`, with both values
    /// (`capture.nt: 128 vs 64`); `None` for the same capture. A `file_bytes` of 0 (a
    /// stream's state, written before its final size was known) matches any size.
    fn differs(&self, b: &Self) -> Option<String> {
        let unknown = self.file_bytes == 0 || b.file_bytes == 0;
        first_difference("capture", self, b, |k| k == "file_bytes" && unknown)
    }
}

/// The probe's kind and parameters: parts with other parameters do not merge.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct ProbeHead {
    kind: String,
    path: String,
    wave: WaveHead,
    config: ConfigHead,
    volume: VolumeHead,
    focus: Option<Point>,
    gate: Option<String>,
    /// `[r0, r1]`, `r1` null for infinity.
    shell: Option<(f32, Option<f32>)>,
    /// Γ as voxel indices (indirect light).
    gamma: Option<Vec<usize>>,
    /// Leak-corrected (gate method, default options) indirect light.
    #[serde(default)]
    leak: bool,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct WaveHead {
    wavelength: Option<f64>,
    sigma: Option<f64>,
    weights: String,
    band_half_width: f64,
    compensate_laser: bool,
    auto_margin: bool,
}

/// The resolved kernel parameters ([`Params`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct ConfigHead {
    wavelength: f64,
    sigma: Option<f64>,
    band_half_width: f64,
    gate_support: f64,
    margin: f64,
    nt: usize,
    dt: f64,
    t0: f64,
    /// `[laser_origin, sensor_origin]` when the time axis includes the device legs.
    legs: Option<[[f64; 3]; 2]>,
    weights: String,
    d_min: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct VolumeHead {
    shape: [usize; 3],
    axes: Option<[[f32; 2]; 3]>,
    points_fnv64: String,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
struct Counters {
    rows: u64,
    non_finite: u64,
    dropped: u64,
    /// `Σ H²` read and zeroed by the leak gate ([`GateEnergy`]).
    #[serde(default)]
    leak_total: f64,
    #[serde(default)]
    leak_cut: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Head {
    capture: Identity,
    probe: ProbeHead,
    rows: Vec<[usize; 2]>,
    report: Counters,
    /// Per factorised column: the projector leg range `[min, max]`, null before any row.
    legs: Vec<Option<[f64; 2]>>,
    n_spads: usize,
    n_points: usize,
    /// Foci of a matrix (their points follow the volume's).
    #[serde(default)]
    n_from: usize,
    n_acc: usize,
    /// CRC-32 of the bytes after the header, 8 hex digits.
    crc32: String,
    capture_name: String,
}

/// The accumulator state of a probe over some laser rows of a capture: serialises
/// ([`Partial::to_bytes`]), merges by addition ([`Partial::merge`]) and finishes into the
/// probe's volume ([`Partial::finish`]) once its rows cover the scan.
#[derive(Clone, Debug)]
pub struct Partial {
    head: Head,
    spads: Vec<Point>,
    points: Vec<Point>,
    from: Vec<Point>,
    acc: Vec<f64>,
}

fn config_head(cfg: &Config) -> ConfigHead {
    let p = cfg.params();
    ConfigHead {
        wavelength: p.wavelength,
        sigma: p.sigma,
        band_half_width: p.band_half_width,
        gate_support: p.gate_support,
        margin: p.margin,
        nt: p.nt,
        dt: p.dt,
        t0: p.t0,
        legs: match p.legs {
            Legs::WallToWall => None,
            Legs::FirstAndLast {
                laser_origin,
                sensor_origin,
            } => Some([laser_origin, sensor_origin]),
        },
        weights: weights_name(p.weights).into(),
        d_min: p.d_min,
    }
}

/// Runs `task` over the laser rows `rows` of `src` and returns its accumulator state.
/// `file_bytes` is the capture file's size (0 for a capture made in memory or a stream whose
/// final size is not known yet: it then matches any size when parts merge) and
/// `capture_name` its name (recorded, not compared). Every parameter is derived from the whole
/// capture's geometry, exactly as one pass over all rows derives it.
///
/// # Errors
/// [`Error::Argument`] (`rows`) for rows outside the scan; the probe's own errors.
#[allow(clippy::too_many_arguments)]
pub fn accumulate(
    src: &mut dyn RowSource,
    file_bytes: u64,
    capture_name: &str,
    volume: &Volume,
    task: &Task,
    wave: &Wave,
    exec: Exec<'_>,
    rows: Range<usize>,
) -> Result<Partial> {
    wave.refuse_cosine("a scan split by rows (`$rows`)")?;
    let g = src.geometry().clone();
    let mut part = RowRange::new(src, rows.clone())?;
    let mut legs = Vec::new();
    let mut spads = Vec::new();
    let mut energy = GateEnergy::default();
    let (cfg, acc, report, path, focus, gate, shell, gamma) = match task {
        Task::Direct => {
            let (a, cfg) = direct_acc(&mut part, volume, wave, exec)?;
            let acc = flat(&a.acc);
            (cfg, acc, a.report, a.path, None, None, None, None)
        }
        Task::Column { focus, gate, shell } => {
            let (state, cfg, _) = column_acc(&mut part, *focus, volume, *gate, wave, exec, true)?;
            let (acc, report, path) = match state {
                ColumnState::Voxels(acc, r) => (flat(&acc), r, Path::Band),
                ColumnState::Factorised {
                    state,
                    report,
                    legs: l,
                    path,
                    ..
                } => {
                    legs.push(leg_head(l));
                    spads.clone_from(&g.spads);
                    (state, report, path)
                }
            };
            let sh = Some(shell_head(*shell));
            (cfg, acc, report, path, Some(*focus), Some(*gate), sh, None)
        }
        Task::Indirect { gamma, shell, leak } => {
            if gamma.len() != volume.len() {
                return Err(Error::arg(
                    "gamma",
                    format!("expected {} flags, found {}", volume.len(), gamma.len()),
                ));
            }
            let idx: Vec<usize> = (0..gamma.len()).filter(|&i| gamma[i]).collect();
            let pts: Vec<Point> = idx.iter().map(|&i| volume.points[i]).collect();
            // The window rule on the volume's diagonal, as a whole `indirect` applies it.
            let base = wave.config(&g)?;
            super::window::window_coverage(&g, &base, None, &volume.points, ColumnGate::TwoBounce)?;
            // The time axis cropped to the Γ pairs' reach, as `indirect` crops it.
            let reach = Reach {
                foci: Some(&pts),
                voxels: &pts,
                late: false,
            };
            let bins = crop::bins(&g, wave, reach)?;
            let cfg = wave.column_config(&crop::cropped_geometry(&g, &bins), &pts, &pts)?;
            let shell = shell.unwrap_or(Shell {
                r0: 1.5 * cfg.sigma() as f32,
                r1: f32::INFINITY,
            });
            let job = Job {
                cfg: &cfg,
                wave,
                exec,
            };
            let cols = match (pts.is_empty(), leak) {
                (true, true) => {
                    return Err(Error::arg(
                        "leak_correct",
                        "Γ is empty: no voxel has direct light above ε·max (no direct return in the window for this volume?)",
                    ));
                }
                (true, false) => Columns {
                    state: Vec::new(),
                    report: Report::default(),
                    legs: Vec::new(),
                },
                (false, true) => {
                    let lo = LeakOptions::default();
                    let model = DirectModel::gate(&g, &pts, cell_radius(volume), wave, &lo)?;
                    let mut lc = LeakCorrected::measuring(&mut part, &model);
                    let c = crop::on_bins(&mut lc, bins, |s| {
                        factorised_columns(s, job, &pts, Gate::Gaussian, "indirect")
                    })?;
                    energy = lc.energy().unwrap_or_default();
                    c
                }
                (false, false) => crop::on_bins(&mut part, bins, |s| {
                    factorised_columns(s, job, &pts, Gate::Gaussian, "indirect")
                })?,
            };
            legs = cols.legs.iter().copied().map(leg_head).collect();
            spads.clone_from(&g.spads);
            let sh = Some(shell_head(shell));
            (
                cfg,
                cols.state,
                cols.report,
                Path::Band,
                None,
                None,
                sh,
                Some(idx),
            )
        }
        Task::Matrix { from } => {
            let (cols, cfg) = matrix_acc(&mut part, from, &volume.points, wave, exec)?;
            legs = cols.legs.iter().copied().map(leg_head).collect();
            spads.clone_from(&g.spads);
            (
                cfg,
                cols.state,
                cols.report,
                Path::Band,
                None,
                None,
                None,
                None,
            )
        }
    };
    let (kind, from, leak) = match task {
        Task::Direct => ("direct", Vec::new(), false),
        Task::Column { .. } => ("column", Vec::new(), false),
        Task::Indirect { leak, .. } => ("indirect", Vec::new(), *leak),
        Task::Matrix { from } => ("matrix", from.clone(), false),
    };
    let points = if volume.axes.is_some() {
        Vec::new()
    } else {
        volume.points.clone()
    };
    let head = Head {
        capture: Identity {
            file_bytes,
            lasers: g.lasers.len(),
            laser_shape: g.laser_shape,
            spads: g.spads.len(),
            spad_shape: g.spad_shape,
            nt: g.nt,
            dt: g.dt,
            t0: g.t0,
            confocal: g.confocal,
            legs_in_time: g.legs_in_time,
            geometry_fnv64: geometry_hash(&g),
        },
        probe: ProbeHead {
            kind: kind.into(),
            path: path.name().into(),
            wave: WaveHead {
                wavelength: wave.wavelength,
                sigma: wave.sigma,
                weights: weights_name(wave.weights).into(),
                band_half_width: wave.band_half_width,
                compensate_laser: wave.compensate_laser,
                auto_margin: wave.auto_margin,
            },
            config: config_head(&cfg),
            volume: VolumeHead {
                shape: volume.shape,
                axes: volume.axes,
                points_fnv64: format!("{:016x}", fnv(point_bytes(&volume.points))),
            },
            focus,
            gate: gate.map(|g| gate_name(g).into()),
            shell,
            gamma,
            leak,
        },
        rows: if rows.is_empty() {
            Vec::new()
        } else {
            vec![[rows.start, rows.end]]
        },
        report: Counters {
            rows: report.rows,
            non_finite: report.non_finite,
            dropped: report.dropped,
            leak_total: energy.total,
            leak_cut: energy.cut,
        },
        legs,
        n_spads: spads.len(),
        n_points: points.len(),
        n_from: from.len(),
        n_acc: acc.len(),
        crc32: String::new(),
        capture_name: capture_name.into(),
    };
    Ok(Partial {
        head,
        spads,
        points,
        from,
        acc,
    })
}

/// The probe's result from a finished [`Partial`].
#[derive(Clone, Debug)]
pub struct Finished {
    /// Intensities, configuration, counters and path (`seconds`: the finishing time).
    pub output: Output,
    /// Complex amplitudes per voxel (`T = |A|²`), for direct light and higher-order columns,
    /// and for two-bounce columns when asked for ([`Partial::finish_with`]); `None` for
    /// un-gated columns, indirect light (imaged as intensities) and the matrix.
    pub amplitudes: Option<Vec<Complex64>>,
    /// The volume the state was accumulated over (the matrix's `to` voxels).
    pub volume: Volume,
    /// The matrix (its `output.values` are the intensities, row-major `n_from × n_to`).
    pub matrix: Option<Matrix>,
    /// Leak-corrected indirect light: the fraction of the capture's energy the gate removed.
    pub explained: Option<f64>,
}

impl Partial {
    /// The probe's kind: `direct`, `column`, `indirect` or `matrix`.
    pub fn kind(&self) -> &str {
        &self.head.probe.kind
    }

    /// The row ranges `[a, b)` the state holds, in order.
    pub fn rows(&self) -> Vec<Range<usize>> {
        self.head.rows.iter().map(|r| r[0]..r[1]).collect()
    }

    /// Laser rows of the whole scan.
    pub fn total_rows(&self) -> usize {
        self.head.capture.lasers
    }

    /// The capture's name as given when the part was made (informational).
    pub fn capture_name(&self) -> &str {
        &self.head.capture_name
    }

    /// The focus of a column.
    pub fn focus(&self) -> Option<Point> {
        self.head.probe.focus
    }

    /// The foci of a matrix (its rows; empty for other probes).
    pub fn from_points(&self) -> &[Point] {
        &self.from
    }

    /// Size of [`Partial::to_bytes`] without building it (bytes).
    pub fn byte_len(&self) -> usize {
        let points = [&self.spads[..], &self.points[..], &self.from[..]];
        state::byte_len(points, self.acc.len(), self.header_json(0).len())
    }

    fn header_json(&self, crc32: u32) -> Vec<u8> {
        // A struct of plain data: serialising it cannot fail.
        serde_json::to_vec(&Head {
            crc32: format!("{crc32:08x}"),
            ..self.head.clone()
        })
        .unwrap_or_default()
    }

    /// The state in the binary format of [`crate::io::state`].
    pub fn to_bytes(&self) -> Vec<u8> {
        let points = [&self.spads[..], &self.points[..], &self.from[..]];
        state::encode(points, &self.acc, |crc| self.header_json(crc))
    }

    /// Reads a state written by [`Partial::to_bytes`]; `what` names its origin in errors.
    ///
    /// # Errors
    /// [`Error::Format`] for another magic or version, a header that does not parse, a size
    /// that does not match or a CRC that fails.
    pub fn from_bytes(bytes: &[u8], what: &std::path::Path) -> Result<Self> {
        let (head, s) = state::decode(bytes, what)?;
        let head: Head = serde_json::from_slice(head).map_err(|e| {
            Error::format(what, "header", "the JSON header of format 1", e.to_string())
        })?;
        let p = Self {
            spads: s.spads,
            points: s.points,
            from: s.from,
            acc: s.acc,
            head,
        };
        p.check_rows(what)?;
        Ok(p)
    }

    fn check_rows(&self, what: &std::path::Path) -> Result<()> {
        let n = self.head.capture.lasers;
        let mut end = 0;
        for r in &self.head.rows {
            if r[0] < end || r[0] >= r[1] || r[1] > n {
                return Err(Error::format(
                    what,
                    "rows",
                    format!("ordered, disjoint ranges within 0:{n}"),
                    format!("{:?}", self.head.rows),
                ));
            }
            end = r[1];
        }
        Ok(())
    }

    /// Reads a state from a file.
    ///
    /// # Errors
    /// [`Error::Io`] if unreadable; as [`Partial::from_bytes`].
    pub fn read(path: &std::path::Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        Self::from_bytes(&bytes, path)
    }

    /// Writes the state to a file, all or nothing ([`crate::atomic`]).
    ///
    /// # Errors
    /// [`Error::Io`] if the file cannot be written.
    pub fn write(&self, path: &std::path::Path) -> Result<()> {
        crate::atomic::write_bytes(path, &self.to_bytes())
    }

    /// Adds the parts' accumulators (in the order of their first rows) into one state.
    /// `names` name the parts in errors (`parts[i]` is `names[i]`).
    ///
    /// # Errors
    /// [`Error::Argument`] (`merge`) for no parts, parts of different captures or with
    /// different parameters, and overlapping rows.
    pub fn merge(parts: Vec<Self>, names: &[String]) -> Result<Self> {
        let name = |i: usize| names.get(i).cloned().unwrap_or_else(|| format!("part {i}"));
        let mut order: Vec<usize> = (0..parts.len()).collect();
        order.sort_by_key(|&i| parts[i].head.rows.first().map_or(0, |r| r[0]));
        let Some(&first) = order.first() else {
            return Err(Error::arg("merge", "no partial states to merge"));
        };
        let a = &parts[first];
        for &i in &order {
            let b = &parts[i];
            let differ = |what: &str| {
                Err(Error::arg(
                    "merge",
                    format!(
                        "{} and {} {what}: they are not parts of one scan",
                        name(first),
                        name(i)
                    ),
                ))
            };
            if let Some(d) = a.head.capture.differs(&b.head.capture) {
                return differ(&format!("come from different captures ({d})"));
            }
            if let Some(d) = first_difference("probe", &a.head.probe, &b.head.probe, |_| false) {
                return differ(&format!("have different probes or parameters ({d})"));
            }
            if a.spads != b.spads
                || a.points != b.points
                || a.from != b.from
                || a.acc.len() != b.acc.len()
                || a.head.legs.len() != b.head.legs.len()
            {
                return differ("have different probes or parameters");
            }
        }
        // Row ranges: disjoint, then coalesced.
        let mut ranges: Vec<([usize; 2], usize)> = order
            .iter()
            .flat_map(|&i| parts[i].head.rows.iter().map(move |r| (*r, i)))
            .collect();
        ranges.sort_by_key(|(r, _)| r[0]);
        for w in ranges.windows(2) {
            if w[1].0[0] < w[0].0[1] {
                return Err(Error::arg(
                    "merge",
                    format!(
                        "{} (rows {}:{}) and {} (rows {}:{}) overlap: each row must be in one part",
                        name(w[0].1),
                        w[0].0[0],
                        w[0].0[1],
                        name(w[1].1),
                        w[1].0[0],
                        w[1].0[1]
                    ),
                ));
            }
        }
        let mut rows: Vec<[usize; 2]> = Vec::new();
        for (r, _) in ranges {
            match rows.last_mut() {
                Some(last) if last[1] == r[0] => last[1] = r[1],
                _ => rows.push(r),
            }
        }
        let mut parts = parts;
        let head = parts[first].head.clone();
        let mut out = std::mem::replace(
            &mut parts[first],
            Self {
                head,
                spads: Vec::new(),
                points: Vec::new(),
                from: Vec::new(),
                acc: Vec::new(),
            },
        );
        for &i in order.iter().skip(1) {
            let b = &parts[i];
            for (x, y) in out.acc.iter_mut().zip(&b.acc) {
                *x += y;
            }
            let (r, s) = (&mut out.head.report, b.head.report);
            r.rows += s.rows;
            r.non_finite += s.non_finite;
            r.dropped += s.dropped;
            r.leak_total += s.leak_total;
            r.leak_cut += s.leak_cut;
            for (l, m) in out.head.legs.iter_mut().zip(&b.head.legs) {
                let (x, y) = (leg_of(*l), leg_of(*m));
                *l = leg_head((x.0.min(y.0), x.1.max(y.1)));
            }
        }
        out.head.rows = rows;
        // A stream's state (size 0) merged with a finished file's records the size.
        out.head.capture.file_bytes = order
            .iter()
            .map(|&i| parts[i].head.capture.file_bytes)
            .max()
            .unwrap_or(0);
        Ok(out)
    }

    /// Whether the state's rows cover the whole scan.
    pub fn is_complete(&self) -> bool {
        self.head.rows == [[0, self.head.capture.lasers]]
            || (self.head.capture.lasers == 0 && self.head.rows.is_empty())
    }

    /// The probe's volume from the accumulated state, exactly as one pass over all rows
    /// finishes it.
    ///
    /// # Errors
    /// [`Error::Argument`] (`merge`) when rows are missing; configuration and kernel errors.
    pub fn finish(&self) -> Result<Finished> {
        self.finish_with(false)
    }

    /// As [`Partial::finish`]; `amplitudes`: also image the complex amplitudes of a
    /// two-bounce column (beside its intensities: about twice the imaging time).
    ///
    /// # Errors
    /// As [`Partial::finish`]; [`Error::Argument`] (`leak_correct`) for leak-corrected
    /// indirect light when the gate removed nothing (as one pass).
    pub fn finish_with(&self, amplitudes: bool) -> Result<Finished> {
        let t = Instant::now();
        if !self.is_complete() {
            let mut missing = Vec::new();
            let mut at = 0;
            for r in self
                .head
                .rows
                .iter()
                .chain([&[self.head.capture.lasers; 2]])
            {
                if r[0] > at {
                    missing.push(format!("{at}:{}", r[0]));
                }
                at = r[1];
            }
            return Err(Error::arg(
                "merge",
                format!(
                    "rows {} of the {} laser rows are missing: merge every part of the scan",
                    missing.join(", "),
                    self.head.capture.lasers
                ),
            ));
        }
        self.image(amplitudes, t)
    }

    /// The probe's volume from the rows accumulated so far, whether or not they cover the
    /// scan: the picture of a scan still being acquired (`vltm live`). For a complete state it
    /// is [`Partial::finish`]'s.
    ///
    /// # Errors
    /// Configuration and kernel errors, as [`Partial::finish`].
    pub fn preview(&self) -> Result<Finished> {
        self.image(false, Instant::now())
    }

    fn image(&self, amplitudes: bool, t: Instant) -> Result<Finished> {
        let p = &self.head.probe;
        let c = &p.config;
        let cfg = Config::try_new(&Params {
            wavelength: c.wavelength,
            sigma: c.sigma,
            band_half_width: c.band_half_width,
            gate_support: c.gate_support,
            margin: c.margin,
            nt: c.nt,
            dt: c.dt,
            t0: c.t0,
            legs: match c.legs {
                None => Legs::WallToWall,
                Some([laser_origin, sensor_origin]) => Legs::FirstAndLast {
                    laser_origin,
                    sensor_origin,
                },
            },
            weights: parse_weights(&c.weights)?,
            d_min: c.d_min,
        })?;
        let volume = match p.volume.axes {
            Some(ax) => Volume::grid(
                [ax[0][0], ax[1][0], ax[2][0]],
                [ax[0][1], ax[1][1], ax[2][1]],
                p.volume.shape,
            )?,
            None => Volume::points(self.points.clone())?,
        };
        if format!("{:016x}", fnv(point_bytes(&volume.points))) != p.volume.points_fnv64 {
            return Err(Error::arg(
                "merge",
                "the volume rebuilt from the partial state is not the one it was accumulated over",
            ));
        }
        let report = Report {
            rows: self.head.report.rows,
            non_finite: self.head.report.non_finite,
            dropped: self.head.report.dropped,
            aliased: 0,
        };
        let path = parse_path(&p.path).unwrap_or(Path::Band);
        let shell = p.shell.map_or(Shell::ALL, shell_of);
        let mut matrix = None;
        let (values, report, path, amplitudes) = match p.kind.as_str() {
            "direct" => {
                let acc = complex(&self.acc);
                (intensities(&acc), report, path, Some(acc))
            }
            "column" => {
                let focus = p.focus.unwrap_or([0.0, 0.0, 1.0]);
                check_focus(focus)?;
                let gate = p.gate.as_deref().and_then(parse_gate);
                let state = match gate {
                    Some(ColumnGate::HigherOrder) => {
                        ColumnState::Voxels(complex(&self.acc), report)
                    }
                    Some(g) => ColumnState::Factorised {
                        state: self.acc.clone(),
                        report,
                        legs: leg_of(self.head.legs.first().copied().flatten()),
                        gate: if g == ColumnGate::None {
                            Gate::None
                        } else {
                            Gate::Gaussian
                        },
                        path,
                        planar: None,
                    },
                    None => return Err(Error::arg("gate", "unknown gate in the partial state")),
                };
                let amps = amplitudes || gate == Some(ColumnGate::HigherOrder);
                state.finish(&cfg, &self.spads, focus, &volume, shell, amps)?
            }
            "indirect" => {
                let idx = p.gamma.clone().unwrap_or_default();
                let pts: Vec<Point> = idx
                    .iter()
                    .filter_map(|&i| volume.points.get(i).copied())
                    .collect();
                let mut cols = Columns {
                    state: self.acc.clone(),
                    report,
                    legs: self.head.legs.iter().copied().map(leg_of).collect(),
                };
                let (v, r) = indirect_sum(
                    &mut cols,
                    &cfg,
                    &self.spads,
                    &pts,
                    &idx,
                    shell,
                    volume.len(),
                    Exec::default(),
                )?;
                (v, r, Path::Band, None)
            }
            "matrix" => {
                let mut cols = Columns {
                    state: self.acc.clone(),
                    report,
                    legs: self.head.legs.iter().copied().map(leg_of).collect(),
                };
                let m =
                    matrix_of_columns(&mut cols, &cfg, &self.spads, &self.from, &volume.points)?;
                let v = m.intensities();
                let r = m.report;
                matrix = Some(m);
                (v, r, Path::Band, None)
            }
            k => return Err(Error::arg("kind", format!("unknown probe `{k}`"))),
        };
        Ok(Finished {
            output: Output {
                values,
                report,
                seconds: t.elapsed().as_secs_f64(),
                config: cfg,
                path,
                crop: None,
                aligned: None,
            },
            amplitudes,
            volume,
            matrix,
            explained: if p.leak {
                Some(
                    GateEnergy {
                        total: self.head.report.leak_total,
                        cut: self.head.report.leak_cut,
                    }
                    .explained()?,
                )
            } else {
                None
            },
        })
    }
}
