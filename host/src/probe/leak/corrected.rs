//! The capture with the direct light removed, as a [`RowSource`], row by row.

use super::energy::GateEnergy;
use super::fit::DirectModel;
use crate::error::Result;
use crate::io::capture::{Geometry, RowSource};
use rayon::prelude::*;
use vltm_kernel::Point;

/// A [`RowSource`] that returns `H − H_d`: the capture with the fitted direct light removed,
/// row by row (nothing held but one row).
pub struct LeakCorrected<'a> {
    src: &'a mut dyn RowSource,
    model: &'a DirectModel,
    /// The energy removed from the rows read, and a copy of the last raw row (when measuring).
    energy: Option<(GateEnergy, Vec<f32>)>,
}

impl<'a> LeakCorrected<'a> {
    /// Wraps `src` with the model fitted to it.
    pub fn new(src: &'a mut dyn RowSource, model: &'a DirectModel) -> Self {
        Self {
            src,
            model,
            energy: None,
        }
    }

    /// As [`LeakCorrected::new`], also summing the energy the gate removes from the rows
    /// read ([`LeakCorrected::energy`]; one row copy per read).
    pub fn measuring(src: &'a mut dyn RowSource, model: &'a DirectModel) -> Self {
        Self {
            src,
            model,
            energy: Some((GateEnergy::default(), Vec::new())),
        }
    }

    /// The energy removed so far (when measuring).
    pub fn energy(&self) -> Option<GateEnergy> {
        self.energy.as_ref().map(|(e, _)| *e)
    }
}

impl RowSource for LeakCorrected<'_> {
    fn geometry(&self) -> &Geometry {
        self.src.geometry()
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        let x = self.src.read_row(l, out)?;
        match &mut self.energy {
            Some((e, raw)) => {
                raw.clone_from(out);
                self.model.subtract_row(l, out);
                e.add(raw, out);
            }
            None => self.model.subtract_row(l, out),
        }
        Ok(x)
    }

    fn read_rows(&mut self, first: usize, out: &mut [(Point, Vec<f32>)]) -> Result<()> {
        if self.energy.is_some() {
            // Measuring: the energies summed row by row, in order.
            for (l, (x, h)) in (first..).zip(out.iter_mut()) {
                *x = self.read_row(l, h)?;
            }
            return Ok(());
        }
        self.src.read_rows(first, out)?;
        let model = self.model;
        out.par_iter_mut()
            .enumerate()
            .for_each(|(i, (_, h))| model.subtract_row(first + i, h));
        Ok(())
    }

    fn reads_in_parallel(&self) -> bool {
        self.energy.is_none()
    }

    fn rows(&self) -> std::ops::Range<usize> {
        self.src.rows()
    }
}
