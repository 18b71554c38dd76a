//! What a live run computes once every row is in: the in-focus indirect light (its Γ needs
//! the whole diagonal) and the `--focus` columns leak-corrected over the whole scan, by the
//! time windows or by a surface model of the stored rows ([`LiveRun::surface_model`]).

use super::probes::exec;
use super::run::{EndModel, LiveRun};
use crate::error::{Error, Result};
use crate::io::capture::RowSource;
use crate::probe::{
    ColumnGate, IndirectOptions, IndirectOutput, ModelOutcome, Shell, SurfaceModel, gamma_mask,
    indirect_over, model_of_capture,
};

impl LiveRun {
    /// Checks that every row is stored: else an error naming `arg`, saying that `what` needs
    /// the whole scan.
    fn whole_scan(&self, arg: &str, what: &str) -> Result<()> {
        if self.received < self.total_rows() || self.stored_from > 0 {
            return Err(Error::arg(
                arg,
                format!(
                    "the {what} needs the whole scan: {} of {} rows are in",
                    self.received - self.stored_from,
                    self.total_rows()
                ),
            ));
        }
        Ok(())
    }

    /// The surface model of the whole scan ([`model_of_capture`] with
    /// [`super::LiveOptions::model`] and the run's wave options), recorded in
    /// [`LiveRun::end_model`]: `Ok(None)` when none is asked for or when it is not used (the
    /// caller then uses the time windows).
    ///
    /// # Errors
    /// [`Error::Argument`] before every row is in; the model's option errors.
    pub fn surface_model(&mut self) -> Result<Option<SurfaceModel>> {
        let Some(opts) = self.opts.model.clone() else {
            return Ok(None);
        };
        self.whole_scan("leak_correct", "leak correction")?;
        let (wave, ex) = (self.opts.wave, exec(self.opts.path));
        match model_of_capture(&mut self.capture, &wave, &opts, ex)? {
            ModelOutcome::Fitted(m) => {
                self.end_model = Some(EndModel::Used {
                    facets: m.facets.amplitudes.iter().filter(|&&a| a > 0.0).count(),
                    surfels: m.model.surfels().len(),
                    explained: m.explained,
                    photon_noise: m.photon_noise,
                    seconds: m.seconds,
                });
                Ok(Some(*m))
            }
            ModelOutcome::Unexplained { reason, .. } => {
                self.end_model = Some(EndModel::Unused(reason));
                Ok(None)
            }
        }
    }

    /// The in-focus indirect light over the whole scan, Γ from `direct` (the final direct
    /// light): as `vltm indirect --direct`; with `model` (from [`LiveRun::surface_model`]) on
    /// the rows minus the model and no other correction, as `vltm indirect --leak-correct
    /// model`.
    ///
    /// # Errors
    /// [`Error::Argument`] before every row is in; the probe's errors.
    pub fn indirect(
        &mut self,
        direct: &[f32],
        opts: &IndirectOptions,
        model: Option<&SurfaceModel>,
    ) -> Result<IndirectOutput> {
        self.whole_scan("indirect", "in-focus indirect light")?;
        let gamma = gamma_mask(direct, opts.epsilon);
        let (volume, wave, ex) = (&self.opts.volume, self.opts.wave, exec(self.opts.path));
        let mut o = match model {
            Some(m) => {
                let opts = IndirectOptions {
                    leak: None,
                    ..*opts
                };
                let mut src = m.subtracted(&mut self.capture);
                indirect_over(&mut src, volume, &gamma, &opts, &wave, ex)?
            }
            None => indirect_over(&mut self.capture, volume, &gamma, opts, &wave, ex)?,
        };
        o.direct = direct.to_vec();
        Ok(o)
    }
    /// The `--focus` columns over the whole scan, leak-corrected as `vltm column` corrects
    /// them by default (Γ = direct light above `epsilon`·max over the volume, its direct
    /// returns zeroed), or with `model` (from [`LiveRun::surface_model`]) on the rows minus the
    /// model, as `vltm column --leak-correct model`: possible only at the end, once every row
    /// is stored and Γ is known. The running columns cannot be: they are folded row by row
    /// before Γ exists.
    ///
    /// # Errors
    /// As [`LiveRun::indirect`] (the whole scan), and the leak fit's and the column's errors.
    pub fn corrected_columns(
        &mut self,
        epsilon: f32,
        model: Option<&SurfaceModel>,
    ) -> Result<Vec<crate::probe::Output>> {
        self.whole_scan("live", "leak correction")?;
        let (wave, ex) = (self.opts.wave, exec(self.opts.path));
        let volume = &self.opts.volume;
        // The model subtracted, or the windows of Γ fitted once.
        let windows;
        let fix = match model {
            Some(m) => Fix::Model(m),
            None => {
                windows = crate::probe::fit_over_volume(
                    &mut self.capture,
                    volume,
                    epsilon,
                    &wave,
                    &crate::probe::LeakOptions::default(),
                    ex,
                )?;
                Fix::Windows(&windows)
            }
        };
        let mut out = Vec::new();
        for &a in &self.opts.focus {
            let (mut subtracted, mut gated);
            let src: &mut dyn RowSource = match fix {
                Fix::Model(m) => {
                    subtracted = m.subtracted(&mut self.capture);
                    &mut subtracted
                }
                Fix::Windows(w) => {
                    gated = crate::probe::LeakCorrected::new(&mut self.capture, w);
                    &mut gated
                }
            };
            out.push(crate::probe::column(
                src,
                a,
                volume,
                ColumnGate::TwoBounce,
                Shell::ALL,
                &wave,
                ex,
            )?);
        }
        Ok(out)
    }
}

/// How the end's columns are corrected.
#[derive(Clone, Copy)]
enum Fix<'a> {
    /// The surface model subtracted.
    Model(&'a SurfaceModel),
    /// The time windows of Γ zeroed.
    Windows(&'a crate::probe::DirectModel),
}
