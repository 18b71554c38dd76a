//! Instruction counts of the kernel's **lookup path** for the paper's real setup, called by
//! the cycles firmware (`src/bin/cycles.rs`) after its own measurements: a Gaussian diagonal
//! over the 64 × 64 slice and one column `T(a, ·)` over the same slice, per laser row, at the
//! default tolerance (1e-5: `L` = 1024) and at 1e-4 (`L` = 512), plus the per-row fixed part
//! (the `Ks` grid syntheses: a push with no voxels). Prints `CYCLES lookup_…` lines.

use cortex_m::singleton;
use semihosting::println;
use vltm_kernel::{Lookup, LookupGrid, LookupParams, LookupProbe, Point, RowBuffer, Scan, Target};

/// Largest grid measured.
const L_MAX: usize = 1024;

/// Runs the measurements. `measure(f)` returns the SysTick ticks taken by `f`,
/// `per_tick` the instructions per tick. Returns the 64×64 diagonal's and column's
/// instructions per row at the default tolerance, `None` if a kernel call was rejected.
pub fn run(
    scan: &Scan<'_>,
    rows: &mut RowBuffer<'_>,
    hists: &[u16],
    voxels: &[Point],
    measure: &mut dyn FnMut(&mut dyn FnMut()) -> u64,
    per_tick: f64,
) -> Option<[f64; 2]> {
    const KV_MAX: usize = 64 * 64;
    let (Some(tables), Some(state), Some(scratch)) = (
        singleton!(: [f32; 4 * L_MAX] = [0.0; 4 * L_MAX]),
        singleton!(: [f64; 2 * KV_MAX] = [0.0; 2 * KV_MAX]),
        singleton!(: [f32; 2 * (L_MAX + 3) + 3 * KV_MAX] = [0.0; 2 * (L_MAX + 3) + 3 * KV_MAX]),
    ) else {
        return None;
    };
    let cfg = scan.config();
    let ks = scan.spads().len();
    let kv = voxels.len().min(KV_MAX);
    let Some(voxels) = voxels.get(..kv) else {
        return None;
    };
    let laser = [-0.45f32, -0.5, 0.0];
    // Instructions of the diagonal and the column at the default tolerance (the first).
    let mut first: Option<[f64; 2]> = None;
    for tol in [1e-5, 1e-4] {
        let p = LookupParams {
            tolerance: tol,
            grid_len: None,
        };
        let Ok(grid) = LookupGrid::try_new(cfg, &p) else {
            return None;
        };
        let l = grid.len();
        if l > L_MAX {
            return None;
        }
        let Some(t) = tables.get_mut(..Lookup::tables_len(&grid)) else {
            return None;
        };
        let Ok(lookup) = Lookup::new(&grid, t) else {
            return None;
        };
        let mut counts = [0u64; 3];
        for (k, (target, n)) in [
            (Target::Diagonal, 0),
            (Target::Diagonal, kv),
            (Target::Column([0.1, 0.2, 1.0]), kv),
        ]
        .into_iter()
        .enumerate()
        {
            let Some(vox) = voxels.get(..n) else {
                return None;
            };
            let (Some(s), Some(sc)) = (
                state.get_mut(..LookupProbe::state_len(n)),
                scratch.get_mut(..LookupProbe::scratch_len(&grid, n)),
            ) else {
                return None;
            };
            let Ok(mut probe) = LookupProbe::new(scan, &lookup, target, vox, s, sc) else {
                return None;
            };
            let Ok(row) = rows.load(scan, laser, hists) else {
                return None;
            };
            let mut ok = true;
            let t = measure(&mut || ok = probe.push_row(scan, &lookup, &row).is_ok());
            if !ok {
                return None;
            }
            if let Some(c) = counts.get_mut(k) {
                *c = t;
            }
        }
        let i = |t: u64| t as f64 * per_tick;
        let pairs = (kv * ks) as f64;
        let [t_fixed, t_diag, t_col] = counts;
        println!(
            "CYCLES lookup_grid tolerance={tol:e} L={l} bound={:.2e} synth_instructions={:.0} per_spad={:.0}",
            grid.bound(),
            i(t_fixed),
            i(t_fixed) / ks as f64
        );
        println!(
            "CYCLES lookup_diag64x64 L={l} instructions={:.0} per_pair={:.1} lookups_per_pair={:.1}",
            i(t_diag),
            i(t_diag) / pairs,
            (i(t_diag) - i(t_fixed)) / pairs
        );
        println!(
            "CYCLES lookup_column64x64 L={l} instructions={:.0} per_pair={:.1}",
            i(t_col),
            i(t_col) / pairs
        );
        first.get_or_insert([i(t_diag), i(t_col)]);
    }
    first
}
