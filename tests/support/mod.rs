//! Drives the kernel the way a host does: tables, row buffer, one probe, rows streamed in a
//! given order, `finish`. Shared by the test files via `mod support;`.
#![allow(dead_code)]

use vltm_kernel::{Config, Gate, Point, Probe, Report, RowBuffer, Sample, Scan, Target};

/// A scan for the kernel: apertures and histograms `hists[(l·Ks + s)·Nt + n]`.
#[derive(Clone, Copy, Debug)]
pub struct Data<'a, T> {
    /// Laser spots (one row each).
    pub lasers: &'a [Point],
    /// SPAD spots.
    pub spads: &'a [Point],
    /// Histograms, laser-major.
    pub hists: &'a [T],
}

impl<T: Sample> Data<'_, T> {
    /// The histograms of laser row `l`.
    pub fn row(&self, nt: usize, l: usize) -> &[T] {
        let len = self.spads.len() * nt;
        &self.hists[l * len..(l + 1) * len]
    }
}

/// The laser rows `0..Kl` in order.
pub fn all_rows(kl: usize) -> Vec<usize> {
    (0..kl).collect()
}

/// Streams the rows `order` of `data` through one probe and returns `(T, report)`.
pub fn run<T: Sample>(
    cfg: &Config,
    data: Data<'_, T>,
    target: Target,
    gate: Gate,
    voxels: &[Point],
    order: &[usize],
) -> (Vec<f64>, Report) {
    let ks = data.spads.len();
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, data.spads, &mut tables).expect("scan");
    let mut state = vec![0.0f64; Probe::state_len(cfg, target, gate, voxels.len(), ks)];
    let mut probe = Probe::new(&scan, target, gate, voxels, &mut state).expect("probe");
    let mut buf = vec![0.0f32; RowBuffer::len(cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).expect("row buffer");
    for &l in order {
        let row = rows
            .load(&scan, data.lasers[l], data.row(cfg.nt(), l))
            .expect("load");
        probe.push_row(&scan, &row).expect("push_row");
    }
    let mut out = vec![0.0f64; voxels.len()];
    let report = probe.finish(&scan, &mut out).expect("finish");
    (out, report)
}

/// Every (target kind, gate) combination the kernel offers, for a column focus `focus`.
pub fn all_probes(focus: Point) -> [(Target, Gate); 6] {
    [
        (Target::Diagonal, Gate::Gaussian),
        (Target::Diagonal, Gate::HigherOrder),
        (Target::Diagonal, Gate::None),
        (Target::Column(focus), Gate::Gaussian),
        (Target::Column(focus), Gate::HigherOrder),
        (Target::Column(focus), Gate::None),
    ]
}

/// Largest `|x − y|` relative to `max |y|` (0 when both are all zero).
pub fn max_rel_diff(x: &[f64], y: &[f64]) -> f64 {
    assert_eq!(x.len(), y.len());
    let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = x
        .iter()
        .zip(y)
        .fold(0.0f64, |m, (a, b)| m.max(nan_is_inf((a - b).abs())));
    if diff == 0.0 { 0.0 } else { diff / scale }
}

/// An error measure with NaN turned into +∞, so that `f64::max` (which drops NaN) cannot
/// hide a NaN result from a `worst ≤ tol` assertion.
pub fn nan_is_inf(err: f64) -> f64 {
    if err.is_nan() { f64::INFINITY } else { err }
}
