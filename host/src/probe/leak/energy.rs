//! The energy a correction removes, summed row by row, and where the energy it leaves lies.
//!
//! **Adjacency** ([`GateEnergy::adjacency`]): of the energy the windows leave (`Σ H²` outside
//! them), the share within one window half-width of a zeroed sample of the same histogram.
//! Where the windows separate the direct light cleanly (small objects, whose inter-reflections
//! arrive apart from their direct returns) little is left next to them; where they cut
//! through light that goes on past their edges (extended surfaces: their direct light spills
//! past the windows and their two-bounce light arrives in and around them), most is. Measured
//! on seven captures (docs/indirect-light.md): 0.03–0.11 on the simulator's patches and points,
//! 0.68–0.72 on the path-traced panel/figure and corner. Cost: one more pass over each row's
//! samples and one flag per bin of a histogram.

use crate::error::{Error, Result};

/// The energy the gate method removes, summed over rows (any order, any split):
/// `Σ H²` of the capture and of the zeroed samples.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GateEnergy {
    /// `Σ H²` over the finite samples read.
    pub total: f64,
    /// `Σ H²` over the samples the gate zeroed.
    pub cut: f64,
    /// `Σ H²` over the samples the gate left within its reach of a zeroed sample
    /// ([`GateEnergy::add_near`]; 0 when only [`GateEnergy::add`] was used).
    pub near: f64,
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

    /// [`GateEnergy::add`], and the energy the gate left within `reach` bins of a sample it
    /// zeroed (a non-zero sample read as 0 after the gate), histogram by histogram (`nt` bins
    /// each, `raw` and `kept` SPAD-major).
    pub fn add_near(&mut self, raw: &[f32], kept: &[f32], nt: usize, reach: usize) {
        self.add(raw, kept);
        let nt = nt.max(1);
        let mut near = vec![false; nt];
        for (r, k) in raw.chunks_exact(nt).zip(kept.chunks_exact(nt)) {
            let cut = |i: usize| r[i] != 0.0 && r[i].is_finite() && k[i] == 0.0;
            near.fill(false);
            // Forward and backward: the distance to the last and to the next zeroed sample.
            let mut last: Option<usize> = None;
            for (i, n) in near.iter_mut().enumerate() {
                if cut(i) {
                    last = Some(i);
                } else if last.is_some_and(|l| i - l <= reach) {
                    *n = true;
                }
            }
            let mut next: Option<usize> = None;
            for (i, n) in near.iter_mut().enumerate().rev() {
                if cut(i) {
                    next = Some(i);
                } else if next.is_some_and(|j| j - i <= reach) {
                    *n = true;
                }
            }
            for (&x, _) in r.iter().zip(&near).filter(|(x, n)| **n && x.is_finite()) {
                self.near += f64::from(x) * f64::from(x);
            }
        }
    }

    /// Of the energy the gate left, the share next to its windows (module docs): `None` when
    /// it zeroed nothing or left nothing (0 when only [`GateEnergy::add`] was used).
    pub fn adjacency(&self) -> Option<f64> {
        let left = self.total - self.cut;
        (left > 0.0 && left.is_finite() && self.cut > 0.0).then(|| (self.near / left).min(1.0))
    }

    /// Adds the sums of another part of the rows.
    pub fn merge(&mut self, other: &Self) {
        self.total += other.total;
        self.cut += other.cut;
        self.near += other.near;
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

#[cfg(test)]
mod tests {
    use super::GateEnergy;

    /// Adjacency counts the energy the gate left within its reach of a zeroed sample, in the
    /// same histogram only, on both sides; a zero sample inside the window does not count as
    /// zeroed, and non-finite samples are left out.
    #[test]
    fn adjacency_is_the_left_energy_next_to_the_windows() {
        // Two histograms of 12 bins; the gate zeroes bins 4..6 of the first.
        let mut raw = vec![0.0f32; 24];
        raw[1] = 2.0; // 3 bins before the window: near with reach 3, not with 2
        raw[4] = 5.0; // zeroed
        raw[5] = 5.0; // zeroed
        raw[7] = 1.0; // 2 bins after: near
        raw[11] = 3.0; // 6 bins after: far
        raw[12] = 4.0; // the next histogram: far, though 7 bins from the window in the row
        raw[13] = f32::NAN;
        let mut kept = raw.clone();
        kept[4] = 0.0;
        kept[5] = 0.0;
        let left = 4.0 + 1.0 + 9.0 + 16.0;
        for (reach, near) in [(2, 1.0), (3, 1.0 + 4.0), (6, 1.0 + 4.0 + 9.0)] {
            let mut e = GateEnergy::default();
            e.add_near(&raw, &kept, 12, reach);
            assert_eq!(
                (e.total, e.cut, e.near),
                (50.0 + left, 50.0, near),
                "{reach}"
            );
            assert_eq!(e.adjacency(), Some(near / left));
        }
        // Nothing zeroed, or nothing left: no adjacency.
        let mut e = GateEnergy::default();
        e.add_near(&raw, &raw, 12, 3);
        assert_eq!(e.adjacency(), None);
        let mut e = GateEnergy::default();
        e.add_near(&raw, &[0.0; 24], 12, 3);
        assert_eq!(e.adjacency(), None);
        // Merged parts give the whole.
        let (mut a, mut b, mut all) = (
            GateEnergy::default(),
            GateEnergy::default(),
            GateEnergy::default(),
        );
        a.add_near(&raw[..12], &kept[..12], 12, 3);
        b.add_near(&raw[12..], &kept[12..], 12, 3);
        all.add_near(&raw, &kept, 12, 3);
        a.merge(&b);
        assert_eq!(a, all);
        // Everything left far from the windows: 0.
        let mut far = raw.clone();
        (far[1], far[7]) = (0.0, 0.0);
        let mut e = GateEnergy::default();
        e.add_near(
            &far,
            &far.iter()
                .enumerate()
                .map(|(i, &x)| if (4..6).contains(&i) { 0.0 } else { x })
                .collect::<Vec<_>>(),
            12,
            3,
        );
        assert_eq!(e.adjacency(), Some(0.0));
    }
}
