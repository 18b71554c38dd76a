//! Run kernel probes over a row source with host (`Vec`) memory.

use vltm_kernel::{Config, Error, Gate, Point, Probe, Report, RowBuffer, Scan, Target};

/// One probe request: target, gate and the voxels to image.
#[derive(Clone, Debug)]
pub struct Request {
    /// Diagonal or column.
    pub target: Target,
    /// Time gate.
    pub gate: Gate,
    /// Voxels [m].
    pub voxels: Vec<Point>,
}

/// Streams `n_rows` rows from `source(l, &mut histograms) -> laser spot` through every
/// request at once (one band-spectrum pass per row) and returns intensities `|A|²` per
/// request with their reports. Memory: `O(Ks·Nt + Ks·J + Σ state)`, independent of `n_rows`.
///
/// # Errors
/// Kernel [`Error`]s (a source row of the wrong length, non-finite positions).
pub fn run(
    cfg: &Config,
    spads: &[Point],
    requests: &[Request],
    n_rows: usize,
    mut source: impl FnMut(usize, &mut Vec<f32>) -> Point,
) -> Result<Vec<(Vec<f64>, Report)>, Error> {
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, spads.len())];
    let scan = Scan::new(cfg, spads, &mut tables)?;
    let mut buf = vec![0.0f32; RowBuffer::len(cfg, spads.len())];
    let mut rows = RowBuffer::new(&scan, &mut buf)?;
    let mut states: Vec<Vec<f64>> = requests
        .iter()
        .map(|r| vec![0.0; Probe::state_len(cfg, r.target, r.gate, r.voxels.len(), spads.len())])
        .collect();
    let mut probes = requests
        .iter()
        .zip(states.iter_mut())
        .map(|(r, s)| Probe::new(&scan, r.target, r.gate, &r.voxels, s))
        .collect::<Result<Vec<_>, _>>()?;
    let mut hists = Vec::new();
    for l in 0..n_rows {
        let laser = source(l, &mut hists);
        let row = rows.load(&scan, laser, &hists)?;
        for p in probes.iter_mut() {
            p.push_row(&scan, &row)?;
        }
    }
    probes
        .iter()
        .map(|p| {
            let mut out = vec![0.0; p.voxels().len()];
            let rep = p.finish(&scan, &mut out)?;
            Ok((out, rep))
        })
        .collect()
}
