//! What a front end (the command line, the Python package) does around a probe, kept here so
//! that every front end does it the same way: the preprocessing of a run ([`with_prep`]: the
//! time window, rebinning and background of [`crate::io::prep`] with the imaged volume's
//! reach, and the checks on what it removed), the near/middle/far shells ([`parse_shells`],
//! [`cut`]), Γ with its emptiness check ([`gamma_of`]), the summed transient of `vltm info`
//! ([`summed`]), a source read into memory ([`read_all`], for `--swap-roles`), and the layout
//! text of `vltm info` ([`info::info`]).
//!
//! Units: metres of optical path. Errors name the command line's flags (`--background`,
//! `--shells`); front ends spell them as their own arguments. Cost: [`with_prep`] adds O(Nt)
//! per histogram read; [`read_all`] holds the whole capture (`Kl·Ks·Nt` f32).

use crate::error::{Error, Result};
use crate::io::capture::{Capture, RowSource};
use crate::io::prep::{Prep, Prepared, Reach, Stats};
use crate::probe::{Shell, gamma_mask};
use vltm_kernel::Point;

pub mod info;

/// What the preprocessing of a run did.
#[derive(Clone, Debug, PartialEq)]
pub struct PrepReport {
    /// A one-line account ([`Prepared::summary`]).
    pub summary: String,
    /// A warning when the background left more than half of the histograms empty.
    pub warning: Option<String>,
    /// The counters.
    pub stats: Stats,
}

/// Runs `f` on `src`, through the preprocessing `prep` when there is one: the background's
/// return-free bins are those no path through `points` (widened by `3·sigma` plus one
/// rebinned bin) can reach. Returns `f`'s result and what the preprocessing did.
///
/// # Errors
/// `f`'s errors; [`Error::Argument`] for a window that keeps no bins, and (`--background`)
/// when the background removed every count.
pub fn with_prep<T>(
    prep: Option<Prep>,
    src: &mut dyn RowSource,
    points: &[Point],
    sigma: f64,
    f: impl FnOnce(&mut dyn RowSource) -> Result<T>,
) -> Result<(T, Option<PrepReport>)> {
    let Some(prep) = prep else {
        return Ok((f(src)?, None));
    };
    let src_dt = src.geometry().dt;
    let margin = 3.0 * sigma + src_dt * prep.rebin.max(1) as f64;
    let mut p = Prepared::new(src, prep, Reach::of(points, margin))?;
    let out = f(&mut p)?;
    let report = check(&p)?;
    Ok((out, Some(report)))
}

/// The checks on what a preprocessing removed: every histogram empty is an error, more than
/// half of them a warning.
///
/// # Errors
/// [`Error::Argument`] (`background`) when every histogram read was left empty.
pub fn check(p: &Prepared<'_>) -> Result<PrepReport> {
    let s = &p.stats;
    if s.histograms > 0 && s.empty == s.histograms {
        return Err(Error::arg(
            "background",
            format!(
                "the background removed every count of all {} histograms: nothing left to image (lower it or use auto)",
                s.histograms
            ),
        ));
    }
    let warning = (2 * s.empty > s.histograms).then(|| {
        format!(
            "the background left {} of {} histograms empty: it is larger than most of the signal",
            s.empty, s.histograms
        )
    });
    Ok(PrepReport {
        summary: p.summary(),
        warning,
        stats: s.clone(),
    })
}

/// Parses `R1,R2` (metres, `0 < R1 < R2`, finite) into the near `[0, R1)`, middle
/// `[R1, R2)` and far `[R2, ∞)` shells.
///
/// # Errors
/// [`Error::Argument`] (`--shells`).
pub fn parse_shells(s: &str) -> Result<[Shell; 3]> {
    let bad = || {
        Error::arg(
            "shells",
            format!("expected R1,R2 with 0 < R1 < R2 in metres, found `{s}`"),
        )
    };
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    let r1: f32 = a.trim().parse().map_err(|_| bad())?;
    let r2: f32 = b.trim().parse().map_err(|_| bad())?;
    if !(r1 > 0.0 && r2 > r1 && r2.is_finite()) {
        return Err(bad());
    }
    Ok([
        Shell { r0: 0.0, r1 },
        Shell { r0: r1, r1: r2 },
        Shell {
            r0: r2,
            r1: f32::INFINITY,
        },
    ])
}

/// The names of the three shells of [`parse_shells`].
pub const SHELL_TAGS: [&str; 3] = ["near", "middle", "far"];

/// `values` over `points` with every voxel outside `shell` (distance to `focus`) set to 0.
pub fn cut(values: &[f32], points: &[Point], focus: Point, shell: Shell) -> Vec<f32> {
    values
        .iter()
        .zip(points)
        .map(|(&x, p)| {
            let d = ((0..3).map(|i| (focus[i] - p[i]).powi(2)).sum::<f32>()).sqrt();
            if shell.contains(d) { x } else { 0.0 }
        })
        .collect()
}

/// Γ = {v : I_d(v) > ε·max} of a direct-light volume.
///
/// # Errors
/// [`Error::Argument`] naming `arg` for ε outside `[0, 1)` or an empty Γ.
pub fn gamma_of(direct: &[f32], epsilon: f32, arg: &str) -> Result<Vec<bool>> {
    if !(0.0..1.0).contains(&epsilon) {
        return Err(Error::arg(
            arg,
            format!("expected 0 <= E < 1, found {epsilon}"),
        ));
    }
    let g = gamma_mask(direct, epsilon);
    if !g.contains(&true) {
        return Err(Error::arg(
            arg,
            "Γ is empty: the direct light is zero on every voxel of $volume",
        ));
    }
    Ok(g)
}

/// The histograms of every row summed bin by bin (non-finite samples skipped): the summed
/// transient, `Nt` values over the path axis `t0 + n·Δt`.
///
/// # Errors
/// Read errors.
pub fn summed(src: &mut dyn RowSource) -> Result<Vec<f64>> {
    let g = src.geometry().clone();
    let mut sum = vec![0.0f64; g.nt];
    let mut row = Vec::new();
    for l in 0..g.lasers.len() {
        src.read_row(l, &mut row)?;
        for h in row.chunks_exact(g.nt) {
            for (s, &x) in sum.iter_mut().zip(h) {
                if x.is_finite() {
                    *s += f64::from(x);
                }
            }
        }
    }
    Ok(sum)
}

/// Every row of `src` read into memory.
///
/// # Errors
/// Read errors; the capture's own checks ([`Capture::new`]).
pub fn read_all(src: &mut dyn RowSource, name: &std::path::Path) -> Result<Capture> {
    let g = src.geometry().clone();
    let mut data = Vec::new();
    let mut row = Vec::new();
    for l in 0..g.lasers.len() {
        src.read_row(l, &mut row)?;
        data.extend_from_slice(&row);
    }
    Capture::new(g, data, name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shells_parse_and_cut() {
        let s = parse_shells("0.2, 0.5").unwrap();
        assert_eq!(
            (s[0].r0, s[0].r1, s[1].r0, s[1].r1, s[2].r0),
            (0.0, 0.2, 0.2, 0.5, 0.5)
        );
        assert!(s[2].r1.is_infinite());
        for bad in ["0.5,0.2", "0,1", "1", "a,b", "0.1,inf"] {
            let e = parse_shells(bad).unwrap_err().to_string();
            assert!(e.starts_with("argument `shells`"), "{e}");
        }
        let pts = [[0.0, 0.0, 1.0], [0.0, 0.0, 1.3], [0.0, 0.0, 2.0]];
        let v = [1.0, 2.0, 3.0];
        let f = [0.0, 0.0, 1.0];
        assert_eq!(cut(&v, &pts, f, s[0]), [1.0, 0.0, 0.0]);
        assert_eq!(cut(&v, &pts, f, s[1]), [0.0, 2.0, 0.0]);
        assert_eq!(cut(&v, &pts, f, s[2]), [0.0, 0.0, 3.0]);
    }

    #[test]
    fn gamma_of_refuses_empty_and_bad_epsilon() {
        assert_eq!(
            gamma_of(&[0.0, 1.0, 0.5], 0.6, "e").unwrap(),
            [false, true, false]
        );
        assert!(
            gamma_of(&[0.0, 0.0], 0.1, "e")
                .unwrap_err()
                .to_string()
                .contains("Γ is empty")
        );
        assert!(
            gamma_of(&[1.0], 1.0, "epsilon")
                .unwrap_err()
                .to_string()
                .starts_with("argument `epsilon`")
        );
    }
}
