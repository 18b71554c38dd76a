//! Poisson photon noise with a background ([`Noise`]), applied to a rendered capture.

use std::path::Path;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Poisson};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Largest `peak_counts` / `background` accepted for Poisson noise.
pub const MAX_COUNTS: f64 = 1e15;

/// Poisson photon noise (see the [module documentation](super#noise)).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    /// Expected count of the largest bin of the noise-free capture (> 0).
    pub peak_counts: f64,
    /// Expected background counts added to every bin (≥ 0).
    #[serde(default)]
    pub background: f64,
    /// Random seed.
    #[serde(default)]
    pub seed: u64,
}

impl Noise {
    pub(super) fn validate(&self, path: &Path, field: &str) -> Result<()> {
        if !(self.peak_counts.is_finite()
            && self.peak_counts > 0.0
            && self.peak_counts <= MAX_COUNTS)
        {
            return Err(Error::format(
                path,
                &format!("{field}.peak_counts"),
                format!("a value in (0, {MAX_COUNTS:e}]"),
                self.peak_counts,
            ));
        }
        if !(self.background.is_finite() && self.background >= 0.0 && self.background <= MAX_COUNTS)
        {
            return Err(Error::format(
                path,
                &format!("{field}.background"),
                format!("a value in [0, {MAX_COUNTS:e}]"),
                self.background,
            ));
        }
        Ok(())
    }

    /// Replaces the noise-free histograms `data` (laser rows of `row_len` values) by Poisson
    /// counts: expected value `data·peak_counts/max(data) + background` (negative and
    /// non-finite values count as 0). Row `l` uses its own seeded generator, so the result does
    /// not depend on the number of threads.
    ///
    /// # Errors
    /// [`Error::Format`] (naming `<noise>` and the field) for out-of-range parameters,
    /// [`Error::Argument`] for `row_len` = 0.
    pub fn apply(&self, data: &mut [f32], row_len: usize) -> Result<()> {
        self.validate(Path::new("<noise>"), "noise")?;
        if row_len == 0 {
            return Err(Error::arg("row_len", "expected at least one value per row"));
        }
        let max = data
            .iter()
            .filter(|v| v.is_finite())
            .fold(0.0f32, |m, &v| m.max(v));
        let scale = if max > 0.0 {
            self.peak_counts / f64::from(max)
        } else {
            0.0
        };
        let (seed, background) = (self.seed, self.background);
        data.par_chunks_mut(row_len)
            .enumerate()
            .for_each(|(l, row)| {
                let mut rng = StdRng::seed_from_u64(
                    seed.wrapping_add((l as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)),
                );
                for v in row {
                    let h = f64::from(*v);
                    let lambda = if h.is_finite() && h > 0.0 {
                        h * scale
                    } else {
                        0.0
                    } + background;
                    *v = if lambda > 0.0 {
                        match Poisson::new(lambda) {
                            Ok(p) => p.sample(&mut rng) as f32,
                            Err(_) => lambda as f32,
                        }
                    } else {
                        0.0
                    };
                }
            });
        Ok(())
    }
}
