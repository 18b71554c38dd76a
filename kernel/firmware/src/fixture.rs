//! The fixture scan: geometry and parameters shared by the firmware and the host generator
//! (`gen/`, which includes this file with `#[path]`). Change it only together with
//! `fixture/scan.bin` and `fixture/expected.txt` (regenerate with `gen`, see the README).
//!
//! Scene (`fixture/scene.json`, rendered by the host simulator `vltm simulate`): two point
//! scatterers P1 (bright) and P2 in the plane z = 0.5 m, the direct 3-vertex returns of both
//! and the 4-vertex returns P1 ↔ P2, a Gaussian pulse and seeded Poisson counts with a small
//! background, in `u16` counts. Regenerate with `fixture/regenerate.sh`.
//!
//! `scan.bin` layout: `N_LASERS` rows in the order of [`LASERS`]; a row is `N_SPADS`
//! histograms in the order of [`SPADS`] (SPAD-major, the kernel's layout), each `NT`
//! little-endian `u16` counts; bin `n` is path length `T0 + n·DT`. No header:
//! `16 × 4 × 128 × 2 = 16 384` bytes.

use vltm_kernel::{Params, Point};

/// Histogram length (bins).
pub const NT: usize = 128;
/// Bin width (m of path).
pub const DT: f64 = 0.01;
/// Path length of bin 0 (m).
pub const T0: f64 = 0.5;
/// Virtual wavelength λ (m).
pub const WAVELENGTH: f64 = 0.1;

/// Laser spots on the wall: a 4 × 4 grid, 0.2 m pitch, row-major in y.
pub const LASERS: [Point; 16] = {
    let c = [-0.3f32, -0.1, 0.1, 0.3];
    let mut l = [[0.0f32; 3]; 16];
    let mut i = 0;
    while i < 16 {
        l[i] = [c[i % 4], c[i / 4], 0.0];
        i += 1;
    }
    l
};
/// SPAD spots on the wall: a line of 4 along x.
pub const SPADS: [Point; 4] = [
    [-0.15, 0.0, 0.0],
    [-0.05, 0.0, 0.0],
    [0.05, 0.0, 0.0],
    [0.15, 0.0, 0.0],
];
/// Number of laser rows.
pub const N_LASERS: usize = LASERS.len();
/// Number of SPADs.
pub const N_SPADS: usize = SPADS.len();
/// `u16` samples per row.
pub const ROW: usize = N_SPADS * NT;

/// The bright scatterer (= voxel [`P1_VOXEL`]).
pub const P1: Point = [-0.075, -0.075, 0.5];
/// The second scatterer (= voxel [`P2_VOXEL`]).
pub const P2: Point = [0.225, 0.075, 0.5];
/// Voxels: a 4 × 4 grid at z = 0.5 m, 0.15 m pitch (indices 0..16, row-major in y), then two
/// voxels in front of and behind P1 (16, 17).
pub const VOXELS: [Point; 18] = {
    let c = [-0.225f32, -0.075, 0.075, 0.225];
    let mut v = [[0.0f32; 3]; 18];
    let mut i = 0;
    while i < 16 {
        v[i] = [c[i % 4], c[i / 4], 0.5];
        i += 1;
    }
    v[16] = [P1[0], P1[1], 0.35];
    v[17] = [P1[0], P1[1], 0.65];
    v
};
/// Number of voxels.
pub const N_VOXELS: usize = VOXELS.len();
/// Voxels of the z = 0.5 m slice (the column's sanity check looks only there: the voxel in
/// front of P1 sees P1's direct light through the column's gate).
pub const SLICE: usize = 16;
/// Index of P1 in [`VOXELS`].
pub const P1_VOXEL: usize = 5;
/// Index of P2 in [`VOXELS`].
pub const P2_VOXEL: usize = 11;
/// Focus of the Gaussian column `T(P1, ·)`.
pub const FOCUS: Point = P1;

/// The kernel parameters of the fixture (defaults otherwise: σ = 2λ/3, m = 5, c_g = 5,
/// wall-to-wall legs, 1/d weights).
pub const fn params() -> Params {
    let mut p = Params::new(WAVELENGTH, NT, DT);
    p.t0 = T0;
    p
}

/// Band bins J of [`params`] (checked by the generator and at run time; needed as a
/// constant to size the static buffers).
pub const BINS: usize = 48;
/// DFT length N of [`params`] (checked likewise).
pub const N_FFT: usize = 195;
/// `Scan::tables_len`: `2N + J + Ks` `f32`.
pub const TABLES_LEN: usize = 2 * N_FFT + BINS + N_SPADS;
/// `RowBuffer::len`: `Ks·(2J + 3)` `f32`.
pub const ROWBUF_LEN: usize = N_SPADS * (2 * BINS + 3);
/// Diagonal state (`Probe::state_len`, Gaussian or un-gated): `2Kv` `f64`.
pub const DIAG_LEN: usize = 2 * N_VOXELS;
/// Gaussian column state (factorised): `2J(Ks + 1)` `f64`.
pub const COLUMN_LEN: usize = 2 * BINS * (N_SPADS + 1);
/// Higher-order state (diagonal or column): `2(Kv + Nt + 1)` `f64`.
pub const HO_LEN: usize = 2 * (N_VOXELS + NT + 1);

/// Laser rows the firmware-to-host run (`src/bin/state.rs`) folds before handing its state to
/// the host, which takes the other rows (`0..8`): the second half of the scan.
pub const STATE_ROWS: core::ops::Range<usize> = 8..16;
