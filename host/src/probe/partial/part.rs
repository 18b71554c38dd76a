//! The partial state of a probe, what it accumulates ([`Task`]), merged and finished.

use crate::error::{Error, Result};
use crate::exec::{EvalPath, Exec};
use crate::io::state;
use crate::probe::column::{ColumnState, Columns, Shell, check_focus};
use crate::probe::gate::ColumnGate;
use crate::probe::indirect::indirect_sum;
use crate::probe::leak::GateEnergy;
use crate::probe::matrix::{Matrix, matrix_of_columns};
use crate::probe::output::{Output, intensities};
use crate::volume::Volume;
use num_complex::Complex64;
use std::ops::Range;
use std::time::Instant;
use vltm_kernel::{Config, Gate, Legs, Params, Point, Report};

use super::head::*;
use super::names::*;

/// Which probe a partial state accumulates.
#[derive(Clone, Debug, PartialEq)]
pub enum Task {
    /// Direct light (the diagonal, [`crate::probe::direct`]).
    Direct,
    /// A column ([`crate::probe::column()`]).
    Column {
        /// Focus `x_a` (m).
        focus: Point,
        /// Time gate.
        gate: ColumnGate,
        /// Distance shell kept when finished.
        shell: Shell,
    },
    /// Pass 2 of in-focus indirect light ([`crate::probe::indirect_over`]) for a given Γ (pass 1,
    /// the direct light that defines Γ, is a [`Task::Direct`] of its own).
    Indirect {
        /// Γ membership per voxel.
        gamma: Vec<bool>,
        /// Pair shell (`None`: `r0 = 1.5σ`).
        shell: Option<Shell>,
        /// Leak correction ([`crate::probe::LeakMethod::Gate`], default options) before the columns:
        /// the windows of Γ's direct returns zeroed row by row, as one pass does.
        leak: bool,
    },
    /// The two-bounce LTM between the foci `from` and the volume's voxels ([`crate::probe::matrix()`]).
    Matrix {
        /// Projector foci `x_a` (the matrix's rows, m).
        from: Vec<Point>,
    },
}

/// The accumulator state of a probe over some laser rows of a capture: serialises
/// ([`Partial::to_bytes`]), merges by addition ([`Partial::merge`]) and finishes into the
/// probe's volume ([`Partial::finish`]) once its rows cover the scan.
#[derive(Clone, Debug)]
pub struct Partial {
    pub(super) head: Head,
    pub(super) spads: Vec<Point>,
    pub(super) points: Vec<Point>,
    pub(super) from: Vec<Point>,
    pub(super) acc: Vec<f64>,
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
        let path = parse_path(&p.path).unwrap_or(EvalPath::Band);
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
                (v, r, EvalPath::Band, None)
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
                (v, r, EvalPath::Band, None)
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
                        near: 0.0,
                    }
                    .explained()?,
                )
            } else {
                None
            },
        })
    }
}
