//! Driving a live run ([`drive()`]): the source read on a thread of its own, rows folded in
//! batches as they come, snapshots every `K` rows, and at the end the final volumes, the
//! in-focus indirect light included; an observer sees every fold ([`Update`]).

use std::path::Path;
use std::sync::mpsc;
use std::time::Instant;

use super::outputs::Outputs;
use super::run::LiveRun;
use super::source::{Arrival, LiveSource};
use super::view::{View, view};
use crate::error::{Error, Result};

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
        // `--leak-correct model`: the surface model of the stored rows (the windows when it
        // is not used; the run records which).
        let model = if opts.leak.is_some() {
            run.surface_model()?
        } else {
            None
        };
        let o = run.indirect(&direct, &opts, model.as_ref())?;
        let title = format!(
            "in-focus indirect light (epsilon {}, r0 {:.3} m{})",
            opts.epsilon,
            o.shell.r0,
            if model.is_some() {
                ", surface model subtracted"
            } else {
                ""
            }
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
            let cols = run.corrected_columns(opts.epsilon, model.as_ref())?;
            let how = if model.is_some() {
                "surface model subtracted"
            } else {
                "leak-corrected"
            };
            for (i, (o, a)) in cols.into_iter().zip(run.opts.focus.clone()).enumerate() {
                let title = format!(
                    "column --focus {},{},{} --gate two-bounce ({how}, whole scan)",
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
