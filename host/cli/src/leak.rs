//! The leak correction of `column`, `row`, `relight`, `indirect` and `matrix` (on by
//! default): `--leak-correct gate`, Γ over the probe's volume and the capture's direct-return
//! windows of Γ zeroed as the rows stream in (`vltm::probe::leak`), or `--leak-correct
//! model`, a surface model fitted to the capture and subtracted (`vltm::probe::model_of_capture`),
//! with the windows as its fallback, or `--leak-correct auto`, the windows' pass first and the
//! model where the light they leave lies next to them ([`vltm::probe::AUTO_ADJACENCY`]); and
//! the lines that say which was used and what it removed.

use std::path::Path;

use vltm::exec::{Exec, Progress as _};
use vltm::io::RowSource;
use vltm::probe::{
    self, AUTO_ADJACENCY, DirectModel, LeakOptions, ModelOptions, ModelOutcome, SurfaceModel, Wave,
};
use vltm::volume::Volume;

use crate::args::{LeakArg, LeakArgs};
use crate::console::{Failure, flag, say};

/// The correction a run used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Used {
    /// The time windows of Γ's direct returns.
    Gate,
    /// The surface model, subtracted.
    Model,
}

/// What a command's leak options ask for.
pub(crate) struct Leak {
    /// The method, `None` with `--no-leak-correct`.
    pub(crate) method: Option<LeakArg>,
    /// Γ's threshold of the windows (`--leak-epsilon`).
    pub(crate) epsilon: f32,
    /// Whether the capture holds the physical laser's falloff (the model renders it).
    pub(crate) falloff: bool,
}

impl Leak {
    /// The options of `column`, `row`, `relight` and `matrix` for `capture`.
    pub(crate) fn of(args: &LeakArgs, capture: &Path) -> Result<Self, Failure> {
        Self::new(args.method(), args.leak_epsilon, capture)
    }

    /// `method` (`None`: no correction) with the windows' threshold `epsilon`, for `capture`.
    pub(crate) fn new(
        method: Option<LeakArg>,
        epsilon: f32,
        capture: &Path,
    ) -> Result<Self, Failure> {
        let falloff = match method {
            Some(LeakArg::Model | LeakArg::Auto) => vltm::io::laser_falloff_in_data(capture)?.0,
            _ => false,
        };
        Ok(Self {
            method,
            epsilon,
            falloff,
        })
    }
}

/// `--leak-correct model`: the surface model of `src`'s direct light and its summary line, or
/// `None` after one warning line that says why it is not used (the caller then uses the time
/// windows). Options out of range and read errors are errors.
pub(crate) fn fit_model(
    src: &mut dyn RowSource,
    wave: &Wave,
    falloff: bool,
    exec: Exec<'_>,
) -> Result<Option<SurfaceModel>, Failure> {
    let opts = ModelOptions::with_laser_falloff(falloff);
    match probe::model_of_capture(src, wave, &opts, exec)? {
        ModelOutcome::Fitted(m) => {
            let lit = m.facets.amplitudes.iter().filter(|&&a| a > 0.0).count();
            say_model(
                lit,
                m.model.surfels().len(),
                (m.explained, m.photon_noise),
                m.seconds,
            );
            Ok(Some(*m))
        }
        ModelOutcome::Unexplained { reason, .. } => {
            warn_unused(&reason);
            Ok(None)
        }
    }
}

/// The line of a surface model that is subtracted: its lit facets, surfels, the energy it
/// explains (and the share of the capture's photon noise, for photon counts) and its time.
pub(crate) fn say_model(
    facets: usize,
    surfels: usize,
    (explained, noise): (f64, Option<f64>),
    seconds: f64,
) {
    let noise = noise.map_or(String::new(), |n| {
        format!(" (its photon noise holds {n:.4})")
    });
    say!(
        "leak correction (--leak-correct model): the surface model ({facets} facets, {surfels} surfels) explains {explained:.4} of the capture's energy{noise} and is subtracted ({seconds:.2} s)"
    );
}

/// The warning of a surface model that is not used, with the library's `reason`.
pub(crate) fn warn_unused(reason: &str) {
    let reason = vltm::error::respell(reason, flag);
    crate::progress::BARS.warn(&format!(
        "leak correction: {reason}; using the time windows (--leak-correct gate)"
    ));
}

/// `--leak-correct auto`: whether to try the surface model after the windows' pass `gate`
/// ([`vltm::probe::DirectModel::auto_prefers_model`]), and the line that says so.
pub(crate) fn auto_tries_model(gate: &DirectModel) -> bool {
    let a = gate.adjacency.unwrap_or(0.0);
    let model = gate.auto_prefers_model();
    let (cmp, then) = if model {
        (
            ">=",
            "trying the surface model (the windows cut through light that goes on past them)",
        )
    } else {
        ("<", "the windows (what they leave stands apart from them)")
    };
    say!(
        "leak correction (--leak-correct auto): {a:.2} of the energy the windows leave lies within one window half-width of them ({cmp} {AUTO_ADJACENCY}): {then}"
    );
    model
}

/// The line of the time windows' correction.
pub(crate) fn say_gate(explained: f64, voxels: Option<usize>, seconds: Option<f64>) {
    let of = voxels.map_or_else(String::new, |n| format!("'s {n} voxels"));
    let took = seconds.map_or_else(String::new, |s| format!(" ({s:.2} s)"));
    say!(
        "leak correction (--no-leak-correct to skip): {explained:.4} of the capture's energy was in the 3-vertex windows of Γ{of} and removed{took}"
    );
}

/// Runs `probe` on the rows of `src` leak-corrected as `leak` asks: the windows of Γ = direct
/// light above `leak.epsilon`·max over `volume` (an extra diagonal pass), or the surface model
/// (its passes; the windows when it is not used), or on `src` as it is (`--no-leak-correct`).
/// Returns the result and the correction used.
pub(crate) fn corrected<T>(
    src: &mut dyn RowSource,
    volume: &Volume,
    leak: &Leak,
    (wave, exec): (&Wave, Exec<'_>),
    probe: impl FnOnce(&mut dyn RowSource) -> vltm::Result<T>,
) -> Result<(T, Option<Used>), Failure> {
    let Some(method) = leak.method else {
        return Ok((probe(src)?, None));
    };
    if method == LeakArg::Model
        && let Some(m) = fit_model(src, wave, leak.falloff, exec)?
    {
        return Ok((probe(&mut m.subtracted(src))?, Some(Used::Model)));
    }
    let gate = probe::fit_over_volume(
        src,
        volume,
        leak.epsilon,
        wave,
        &LeakOptions::default(),
        exec,
    )?;
    say_gate(
        gate.explained,
        Some(gate.points().len()),
        Some(gate.seconds),
    );
    if method == LeakArg::Auto
        && auto_tries_model(&gate)
        && let Some(m) = fit_model(src, wave, leak.falloff, exec)?
    {
        return Ok((probe(&mut m.subtracted(src))?, Some(Used::Model)));
    }
    let mut lc = probe::LeakCorrected::new(src, &gate);
    Ok((probe(&mut lc)?, Some(Used::Gate)))
}
