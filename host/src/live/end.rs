//! What a live run computes once every row is in: the in-focus indirect light (its Γ needs
//! the whole diagonal) and the `--focus` columns leak-corrected over the whole scan.

use super::probes::exec;
use super::run::LiveRun;
use crate::error::{Error, Result};
use crate::probe::{ColumnGate, IndirectOptions, IndirectOutput, Shell, gamma_mask, indirect_over};

impl LiveRun {
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
