//! In-focus indirect light (Eqs. 15–17): Γ from the diagonal, then the Γ-masked sum of
//! factorised columns over pairs in a distance shell.

use super::column::*;
use super::direct::*;
use super::drive::*;
use super::leak::{DirectModel, LeakCorrected, LeakOptions, cell_radius};
use super::wave::*;
use crate::error::{Error, Result};
use crate::exec::Exec;
use crate::io::capture::RowSource;
use crate::volume::Volume;
use std::time::Instant;
use vltm_kernel::{Gate, Point, Probe, Report, Target};

/// Options of the in-focus indirect sum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IndirectOptions {
    /// Relative threshold ε: Γ = {v : I_d(v) > ε·max I_d} (default 0.1).
    pub epsilon: f32,
    /// Pair distances accumulated: `r0 ≤ |x_a − x_b| < r1`; `r0` default 1.5σ (DESIGN §B.3.4).
    pub shell: Option<Shell>,
    /// Largest accumulator memory accepted (bytes) (default 8 GiB).
    pub max_bytes: usize,
    /// Remove the capture's fitted direct light before the columns (`--leak-correct`,
    /// [`DirectModel`]); `None` = the paper's Eq. 17 on the capture as it is.
    pub leak: Option<LeakOptions>,
}

impl Default for IndirectOptions {
    fn default() -> Self {
        Self {
            epsilon: 0.1,
            shell: None,
            max_bytes: 8 << 30,
            leak: None,
        }
    }
}

/// Result of [`indirect`].
#[derive(Clone, Debug, PartialEq)]
pub struct IndirectOutput {
    /// In-focus indirect light `I_i(b)` (0 outside Γ).
    pub values: Vec<f32>,
    /// The direct light `I_d` of pass 1.
    pub direct: Vec<f32>,
    /// Γ membership per voxel.
    pub gamma: Vec<bool>,
    /// The pair shell used.
    pub shell: Shell,
    /// Counters of pass 2.
    pub report: Report,
    /// With leak correction: the fraction of the demodulated capture's energy the direct
    /// model explains ([`DirectModel::explained`]).
    pub explained: Option<f64>,
    /// Wall-clock seconds for both passes.
    pub seconds: f64,
}

/// Γ = {v : I_d(v) > ε·max I_d} (Eq. 15 with a relative threshold); empty if the maximum is
/// not positive or not finite.
pub fn gamma_mask(direct: &[f32], epsilon: f32) -> Vec<bool> {
    let max = direct.iter().copied().fold(0.0f32, f32::max);
    direct
        .iter()
        .map(|&v| max.is_finite() && max > 0.0 && v > epsilon * max)
        .collect()
}

/// In-focus indirect light (Eqs. 15–17): pass 1 the diagonal, Γ = {I_d > ε·max}, pass 2
/// one factorised column per `a ∈ Γ`, and `I_i(b) = Σ_{a∈Γ, a≠b, r0≤|a−b|<r1} T(a, b)` for
/// `b ∈ Γ`. Reads the source twice.
///
/// # Errors
/// ε out of range, Γ too large for `max_bytes`, configuration, read and kernel errors.
pub fn indirect(
    src: &mut dyn RowSource,
    volume: &Volume,
    opts: &IndirectOptions,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<IndirectOutput> {
    if !(opts.epsilon >= 0.0 && opts.epsilon < 1.0) {
        return Err(Error::arg(
            "--epsilon",
            format!("expected 0 <= E < 1, found {}", opts.epsilon),
        ));
    }
    let t = Instant::now();
    let d = direct(src, volume, wave, exec)?;
    let gamma = gamma_mask(&d.values, opts.epsilon);
    let mut out = indirect_over(src, volume, &gamma, opts, wave, exec)?;
    out.direct = d.values;
    out.seconds = t.elapsed().as_secs_f64();
    Ok(out)
}

/// Pass 2 of [`indirect`] for a given Γ (e.g. from a direct-light image computed once and
/// reused for several captures, such as a scene and its direct-only control).
/// `IndirectOutput::direct` is left empty.
///
/// # Errors
/// Γ of the wrong length or too large for `max_bytes`, configuration, read and kernel errors.
pub fn indirect_over(
    src: &mut dyn RowSource,
    volume: &Volume,
    gamma: &[bool],
    opts: &IndirectOptions,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<IndirectOutput> {
    let t = Instant::now();
    if gamma.len() != volume.len() {
        return Err(Error::arg(
            "gamma",
            format!("expected {} flags, found {}", volume.len(), gamma.len()),
        ));
    }
    let idx: Vec<usize> = (0..gamma.len()).filter(|&i| gamma[i]).collect();
    let pts: Vec<Point> = idx.iter().map(|&i| volume.points[i]).collect();
    let cfg = wave.column_config(src.geometry(), &pts, &pts)?;
    let shell = opts.shell.unwrap_or(Shell {
        r0: 1.5 * cfg.sigma() as f32,
        r1: f32::INFINITY,
    });
    let mut values = vec![0.0f32; volume.len()];
    let mut report = Report::default();
    let mut explained = None;
    if idx.is_empty() && opts.leak.is_some() {
        return Err(Error::arg(
            "--leak-correct",
            "Γ is empty: no voxel has direct light above ε·max (no direct return in the window for this volume?)",
        ));
    }
    if !idx.is_empty() {
        let ks = src.geometry().spads_per_row();
        let bytes = idx.len()
            * Probe::state_bytes(&cfg, Target::Column([0.0, 0.0, 1.0]), Gate::Gaussian, 0, ks);
        if bytes > opts.max_bytes {
            return Err(Error::arg(
                "--epsilon",
                format!(
                    "Γ has {} voxels and needs {:.1} GB of accumulators; raise --epsilon",
                    idx.len(),
                    bytes as f64 / 1e9
                ),
            ));
        }
        let model = match &opts.leak {
            Some(lo) => Some(DirectModel::fit(
                src,
                &pts,
                cell_radius(volume),
                wave,
                lo,
                exec,
            )?),
            None => None,
        };
        explained = model.as_ref().map(|m| m.explained);
        let mut corrected;
        let src: &mut dyn RowSource = match &model {
            Some(m) => {
                corrected = LeakCorrected::new(src, m);
                &mut corrected
            }
            None => src,
        };
        let cols = factorised_columns(
            src,
            Job {
                cfg: &cfg,
                wave,
                exec,
            },
            &pts,
            Gate::Gaussian,
            &pts,
            "indirect",
        )?;
        let mut sum = vec![0.0f64; pts.len()];
        for (ai, (col, r)) in cols.iter().enumerate() {
            report = *r;
            for (bi, t) in col.iter().enumerate() {
                if ai != bi && shell.contains(dist(pts[ai], pts[bi])) {
                    sum[bi] += t;
                }
            }
        }
        for (&i, s) in idx.iter().zip(sum) {
            values[i] = s as f32;
        }
    }
    Ok(IndirectOutput {
        values,
        direct: Vec::new(),
        gamma: gamma.to_vec(),
        shell,
        report,
        explained,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// The fit for a single column (`vltm column --leak-correct`): pass 1 the diagonal over
/// `volume`, Γ = {I_d > ε·max}, then [`DirectModel::fit`] over Γ. Reads the source twice.
///
/// # Errors
/// ε out of range (`--leak-epsilon`), as [`DirectModel::fit`] (an empty Γ names
/// `--leak-correct`), configuration and read errors.
pub fn fit_over_volume(
    src: &mut dyn RowSource,
    volume: &Volume,
    epsilon: f32,
    wave: &Wave,
    opts: &LeakOptions,
    exec: Exec<'_>,
) -> Result<DirectModel> {
    if !(0.0..1.0).contains(&epsilon) {
        return Err(Error::arg(
            "--leak-epsilon",
            format!("expected 0 <= E < 1, found {epsilon}"),
        ));
    }
    let d = direct(src, volume, wave, exec)?;
    let gamma = gamma_mask(&d.values, epsilon);
    let pts: Vec<Point> = (0..volume.len())
        .filter(|&i| gamma[i])
        .map(|i| volume.points[i])
        .collect();
    DirectModel::fit(src, &pts, cell_radius(volume), wave, opts, exec)
}
