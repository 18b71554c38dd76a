//! The diagonal on the phasor path ([`crate::probe::fast::phasor`]), planned by the planner
//! (`probe::plan`: the table for the stated error bound within the memory budget, the flop
//! model): the driver that streams rows in batches whose tables are built in parallel, then
//! sums every voxel tile over the batch's rows in order (so the result does not depend on the
//! threads).

use crate::budget;
use crate::error::Result;
use crate::io::capture::RowSource;
use crate::probe::drive::*;
use crate::probe::fast::{Phasor, phasor};
use crate::probe::plan::{PHASOR_FEW_SPADS, phasor_batch};
use crate::volume::Volume;
use num_complex::Complex64;
use rayon::prelude::*;
use vltm_kernel::{Point, Report};

/// Voxels per tile of the phasor path (its `f32` accumulators live on the stack).
const PHASOR_TILE: usize = phasor::TILE;

/// The diagonal's accumulators on the phasor path ([`crate::probe::fast::phasor`]): rows in
/// batches, their tables in parallel, then voxel tiles in parallel, each summing the batch's
/// rows in order (the same sums on any number of threads).
pub(super) fn direct_phasor(
    src: &mut dyn RowSource,
    job: Job<'_>,
    volume: &Volume,
    ph: &Phasor,
    plan: &budget::Plan,
) -> Result<(Vec<Complex64>, Report)> {
    use crate::exec::Pass;
    use crate::probe::fast::phasor::{Histogram, TableScratch};
    use crate::timings::{self, Kind};
    use std::sync::Mutex;
    let Job { cfg, wave, exec } = job;
    let g = src.geometry().clone();
    plan.check(|| pass_name(&g, cfg, "direct light (phasor)"))?;
    check_laser_falloff(&g, wave)?;
    let ks = g.spads_per_row();
    let n = volume.len();
    // Voxel positions as structures of arrays, padded to whole lane groups (the padding
    // repeats the last voxel; its sums are dropped).
    let np = n.next_multiple_of(8);
    let coord = |i: usize| -> Vec<f32> {
        (0..np)
            .map(|v| {
                volume
                    .points
                    .get(v.min(n.saturating_sub(1)))
                    .map_or(0.0, |p| p[i])
            })
            .collect()
    };
    let (vx, vy, vz) = (coord(0), coord(1), coord(2));
    let mut acc = vec![Complex64::new(0.0, 0.0); np];
    // A batch's f32 sums, per voxel.
    let (mut re, mut im) = (vec![0.0f32; np], vec![0.0f32; np]);
    let threads = rayon::current_num_threads().max(1);
    // Voxel chunks: 4 per thread, whole sub-tiles (each thread sweeps its chunk once per
    // row, the row's table in cache); results do not depend on the chunking.
    let chunk = np
        .div_ceil(4 * threads)
        .next_multiple_of(PHASOR_TILE)
        .max(PHASOR_TILE);
    let batch = phasor_batch(ks);
    let tl = ph.table_len();
    let mut tables = vec![[0.0f32; 4]; batch * ks * tl];
    let mut entries = vec![Histogram::default(); batch * ks];
    let mut bad = vec![0u32; batch * ks];
    let scratches: Vec<Mutex<TableScratch>> =
        (0..threads).map(|_| Mutex::new(ph.scratch())).collect();
    let leg = |p: Point, origin: Option<[f64; 3]>| -> f64 {
        origin.map_or(0.0, |o| vltm_kernel::geometry::dist64(&p, &o))
    };
    let (l_origin, s_origin) = match cfg.legs() {
        vltm_kernel::Legs::WallToWall => (None, None),
        vltm_kernel::Legs::FirstAndLast {
            laser_origin,
            sensor_origin,
        } => (Some(laser_origin), Some(sensor_origin)),
    };
    let range = src.rows();
    let bar = Pass::start(exec, "direct", range.len());
    let mut rows: Vec<(Point, Vec<f32>)> = Vec::new();
    let mut report = Report::default();
    let nt = g.nt;
    for start in range.clone().step_by(batch) {
        let end = (start + batch).min(range.end);
        rows.resize_with(end - start, || ([0.0; 3], Vec::new()));
        {
            let _t = timings::section("read rows", read_kind(src));
            src.read_rows(start, &mut rows)?;
            compensate_all(&g, wave, start, &mut rows);
        }
        let ne = (end - start) * ks;
        for (i, (x_l, _)) in rows.iter().enumerate() {
            let l = start + i;
            let d1 = leg(*x_l, l_origin);
            for s in 0..ks {
                let spad = if g.confocal {
                    g.spads.get(l).copied().unwrap_or(*x_l)
                } else {
                    g.spads[s]
                };
                entries[i * ks + s] = Histogram {
                    laser: *x_l,
                    spad,
                    offset: (d1 + leg(spad, s_origin) - cfg.t0()) as f32,
                };
            }
        }
        {
            let _t = timings::section("phasor tables", Kind::Parallel);
            tables[..ne * tl]
                .par_chunks_mut(tl)
                .zip(bad[..ne].par_iter_mut())
                .enumerate()
                .for_each(|(e, (tab, b))| {
                    let (row, s) = (e / ks, e % ks);
                    let h = rows[row].1.get(s * nt..(s + 1) * nt).unwrap_or_default();
                    let i = rayon::current_thread_index().unwrap_or(0) % scratches.len();
                    let mut sc = scratches[i].lock().unwrap_or_else(|e| e.into_inner());
                    *b = ph.table(h, &mut sc, tab);
                });
        }
        {
            let _t = timings::section("phasor voxels", Kind::Parallel);
            let (es, ts) = (&entries[..ne], &tables[..ne * tl]);
            // The `f32` partial sums go into the `f64` accumulators once per batch of rows of
            // few SPADs, once per row of more: a scan split at any row then merges to the
            // same sums up to the `f64` rounding of the merge.
            let group = if ks > PHASOR_FEW_SPADS { ks } else { ne.max(1) };
            acc.par_chunks_mut(chunk)
                .zip(vx.par_chunks(chunk))
                .zip(vy.par_chunks(chunk))
                .zip(vz.par_chunks(chunk))
                .zip(re.par_chunks_mut(chunk))
                .zip(im.par_chunks_mut(chunk))
                .for_each(|(((((a, x), y), z), re), im)| {
                    for (es, ts) in es.chunks(group).zip(ts.chunks(group * tl)) {
                        re.fill(0.0);
                        im.fill(0.0);
                        ph.accumulate(es, ts, x, y, z, re, im);
                        for ((a, r), i) in a.iter_mut().zip(&*re).zip(&*im) {
                            *a += Complex64::new(f64::from(*r), f64::from(*i));
                        }
                    }
                });
        }
        report.rows += (end - start) as u64;
        report.non_finite += bad[..ne].iter().map(|&b| u64::from(b)).sum::<u64>();
        bar.advance(end - start);
    }
    acc.truncate(n);
    Ok((acc, report))
}
