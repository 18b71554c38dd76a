//! A probe's result ([`Output`]: intensities per voxel, the kernel's counters, the
//! configuration and path that computed them) and the check that its intensities are finite
//! before they are handed out.

use super::crop::Crop;
use crate::error::Result;
use crate::exec::EvalPath;
use num_complex::Complex64;
use vltm_kernel::{Config, Point, Report};

/// Result of a probe: intensities per voxel (volume order) and the kernel's counters.
#[derive(Clone, Debug, PartialEq)]
pub struct Output {
    /// `|A|²` per voxel.
    pub values: Vec<f32>,
    /// Rows, non-finite samples, aliased voxels.
    pub report: Report,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// The kernel configuration used (λ, σ, J…).
    pub config: Config,
    /// The evaluation path that computed the voxel sums (never [`EvalPath::Auto`]).
    pub path: EvalPath,
    /// The part of the time axis kept ([`Wave::crop`](super::Wave::crop)); `None`: all of it.
    pub crop: Option<Crop>,
    /// When a slower path than the FFT convolution ran on a grid because of its x–y pitch:
    /// the `--volume` SPEC of the nearest grid the FFT path takes (`probe::aligned_volume`).
    /// When the FFT path ([`crate::exec::EvalPath::Planar`]) ran on a grid off the wall's lattice: the SPEC of
    /// the support grid it computed on before resampling ([`crate::probe::resample`]).
    pub aligned: Option<String>,
}

/// Intensities `|A|²` of complex accumulators, as `f32`.
pub(super) fn intensities(acc: &[Complex64]) -> Vec<f32> {
    acc.iter().map(|a| a.norm_sqr() as f32).collect()
}

/// Checks that a probe's intensities are finite: an `f32` output cannot hold intensities
/// above 3.4e38 (histogram values so large that `|A|²` overflows), and a non-finite value is
/// never written silently.
///
/// # Errors
/// [`Error::Format`](crate::Error::Format) on `intensity`, naming the first voxel and the
/// cause.
pub(super) fn check_finite(values: &[f32], voxels: &[Point], what: &str) -> Result<()> {
    let Some(i) = values.iter().position(|v| !v.is_finite()) else {
        return Ok(());
    };
    let n = values.iter().filter(|v| !v.is_finite()).count();
    let p = voxels.get(i).copied().unwrap_or_default();
    Err(crate::error::Error::format(
        "(result)",
        "intensity",
        format!("finite {what} intensities within the float32 range (< 3.4e38)"),
        format!(
            "{} at ({:.3}, {:.3}, {:.3}) m and {} more voxels: the capture's histogram values are too large (|A|² overflows float32); scale H down",
            values[i],
            p[0],
            p[1],
            p[2],
            n - 1
        ),
    ))
}
