//! Streaming the rows of a capture through the kernel ([`RowSource::rows`]: all, or a part of
//! the scan): stage 1 (band spectra) of every row once, handed to the probes sequentially ([`drive`];
//! [`drive_probes`] for one kernel probe per accumulator state, pushed in parallel) or to one worker per thread in
//! parallel ([`drive_rows`]); element-wise probes over voxel chunks ([`elementwise`]).
//! Memory: `4·threads` rows of histograms (a batch read while another is worked on) and one
//! row buffer per worker, never the capture.

use super::wave::*;
use crate::budget;
use crate::error::{Error, Result};
use crate::exec::{Exec, Pass, chunk_len, row_batch};
use crate::io::capture::{Geometry, RowSource};
use crate::probe::fast::BandDft;
use crate::timings::{self, Kind};
use num_complex::Complex64;
use rayon::prelude::*;
use vltm_kernel::{Config, Gate, Point, Probe, Report, Row, RowBuffer, Scan, Target};

/// What every pass needs: the kernel configuration and the user's options.
#[derive(Clone, Copy)]
pub(super) struct Job<'a> {
    pub(super) cfg: &'a Config,
    pub(super) wave: &'a Wave,
    pub(super) exec: Exec<'a>,
}

/// Streams every row of `src` through `push` with the row's spectra (computed once per row).
/// Over a SPAD grid the rows are read in batches of one per pool thread and stage 1 of a
/// batch runs in parallel (`threads` row buffers); `push` gets the rows in order. A confocal
/// capture (a scan per row) goes row by row.
pub(super) fn drive(
    src: &mut dyn RowSource,
    job: Job<'_>,
    label: &str,
    mut push: impl FnMut(&Scan<'_>, &Row<'_, f32>) -> Result<()>,
) -> Result<()> {
    let Job { cfg, wave, exec } = job;
    let g = src.geometry().clone();
    check_laser_falloff(&g, wave)?;
    check_memory(&g, cfg, 0, label)?;
    let dft = BandDft::new(cfg);
    let ks = g.spads_per_row();
    let range = src.rows();
    let bar = Pass::start(exec, label, range.len());
    if g.confocal {
        // One wall point per row: each row has its own scan (its tables), rows one by one.
        let mut clean = Vec::new();
        let mut buf = vec![0.0f32; RowBuffer::len(cfg, ks)];
        let mut hist = Vec::new();
        // The twiddle and gate tables once; per row only the SPAD spot's leg.
        let mut tables = vec![0.0f32; Scan::tables_len(cfg, 1)];
        let first = [g.spads.first().copied().unwrap_or_default()];
        let base = Scan::new(cfg, &first, &mut tables)?;
        let mut d4 = [0.0f32; 1];
        for l in range {
            let x_l = {
                let _t = timings::section("read rows", Kind::Serial);
                let x_l = src.read_row(l, &mut hist)?;
                compensate(&g, wave, l, &mut hist);
                x_l
            };
            // Paired (and confocal) scans: the row's own SPAD spot.
            let spad = [g.spads.get(l).copied().unwrap_or(x_l)];
            let scan = base.with_spads(&spad, &mut d4)?;
            let mut rows = RowBuffer::new(&scan, &mut buf)?;
            let row = {
                let _t = timings::section("stage 1 (band spectra)", Kind::Serial);
                load_row(&mut rows, &scan, &dft, x_l, &hist, &mut clean)?
            };
            push(&scan, &row)?;
            bar.advance(1);
        }
        return Ok(());
    }
    // A grid of SPADs: rows read in batches of one per thread, stage 1 of a batch in
    // parallel (one row buffer per row), then pushed in order.
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, &g.spads, &mut tables)?;
    let batch = rayon::current_num_threads().clamp(1, range.len().max(1));
    let mut bufs: Vec<Vec<f32>> = (0..batch)
        .map(|_| vec![0.0f32; RowBuffer::len(cfg, ks)])
        .collect();
    let mut hists: Vec<(Point, Vec<f32>)> = (0..batch).map(|_| ([0.0; 3], Vec::new())).collect();
    let mut cleans: Vec<Vec<f32>> = (0..batch).map(|_| Vec::new()).collect();
    for start in range.clone().step_by(batch) {
        let n = (start + batch).min(range.end) - start;
        {
            let _t = timings::section("read rows", read_kind(src));
            src.read_rows(start, &mut hists[..n])?;
            compensate_all(&g, wave, start, &mut hists[..n]);
        }
        let mut rbs = bufs[..n]
            .iter_mut()
            .map(|b| RowBuffer::new(&scan, b))
            .collect::<Result<Vec<_>, _>>()?;
        let rows = {
            let _t = timings::section("stage 1 (band spectra)", Kind::Parallel);
            rbs.par_iter_mut()
                .zip(hists[..n].par_iter())
                .zip(cleans[..n].par_iter_mut())
                .map(|((rb, (x_l, hist)), clean)| load_row(rb, &scan, &dft, *x_l, hist, clean))
                .collect::<Result<Vec<_>>>()?
        };
        for row in &rows {
            push(&scan, row)?;
            bar.advance(1);
        }
    }
    Ok(())
}

/// Divides laser row `l` by the laser's falloff to its spot under `compensate_laser`
/// ([`Geometry::laser_falloff_at`]: the spot's own normal).
fn compensate(g: &Geometry, wave: &Wave, l: usize, hist: &mut [f32]) {
    if wave.compensate_laser {
        let k = (1.0 / g.laser_falloff_at(l)) as f32;
        hist.iter_mut().for_each(|h| *h *= k);
    }
}

/// [`compensate`] on a batch of rows `first..`, in parallel.
pub(super) fn compensate_all(
    g: &Geometry,
    wave: &Wave,
    first: usize,
    rows: &mut [(Point, Vec<f32>)],
) {
    if wave.compensate_laser {
        rows.par_iter_mut()
            .enumerate()
            .for_each(|(i, (_, h))| compensate(g, wave, first + i, h));
    }
}

/// How a source reads a batch of rows, for the section timings.
pub(super) fn read_kind(src: &dyn RowSource) -> Kind {
    if src.reads_in_parallel() {
        Kind::Parallel
    } else {
        Kind::Serial
    }
}

/// Stage 1 of one row through the host's matrix product ([`BandDft`]); non-finite samples
/// are zeroed in a copy (`clean`) for the product and counted, and the row is read once more
/// only where it has one (or its sums overflow).
pub(super) fn load_row<'r>(
    rows: &'r mut RowBuffer<'_>,
    scan: &Scan<'_>,
    dft: &BandDft,
    x_l: Point,
    hist: &'r [f32],
    clean: &mut Vec<f32>,
) -> Result<Row<'r, f32>> {
    // The raw sums first: a NaN or ±∞ sample makes every sum of its histogram non-finite
    // (`NaN·w`, `±∞·w`, `±∞·0` and any sum holding one are), and every band bin sums every
    // sample, so finite spectra prove a finite row, which is then read once, not three times
    // (a check, the sums, the kernel's count). Otherwise the row is counted and, if it has
    // non-finite samples, summed again with them zeroed; finite samples whose sums overflow
    // keep their overflowed sums, as before.
    Ok(rows.load_counted(scan, x_l, hist, |band, ungated| {
        dft.apply(hist, band, ungated);
        if all_finite(bytemuck::cast_slice(band)) && all_finite(bytemuck::cast_slice(ungated)) {
            return 0;
        }
        let bad = hist.iter().filter(|x| !x.is_finite()).count();
        if bad > 0 {
            clean.clear();
            clean.extend(hist.iter().map(|&x| if x.is_finite() { x } else { 0.0 }));
            dft.apply(clean, band, ungated);
        }
        u32::try_from(bad).unwrap_or(u32::MAX)
    })?)
}

/// Whether every sample is finite: exponent bits not all set, OR-ed over blocks of 256 in a
/// branch-free loop that vectorises (a plain `all(is_finite)` stops at the first non-finite
/// sample and runs one scalar compare per sample: 4–11 % of a row's work on exhaustive
/// captures).
pub(super) fn all_finite(x: &[f32]) -> bool {
    const EXP: u32 = 0x7f80_0000;
    x.chunks(256).all(|c| {
        c.iter()
            .fold(0u32, |any, v| any | u32::from(v.to_bits() & EXP == EXP))
            == 0
    })
}

/// Reads rows in batches and hands each to one of `workers` in parallel (one worker per
/// thread, each with its own row buffer), so stage 1 and the per-row probe work use every
/// core; the next batch is read while the pool works on one. `work` gets the row's scan:
/// `scan` itself, or for a paired or confocal capture (where `scan` only sizes the buffers:
/// one SPAD) a scan of the row's own SPAD spot. Memory:
/// `4·threads` rows of histograms (two batches), never the whole capture.
///
/// Which worker sums which rows depends on the row's index only ([`worker_of`]: row `l` to
/// worker `l mod workers`, each worker's rows in ascending order), never on the thread that
/// runs it: a worker's partial sums, hence the merged result, are the same run to run for a
/// given number of workers.
pub(super) fn drive_rows<W: Send>(
    src: &mut dyn RowSource,
    job: Job<'_>,
    scan: &Scan<'_>,
    label: &str,
    workers: Vec<W>,
    work: impl Fn(&mut W, &Scan<'_>, &Row<'_, f32>) -> Result<()> + Sync,
) -> Result<Vec<W>> {
    drive_rows_indexed(src, job, scan, label, workers, |w, _, scan, row| {
        work(w, scan, row)
    })
}

/// The worker of [`drive_rows`] that sums capture row `l` among `workers`.
pub(super) fn worker_of(l: usize, workers: usize) -> usize {
    l % workers.max(1)
}

/// A worker of [`drive_rows`] with its buffers: the row buffer, a copy of a row with
/// non-finite samples zeroed, the sensor leg of a confocal or paired row's own SPAD spot
/// (`scan`'s tables serve every row).
struct Slot<W> {
    worker: W,
    buf: Vec<f32>,
    clean: Vec<f32>,
    d4: [f32; 1],
}

/// [`drive_rows`] with the row's index in the capture handed to `work` (its laser spot is
/// `lasers[l]`; of a paired scan, its SPAD spot `spads[l]`).
pub(super) fn drive_rows_indexed<W: Send>(
    src: &mut dyn RowSource,
    job: Job<'_>,
    scan: &Scan<'_>,
    label: &str,
    workers: Vec<W>,
    work: impl Fn(&mut W, usize, &Scan<'_>, &Row<'_, f32>) -> Result<()> + Sync,
) -> Result<Vec<W>> {
    let Job { cfg, wave, exec } = job;
    let g = src.geometry().clone();
    check_laser_falloff(&g, wave)?;
    let ks = g.spads_per_row();
    check_memory(&g, cfg, 0, label)?;
    let dft = BandDft::new(cfg);
    let mut slots: Vec<Slot<W>> = workers
        .into_iter()
        .map(|worker| Slot {
            worker,
            buf: vec![0.0f32; RowBuffer::len(cfg, ks)],
            clean: Vec::new(),
            d4: [0.0f32; 1],
        })
        .collect();
    let n_slots = slots.len();
    let range = src.rows();
    let bar = Pass::start(exec, label, range.len());
    let batch = row_batch();
    // Stage 1 and the probes of one batch of rows `start..` (laser spot, histograms); a
    // paired row's own SPAD spot is `g.spads[l]`. Each worker takes its own rows of the
    // batch, in order, on whichever thread.
    let run = |slots: &mut [Slot<W>], start: usize, rows: &[(Point, Vec<f32>)]| -> Result<()> {
        let end = start + rows.len();
        slots.par_iter_mut().enumerate().try_for_each(|(k, slot)| {
            let Slot {
                worker,
                buf,
                clean,
                d4,
            } = slot;
            for l in (start..end).filter(|&l| worker_of(l, n_slots) == k) {
                let (x_l, hist) = &rows[l - start];
                // Paired (and confocal) scans: the row's own SPAD spot.
                let spad = [g.spads.get(l).copied().unwrap_or(*x_l)];
                let own;
                let scan = if g.confocal {
                    own = scan.with_spads(&spad, d4)?;
                    &own
                } else {
                    scan
                };
                let mut rb = RowBuffer::new(scan, buf)?;
                let row = load_row(&mut rb, scan, &dft, *x_l, hist, clean)?;
                work(worker, l, scan, &row)?;
            }
            Ok::<_, Error>(())
        })
    };
    let read = |src: &mut dyn RowSource, start: usize, rows: &mut Vec<(Point, Vec<f32>)>| {
        let end = (start + batch).min(range.end);
        rows.resize_with(end - start, || ([0.0; 3], Vec::new()));
        src.read_rows(start, rows)?;
        compensate_all(&g, wave, start, rows);
        Ok::<_, Error>(())
    };
    // Two batches: the pool runs one while this thread reads the next into the other (its
    // reader's own parallel work shares the pool), so reading does not stop the probes.
    let mut rows: Vec<(Point, Vec<f32>)> = Vec::new();
    let mut next: Vec<(Point, Vec<f32>)> = Vec::new();
    if !range.is_empty() {
        let _t = timings::section("read rows", read_kind(src));
        read(src, range.start, &mut rows)?;
    }
    for start in range.clone().step_by(batch) {
        let ahead = start + batch;
        let mut done = Ok(());
        {
            let _t = timings::section("rows, next batch read", Kind::Parallel);
            rayon::in_place_scope(|s| {
                let (rows, done, slots) = (&rows, &mut done, &mut slots);
                s.spawn(move |_| *done = run(slots, start, rows));
                if ahead < range.end {
                    read(src, ahead, &mut next)
                } else {
                    Ok(())
                }
            })?;
        }
        done?;
        bar.advance(rows.len());
        std::mem::swap(&mut rows, &mut next);
    }
    Ok(slots.into_iter().map(|s| s.worker).collect())
}

/// Checks what a pass over `g` holds at once against the memory budget ([`budget`]): the
/// kernel's tables (`2N + J + Ks` f32), the band-DFT table (at most
/// [`fast::band::MAX_TABLE_BYTES`](crate::probe::fast::band::MAX_TABLE_BYTES)), and per thread
/// a row buffer (`Ks·(2J + 3)` f32) and four rows of histograms (a batch being read while
/// another is worked on), plus `extra` bytes (probe states, outputs). `what` names the pass.
///
/// # Errors
/// [`Error::Memory`] naming the pass, the DFT sizes and σ.
pub(super) fn check_memory(g: &Geometry, cfg: &Config, extra: u128, what: &str) -> Result<()> {
    memory_plan(g, cfg, extra, what).check(|| pass_name(g, cfg, what))
}

/// The buffers of [`check_memory`], named (`extra` as `what`'s states and outputs).
pub(super) fn memory_plan(g: &Geometry, cfg: &Config, extra: u128, what: &str) -> budget::Plan {
    let mut plan = pass_plan(g, cfg);
    plan.add(format!("the states and outputs of {what}"), extra);
    plan
}

/// What every pass over `g` holds before its probes' states and outputs: the kernel's tables,
/// the band-DFT table, and per thread a row buffer and four rows of histograms (two batches).
pub(super) fn pass_plan(g: &Geometry, cfg: &Config) -> budget::Plan {
    let threads = rayon::current_num_threads() as u128;
    let ks = g.spads_per_row();
    let mut plan = budget::Plan::new();
    plan.add(
        format!(
            "the kernel's tables (2N + J + Ks = {} f32)",
            budget::count(Scan::tables_len(cfg, ks) as u128)
        ),
        budget::bytes(Scan::tables_len(cfg, ks), 4),
    )
    .add(
        "the band-DFT table",
        BandDft::table_bytes(cfg).min(crate::probe::fast::band::MAX_TABLE_BYTES as u128),
    )
    .add(
        format!("{threads} row buffers (one per thread)"),
        budget::bytes(RowBuffer::len(cfg, ks), 4 * threads),
    )
    .add(
        format!("{threads} × 4 rows of histograms (two batches)"),
        budget::bytes(ks.saturating_mul(g.nt), 16 * threads),
    );
    plan
}

/// A pass's name with its sizes, for [`Error::Memory`].
pub(super) fn pass_name(g: &Geometry, cfg: &Config, what: &str) -> String {
    format!(
        "{what} with a DFT period of {} bins, a band of {} bins and rows of {} SPADs × {} bins (σ = {} m)",
        budget::count(cfg.n_fft() as u128),
        budget::count(cfg.bins() as u128),
        g.spads_per_row(),
        g.nt,
        cfg.sigma()
    )
}

/// Under `compensate_laser`, refuses a capture where the laser's falloff `|cos θ| / d²` to
/// some spot is 0 or not finite (the laser in the plane of the spot's surface, or on it).
pub(super) fn check_laser_falloff(g: &Geometry, wave: &Wave) -> Result<()> {
    if wave.compensate_laser {
        let bad = (0..g.lasers.len()).find(|&l| {
            let f = g.laser_falloff_at(l);
            !(f.is_finite() && f > 0.0)
        });
        if let Some(l) = bad {
            let why = if g.normals.lasers.is_empty() {
                "laser_xyz lies in the wall plane: cos θ / d² is 0".to_string()
            } else {
                format!(
                    "laser_xyz lies in the tangent plane of laser spot {l} {:?} (its normal {:?}): cos θ / d² is 0",
                    g.lasers[l],
                    g.laser_normal(l).map(|c| c as f32)
                )
            };
            return Err(Error::arg("compensate_laser", why));
        }
    }
    Ok(())
}

/// Streams every row of `src` ([`drive`]) through one kernel probe per accumulator state,
/// the probes pushed in parallel. The probes need a `Scan` only to validate sizes, so they are
/// made on the first row, by `make(scan, k, state)` for the `k`-th state. Returns the probes
/// (none when the pass read no row).
pub(super) fn drive_probes<'m>(
    src: &mut dyn RowSource,
    job: Job<'_>,
    label: &str,
    states: impl Iterator<Item = &'m mut [f64]>,
    make: impl Fn(&Scan<'_>, usize, &'m mut [f64]) -> Result<Probe<'m>, vltm_kernel::ArgumentError>,
) -> Result<Vec<Probe<'m>>> {
    let mut probes = Vec::new();
    let mut states = Some(states);
    drive(src, job, label, |scan, row| {
        if let Some(it) = states.take() {
            probes = it
                .enumerate()
                .map(|(k, s)| make(scan, k, s))
                .collect::<Result<_, _>>()?;
        }
        let _t = timings::section("probe pushes", Kind::Parallel);
        probes
            .par_iter_mut()
            .try_for_each(|p| p.push_row(scan, row))?;
        Ok(())
    })?;
    Ok(probes)
}

/// Element-wise probes (diagonal, higher-order column) over voxel chunks in parallel: the
/// complex accumulator of every voxel (volume order; `T = |A|²`) and the counters.
pub(super) fn elementwise(
    src: &mut dyn RowSource,
    job: Job<'_>,
    target: Target,
    gate: Gate,
    voxels: &[Point],
    label: &str,
) -> Result<(Vec<Complex64>, Report)> {
    let cfg = job.cfg;
    let ks = src.geometry().spads_per_row();
    let cl = chunk_len(voxels.len());
    let states = voxels
        .chunks(cl)
        .map(|c| budget::bytes(Probe::state_len(cfg, target, gate, c.len(), ks), 8))
        .fold(budget::bytes(voxels.len(), 8), u128::saturating_add);
    check_memory(src.geometry(), cfg, states, label)?;
    let chunks: Vec<&[Point]> = voxels.chunks(cl).collect();
    let mut states: Vec<Vec<f64>> = chunks
        .iter()
        .map(|c| vec![0.0; Probe::state_len(cfg, target, gate, c.len(), ks)])
        .collect();
    let probes = drive_probes(
        src,
        job,
        label,
        states.iter_mut().map(Vec::as_mut_slice),
        |scan, k, s| Probe::new(scan, target, gate, chunks[k], s),
    )?;
    // Every chunk saw the same rows: one chunk's counters are the pass's.
    let report = probes.first().map(Probe::report).unwrap_or_default();
    let mut acc = Vec::with_capacity(voxels.len());
    for (p, c) in probes.iter().zip(&chunks) {
        acc.extend(p.accumulators().iter().take(c.len()));
    }
    // No row: zero accumulators.
    acc.resize(voxels.len(), Complex64::new(0.0, 0.0));
    Ok((acc, report))
}

/// The diagonal of `points` by an FFT path that cannot evaluate the voxels `skip` marks (paths
/// outside its guard): `core` gets those voxels as band-path points and returns the grid's
/// accumulators (skipped ones at 0) and the band path's; the band path's are put back in place.
pub(super) fn with_band_fallback(
    points: &[Point],
    skip: &[bool],
    core: impl FnOnce(&[Point]) -> Result<(Vec<Complex64>, Vec<Complex64>, Report)>,
) -> Result<(Vec<Complex64>, Report)> {
    let fb_idx: Vec<usize> = (0..skip.len()).filter(|&i| skip[i]).collect();
    let fb_pts: Vec<Point> = fb_idx.iter().map(|&i| points[i]).collect();
    let (mut acc, fb_acc, report) = core(&fb_pts)?;
    for (&i, a) in fb_idx.iter().zip(fb_acc) {
        acc[i] = a;
    }
    Ok((acc, report))
}

#[cfg(test)]
mod tests {
    use super::{all_finite, load_row};
    use crate::probe::fast::BandDft;
    use crate::probe::fast::band::tests::sample_row;
    use vltm_kernel::{RowBuffer, Scan};

    /// A row with NaN and ±∞ samples gives the spectra of the row with them zeroed and their
    /// count, through every stage-1 method (the product, portable or in AVX-512 lanes, and
    /// the FFT); a finite row counts none; finite samples whose sums overflow keep their
    /// overflowed sums and count none (as the kernel's own `load` does).
    #[test]
    fn load_row_zeroes_and_counts_non_finite_samples() {
        let (cfg, spads, finite) = sample_row();
        let mut tables = vec![0.0f32; Scan::tables_len(&cfg, spads.len())];
        let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
        let n = finite.len();
        let mut bad = finite.clone();
        for (at, x) in [
            (0, f32::NAN),
            (n / 2, f32::INFINITY),
            (n - 1, f32::NEG_INFINITY),
        ] {
            bad[at] = x;
        }
        let zeroed: Vec<f32> = bad
            .iter()
            .map(|&x| if x.is_finite() { x } else { 0.0 })
            .collect();
        let mut huge = finite.clone();
        huge[5] = f32::MAX;
        huge[6] = f32::MAX;
        let len = RowBuffer::len(&cfg, spads.len());
        let (mut b1, mut b2) = (vec![0.0f32; len], vec![0.0f32; len]);
        let laser = [0.3, 0.2, 0.0];
        let dfts = [
            BandDft::table(&cfg),
            BandDft::portable_table(&cfg),
            BandDft::fft(&cfg),
        ];
        for dft in &dfts {
            let mut clean = Vec::new();
            let mut r1 = RowBuffer::new(&scan, &mut b1).unwrap();
            let got = load_row(&mut r1, &scan, dft, laser, &bad, &mut clean).unwrap();
            let mut r2 = RowBuffer::new(&scan, &mut b2).unwrap();
            let want = r2
                .load_with(&scan, laser, &zeroed, |b, m| dft.apply(&zeroed, b, m))
                .unwrap();
            assert_eq!(got.non_finite(), 3, "{dft:?}");
            assert_eq!(got.band(), want.band(), "{dft:?}");
            assert_eq!(got.ungated(), want.ungated(), "{dft:?}");
            let mut r1 = RowBuffer::new(&scan, &mut b1).unwrap();
            let ok = load_row(&mut r1, &scan, dft, laser, &finite, &mut clean).unwrap();
            assert_eq!(ok.non_finite(), 0, "{dft:?}");
            assert!(
                ok.band()
                    .iter()
                    .all(|z| z.re.is_finite() && z.im.is_finite())
            );
            let mut r1 = RowBuffer::new(&scan, &mut b1).unwrap();
            let over = load_row(&mut r1, &scan, dft, laser, &huge, &mut clean).unwrap();
            assert_eq!(over.non_finite(), 0, "{dft:?}");
            assert!(
                over.band()
                    .iter()
                    .any(|z| !z.re.is_finite() || !z.im.is_finite())
            );
        }
    }

    /// `all_finite` agrees with `all(is_finite)` for a non-finite sample anywhere (first,
    /// last, inside a block, in the short last block) and for finite extremes (±MAX,
    /// subnormals, −0).
    #[test]
    fn all_finite_matches_the_plain_check() {
        let finite = [f32::MAX, -f32::MAX, f32::MIN_POSITIVE / 4.0, -0.0, 1.0, 0.0];
        for len in [0, 1, 255, 256, 257, 1000] {
            let base: Vec<f32> = (0..len).map(|i| finite[i % finite.len()]).collect();
            assert!(all_finite(&base), "len {len}");
            for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -f32::NAN] {
                for at in [0, len / 2, 255, 256, len.saturating_sub(1)] {
                    if at >= len {
                        continue;
                    }
                    let mut v = base.clone();
                    v[at] = bad;
                    assert_eq!(all_finite(&v), v.iter().all(|x| x.is_finite()));
                    assert!(!all_finite(&v), "len {len}, {bad} at {at}");
                }
            }
        }
    }
}
