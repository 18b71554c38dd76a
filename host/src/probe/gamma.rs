//! Γ, the voxels of a volume that hold direct light (Eq. 15 with a relative threshold):
//! `Γ = {v : I_d(v) > ε·max I_d}`, the foci of the in-focus indirect sum, of the
//! leak-correction fit and of a matrix's `gamma` sets.
//!
//! [`Gamma`] is the one place where ε is checked (`0 ≤ ε < 1`, naming the caller's
//! parameter: `epsilon`, `leak_epsilon`, `mask_epsilon`) and Γ is built from a direct-light
//! volume, whether measured here ([`Gamma::measure`]: one diagonal pass over the capture) or
//! given ([`Gamma::of`]: e.g. a merged direct-light volume). Memory: one flag per voxel.

use super::direct::direct;
use super::output::Output;
use super::wave::Wave;
use crate::error::{Error, Result};
use crate::exec::Exec;
use crate::io::capture::RowSource;
use crate::volume::Volume;
use vltm_kernel::Point;

/// Γ over a volume: one flag per voxel, and the threshold it was taken at.
#[derive(Clone, Debug, PartialEq)]
pub struct Gamma {
    /// Γ membership per voxel of the volume.
    pub mask: Vec<bool>,
    /// The relative threshold ε (of the direct maximum).
    pub epsilon: f32,
}

/// Γ = {v : I_d(v) > ε·max I_d} (Eq. 15 with a relative threshold); empty if the maximum is
/// not positive or not finite. No check of ε: [`Gamma::of`] is the checked form.
pub fn gamma_mask(direct: &[f32], epsilon: f32) -> Vec<bool> {
    let max = direct.iter().copied().fold(0.0f32, f32::max);
    direct
        .iter()
        .map(|&v| max.is_finite() && max > 0.0 && v > epsilon * max)
        .collect()
}

/// The points of `volume` where `mask` (a Γ of the volume) holds, in volume order.
pub(crate) fn gamma_points(volume: &Volume, mask: &[bool]) -> Vec<Point> {
    volume
        .points
        .iter()
        .zip(mask)
        .filter_map(|(p, &k)| k.then_some(*p))
        .collect()
}

impl Gamma {
    /// Checks a relative threshold: `0 ≤ ε < 1`.
    ///
    /// # Errors
    /// [`Error::Argument`] naming `param` otherwise (NaN included).
    pub fn check_epsilon(epsilon: f32, param: &str) -> Result<()> {
        if (0.0..1.0).contains(&epsilon) {
            Ok(())
        } else {
            Err(Error::arg(
                param,
                format!("expected 0 <= E < 1, found {epsilon}"),
            ))
        }
    }

    /// Γ of a direct-light volume at `epsilon` (of its maximum).
    ///
    /// # Errors
    /// As [`Gamma::check_epsilon`].
    pub fn of(direct: &[f32], epsilon: f32, param: &str) -> Result<Self> {
        Self::check_epsilon(epsilon, param)?;
        Ok(Self {
            mask: gamma_mask(direct, epsilon),
            epsilon,
        })
    }

    /// Pass 1: the direct light over `volume` (one diagonal pass over `src`) and its Γ.
    ///
    /// # Errors
    /// As [`Gamma::check_epsilon`] (before the pass), and the errors of
    /// [`direct`](super::direct()).
    pub fn measure(
        src: &mut dyn RowSource,
        volume: &Volume,
        epsilon: f32,
        param: &str,
        wave: &Wave,
        exec: Exec<'_>,
    ) -> Result<(Self, Output)> {
        Self::check_epsilon(epsilon, param)?;
        let d = direct(src, volume, wave, exec)?;
        Ok((Self::of(&d.values, epsilon, param)?, d))
    }

    /// The number of voxels in Γ.
    pub fn count(&self) -> usize {
        self.mask.iter().filter(|&&k| k).count()
    }

    /// The points of `volume` in Γ, in volume order.
    pub fn points(&self, volume: &Volume) -> Vec<Point> {
        gamma_points(volume, &self.mask)
    }

    /// Γ itself, or an error naming `param` when it is empty (no voxel of the volume has
    /// direct light above ε·max).
    ///
    /// # Errors
    /// [`Error::Argument`] naming `param` for an empty Γ.
    pub fn non_empty(self, param: &str) -> Result<Self> {
        if self.count() > 0 {
            return Ok(self);
        }
        Err(Error::arg(
            param,
            format!(
                "Γ is empty: no voxel of $volume has direct light above ε·max (ε = {}; all zero?)",
                self.epsilon
            ),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threshold_is_relative_and_checked() {
        let g = Gamma::of(&[0.0, 0.5, 1.0, 0.05], 0.1, "epsilon").unwrap();
        assert_eq!(g.mask, [false, true, true, false]);
        assert_eq!(g.count(), 2);
        for bad in [-0.1, 1.0, f32::NAN] {
            let e = Gamma::of(&[1.0], bad, "leak_epsilon").unwrap_err();
            assert!(e.to_string().starts_with("argument `leak_epsilon`"), "{e}");
        }
        let empty = Gamma::of(&[0.0, 0.0], 0.1, "epsilon").unwrap();
        let e = empty.non_empty("epsilon").unwrap_err();
        let cli = e.render(|p| format!("--{p}"));
        assert!(cli.contains("no voxel of --volume"), "{cli}");
    }
}
