//! Rows of the LTM, `T(·, x_b)`: the light that reaches a virtual camera focused at `x_b`
//! from every projector focus `x_a` of a volume (two-bounce gate, Eq. 14), streamed by laser
//! rows, without transposing the capture.
//!
//! **Method.** By reciprocity a row is a column with the projector and camera roles swapped
//! (`vltm column --swap-roles` computes it by transposing the capture in memory). Here the
//! factorisation runs over the camera leg instead, one laser row at a time: for row `l`,
//! `V_l[j] = Σ_s w(|x_b − x_s|)·e^{iν_j|x_b − x_s|}·HG_ls[j]` (one J-vector), then every
//! voxel `a` gets `A(a, b) += w(|x_l − x_a|)·Σ_j e^{iν_j(|x_l − x_a| + |x_a − x_b|)}·V_l[j]`.
//! The amplitudes are those of the kernel's factorised column with the sums
//! taken in another order; the configuration is [`Wave::column_config`] with the volume as
//! the foci and `x_b` as the imaged voxel, so every element is alias-free.
//!
//! **Cost.** Per laser row `Ks·8J` flops for `V_l` and `Ka·(8J + E0)` for the voxels (split
//! over threads). **Memory:** `16·Ka` bytes of accumulators, one row of histograms and its
//! spectra (`Ks·(Nt + 2J + 3)` f32) — never the capture; the transposing `--swap-roles`
//! holds all of it (`4·Kl·Ks·Nt` bytes).

use super::crop::{Reach, with_crop};
use super::drive::*;
use super::output::Output;
use super::wave::*;
use crate::error::Result;
use crate::exec::{EvalPath, Exec, chunk_len};
use crate::io::capture::{Geometry, RowSource};
use crate::volume::Volume;
use num_complex::{Complex32, Complex64};
use rayon::prelude::*;
use std::time::Instant;
use vltm_kernel::geometry::dist;
use vltm_kernel::{Point, Report, cis_turns, geometry};

/// The checks [`row`] makes before it reads a row: the lens weights, the focus, a SPAD grid
/// and the capture's window; for a front end that runs another pass first (the leak
/// correction's Γ).
///
/// # Errors
/// As [`row`]'s argument errors.
pub fn check_row(g: &Geometry, focus: Point, volume: &Volume, wave: &Wave) -> Result<()> {
    wave.refuse_cosine("`row`")?;
    super::column::check_focus(focus)?;
    g.need_spad_grid("row", "rows need")?;
    let base = wave.config(g)?;
    super::window::window_rule(
        g,
        &base,
        Some(&volume.points),
        &[focus],
        super::gate::ColumnGate::TwoBounce,
        Exec::default(),
    )
    .map(|_| ())
}

/// The row `T(·, x_b)` over `volume` (intensities `|A(a, b)|²` per voxel `a`), streamed by
/// laser rows (see the module docs).
///
/// # Errors
/// Focus on or behind the wall ([`Error::Argument`](crate::error::Error::Argument) `focus`), a confocal capture,
/// configuration, read and kernel errors.
pub fn row(
    src: &mut dyn RowSource,
    focus: Point,
    volume: &Volume,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<Output> {
    wave.refuse_cosine("`row`")?;
    super::column::check_focus(focus)?;
    let t = Instant::now();
    let g = src.geometry().clone();
    g.need_spad_grid("row", "rows need")?;
    let b = focus;
    let voxels = &volume.points;
    let base = wave.config(&g)?;
    let to = [b];
    super::window::window_rule(
        &g,
        &base,
        Some(voxels),
        &to,
        super::gate::ColumnGate::TwoBounce,
        exec,
    )?;
    // The time axis cropped to the paths' reach: the laser leg ends at the volume's x_a, the
    // camera leg starts at x_b.
    let reach = Reach {
        foci: Some(voxels),
        voxels: &to,
        late: false,
    };
    let (acc, report, cfg, crop) = with_crop(src, wave, exec, reach, |src, exec, crop| {
        let g = src.geometry().clone();
        let cfg = wave.column_config(&g, voxels, &to)?;
        let j = cfg.bins().max(1);
        let span = cfg.span();
        let (klo, inv) = ((cfg.k_lo() as f64 / span) as f32, (1.0 / span) as f32);
        let (d1, d4) = legs(&g, &cfg);
        // The camera leg of every SPAD: weight and phase seeds (fixed for the whole scan).
        let cam: Vec<(f32, Complex32, Complex32)> = g
            .spads
            .iter()
            .map(|s| {
                let d_bs = dist(&b, s);
                (
                    cfg.weight(d_bs),
                    cis_turns(klo * d_bs),
                    cis_turns(inv * d_bs),
                )
            })
            .collect();
        let d_ab: Vec<f32> = voxels.iter().map(|a| dist(a, &b)).collect();
        let mut acc = vec![Complex64::new(0.0, 0.0); voxels.len()];
        let mut v = vec![Complex64::new(0.0, 0.0); j];
        let mut report = Report::default();
        let cl = chunk_len(voxels.len());
        drive(
            src,
            Job {
                cfg: &cfg,
                wave,
                exec,
            },
            "row",
            |_, row| {
                v.fill(Complex64::new(0.0, 0.0));
                for ((w, p0, step), hg) in cam.iter().zip(row.band().chunks_exact(j)) {
                    let mut p = *p0 * *w;
                    for (o, h) in v.iter_mut().zip(hg) {
                        let x = *h * p;
                        *o += Complex64::new(f64::from(x.re), f64::from(x.im));
                        p *= *step;
                    }
                }
                let laser = row.laser();
                let vr = &v;
                voxels
                    .par_chunks(cl)
                    .zip(acc.par_chunks_mut(cl))
                    .zip(d_ab.par_chunks(cl))
                    .for_each(|((vs, os), ds)| {
                        for ((a, o), dab) in vs.iter().zip(os.iter_mut()).zip(ds) {
                            let d_la = dist(&laser, a);
                            let tau = d_la + dab;
                            let mut ph = cis_turns(klo * tau);
                            let step = cis_turns(inv * tau);
                            let mut z = Complex64::new(0.0, 0.0);
                            for x in vr {
                                z += *x * Complex64::new(f64::from(ph.re), f64::from(ph.im));
                                ph *= step;
                            }
                            *o += z * f64::from(cfg.weight(d_la));
                        }
                    });
                report.rows += 1;
                report.non_finite += u64::from(row.non_finite());
                Ok(())
            },
        )?;
        // Elements whose path times leave the alias-free window (0 under the automatic margin).
        let window = geometry::alias_window(&cfg);
        let span_of = |pts: &[Point], legs: &[f64], x: Point| {
            pts.iter()
                .zip(legs)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |r, (p, d)| {
                    geometry::widen(r, f64::from(dist(p, &x)) + d)
                })
        };
        let (c_lo, c_hi) = span_of(&g.spads, &d4, b);
        report.aliased = voxels
            .par_iter()
            .zip(&d_ab)
            .filter(|(a, dab)| {
                let legs = span_of(&g.lasers, &d1, **a);
                let d = f64::from(**dab);
                geometry::leaves_window(window, legs, (d + c_lo, d + c_hi))
            })
            .count();
        Ok((acc, report, cfg, crop))
    })?;
    Ok(Output {
        values: acc.iter().map(|z| z.norm_sqr() as f32).collect(),
        report,
        seconds: t.elapsed().as_secs_f64(),
        config: cfg,
        path: EvalPath::Band,
        crop,
        aligned: None,
    })
}
