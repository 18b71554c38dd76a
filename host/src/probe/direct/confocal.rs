//! Direct light of confocal captures by the confocal FFT convolution
//! ([`crate::probe::fast::confocal`], confocal scans only: laser and SPAD at the same wall
//! point), when the planner (`probe::plan`) takes it: the convolution's row pass. Paired scans
//! and the other paths of confocal ones (lookup, phasor, band sum) run as on any capture.
//!
//! The convolution needs every row's band spectrum on the wall grid before it can image:
//! rows are read in batches of `128·threads`, their stage 1 done as one `sgemm` per 128 rows
//! ([`BandDft`]), the gate weights and legs folded in exactly as the kernel's
//! `RowBuffer::load_with` does, and each spectrum placed on the wall image. Paths outside the
//! guard interval contribute nothing, as on the band path: when all rows share one leg
//! offset `d1 + d4 − t0` (wall-to-wall time axes) the convolution kernel is zeroed where the
//! path leaves the guard (`guard` of [`Confocal::run`]); otherwise (legs in the time axis) the
//! voxels with such a path are evaluated on the band path in the same pass (kernel probes
//! over voxel chunks, one `Scan` per row), as the planar path does.
//!
//! Memory: the wall spectra `J·Mx·My` complex `f32` (twice on a layout with transposed
//! twins, `fast::confocal::twins`), one batch of rows (`128·threads·Nt` `f32` and its
//! spectra), the convolution's per-worker scratch (`~5·Mx·My` complex) and the output:
//! nothing grows with the number of slices or rows beyond the output itself.

use crate::error::Result;
use crate::exec::{Pass, chunk_len};
use crate::io::capture::{Geometry, RowSource};
use crate::probe::drive::*;
use crate::probe::fast::{BandDft, Confocal};
use crate::volume::Volume;
use num_complex::{Complex32, Complex64};
use rayon::prelude::*;
use vltm_kernel::geometry::dist;
use vltm_kernel::{Config, Gate, Point, Probe, Report, RowBuffer, Scan, Target, cis_turns_f64};

/// Rows per `sgemm` of stage 1.
const ROWS_PER_GEMM: usize = 128;

/// Voxels with some confocal path `d1_l + d4_l + 2|x_l − x_v| − t0` outside the guard
/// interval (within `1e-4·σ` counts as outside, as for the planar path). A bound from the
/// wall points' bounding box settles most voxels; the rest are checked point by point.
pub(super) fn outside_guard(
    g: &Geometry,
    cfg: &Config,
    (d1, d4): &(Vec<f64>, Vec<f64>),
    voxels: &[Point],
) -> Vec<bool> {
    let e: Vec<f64> = d1.iter().zip(d4).map(|(a, b)| a + b).collect();
    let (e_lo, e_hi) = e
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let mut bmin = [f32::INFINITY; 3];
    let mut bmax = [f32::NEG_INFINITY; 3];
    for p in &g.lasers {
        for i in 0..3 {
            bmin[i] = bmin[i].min(p[i]);
            bmax[i] = bmax[i].max(p[i]);
        }
    }
    let (lo, hi) = cfg.guard();
    let m = 1e-4 * cfg.sigma();
    let t0 = cfg.t0();
    let outside = |a: f64, b: f64| a - t0 < lo + m || b - t0 > hi - m;
    voxels
        .par_iter()
        .map(|v| {
            // Nearest and farthest points of the box (f64), with an f32 rounding margin.
            let near: f64 = (0..3)
                .map(|i| f64::from(v[i] - v[i].clamp(bmin[i], bmax[i])).powi(2))
                .sum::<f64>()
                .sqrt();
            let far: f64 = (0..3)
                .map(|i| f64::from((v[i] - bmin[i]).abs().max((v[i] - bmax[i]).abs())).powi(2))
                .sum::<f64>()
                .sqrt();
            let slack = 1e-6 * (1.0 + far);
            if !outside(2.0 * (near - slack) + e_lo, 2.0 * (far + slack) + e_hi) {
                return false;
            }
            let (a, b) = g.lasers.iter().zip(&e).fold(
                (f64::INFINITY, f64::NEG_INFINITY),
                |(a, b), (p, e)| {
                    let x = 2.0 * f64::from(dist(p, v)) + e;
                    (a.min(x), b.max(x))
                },
            );
            outside(a, b)
        })
        .collect()
}

/// Folds the gate weights and the legs into raw band spectra, as the kernel's
/// `RowBuffer::load_with` does: `HG[j] = B[j]·Ĝ_j·e^{iν_j x}`, `x = d1 + d4 − t0`.
fn fold(cfg: &Config, gate: &[f32], x: f64, band: &mut [Complex32]) {
    let span = cfg.span();
    let mut p = cis_turns_f64(cfg.k_lo() as f64 * x / span);
    let step = cis_turns_f64(x / span);
    for (v, g) in band.iter_mut().zip(gate) {
        *v = *v * p * *g;
        p *= step;
    }
}

/// The diagonal of a confocal capture by the convolution `conv`; voxels with paths outside
/// the guard on the kernel's band path.
pub(super) fn direct_convolution(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
    conv: &Confocal,
    legs: &(Vec<f64>, Vec<f64>),
) -> Result<(Vec<Complex64>, Report)> {
    let g = src.geometry().clone();
    let guard = common_offset(job.cfg, legs);
    let skip = match guard {
        Some(_) => vec![false; volume.len()],
        None => outside_guard(&g, job.cfg, legs, &volume.points),
    };
    with_band_fallback(&volume.points, &skip, |fb_pts| {
        convolution_core(src, job, conv, guard, &skip, fb_pts, legs)
    })
}

/// The rows' common leg offset `d1 + d4 − t0` (`f32`, m) when every row has the same one
/// (wall-to-wall time axes): then the convolution applies the guard in its kernel.
pub(super) fn common_offset(cfg: &Config, (legs1, legs4): &(Vec<f64>, Vec<f64>)) -> Option<f32> {
    let mut offsets = legs1
        .iter()
        .zip(legs4)
        .map(|(a, b)| (a + b - cfg.t0()) as f32);
    let first = offsets.next()?;
    offsets.all(|x| x == first).then_some(first)
}

/// The confocal convolution `conv` over its voxel grid (voxels with `skip` left at 0; the
/// guard in its kernel at the rows' common offset `guard`, [`common_offset`]), and the band
/// path's accumulators of the points `fb_pts`, in one pass over the rows (`(d1, d4)`: the
/// device legs of the wall points): [`Confocal::run`] with this file's row reader.
pub(super) fn convolution_core(
    src: &mut dyn RowSource,
    job: Job<'_>,
    conv: &Confocal,
    guard: Option<f32>,
    skip: &[bool],
    fb_pts: &[Point],
    (legs1, legs4): &(Vec<f64>, Vec<f64>),
) -> Result<(Vec<Complex64>, Vec<Complex64>, Report)> {
    let Job { cfg, wave, exec } = job;
    let g = src.geometry().clone();
    check_laser_falloff(&g, wave)?;
    let cl = chunk_len(fb_pts.len());
    let chunks: Vec<&[Point]> = fb_pts.chunks(cl).collect();
    let mut states: Vec<Vec<f64>> = chunks
        .iter()
        .map(|c| vec![0.0; Probe::state_len(cfg, Target::Diagonal, Gate::Gaussian, c.len(), 1)])
        .collect();
    // The twiddle and gate tables once; per row only its spot's sensor leg (`with_spads`).
    let mut fb_tables = vec![0.0f32; Scan::tables_len(cfg, 1)];
    let first = [g.lasers[0]];
    let fb_scan = Scan::new(cfg, &first, &mut fb_tables)?;
    let mut fb_d4 = [0.0f32; 1];
    let mut probes: Vec<Probe<'_>> = chunks
        .iter()
        .zip(states.iter_mut())
        .map(|(c, s)| Probe::new(&fb_scan, Target::Diagonal, Gate::Gaussian, c, s))
        .collect::<Result<_, _>>()?;
    let mut fb_buf = vec![0.0f32; RowBuffer::len(cfg, 1)];
    let gate: Vec<f32> = (0..cfg.bins()).map(|j| cfg.gate_weight(j) as f32).collect();
    let dft = BandDft::new(cfg);
    let (nt, j_n) = (g.nt, cfg.bins());
    let batch = ROWS_PER_GEMM * rayon::current_num_threads().max(1);
    let mut hists = vec![0.0f32; batch * nt];
    let mut ungated = vec![Complex32::new(0.0, 0.0); batch];
    let mut row = Vec::new();
    let mut lasers = vec![[0.0f32; 3]; batch];
    let mut report = Report::default();
    let bar = Pass::start(exec, "direct", g.lasers.len());
    // One batch of rows: read, stage 1 as sgemms, the band path's points, then folded.
    let fill = |start: usize, band: &mut [Complex32]| -> Result<()> {
        let n = band.len() / j_n;
        for (k, h) in hists.chunks_exact_mut(nt).take(n).enumerate() {
            let x_l = src.read_row(start + k, &mut row)?;
            lasers[k] = x_l;
            let c = if wave.compensate_laser {
                (1.0 / g.laser_falloff_at(start + k)) as f32
            } else {
                1.0
            };
            for (o, &s) in h.iter_mut().zip(&row) {
                let s = s * c;
                report.non_finite += u64::from(!s.is_finite());
                *o = if s.is_finite() { s } else { 0.0 };
            }
        }
        hists[..n * nt]
            .par_chunks(ROWS_PER_GEMM * nt)
            .zip(band.par_chunks_mut(ROWS_PER_GEMM * j_n))
            .zip(ungated[..n].par_chunks_mut(ROWS_PER_GEMM))
            .for_each(|((h, b), u)| dft.apply(h, b, u));
        if !chunks.is_empty() {
            for k in 0..n {
                let spad = [lasers[k]];
                let scan = fb_scan.with_spads(&spad, &mut fb_d4)?;
                let h = &hists[k * nt..(k + 1) * nt];
                let mut rb = RowBuffer::new(&scan, &mut fb_buf)?;
                // The raw spectra of the batch's sgemm (not folded yet).
                let r = rb.load_with(&scan, lasers[k], h, |b, u| {
                    b.copy_from_slice(&band[k * j_n..(k + 1) * j_n]);
                    u[0] = ungated[k];
                })?;
                probes
                    .par_iter_mut()
                    .try_for_each(|p| p.push_row(&scan, &r))?;
            }
        }
        for (k, hg) in band.chunks_exact_mut(j_n).enumerate() {
            let l = start + k;
            fold(cfg, &gate, legs1[l] + legs4[l] - cfg.t0(), hg);
        }
        report.rows += n as u64;
        bar.advance(n);
        Ok(())
    };
    let acc = conv.run(guard, batch, skip, fill)?;
    drop(bar);
    // The points on the band path: their accumulators are their amplitudes.
    let fb_acc = probes
        .iter()
        .zip(&chunks)
        .flat_map(|(p, c)| p.accumulators().iter().take(c.len()).copied())
        .collect();
    Ok((acc, fb_acc, report))
}
