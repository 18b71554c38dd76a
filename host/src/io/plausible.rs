//! Implausible data: a warning, with the position of the worst value, when a capture holds
//! values no instrument or renderer makes.
//!
//! A flipped byte inside an HDF5 file's contiguous `H` block has no checksum to catch it: a
//! corrupted exponent turns 3.2 into 5.7e37, and the file still opens. Two signs are checked:
//!
//! - a value whose magnitude is more than [`FACTOR`] (10⁶) times the capture's 99.9th
//!   percentile of magnitudes (the percentile estimated from an even sample of at most
//!   [`SAMPLE`] values, below at least its largest value, so that one or a few corrupted
//!   values do not move it; a capture
//!   whose percentile is 0 is compared with the median of its non-zero sampled values);
//! - a negative value in a format that holds counts or radiance ([`nonnegative_format`]:
//!   tal/Z-NLOS HDF5, PicoQuant PTU, Stanford `.mat`), where none can be negative. A `.npz`
//!   may hold background-subtracted data, so negatives are allowed there.
//!
//! Non-finite samples are not judged here: the probes read them as 0 and say so.
//!
//! Cost: one pass over each row as it is read (a max/min scan and every `stride`-th value
//! copied, both on the thread that reads the row, the rows of a batch in parallel; where a
//! row beats a record, the record's position is looked up there too, in blocks of 64);
//! memory:
//! [`SAMPLE`] f32 at most, and one row's sample per row of a batch. The check never changes
//! the data and never fails a run: it only warns (the values are what the file holds; the
//! user decides).

use rayon::prelude::*;
use std::path::Path;

use crate::error::Result;
use crate::io::capture::{Geometry, RowSource};
use vltm_kernel::Point;

/// How many times the 99.9th percentile a value may reach before it is implausible.
pub const FACTOR: f64 = 1e6;

/// The most values sampled for the percentile.
pub const SAMPLE: usize = 1 << 20;

/// Whether the format of `path` holds values that cannot be negative (counts or radiance):
/// HDF5 (y-tal, Z-NLOS), PTU and `.mat` captures; not `.npz` (it may hold processed data).
pub fn nonnegative_format(path: &Path) -> bool {
    matches!(
        crate::io::extension(path).as_deref(),
        Some("hdf5" | "h5" | "ptu" | "mat")
    )
}

/// A value and where it lies: laser row, SPAD within the row, time bin.
#[derive(Clone, Copy, Debug, PartialEq)]
struct At {
    value: f32,
    row: usize,
    spad: usize,
    bin: usize,
}

/// Statistics of the rows seen so far, and the verdict on them.
#[derive(Clone, Debug)]
pub struct Plausibility {
    nt: usize,
    nonnegative: bool,
    stride: usize,
    sample: Vec<f32>,
    largest: Option<At>,
    lowest: Option<At>,
    negatives: u64,
}

impl Plausibility {
    /// Statistics for a capture of geometry `g`; `nonnegative`: negative values are
    /// implausible (see [`nonnegative_format`]).
    pub fn new(g: &Geometry, nonnegative: bool) -> Self {
        let total = g.lasers.len() * g.spads_per_row() * g.nt;
        Self {
            nt: g.nt.max(1),
            nonnegative,
            stride: total.div_ceil(SAMPLE).max(1),
            sample: Vec::new(),
            largest: None,
            lowest: None,
            negatives: 0,
        }
    }

    /// Takes row `l`'s histograms (SPAD-major, `Nt` bins each) into the statistics.
    pub fn observe(&mut self, l: usize, row: &[f32]) {
        let stats = self.row_stats(row);
        self.observe_with(l, row, stats);
    }

    /// What row `row` contributes, computed on any thread (the rows of a batch in parallel,
    /// then observed in order with [`Plausibility::observe_with`]): its [`extremes`] and,
    /// while the sample has room, its every `stride`-th finite magnitude, gathered while the
    /// row is still in this thread's cache.
    pub fn row_stats(&self, row: &[f32]) -> RowStats {
        let (hi, lo, negatives) = extremes(row);
        let sample = if self.sample.len() < SAMPLE {
            row.iter()
                .step_by(self.stride)
                .filter(|x| x.is_finite())
                .map(|x| x.abs())
                .collect()
        } else {
            Vec::new()
        };
        RowStats {
            hi,
            lo,
            negatives,
            sample,
            hi_at: None,
            lo_at: None,
        }
    }

    /// [`Plausibility::row_stats`], and the positions of the row's extremes where they beat
    /// the records seen so far (so that [`Plausibility::observe_with`] need not search the
    /// row again, on the thread that observes the rows in order, long after it was read). A
    /// row that beats the records now but not those of an earlier row of its batch costs a
    /// search that is not used.
    pub fn row_stats_located(&self, row: &[f32]) -> RowStats {
        let mut s = self.row_stats(row);
        if self.beats_largest(s.hi) {
            s.hi_at = Some(position_of_largest(row, s.hi));
        }
        if self.beats_lowest(s.lo) {
            s.lo_at = Some(position_of_lowest(row, s.lo));
        }
        s
    }

    /// Whether a row whose largest finite magnitude is `hi` sets a new record.
    fn beats_largest(&self, hi: f32) -> bool {
        hi > 0.0 && self.largest.is_none_or(|a| hi > a.value.abs())
    }

    /// Whether a row whose lowest finite value is `lo` sets a new record.
    fn beats_lowest(&self, lo: f32) -> bool {
        lo < 0.0 && self.lowest.is_none_or(|a| lo < a.value)
    }

    /// [`Plausibility::observe`] with the row's [`RowStats`] computed beforehand.
    pub fn observe_with(&mut self, l: usize, row: &[f32], stats: RowStats) {
        let RowStats {
            hi,
            lo,
            negatives,
            sample,
            hi_at,
            lo_at,
        } = stats;
        let at = |i: usize, value: f32| At {
            value,
            row: l,
            spad: i / self.nt,
            bin: i % self.nt,
        };
        // Positions only when a record is beaten (looked up already, or now).
        if self.beats_largest(hi) {
            let i = hi_at.unwrap_or_else(|| position_of_largest(row, hi));
            self.largest = row.get(i).map(|&v| at(i, v));
        }
        if lo < 0.0 {
            self.negatives += negatives;
            if self.beats_lowest(lo) {
                let i = lo_at.unwrap_or_else(|| position_of_lowest(row, lo));
                self.lowest = row.get(i).map(|&v| at(i, v));
            }
        }
        let room = SAMPLE.saturating_sub(self.sample.len());
        self.sample.extend(sample.into_iter().take(room));
    }

    /// One warning line when the rows seen hold implausible values, naming the worst one and
    /// where it lies; `None` when they look like data.
    pub fn verdict(&self) -> Option<String> {
        let mut said = Vec::new();
        if let (Some(a), Some(reference)) = (self.largest, self.reference()) {
            let ratio = f64::from(a.value.abs()) / reference;
            if ratio > FACTOR {
                said.push(format!(
                    "the value {:e} at laser row {}, SPAD {}, bin {} is {ratio:.1e} times the capture's 99.9th percentile ({reference:.4e}): the file may be damaged (a flipped byte), or the capture holds an outlier the probes will spread over the volume",
                    a.value, a.row, a.spad, a.bin
                ));
            }
        }
        if self.nonnegative
            && let Some(a) = self.lowest
        {
            said.push(format!(
                "{} negative values in a format that holds counts (the lowest, {:e}, at laser row {}, SPAD {}, bin {}): the file may be damaged",
                self.negatives, a.value, a.row, a.spad, a.bin
            ));
        }
        (!said.is_empty()).then(|| format!("implausible data: {}", said.join("; ")))
    }

    /// The scale a plausible value stays within [`FACTOR`] of: the 99.9th percentile of the
    /// sampled magnitudes, or the median of the non-zero ones when that percentile is 0.
    fn reference(&self) -> Option<f64> {
        let mut s = self.sample.clone();
        if s.is_empty() {
            return None;
        }
        // The rank below the largest 0.1 % (at least the largest value), so that a small
        // capture's percentile is not its outlier.
        let n = s.len();
        let k = (n - n.div_ceil(1000)).saturating_sub(1);
        let (_, p, _) = s.select_nth_unstable_by(k, f32::total_cmp);
        if *p > 0.0 {
            return Some(f64::from(*p));
        }
        let mut nz: Vec<f32> = s.into_iter().filter(|&x| x > 0.0).collect();
        if nz.is_empty() {
            return None;
        }
        let m = nz.len() / 2;
        let (_, p, _) = nz.select_nth_unstable_by(m, f32::total_cmp);
        Some(f64::from(*p))
    }
}

/// One row's contribution to [`Plausibility`] ([`Plausibility::row_stats`]).
#[derive(Clone, Debug, Default)]
pub struct RowStats {
    /// The largest finite magnitude (≥ 0).
    hi: f32,
    /// The lowest finite value (≤ 0).
    lo: f32,
    /// How many finite values are negative.
    negatives: u64,
    /// Every `stride`-th finite magnitude, in row order (empty once the sample is full).
    sample: Vec<f32>,
    /// Where `hi` and `lo` first occur, when looked up ([`Plausibility::row_stats_located`]).
    hi_at: Option<usize>,
    lo_at: Option<usize>,
}

/// The first index whose finite magnitude is `hi` (non-finite samples read as 0), or 0.
fn position_of_largest(row: &[f32], hi: f32) -> usize {
    first_where(row, |x| {
        if x.is_finite() {
            x.abs() == hi
        } else {
            hi == 0.0
        }
    })
}

/// The first index whose finite value is `lo` (non-finite samples read as 0), or 0.
fn position_of_lowest(row: &[f32], lo: f32) -> usize {
    first_where(row, |x| if x.is_finite() { x == lo } else { lo == 0.0 })
}

/// The first index where `hit` holds, or 0: blocks of 64 tested branch-free (it
/// vectorises), then the block that holds it one by one.
fn first_where(row: &[f32], hit: impl Fn(f32) -> bool) -> usize {
    const B: usize = 64;
    row.chunks(B)
        .enumerate()
        .find(|(_, c)| c.iter().fold(false, |any, &x| any | hit(x)))
        .and_then(|(k, c)| c.iter().position(|&x| hit(x)).map(|i| k * B + i))
        .unwrap_or(0)
}

/// The largest magnitude (≥ 0), the lowest value (≤ 0) and the number of negative values of
/// a row's finite samples (others read as 0): one branch-free pass in 16 independent lanes
/// (it vectorises; max, min and counts do not depend on the order, so the result is that of
/// a plain fold), compiled for AVX2 where the CPU has it (`pulp`'s x86-64-v3, as the planar
/// path) and for baseline x86-64 elsewhere: the same result either way.
pub fn extremes(row: &[f32]) -> (f32, f32, u64) {
    #[cfg(target_arch = "x86_64")]
    if let Some(v3) = pulp::x86::V3::try_new() {
        return v3.vectorize(|| extremes_lanes(row));
    }
    extremes_lanes(row)
}

/// [`extremes`]' pass, inlined into the caller's target features.
#[inline(always)]
fn extremes_lanes(row: &[f32]) -> (f32, f32, u64) {
    const W: usize = 16;
    let finite = |x: f32| if x.is_finite() { x } else { 0.0 };
    let (mut hi, mut lo, mut neg) = ([0.0f32; W], [0.0f32; W], [0u32; W]);
    let mut negatives = 0u64;
    // Blocks short enough for the lanes' `u32` counts.
    for block in row.chunks(W << 20) {
        let mut chunks = block.chunks_exact(W);
        for c in &mut chunks {
            for (((h, l), n), &x) in hi.iter_mut().zip(lo.iter_mut()).zip(neg.iter_mut()).zip(c) {
                let x = finite(x);
                let a = x.abs();
                *h = if a > *h { a } else { *h };
                *l = if x < *l { x } else { *l };
                *n += u32::from(x < 0.0);
            }
        }
        for &x in chunks.remainder() {
            let x = finite(x);
            hi[0] = hi[0].max(x.abs());
            lo[0] = lo[0].min(x);
            neg[0] += u32::from(x < 0.0);
        }
        negatives += neg.iter().map(|&n| u64::from(n)).sum::<u64>();
        neg = [0; W];
    }
    let hi = hi.iter().fold(0.0f32, |a, &b| a.max(b));
    let lo = lo.iter().fold(0.0f32, |a, &b| a.min(b));
    (hi, lo, negatives)
}

/// A row source that judges its rows as they pass ([`Plausibility`]) and hands the verdict to
/// `warn` once, when every row of the source has been read; the rows are passed on unchanged.
pub struct Watched {
    src: Box<dyn RowSource>,
    stats: Plausibility,
    seen: Vec<bool>,
    left: usize,
    warn: Box<dyn FnMut(&str)>,
}

impl Watched {
    /// Watches `src`; `nonnegative` as [`Plausibility::new`]; `warn` receives the one line.
    pub fn new(src: Box<dyn RowSource>, nonnegative: bool, warn: Box<dyn FnMut(&str)>) -> Self {
        let g = src.geometry();
        let stats = Plausibility::new(g, nonnegative);
        let rows = src.rows();
        let mut seen = vec![true; g.lasers.len()];
        for l in rows.clone() {
            seen[l] = false;
        }
        Self {
            stats,
            seen,
            left: rows.len(),
            src,
            warn,
        }
    }

    fn observe(&mut self, l: usize, row: &[f32], stats: RowStats) {
        let Some(seen) = self.seen.get_mut(l) else {
            return;
        };
        if *seen {
            return;
        }
        *seen = true;
        self.stats.observe_with(l, row, stats);
        self.left -= 1;
        if self.left == 0
            && let Some(w) = self.stats.verdict()
        {
            (self.warn)(&w);
        }
    }
}

impl RowSource for Watched {
    fn geometry(&self) -> &Geometry {
        self.src.geometry()
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        let x = self.src.read_row(l, out)?;
        let stats = self.stats.row_stats(out);
        self.observe(l, out, stats);
        Ok(x)
    }

    fn read_rows(&mut self, first: usize, out: &mut [(Point, Vec<f32>)]) -> Result<()> {
        self.src.read_rows(first, out)?;
        // The rows' passes in parallel; the statistics in row order.
        let stats = &self.stats;
        let ext: Vec<_> = out
            .par_iter()
            .map(|(_, h)| stats.row_stats_located(h))
            .collect();
        for ((l, (_, h)), e) in (first..).zip(out.iter()).zip(ext) {
            self.observe(l, h, e);
        }
        Ok(())
    }

    fn reads_in_parallel(&self) -> bool {
        self.src.reads_in_parallel()
    }

    fn rows(&self) -> std::ops::Range<usize> {
        self.src.rows()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::Capture;

    fn capture(values: impl Fn(usize) -> f32) -> Capture {
        let g = Geometry {
            lasers: (0..4).map(|i| [0.1 * i as f32, 0.0, 0.0]).collect(),
            laser_shape: [4, 1],
            spads: (0..3).map(|i| [0.0, 0.1 * i as f32, 0.0]).collect(),
            spad_shape: [3, 1],
            laser_origin: [0.0; 3],
            sensor_origin: [0.0; 3],
            legs_in_time: false,
            confocal: false,
            nt: 50,
            dt: 0.01,
            t0: 0.0,
            normals: crate::io::capture::Normals::default(),
        };
        let n = 4 * 3 * 50;
        Capture::new(g, (0..n).map(values).collect(), Path::new("test")).expect("capture")
    }

    fn verdict(c: Capture, nonnegative: bool) -> Option<String> {
        let said = std::rc::Rc::new(std::cell::RefCell::new(None));
        let s = said.clone();
        let mut w = Watched::new(
            Box::new(c),
            nonnegative,
            Box::new(move |m: &str| *s.borrow_mut() = Some(m.to_string())),
        );
        let mut row = Vec::new();
        // Out of order and twice: each row counts once, the verdict comes after the last.
        for l in [2, 0, 0, 3, 1] {
            w.read_row(l, &mut row).expect("row");
        }
        said.take()
    }

    /// A smooth transient with noise-like spread.
    fn clean(i: usize) -> f32 {
        1.0 + ((i * 7919) % 97) as f32 * 0.3
    }

    #[test]
    fn clean_data_say_nothing() {
        assert_eq!(verdict(capture(clean), true), None);
    }

    #[test]
    fn a_flipped_exponent_is_named_with_its_position() {
        // Row 1, SPAD 2, bin 7: index 1·150 + 2·50 + 7.
        let w = verdict(capture(|i| if i == 257 { 5.7e37 } else { clean(i) }), true)
            .expect("a warning");
        assert!(
            w.contains("laser row 1, SPAD 2, bin 7") && w.contains("5.7e37"),
            "{w}"
        );
        // Large, but within the factor: data.
        assert_eq!(
            verdict(capture(|i| if i == 257 { 3e4 } else { clean(i) }), true),
            None
        );
    }

    #[test]
    fn negatives_are_implausible_only_in_counts() {
        let c = || capture(|i| if i == 3 { -2.0 } else { clean(i) });
        let w = verdict(c(), true).expect("a warning");
        assert!(w.contains("1 negative values") && w.contains("laser row 0, SPAD 0, bin 3"));
        assert_eq!(verdict(c(), false), None);
    }

    #[test]
    fn sparse_data_compare_with_their_non_zero_values() {
        // Almost all zeros: the 99.9th percentile is 0; the non-zero values set the scale.
        let sparse = |i: usize| if i.is_multiple_of(100) { 2.0 } else { 0.0 };
        assert_eq!(verdict(capture(sparse), true), None);
        let w = verdict(capture(|i| if i == 51 { 1e9 } else { sparse(i) }), true);
        assert!(w.is_some_and(|w| w.contains("bin 1")));
    }

    /// Records looked up on the reading threads (a batch) name the same values and positions
    /// as a search at observation time (rows one by one): a tie goes to the earlier row, a
    /// later row of the batch beats an earlier one, NaN reads as 0.
    #[test]
    fn batch_records_equal_row_by_row_records() {
        let values = |i: usize| match i {
            30 | 180 => -3.0,
            290 => 6.1e37,
            500 => f32::NAN,
            _ => clean(i),
        };
        let read = |batch: bool| {
            let said = std::rc::Rc::new(std::cell::RefCell::new(None));
            let s = said.clone();
            let mut w = Watched::new(
                Box::new(capture(values)),
                true,
                Box::new(move |m: &str| *s.borrow_mut() = Some(m.to_string())),
            );
            if batch {
                let mut rows = vec![([0.0; 3], Vec::new()); 4];
                w.read_rows(0, &mut rows).expect("rows");
            } else {
                let mut row = Vec::new();
                for l in 0..4 {
                    w.read_row(l, &mut row).expect("row");
                }
            }
            said.take().expect("a warning")
        };
        let (one, batch) = (read(false), read(true));
        assert_eq!(one, batch);
        // 290 = row 1, SPAD 2, bin 40; 30 = row 0, SPAD 0, bin 30.
        assert!(
            one.contains("value 6.1e37 at laser row 1, SPAD 2, bin 40"),
            "{one}"
        );
        assert!(
            one.contains("(the lowest, -3e0, at laser row 0, SPAD 0, bin 30)"),
            "{one}"
        );
        for (at, n) in [(0, 1), (63, 64), (64, 65), (127, 300), (299, 300)] {
            let mut v = vec![1.0f32; n];
            v[at] = 2.0;
            assert_eq!(position_of_largest(&v, 2.0), at);
            v[at] = -2.0;
            assert_eq!(position_of_lowest(&v, -2.0), at);
        }
    }

    #[test]
    fn formats_that_hold_counts() {
        assert!(nonnegative_format(Path::new("a.hdf5")));
        assert!(nonnegative_format(Path::new("a.ptu")));
        assert!(!nonnegative_format(Path::new("a.npz")));
    }

    /// The dispatched pass (AVX2 where the CPU has it) equals a plain scalar fold on rows of
    /// every length modulo the lanes, with NaN, infinities, signed zeros and blocks of
    /// negatives; non-finite samples read as 0.
    #[test]
    fn extremes_equal_a_plain_fold() {
        for len in [0usize, 1, 15, 16, 17, 31, 33, 1000, 4099] {
            // Special values scattered over the lanes by a stride coprime to 23.
            let row: Vec<f32> = (0..len)
                .map(|i| match (i * 7919 + 13) % 23 {
                    0 => f32::NAN,
                    1 => f32::INFINITY,
                    2 => f32::NEG_INFINITY,
                    3 => -0.0,
                    k => (k as f32 - 12.0) * (1.0 + i as f32 * 1e-3),
                })
                .collect();
            let finite = |v: f32| if v.is_finite() { v } else { 0.0 };
            let hi = row.iter().fold(0.0f32, |a, &v| a.max(finite(v).abs()));
            let lo = row.iter().fold(0.0f32, |a, &v| a.min(finite(v)));
            let neg = row.iter().filter(|&&v| finite(v) < 0.0).count() as u64;
            assert_eq!(extremes(&row), (hi, lo, neg), "length {len}");
            assert_eq!(extremes_lanes(&row), (hi, lo, neg), "length {len}");
        }
    }
}
