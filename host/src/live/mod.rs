//! Following a scan while it is acquired (`vltm live`): rows arrive one at a time from a
//! [`LiveSource`] (a PTU file still being written or a pipe,
//! [`Follower`](crate::io::ptu::Follower); any capture replayed at a fixed rate, [`Replay`]), are folded into the direct light and the columns at
//! the focus points as they come, and every `K` rows the current volumes, their figures and
//! the partial states are written at once ([`crate::atomic`]). When the last row is in, the
//! in-focus indirect light (whose Γ needs the whole diagonal) is computed over the whole scan,
//! leak-corrected by the time windows or, with [`LiveOptions::model`], by a surface model
//! fitted to the stored rows and subtracted ([`LiveRun::end_model`] says which).
//!
//! # Folding
//!
//! Each probe keeps a [`Partial`] state. The rows that arrived since the last fold are run as
//! one part ([`crate::probe::partial::accumulate`]) and merged into it ([`Partial::merge`]):
//! the batch grows by itself when the rows arrive faster than they are folded, and is one row at
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
//!
//! # Modules
//!
//! `probes` ([`LiveProbe`], [`LiveOptions`]: the probes, started from the states of an
//! interrupted run), `run` ([`LiveRun`]: the rows received, the probes' states, folding),
//! `end` (what needs the whole scan: the surface model, the in-focus indirect light, the
//! leak-corrected columns), `view` ([`View`]: a volume with its figure; the transient's plot), `outputs`
//! ([`Outputs`]: the files a run writes, all or nothing), `drive` ([`drive()`]: the reader
//! thread, batches, snapshots, the end), `source` ([`LiveSource`]: where the rows come from).
//!
//! [`Partial`]: crate::probe::partial::Partial
//! [`Partial::merge`]: crate::probe::partial::Partial::merge
//! [`Partial::preview`]: crate::probe::partial::Partial::preview

mod drive;
mod end;
mod outputs;
mod probes;
mod run;
mod source;
mod view;

pub use drive::{Update, drive};
pub use outputs::Outputs;
pub use probes::{LiveOptions, LiveProbe};
pub use run::{EndModel, LiveRun};
pub use source::{Arrival, LiveSource, Replay};
pub use view::{View, view};
