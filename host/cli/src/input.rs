//! Reading a capture for a command: conventions a file does not record (`--delta-t`,
//! `--t-start`, `--grid-width`, for `.mat` captures) and the preprocessing of raw counts
//! (`--t-min`, `--t-max`, `--rebin`, `--background`, [`vltm::io::prep`]), run and reported
//! as every front end runs it ([`vltm::io::prep::with_prep`]).

use crate::console::{Failure, say, tell};
use clap::Args;
use vltm::io::prep::{self, Prep};
use vltm::io::{self, RowSource};
use vltm_kernel::Point;

/// How to read a capture and preprocess its counts.
#[derive(Args, Debug, Default)]
pub struct Input {
    /// Bin width in metres of path (.mat: overrides the layout's convention; Stanford: 4 ps).
    #[arg(long, value_name = "M")]
    pub delta_t: Option<f64>,
    /// Path length of bin 0 in metres (.mat: overrides the layout's convention; Stanford: 0).
    #[arg(long, value_name = "M", allow_hyphen_values = true)]
    pub t_start: Option<f64>,
    /// Half-width W of a confocal .mat grid [-W, W]^2 in metres (Stanford: the file's width).
    #[arg(long, value_name = "M")]
    pub grid_width: Option<f64>,
    /// Start of the time window (inclusive): metres of path (0.72, 0.72m) or a bin (600b).
    #[arg(long, value_name = "T")]
    pub t_min: Option<String>,
    /// End of the time window (exclusive): metres of path or a bin (2048b).
    #[arg(long, value_name = "T")]
    pub t_max: Option<String>,
    /// Sum K consecutive bins (after the window).
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub rebin: usize,
    /// Subtract a floor per histogram: auto (from bins no return from the volume can reach),
    /// none, or counts per source bin.
    #[arg(long, value_name = "auto|VALUE")]
    pub background: Option<String>,
}

impl Input {
    /// The `.mat` overrides.
    pub fn mat_options(&self) -> io::mat::MatOptions {
        io::mat::MatOptions {
            delta_t: self.delta_t,
            t_start: self.t_start,
            grid_width: self.grid_width,
        }
    }

    /// The preprocessing asked for, if any ([`Prep::parse`]).
    pub fn prep(&self) -> vltm::Result<Option<Prep>> {
        Prep::parse(
            self.t_min.as_deref(),
            self.t_max.as_deref(),
            self.rebin,
            self.background.as_deref(),
        )
    }
}

/// Runs `f` on `src` through the preprocessing asked for ([`prep::with_prep`]): prints what
/// it did (also when its check then fails), warns when the background left most histograms
/// empty, and refuses a result made of empty histograms only.
pub fn with_prep<T, E: Into<Failure>>(
    input: &Input,
    src: &mut dyn RowSource,
    points: &[Point],
    sigma: f64,
    f: impl FnOnce(&mut dyn RowSource) -> Result<T, E>,
) -> Result<T, Failure> {
    let (out, report) = prep::with_prep(
        input.prep()?,
        src,
        points,
        sigma,
        |rows| f(rows).map_err(Into::into),
        |r| say!("preprocessing: {}", r.summary),
    )?;
    if let Some(w) = report.and_then(|r| r.warning) {
        tell!("vltm: warning: {w}");
    }
    Ok(out)
}
