//! Instruction counts of the kernel's **lookup path** for the paper's real setup, called by
//! the cycles firmware (`src/bin/cycles.rs`) after its own measurements: a Gaussian diagonal
//! over the 64 × 64 slice and one column `T(a, ·)` over the same slice, per laser row, at the
//! default tolerance (1e-5: `L` = 1024) and at 1e-4 (`L` = 512), plus the per-row fixed part
//! (the `Ks` grid syntheses: a push with no voxels). Prints `CYCLES lookup_…` lines.

use cortex_m::singleton;
use semihosting::println;
use vltm_kernel::{
    Interpolant, Lattice, Lookup, LookupGrid, LookupParams, LookupProbe, LookupSlice, Point,
    RowBuffer, Scan, SliceLayout, Target,
};

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
        singleton!(: [f32; 4 * KV_MAX] = [0.0; 4 * KV_MAX]),
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
            ..LookupParams::new()
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

/// The structured slice's 64 × 64 voxels: z = 1 m, x pitch 2.5 cm (the SPAD pitch, so the
/// 28 SPADs sit at lattice offsets 0 … 27), y pitch 2/63 m; 1.575 m × 2 m centred.
pub const SLICE: Lattice = Lattice {
    origin: [-0.7875, -1.0, 1.0],
    step_x: [0.025, 0.0, 0.0],
    step_y: [0.0, 2.0 / 63.0, 0.0],
    nx: 64,
    ny: 64,
};

/// Slice tables for [`SLICE`] and 28 SPADs: `4·(28 + 64·(64 + 27))`.
const SLICE_TABLES: usize = 4 * (28 + 64 * 91);

/// The structured slice ([`LookupSlice`]) over [`SLICE`]: the diagonal and the column per
/// row at tolerance 1e-5 with the Hermite interpolant (`L` = 512), at 1e-4 with the Lagrange
/// one (`L` = 512) and at 1e-5 with the Lagrange one (`L` = 1024, the former default), plus
/// the per-row fixed part (a 1 × 1 slice: the `Ks` syntheses and cubic cells). Prints
/// `CYCLES lookup_slice_…` lines and returns `[diag, column]` instructions per row for each,
/// in that order, `None` if a kernel call was rejected.
pub fn run_slice(
    scan: &Scan<'_>,
    rows: &mut RowBuffer<'_>,
    hists: &[u16],
    measure: &mut dyn FnMut(&mut dyn FnMut()) -> u64,
    per_tick: f64,
) -> Option<[[f64; 2]; 3]> {
    const KV: usize = 64 * 64;
    const SCRATCH: usize = 2 * (L_MAX + 8) + 16 * L_MAX + 4 * KV;
    let (Some(tables), Some(st), Some(state), Some(scratch)) = (
        singleton!(: [f32; 4 * L_MAX] = [0.0; 4 * L_MAX]),
        singleton!(: [f32; SLICE_TABLES] = [0.0; SLICE_TABLES]),
        singleton!(: [f32; 4 * KV] = [0.0; 4 * KV]),
        singleton!(: [f32; SCRATCH] = [0.0; SCRATCH]),
    ) else {
        return None;
    };
    let cfg = scan.config();
    let ks = scan.spads().len();
    let laser = [-0.45f32, -0.5, 0.0];
    let mut result = [[0.0; 2]; 3];
    for (slot, (tol, interpolant)) in [
        (1e-5, Interpolant::Hermite),
        (1e-4, Interpolant::Lagrange),
        (1e-5, Interpolant::Lagrange),
    ]
    .into_iter()
    .enumerate()
    {
        let p = LookupParams {
            tolerance: tol,
            grid_len: None,
            interpolant,
        };
        let Ok(grid) = LookupGrid::try_new(cfg, &p) else {
            return None;
        };
        let l = grid.len();
        let Some(t) = tables.get_mut(..Lookup::tables_len(&grid)) else {
            return None;
        };
        let Ok(lookup) = Lookup::new(&grid, t) else {
            return None;
        };
        let one = Lattice {
            nx: 1,
            ny: 1,
            ..SLICE
        };
        let mut counts = [0u64; 3];
        for (k, (target, lattice)) in [
            (Target::Diagonal, one),
            (Target::Diagonal, SLICE),
            (Target::Column([0.1, 0.2, 1.0]), SLICE),
        ]
        .into_iter()
        .enumerate()
        {
            // The layout checks that the slice tables fit the static buffer.
            let Ok(layout) = SliceLayout::try_new(scan, &grid, &lattice, st.len()) else {
                return None;
            };
            let n = lattice.len();
            let (Some(tb), Some(s), Some(sc)) = (
                st.get_mut(..layout.tables_len()),
                state.get_mut(..LookupSlice::state_len(n)),
                scratch.get_mut(..LookupSlice::scratch_len(&grid, n)),
            ) else {
                return None;
            };
            let Ok(mut probe) = LookupSlice::new(scan, &lookup, &layout, target, tb, s, sc) else {
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
        let pairs = (KV * ks) as f64;
        let [t_fixed, t_diag, t_col] = counts;
        println!(
            "CYCLES lookup_slice_grid tolerance={tol:e} interpolant={interpolant:?} L={l} bound={:.2e} fixed_instructions={:.0} per_spad={:.0} (synthesis + cubic cells)",
            grid.bound(),
            i(t_fixed),
            i(t_fixed) / ks as f64
        );
        println!(
            "CYCLES lookup_slice_diag64x64 {interpolant:?} L={l} instructions={:.0} per_pair={:.1} lookups_per_pair={:.1}",
            i(t_diag),
            i(t_diag) / pairs,
            (i(t_diag) - i(t_fixed)) / pairs
        );
        println!(
            "CYCLES lookup_slice_column64x64 {interpolant:?} L={l} instructions={:.0} per_pair={:.1}",
            i(t_col),
            i(t_col) / pairs
        );
        if let Some(r) = result.get_mut(slot) {
            *r = [i(t_diag), i(t_col)];
        }
    }
    Some(result)
}
