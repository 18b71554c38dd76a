//! The energy a correction removes, summed row by row.

use crate::error::{Error, Result};

/// The energy the gate method removes, summed over rows (any order, any split):
/// `Σ H²` of the capture and of the zeroed samples.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GateEnergy {
    /// `Σ H²` over the finite samples read.
    pub total: f64,
    /// `Σ H²` over the samples the gate zeroed.
    pub cut: f64,
}

impl GateEnergy {
    /// Adds one row: `raw` as read, `kept` after [`DirectModel::subtract_row`](crate::probe::DirectModel::subtract_row).
    pub fn add(&mut self, raw: &[f32], kept: &[f32]) {
        for (a, b) in raw.iter().zip(kept) {
            let a = f64::from(*a);
            if a.is_finite() {
                self.total += a * a;
                if *b == 0.0 {
                    self.cut += a * a;
                }
            }
        }
    }

    /// The fraction removed ([`DirectModel::explained`](crate::probe::DirectModel::explained)).
    ///
    /// # Errors
    /// [`Error::Argument`] (`leak_correct`) when nothing was removed: the capture holds no
    /// light at the direct return times.
    pub fn explained(&self) -> Result<f64> {
        if self.cut.is_nan() || self.cut <= 0.0 {
            return Err(Error::arg(
                "leak_correct",
                "the capture holds no light at the direct (3-vertex) return times of Γ's \
                 voxels: there is no direct light to remove",
            ));
        }
        Ok(self.cut / self.total)
    }
}
