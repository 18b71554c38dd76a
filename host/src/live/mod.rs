//! Following a scan while it is acquired (`vltm live`): rows arrive one at a time from a
//! [`LiveSource`] (a PTU file still being written or a pipe,
//! [`Follower`](crate::io::ptu::Follower); any capture replayed at a fixed rate, [`Replay`]), are folded into the direct light and the columns at
//! the focus points as they come, and every `K` rows the current volumes, their figures and
//! the partial states are written at once ([`crate::atomic`]). When the last row is in, the
//! in-focus indirect light (whose Γ needs the whole diagonal) is computed over the whole scan.
//!
//! # Folding
//!
//! Each probe keeps a [`Partial`] state. The rows that arrived since the last fold are run as
//! one part ([`crate::probe::partial::accumulate`]) and [merged](Partial::merge) into it: the
//! batch grows by itself when the rows arrive faster than they are folded, and is one row at
//! a time otherwise. The previews ([`Partial::preview`]) and the final volumes are imaged
//! from these states exactly as `vltm merge` images parts, so the final direct light and
//! columns equal one pass over the finished file up to the order of the `f64` sums (parts
//! are summed, then added): within float rounding, far below 10⁻⁶ of the peak. The in-focus
//! indirect light is one pass over the stored rows with Γ from the final diagonal, as
//! `vltm indirect --direct` computes it.
//!
//! # Memory and cost
//!
//! The rows are kept (`Kl·Ks·Nt` `f32`, checked against the memory budget) for the indirect
//! pass at the end; the probes' states are those of [`Partial`]. A fold costs what the same
//! rows cost offline plus the probe's set-up (per batch) and a preview per probe (imaging a
//! factorised column over the volume).
//!
//! # Resuming
//!
//! A run started with the states a previous run wrote ([`LiveRun::new`]'s `resume`: a live
//! run's states of rows `0..k`, or any states of the same rows, such as a `--partial` part or
//! the firmware's state of the scan's last rows) folds only the rows the states do not hold.
//! Rows `0..k` at the start of the scan are passed over by the source without binning
//! ([`LiveSource::skip_rows`]); the in-focus indirect light, which needs every row, then reads
//! them again from the finished file at the end ([`LiveSource::reread`]). A stream on
//! standard input cannot be read again: with the indirect light on, its rows are binned and
//! stored as they come, and only the folding is skipped. A state of another capture, probe
//! or configuration is refused (the checks of [`Partial::merge`], naming the field).

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Instant;

use crate::atomic::Transaction;
use crate::budget;
use crate::error::{Error, Result};
use crate::exec::{Exec, Path as EvalPath};
use crate::export::figure::Figure;
use crate::export::figure::plot::Transient;
use crate::io::capture::{Capture, Geometry};
use crate::probe::partial::{self, Finished, Partial, Task};
use crate::probe::{
    ColumnGate, IndirectOptions, IndirectOutput, Shell, Wave, gamma_mask, indirect_over,
    window_coverage,
};
use crate::volume::Volume;
use vltm_kernel::Point;

mod source;
pub use source::{Arrival, LiveSource, Replay};

/// One probe of a live run.
#[derive(Clone, Debug)]
pub struct LiveProbe {
    /// Short name used in file names and the page: `direct`, `column0`, `column1`, ….
    pub tag: String,
    /// A title for figures.
    pub title: String,
    /// What it accumulates.
    pub task: Task,
    /// Its state: the rows folded so far.
    pub state: Partial,
}

/// What the run needs to know besides the rows.
#[derive(Clone, Debug)]
pub struct LiveOptions {
    /// The voxels.
    pub volume: Volume,
    /// Focus points of the columns (two-bounce gate, every voxel).
    pub focus: Vec<Point>,
    /// Wave options, as the offline commands take them.
    pub wave: Wave,
    /// Evaluation path.
    pub path: EvalPath,
    /// The in-focus indirect light at the end (`None`: not computed).
    pub indirect: Option<IndirectOptions>,
    /// The capture's name, recorded in the states (informational).
    pub capture_name: String,
    /// The capture file's size in bytes, recorded in the states' capture identity: a
    /// finished file's size (a replayed capture), 0 for a stream whose final size is not
    /// known when a state is written (a followed file, standard input). 0 matches any size
    /// when states merge ([`Partial::merge`]).
    pub file_bytes: u64,
}

/// The state of a live run: the rows received, the probes' states, the summed transient.
#[derive(Debug)]
pub struct LiveRun {
    opts: LiveOptions,
    capture: Capture,
    received: usize,
    /// Rows in the probes' states (the resumed states' rows included).
    folded: usize,
    /// The rows the resumed states hold (ascending, disjoint).
    held: Vec<Range<usize>>,
    /// Rows below this are folded or held.
    next: usize,
    /// Rows below this were not stored (passed over by a resumed run).
    stored_from: usize,
    probes: Vec<LiveProbe>,
    transient: Vec<f64>,
    photons: f64,
    dwell: Vec<f64>,
    warnings: Vec<String>,
}

fn exec(path: EvalPath) -> Exec<'static> {
    Exec {
        progress: None,
        path,
    }
}

impl LiveRun {
    /// A run over a capture of geometry `g`; `resume`: the states of an interrupted run, one
    /// per probe (direct light first, then the columns), all over the same rows: rows `0..k`
    /// for a live run's states, any rows for the states of `--partial` or of the firmware
    /// (e.g. the scan's last rows). The rows the states hold are not folded again.
    ///
    /// # Errors
    /// [`Error::Argument`] (`--resume`) for states that do not match the probes, the capture
    /// or the parameters, or hold different rows; the probes' configuration errors; the
    /// memory budget for the stored rows.
    pub fn new(g: &Geometry, opts: LiveOptions, resume: Vec<(PathBuf, Partial)>) -> Result<Self> {
        let n = g.lasers.len() * g.spads_per_row() * g.nt;
        budget::check(
            || "the live run's rows (kept for the in-focus indirect light)".to_string(),
            budget::bytes(n, 4),
        )?;
        let mut capture = Capture::new(g.clone(), vec![0.0; n], Path::new("live"))?;
        let mut tasks = vec![(
            "direct".to_string(),
            "direct light".to_string(),
            Task::Direct,
        )];
        for (i, &a) in opts.focus.iter().enumerate() {
            tasks.push((
                format!("column{i}"),
                format!(
                    "column --focus {},{},{} --gate two-bounce (live: not leak-corrected)",
                    a[0], a[1], a[2]
                ),
                Task::Column {
                    focus: a,
                    gate: ColumnGate::TwoBounce,
                    shell: Shell::ALL,
                },
            ));
        }
        let mut resume: Vec<Option<(PathBuf, Partial)>> = resume.into_iter().map(Some).collect();
        let mut probes = Vec::new();
        let mut held: Option<Vec<Range<usize>>> = None;
        for (tag, title, task) in tasks {
            let empty = partial::accumulate(
                &mut capture,
                opts.file_bytes,
                &opts.capture_name,
                &opts.volume,
                &task,
                &opts.wave,
                exec(opts.path),
                0..0,
            )?;
            let focus = match &task {
                Task::Column { focus, .. } => Some(*focus),
                _ => None,
            };
            let found = resume.iter_mut().find(|r| {
                r.as_ref()
                    .is_some_and(|(_, p)| p.kind() == empty.kind() && p.focus() == focus)
            });
            let state = match found.and_then(Option::take) {
                None if held.as_ref().is_some_and(|h| !h.is_empty()) => {
                    return Err(Error::arg(
                        "resume",
                        format!("no state given for the {title}"),
                    ));
                }
                None => {
                    held = Some(Vec::new());
                    empty
                }
                Some((path, p)) => {
                    let rows = p.rows();
                    if held.as_ref().is_some_and(|h| *h != rows) {
                        return Err(Error::arg(
                            "resume",
                            format!(
                                "{} holds rows {}, the other states other rows: give the states of one run",
                                path.display(),
                                show_rows(&rows)
                            ),
                        ));
                    }
                    held = Some(rows);
                    let names = [path.display().to_string(), "this run".to_string()];
                    Partial::merge(vec![p, empty], &names).map_err(|e| {
                        Error::arg(
                            "resume",
                            format!(
                                "{} is not a state of this capture and these parameters: {}",
                                path.display(),
                                e.to_string().trim_start_matches("argument `merge`: ")
                            ),
                        )
                    })?
                }
            };
            probes.push(LiveProbe {
                tag,
                title,
                task,
                state,
            });
        }
        if let Some((path, p)) = resume.into_iter().flatten().next() {
            return Err(Error::arg(
                "resume",
                format!(
                    "{} is a {} state that matches no probe of this run (check $focus)",
                    path.display(),
                    p.kind()
                ),
            ));
        }
        let held = held.unwrap_or_default();
        // The probes' window rule (an empty window already failed above, in the probes' own
        // set-up, with the one line every probe gives): the warnings for few paths in it.
        let base = opts.wave.config(g)?;
        let mut warnings = Vec::new();
        let mut warn = |foci: Option<&[Point]>| -> Result<()> {
            let c = window_coverage(g, &base, foci, &opts.volume.points, ColumnGate::TwoBounce)?;
            if let Some(w) = c.warning()
                && !warnings.contains(&w)
            {
                warnings.push(w);
            }
            Ok(())
        };
        warn(None)?;
        for a in &opts.focus {
            warn(Some(std::slice::from_ref(a)))?;
        }
        let nt = g.nt;
        Ok(Self {
            opts,
            capture,
            received: 0,
            folded: held.iter().map(ExactSizeIterator::len).sum(),
            held,
            next: 0,
            stored_from: 0,
            probes,
            transient: vec![0.0; nt],
            photons: 0.0,
            dwell: Vec::new(),
            warnings,
        })
    }

    /// The probes' warnings of the window rule ([`window_coverage`]: few of the paths through
    /// the volume lie in the capture's time window), as `direct` and `column` give them.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// The geometry.
    pub fn geometry(&self) -> &Geometry {
        &self.capture.geometry
    }

    /// The options.
    pub fn options(&self) -> &LiveOptions {
        &self.opts
    }

    /// Laser rows of the scan.
    pub fn total_rows(&self) -> usize {
        self.capture.geometry.lasers.len()
    }

    /// Rows received.
    pub fn received(&self) -> usize {
        self.received
    }

    /// Rows folded into the probes (those of resumed states included).
    pub fn folded(&self) -> usize {
        self.folded
    }

    /// Photons received (since the start of this run).
    pub fn photons(&self) -> f64 {
        self.photons
    }

    /// The median acquisition time of a row (s) among the rows that carried one.
    pub fn dwell(&self) -> Option<f64> {
        let mut d = self.dwell.clone();
        if d.is_empty() {
            return None;
        }
        d.sort_by(f64::total_cmp);
        Some(d[d.len() / 2])
    }

    /// The capture's summed transient so far: counts per bin over every row and SPAD.
    pub fn transient(&self) -> &[f64] {
        &self.transient
    }

    /// The probes.
    pub fn probes(&self) -> &[LiveProbe] {
        &self.probes
    }

    /// The rows received (zeros for rows not yet received).
    pub fn capture(&self) -> &Capture {
        &self.capture
    }

    /// Stores a row.
    ///
    /// # Errors
    /// [`Error::Format`] (`rows`) for a row out of order or of the wrong length.
    pub fn receive(&mut self, a: Arrival) -> Result<()> {
        let per_row = self.capture.geometry.spads_per_row() * self.capture.geometry.nt;
        if a.index != self.received || a.data.len() != per_row {
            return Err(Error::format(
                Path::new(&self.opts.capture_name),
                "rows",
                format!("row {} of {per_row} values", self.received),
                format!("row {} of {} values", a.index, a.data.len()),
            ));
        }
        self.store(&a);
        self.photons += a.photons;
        if let Some(d) = a.dwell.filter(|d| d.is_finite() && *d > 0.0) {
            self.dwell.push(d);
        }
        self.received += 1;
        Ok(())
    }

    /// The rows at the start of the scan that the resumed states hold (`0..k`: `k`, else 0):
    /// a source may pass over them ([`LiveRun::skip_received`]).
    pub fn held_prefix(&self) -> usize {
        match self.held.first() {
            Some(r) if r.start == 0 => r.end,
            _ => 0,
        }
    }

    /// Rows `0..k` (held by the resumed states, `k ≤` [`LiveRun::held_prefix`]) will not
    /// arrive: the next row received is row `k`. Their values are not stored until
    /// [`LiveRun::refill`].
    ///
    /// # Errors
    /// [`Error::Argument`] (`resume`) after rows arrived, or for rows the states do not hold.
    pub fn skip_received(&mut self, k: usize) -> Result<()> {
        if self.received > 0 || k > self.held_prefix() {
            return Err(Error::arg(
                "resume",
                format!(
                    "cannot pass over rows 0:{k} (the states hold 0:{})",
                    self.held_prefix()
                ),
            ));
        }
        self.received = k;
        self.next = k;
        self.stored_from = k;
        Ok(())
    }

    /// Rows received but not folded yet (waiting for the next fold).
    pub fn pending(&self) -> usize {
        self.received.saturating_sub(self.next)
    }

    /// Rows below this were passed over and are not stored (0 once every row is).
    pub fn stored_from(&self) -> usize {
        self.stored_from
    }

    /// Stores rows passed over by [`LiveRun::skip_received`] (read again after the stream's
    /// end), for the in-focus indirect light; adds them to the summed transient.
    ///
    /// # Errors
    /// [`Error::Format`] (`rows`) unless `rows` are exactly rows `0..stored_from`, in order.
    pub fn refill(&mut self, rows: Vec<Arrival>) -> Result<()> {
        let per_row = self.capture.geometry.spads_per_row() * self.capture.geometry.nt;
        let k = self.stored_from;
        if rows.len() != k
            || rows
                .iter()
                .enumerate()
                .any(|(i, a)| a.index != i || a.data.len() != per_row)
        {
            return Err(Error::format(
                Path::new(&self.opts.capture_name),
                "rows",
                format!("rows 0:{k} read again, of {per_row} values"),
                format!("{} rows", rows.len()),
            ));
        }
        for a in rows {
            self.store(&a);
        }
        self.stored_from = 0;
        Ok(())
    }

    fn store(&mut self, a: &Arrival) {
        let per_row = self.capture.geometry.spads_per_row() * self.capture.geometry.nt;
        let nt = self.capture.geometry.nt;
        for h in a.data.chunks(nt) {
            for (t, &x) in self.transient.iter_mut().zip(h) {
                *t += f64::from(x);
            }
        }
        self.capture.data[a.index * per_row..(a.index + 1) * per_row].copy_from_slice(&a.data);
    }

    /// Folds the rows received but neither folded nor held into every probe; returns how
    /// many.
    ///
    /// # Errors
    /// The probes' errors.
    pub fn fold(&mut self) -> Result<usize> {
        let upto = self.received;
        if upto <= self.next {
            return Ok(0);
        }
        // next..upto less the held rows.
        let mut ranges = Vec::new();
        let mut a = self.next;
        for h in &self.held {
            if h.end <= a {
                continue;
            }
            if h.start >= upto {
                break;
            }
            if h.start > a {
                ranges.push(a..h.start);
            }
            a = a.max(h.end);
        }
        if a < upto {
            ranges.push(a..upto);
        }
        let mut n = 0;
        for rows in ranges {
            for p in &mut self.probes {
                let part = partial::accumulate(
                    &mut self.capture,
                    self.opts.file_bytes,
                    &self.opts.capture_name,
                    &self.opts.volume,
                    &p.task,
                    &self.opts.wave,
                    exec(self.opts.path),
                    rows.clone(),
                )?;
                let state = std::mem::replace(&mut p.state, part.clone());
                p.state = Partial::merge(vec![state, part], &[])?;
            }
            n += rows.len();
        }
        self.next = upto;
        self.folded += n;
        Ok(n)
    }

    /// Whether every row is folded.
    pub fn complete(&self) -> bool {
        self.folded == self.total_rows()
    }

    /// The probe `i`'s volume from the rows folded so far.
    ///
    /// # Errors
    /// As [`Partial::preview`].
    pub fn preview(&self, i: usize) -> Result<Finished> {
        self.probes[i].state.preview()
    }

    /// The in-focus indirect light over the whole scan, Γ from `direct` (the final direct
    /// light): as `vltm indirect --direct`.
    ///
    /// # Errors
    /// [`Error::Argument`] before every row is in; the probe's errors.
    pub fn indirect(&mut self, direct: &[f32], opts: &IndirectOptions) -> Result<IndirectOutput> {
        if self.received < self.total_rows() || self.stored_from > 0 {
            return Err(Error::arg(
                "indirect",
                format!(
                    "the in-focus indirect light needs the whole scan: {} of {} rows are in",
                    self.received - self.stored_from,
                    self.total_rows()
                ),
            ));
        }
        let gamma = gamma_mask(direct, opts.epsilon);
        let mut o = indirect_over(
            &mut self.capture,
            &self.opts.volume,
            &gamma,
            opts,
            &self.opts.wave,
            exec(self.opts.path),
        )?;
        o.direct = direct.to_vec();
        Ok(o)
    }
}

impl LiveRun {
    /// The `--focus` columns over the whole scan, leak-corrected as `vltm column` corrects
    /// them by default (Γ = direct light above `epsilon`·max over the volume, its direct
    /// returns zeroed): possible only at the end, once every row is stored and Γ is known.
    /// The running columns cannot be: they are folded row by row before Γ exists.
    ///
    /// # Errors
    /// As [`LiveRun::indirect`] (the whole scan), and the leak fit's and the column's errors.
    pub fn corrected_columns(&mut self, epsilon: f32) -> Result<Vec<crate::probe::Output>> {
        if self.received < self.total_rows() || self.stored_from > 0 {
            return Err(Error::arg(
                "live",
                "leak-corrected columns need the whole scan stored",
            ));
        }
        let (wave, ex) = (self.opts.wave, exec(self.opts.path));
        let volume = &self.opts.volume;
        let model = crate::probe::fit_over_volume(
            &mut self.capture,
            volume,
            epsilon,
            &wave,
            &crate::probe::LeakOptions::default(),
            ex,
        )?;
        let mut out = Vec::new();
        for &a in &self.opts.focus {
            let mut lc = crate::probe::LeakCorrected::new(&mut self.capture, &model);
            let g = ColumnGate::TwoBounce;
            out.push(crate::probe::column(
                &mut lc,
                a,
                volume,
                g,
                Shell::ALL,
                &wave,
                ex,
            )?);
        }
        Ok(out)
    }
}

/// `[0:8, 12:16]`-style row ranges.
fn show_rows(rows: &[Range<usize>]) -> String {
    let r: Vec<String> = rows
        .iter()
        .map(|r| format!("{}:{}", r.start, r.end))
        .collect();
    format!("[{}]", r.join(", "))
}

/// One volume to show and write: a probe's preview (or final) volume.
#[derive(Clone, Debug)]
pub struct View {
    /// `direct`, `column0`, …, `indirect`.
    pub tag: String,
    /// Figure title.
    pub title: String,
    /// One value per voxel.
    pub values: Vec<f32>,
    /// The figure (front and top views, axes, colour bar) as PNG bytes (empty for a point
    /// list volume).
    pub png: Vec<u8>,
    /// Focus marks drawn on the figure.
    pub marks: Vec<(Point, String)>,
    /// Peak value and its voxel.
    pub peak: (f32, Point),
}

fn encode_png(img: &image::RgbImage) -> Result<Vec<u8>> {
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png)
        .map_err(|e| Error::io("png", std::io::Error::other(e)))?;
    Ok(png.into_inner())
}

/// A view of `values` over `volume` with its figure.
///
/// # Errors
/// PNG encoding errors.
pub fn view(
    tag: &str,
    title: &str,
    values: Vec<f32>,
    volume: &Volume,
    marks: Vec<(Point, String)>,
) -> Result<View> {
    let png = match volume.axes {
        Some([x, y, z]) => encode_png(
            &Figure {
                data: &values,
                shape: volume.shape,
                x,
                y,
                z,
                title: title.to_string(),
                marks: marks.clone(),
            }
            .render(),
        )?,
        None => Vec::new(),
    };
    let (i, m) =
        values.iter().enumerate().fold(
            (0, f32::NEG_INFINITY),
            |a, (i, &x)| if x > a.1 { (i, x) } else { a },
        );
    let p = volume.points.get(i).copied().unwrap_or_default();
    Ok(View {
        tag: tag.to_string(),
        title: title.to_string(),
        values,
        png,
        marks,
        peak: (m, p),
    })
}

impl LiveRun {
    /// The views of every probe from the rows folded so far (titles say how many).
    ///
    /// # Errors
    /// As [`LiveRun::preview`].
    pub fn views(&self) -> Result<Vec<View>> {
        let mut out = Vec::new();
        for (i, p) in self.probes.iter().enumerate() {
            let f = self.preview(i)?;
            let marks = match p.task {
                Task::Column { focus, .. } => vec![(focus, "x_a".to_string())],
                _ => Vec::new(),
            };
            let title = if self.complete() {
                p.title.clone()
            } else if self.held.iter().all(|h| h.start == 0) {
                format!(
                    "{} (rows 0:{} of {})",
                    p.title,
                    self.folded,
                    self.total_rows()
                )
            } else {
                format!(
                    "{} ({} of {} rows)",
                    p.title,
                    self.folded,
                    self.total_rows()
                )
            };
            out.push(view(&p.tag, &title, f.output.values, &f.volume, marks)?);
        }
        Ok(out)
    }

    /// The summed transient's plot (log counts against path length) as PNG bytes; `None`
    /// while no count is positive.
    pub fn transient_png(&self) -> Option<Vec<u8>> {
        let g = &self.capture.geometry;
        let t = Transient {
            counts: &self.transient,
            t0: g.t0,
            dt: g.dt,
            title: format!(
                "summed transient, rows 0:{} of {}",
                self.received,
                self.total_rows()
            ),
            shade: None,
        };
        encode_png(&t.render().ok()?).ok()
    }
}

/// Output paths of a live run, from `--out F.npy` (or `F.h5`): probe `tag` is written to
/// `F.npy` for the direct light and `F.<tag>.npy` otherwise, its figure beside it as `.png`,
/// its state as `F.<tag>.part`; the summed transient as `F.transient.png`.
#[derive(Clone, Debug)]
pub struct Outputs {
    /// `--out`.
    pub out: PathBuf,
}

impl Outputs {
    fn tagged(&self, tag: Option<&str>, ext: &str) -> PathBuf {
        let stem = self.out.file_stem().unwrap_or_default().to_string_lossy();
        let name = match tag {
            Some(t) => format!("{stem}.{t}.{ext}"),
            None => format!("{stem}.{ext}"),
        };
        self.out.with_file_name(name)
    }

    fn main_tag(tag: &str) -> Option<&str> {
        (tag != "direct").then_some(tag)
    }

    /// The volume file of probe `tag`.
    pub fn volume(&self, tag: &str) -> PathBuf {
        let ext = self
            .out
            .extension()
            .map_or_else(|| "npy".to_string(), |e| e.to_string_lossy().into_owned());
        self.tagged(Self::main_tag(tag), &ext)
    }

    /// The figure of probe `tag`.
    pub fn png(&self, tag: &str) -> PathBuf {
        self.tagged(Self::main_tag(tag), "png")
    }

    /// The partial state of probe `tag`.
    pub fn state(&self, tag: &str) -> PathBuf {
        self.tagged(Some(tag), "part")
    }

    /// The summed transient's plot.
    pub fn transient(&self) -> PathBuf {
        self.tagged(Some("transient"), "png")
    }

    /// Every file the run writes for `tags`.
    pub fn all(&self, tags: &[&str]) -> Vec<PathBuf> {
        let mut v = vec![self.transient()];
        for t in tags {
            v.extend([self.volume(t), self.png(t), self.state(t)]);
        }
        v
    }

    /// Writes `views` (volumes and figures), the states of `run` and the transient, all or
    /// nothing.
    ///
    /// # Errors
    /// [`Error::Io`] and encoder errors; nothing is replaced then.
    pub fn write(&self, run: &LiveRun, views: &[View], capture: &Path) -> Result<Vec<PathBuf>> {
        let mut t = Transaction::new();
        let mut wrote = Vec::new();
        let volume = &run.opts.volume;
        for v in views {
            let p = self.volume(&v.tag);
            if crate::io::is_hdf5(&p) {
                let probe = run.probes.iter().find(|q| q.tag == v.tag);
                let cfg = match probe {
                    Some(q) => q.state.preview()?.output.config,
                    None => run.opts.wave.config(run.geometry())?,
                };
                let focus = probe.and_then(|q| q.state.focus());
                let meta = crate::export::h5::Provenance {
                    probe: &v.tag,
                    config: &cfg,
                    focus,
                    capture,
                };
                crate::export::h5::stage_volume(&mut t, &p, &v.values, volume, &meta)?;
            } else {
                crate::export::npy::stage_f32(&mut t, &p, &v.values, &volume.shape)?;
            }
            wrote.push(p);
            if !v.png.is_empty() {
                let p = self.png(&v.tag);
                t.stage(&p, |f| {
                    std::io::Write::write_all(f, &v.png).map_err(|e| Error::io(&p, e))
                })?;
                wrote.push(p);
            }
        }
        for q in &run.probes {
            let p = self.state(&q.tag);
            let bytes = q.state.to_bytes();
            t.stage(&p, |f| {
                std::io::Write::write_all(f, &bytes).map_err(|e| Error::io(&p, e))
            })?;
            wrote.push(p);
        }
        if let Some(png) = run.transient_png() {
            let p = self.transient();
            t.stage(&p, |f| {
                std::io::Write::write_all(f, &png).map_err(|e| Error::io(&p, e))
            })?;
            wrote.push(p);
        }
        t.commit()?;
        Ok(wrote)
    }
}

/// What the driver reports to its observer.
#[derive(Debug)]
pub enum Update<'a> {
    /// Rows were folded; `views` are the current volumes.
    Folded {
        /// The run.
        run: &'a LiveRun,
        /// The current views.
        views: &'a [View],
        /// Seconds the last fold took (the previews included) and the rows it folded.
        fold: (f64, usize),
        /// Whether a snapshot was written after this fold.
        snapshot: bool,
    },
    /// The final volumes (the in-focus indirect light included).
    Finished {
        /// The run.
        run: &'a LiveRun,
        /// The final views.
        views: &'a [View],
    },
}

/// Drives a live run: reads rows from `source` on a thread of its own, folds them in batches
/// as they come, writes a snapshot ([`Outputs::write`]) whenever the rows folded pass a
/// multiple of `every` (0: only at the end), and at the end writes the final volumes, the
/// in-focus indirect light included. `observe` sees every fold and the end.
///
/// On a source error the rows received before it are folded and written as a snapshot (the
/// states only grow: nothing is replaced by a state with fewer rows), then the error is
/// returned.
///
/// # Errors
/// The source's errors; the probes'; [`Error::Io`] writing the outputs.
pub fn drive(
    source: Box<dyn LiveSource>,
    run: &mut LiveRun,
    outputs: &Outputs,
    every: usize,
    capture: &Path,
    observe: &mut dyn FnMut(Update<'_>),
) -> Result<()> {
    let mut source = source;
    // A resumed run passes over the rows its states hold at the start of the scan, unless
    // they are needed for the in-focus indirect light and the source cannot read them again
    // at the end (standard input).
    let k = run.held_prefix();
    if k > 0
        && run.received() == 0
        && (run.opts.indirect.is_none() || source.can_reread())
        && source.skip_rows(k)
    {
        run.skip_received(k)?;
    }
    let (tx, rx) = mpsc::sync_channel::<Result<Arrival>>(1024);
    let reader = std::thread::spawn(move || {
        loop {
            let r = source.next_row();
            let stop = !matches!(r, Ok(Some(_)));
            let item = r.transpose();
            if let Some(item) = item
                && tx.send(item).is_err()
            {
                return source;
            }
            if stop {
                return source;
            }
        }
    });
    let mut snapshot_at = run.folded();
    let mut failure = None;
    let mut ended = false;
    while !ended {
        // Wait for one row, then take whatever else has arrived.
        let mut batch = Vec::new();
        match rx.recv() {
            Ok(r) => batch.push(r),
            Err(_) => ended = true,
        }
        while let Ok(r) = rx.try_recv() {
            batch.push(r);
        }
        for r in batch {
            match r.and_then(|a| run.receive(a)) {
                Ok(()) => {}
                Err(e) => {
                    failure = Some(e);
                    ended = true;
                    break;
                }
            }
        }
        let t = Instant::now();
        let n = run.fold()?;
        let unsaved = failure.is_some() && run.folded() > snapshot_at && !run.complete();
        if n == 0 && !unsaved {
            // Nothing new to show (a resumed run re-reading rows it holds, or the end).
            continue;
        }
        let views = run.views()?;
        let fold = (t.elapsed().as_secs_f64(), n);
        let due = every > 0 && run.folded() / every > snapshot_at / every;
        let snapshot = (due || unsaved) && !run.complete();
        if snapshot {
            outputs.write(run, &views, capture)?;
            snapshot_at = run.folded();
        }
        observe(Update::Folded {
            run,
            views: &views,
            fold,
            snapshot,
        });
    }
    drop(rx);
    let source = reader.join().ok();
    if let Some(e) = failure {
        return Err(e);
    }
    if !run.complete() {
        return Err(Error::arg(
            "live",
            format!(
                "the source ended after {} of {} rows",
                run.received(),
                run.total_rows()
            ),
        ));
    }
    let mut views = run.views()?;
    if let Some(opts) = run.opts.indirect {
        if run.stored_from() > 0 {
            // The rows passed over at the start, read again from the finished file.
            let mut source = source
                .ok_or_else(|| Error::arg("live", "the reader thread of the source panicked"))?;
            let rows = source.reread(0..run.stored_from())?;
            run.refill(rows)?;
        }
        let direct = views[0].values.clone();
        let o = run.indirect(&direct, &opts)?;
        let title = format!(
            "in-focus indirect light (epsilon {}, r0 {:.3} m)",
            opts.epsilon, o.shell.r0
        );
        views.push(view(
            "indirect",
            &title,
            o.values,
            &run.opts.volume,
            Vec::new(),
        )?);
        // With the leak correction on (as for the indirect light), the columns once more over
        // the stored rows, corrected as `vltm column` corrects them.
        if opts.leak.is_some() {
            let cols = run.corrected_columns(opts.epsilon)?;
            for (i, (o, a)) in cols.into_iter().zip(run.opts.focus.clone()).enumerate() {
                let title = format!(
                    "column --focus {},{},{} --gate two-bounce (leak-corrected, whole scan)",
                    a[0], a[1], a[2]
                );
                let marks = vec![(a, "x_a".to_string())];
                let tag = format!("column{i}.corrected");
                views.push(view(&tag, &title, o.values, &run.opts.volume, marks)?);
            }
        }
    }
    outputs.write(run, &views, capture)?;
    observe(Update::Finished { run, views: &views });
    Ok(())
}
