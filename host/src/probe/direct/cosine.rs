//! Direct light under `--weights cos` ([`Wave::cosine`]): each leg's distance weight `w(d)`
//! times the Lambertian cosine at its wall point, `|cos θ| = |n·(x_v − x)| / |x_v − x|` with
//! `n` the relay surface's normal at the wall point `x` (the laser spot for the first leg, the
//! SPAD spot for the last; [`Geometry::laser_normal`](crate::io::capture::Geometry::laser_normal),
//! [`Geometry::spad_normal`](crate::io::capture::Geometry::spad_normal), +z where
//! the capture has none). Together with the default `w = 1/d` this is the obliquity factor
//! `cos θ/d` of the Rayleigh–Sommerfeld propagator on a relay surface
//! of any shape; on a flat wall it is `z_v/d` per leg.
//!
//! **Where it applies.** Scans with one SPAD per row (paired and confocal): the diagonal is
//! `A(v) = Σ_l c_l(v)·c_s(v)·A_l(v)`, where `A_l` is the kernel's one-row diagonal (band sum
//! or baseband lookup, distance weights) and `c_l`, `c_s` the cosines of the row's laser and
//! SPAD spot. The kernel's per-pair loop is unchanged (no normals, no new per-pair work, so
//! the firmware builds are untouched); the host takes each row's accumulators, multiplies
//! them by the two cosines per voxel and adds them up. Over a SPAD grid the sum over SPADs
//! runs inside the kernel, where a per-SPAD cosine does not fit: the planner refuses it in one
//! line (`probe::plan::check_cosine`), as it does the FFT and phasor paths (their kernels are
//! distance-only).
//!
//! **Cost.** The band or lookup path's own cost, plus per row and voxel two cosines (two
//! square roots, ~20 flops) and a reset of one accumulator. Measured (4,096 pairs × 512
//! bins, 32×32×16 voxels, one thread, user CPU): lookup 4.8 s → 5.2 s (1.09×); band about
//! the same as distance-only (`docs/paired.md`).
//! **Memory**: one accumulator set per thread for the row and one for the sum (`32·Kv`
//! bytes per thread), plus the path's own scratch.

use crate::budget;
use crate::error::Result;
use crate::io::capture::{RowSource, wall_cosine};
use crate::probe::drive::*;
use crate::probe::fast::LookupDiagonal;
use crate::volume::Volume;
use num_complex::Complex64;
use vltm_kernel::{Gate, Probe, Report, Scan, Target};

/// The diagonal's accumulators under the wall cosines, on the lookup path (`lookup`: what it
/// holds) or the band path (`None`), as the planner chose (`probe::plan::cosine`), rows in
/// parallel. `job.cfg` has the distance weights of the wave.
pub(super) fn direct(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
    lookup: Option<&budget::Plan>,
) -> Result<(Vec<Complex64>, Report)> {
    let g = src.geometry().clone();
    let cfg = job.cfg;
    let n = volume.len();
    let threads = rayon::current_num_threads().max(1);
    check_memory(
        &g,
        cfg,
        budget::bytes(n, 16 * 2 * threads as u128 + 32),
        "direct light (cos weights)",
    )?;
    let pts = &volume.points;
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, 1)];
    let scan = Scan::new(cfg, &g.spads[..1], &mut tables)?;
    // Per voxel: add the row's accumulators times the two cosines of the row's spots.
    let fold = |acc: &mut [Complex64], row: &[Complex64], l: usize| {
        let (x_l, x_s) = (g.lasers[l], g.spads[l]);
        let (n_l, n_s) = (g.laser_normal(l), g.spad_normal(l));
        for ((a, r), v) in acc.iter_mut().zip(row).zip(pts) {
            *a += *r * (wall_cosine(x_l, n_l, *v) * wall_cosine(x_s, n_s, *v));
        }
    };
    let zero = Complex64::new(0.0, 0.0);
    let (acc_parts, report) = if let Some(lookup_plan) = lookup {
        lookup_plan.check(|| pass_name(&g, cfg, "direct light (lookup)"))?;
        let lk = LookupDiagonal::new(cfg);
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                (
                    lk.scratch(1),
                    vec![zero; n],
                    vec![zero; n],
                    Report::default(),
                )
            })
            .collect();
        let workers = drive_rows_indexed(
            src,
            job,
            &scan,
            "direct",
            workers,
            |(s, tmp, acc, r), l, scan, row| {
                tmp.fill(zero);
                lk.apply(scan, row, pts, s, tmp);
                fold(acc, tmp, l);
                r.count_row(row);
                Ok(())
            },
        )?;
        let mut report = Report::default();
        let parts = workers
            .into_iter()
            .map(|(_, _, a, r)| {
                report.add_part(&r);
                a
            })
            .collect::<Vec<_>>();
        (parts, report)
    } else {
        let len = Probe::state_len(cfg, Target::Diagonal, Gate::Gaussian, n, 1);
        let mut states: Vec<Vec<f64>> = (0..threads).map(|_| vec![0.0; len]).collect();
        let workers = states
            .iter_mut()
            .map(|s| {
                Ok((
                    Probe::new(&scan, Target::Diagonal, Gate::Gaussian, pts, s)?,
                    vec![zero; n],
                    Report::default(),
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        let workers = drive_rows_indexed(
            src,
            job,
            &scan,
            "direct",
            workers,
            |(p, acc, r), l, scan, row| {
                p.reset();
                p.push_row(scan, row)?;
                fold(acc, p.accumulators(), l);
                r.add_part(&p.report());
                Ok(())
            },
        )?;
        let mut report = Report::default();
        let parts = workers
            .into_iter()
            .map(|(_, a, r)| {
                report.add_part(&r);
                a
            })
            .collect::<Vec<_>>();
        (parts, report)
    };
    let mut acc = vec![zero; n];
    for part in acc_parts {
        for (a, b) in acc.iter_mut().zip(part) {
            *a += b;
        }
    }
    Ok((acc, report))
}
