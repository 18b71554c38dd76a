//! The leak corrections of `column`, `indirect`, `relight` and `row`: `leak_correct=True` or
//! `"gate"`, the time windows of Γ's direct returns ([`corrected`], as the command line's
//! `--leak-correct gate`), and `leak_correct="model"`, the surface model of the capture's
//! direct light (`--leak-correct model`, `vltm::probe::model_of_capture`), fitted to the
//! whole (preprocessed) capture before a probe runs on the capture minus it; or, when it is
//! not used, the reason, which the run reports as a warning before it takes the windows; and
//! `leak_correct="auto"` (`--leak-correct auto`), the windows' pass first and the model only
//! where the energy they leave lies next to them ([`vltm::probe::AUTO_ADJACENCY`]).

use vltm::exec::Exec;
use vltm::io::RowSource;
use vltm::probe::{
    self, DirectModel, Gamma, LeakCorrected, LeakOptions, ModelOptions, ModelOutcome,
    SurfaceModel, Wave,
};

use crate::capture::{NativeCapture, Store};
use crate::job::Job;

/// Whether the capture's file holds the physical laser's falloff (a y-tal render), which the
/// model then renders (arrays and `.mat` captures hold none).
pub(crate) fn falloff_of(cap: &NativeCapture) -> vltm::Result<bool> {
    match &cap.store {
        Store::File { path, .. } => Ok(vltm::io::laser_falloff_in_data(path)?.0),
        Store::Memory { .. } => Ok(false),
    }
}

/// The surface model of `src`, or why it is not used (option names spelled as keywords).
///
/// # Errors
/// Read errors and options out of range; everything that keeps the model from being used is
/// the `Err` reason inside.
pub(crate) fn surface_model(
    src: &mut dyn RowSource,
    wave: &Wave,
    falloff: bool,
    exec: Exec<'_>,
) -> vltm::Result<Result<SurfaceModel, String>> {
    let opts = ModelOptions::with_laser_falloff(falloff);
    Ok(match probe::model_of_capture(src, wave, &opts, exec)? {
        ModelOutcome::Fitted(m) => Ok(*m),
        ModelOutcome::Unexplained { reason, .. } => {
            Err(vltm::error::respell(&reason, crate::param))
        }
    })
}

/// The warning of a model that is not used.
pub(crate) fn fallback_warning(reason: &str) -> String {
    format!("leak correction: {reason}; using the time windows (leak_correct=\"gate\")")
}

/// `probe` on the rows of `src`, leak-corrected with Γ above `epsilon`·max over `vol` (as
/// the command line's `row` and `relight`), or on `src` as it is for `None`; with the energy
/// the correction removed.
pub(crate) fn corrected<T>(
    src: &mut dyn RowSource,
    vol: &vltm::volume::Volume,
    epsilon: Option<f32>,
    wave: &Wave,
    exec: Exec<'_>,
    probe: impl FnOnce(&mut dyn RowSource) -> vltm::Result<T>,
) -> vltm::Result<(T, Option<f64>)> {
    let Some(e) = epsilon else {
        return Ok((probe(src)?, None));
    };
    let model = probe::fit_over_volume(src, vol, e, wave, &LeakOptions::default(), exec)?;
    let mut lc = LeakCorrected::new(src, &model);
    Ok((probe(&mut lc)?, Some(model.explained)))
}

/// Zeroes the voxels outside `mask` (a column's `mask_epsilon`).
pub(crate) fn apply_mask(values: &mut [f32], mask: &[bool]) {
    values
        .iter_mut()
        .zip(mask)
        .for_each(|(x, &k)| *x *= f32::from(u8::from(k)));
}

/// `leak_correct="auto"`: the windows `job` would use on `rows` (their pass: over Γ of
/// `indirect`, or over the volume of a column, row or relight), as the command line's
/// `--leak-correct auto` measures them first; `None` for a job without windows.
pub(crate) fn auto_windows(
    rows: &mut dyn RowSource,
    vol: &vltm::volume::Volume,
    job: &Job,
    wave: &Wave,
    exec: Exec<'_>,
) -> vltm::Result<Option<DirectModel>> {
    let gate = LeakOptions::default();
    Ok(Some(match job {
        Job::Indirect {
            opts,
            direct: Some(d),
            ..
        } => {
            let gamma = probe::gamma_mask(d, opts.epsilon);
            let lo = opts.leak.unwrap_or(gate);
            probe::fit_over_gamma(rows, vol, &gamma, wave, &lo, exec)?
        }
        Job::Column {
            leak_epsilon: Some(le),
            ..
        }
        | Job::Relight {
            leak_epsilon: Some(le),
            ..
        }
        | Job::Row {
            leak_epsilon: Some(le),
            ..
        } => probe::fit_over_volume(rows, vol, *le, wave, &gate, exec)?,
        _ => return Ok(None),
    }))
}

/// A column's `mask_epsilon`: the voxels whose direct light in `rows` is above `e`·max.
pub(crate) fn column_mask(
    rows: &mut dyn RowSource,
    vol: &vltm::volume::Volume,
    e: f32,
    wave: &Wave,
    exec: Exec<'_>,
) -> vltm::Result<Vec<bool>> {
    let (g, _) = Gamma::measure(rows, vol, e, "mask_epsilon", wave, exec)?;
    Ok(g.non_empty("mask_epsilon")?.mask)
}
