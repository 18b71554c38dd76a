//! The probes of a live run ([`LiveProbe`]) and what they need besides the rows
//! ([`LiveOptions`]): the direct light and one two-bounce column per focus, each started from
//! the resumed state that matches it (or empty), all states holding the same rows.

use std::ops::Range;
use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::exec::{EvalPath, Exec};
use crate::io::capture::Capture;
use crate::probe::partial::{self, Partial, Task};
use crate::probe::{ColumnGate, IndirectOptions, ModelOptions, Shell, Wave};
use crate::volume::Volume;
use vltm_kernel::Point;

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
    /// The end's leak correction by a surface model fitted to the stored rows
    /// ([`crate::probe::model_of_capture`], `--leak-correct model`), when `indirect` asks for
    /// a leak correction: the in-focus indirect light and the corrected columns then run on
    /// the rows minus the model, or with the time windows when the model is not used
    /// ([`super::LiveRun::end_model`] says which and why). `None`: the time windows.
    pub model: Option<ModelOptions>,
    /// The capture's name, recorded in the states (informational).
    pub capture_name: String,
    /// The capture file's size in bytes, recorded in the states' capture identity: a
    /// finished file's size (a replayed capture), 0 for a stream whose final size is not
    /// known when a state is written (a followed file, standard input). 0 matches any size
    /// when states merge ([`Partial::merge`]).
    pub file_bytes: u64,
}

/// The execution options of a live run's probes: no progress (the run reports its own).
pub(super) fn exec(path: EvalPath) -> Exec<'static> {
    Exec {
        progress: None,
        path,
    }
}

/// The probes of a run over `capture` with `opts` (direct light first, then the columns in
/// `opts.focus` order), each merged with its state in `resume` (a probe without one starts
/// empty), and the rows the states hold (ascending, disjoint; none without states).
///
/// # Errors
/// [`Error::Argument`] (`resume`) for a state that matches no probe, another capture or other
/// parameters, states of different rows, or a probe left without a state when the others have
/// one; the probes' configuration errors.
pub(super) fn probes(
    capture: &mut Capture,
    opts: &LiveOptions,
    resume: Vec<(PathBuf, Partial)>,
) -> Result<(Vec<LiveProbe>, Vec<Range<usize>>)> {
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
            capture,
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
    Ok((probes, held.unwrap_or_default()))
}

/// `[0:8, 12:16]`-style row ranges.
fn show_rows(rows: &[Range<usize>]) -> String {
    let r: Vec<String> = rows
        .iter()
        .map(|r| format!("{}:{}", r.start, r.end))
        .collect();
    format!("[{}]", r.join(", "))
}
