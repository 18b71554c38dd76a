//! What the leak correction is asked to do: the method and its options, and the voxel cell
//! radius its windows are measured in.

use crate::volume::Volume;

/// How the direct light is removed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LeakMethod {
    /// Zero, per (laser, SPAD), the bins where a 3-vertex return of a Γ voxel can arrive:
    /// `τ_lvs ± (r_cell + 3Δt)` (`r_cell` half a voxel's diagonal).
    Gate,
    /// Fit the one-bounce model's reflectances (CGNR) and subtract its render.
    Fit,
}

/// The adjacency ([`GateEnergy::adjacency`](super::GateEnergy::adjacency)) from which the
/// command line's `--leak-correct auto` tries the surface model instead of the windows: the
/// light the windows leave lies mostly next to them, so they cut through light that goes on
/// past their edges. Measured (docs/indirect-light.md): 0.03–0.11 on the simulator's compact
/// scenes, where the windows keep all of the indirect light, 0.68–0.72 on the path-traced
/// extended surfaces, where the model keeps 0.9 of it and the windows 0.3.
pub const AUTO_ADJACENCY: f64 = 0.4;

/// Options of the direct-light removal (the CLI's `--leak-correct`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeakOptions {
    /// Time-gating of the 3-vertex windows or the model fit (default gate).
    pub method: LeakMethod,
    /// Conjugate-gradient iterations of the fit (default 30).
    pub iterations: usize,
    /// Complex reflectances of the fit (a path offset per voxel, default) or real ones only.
    pub complex: bool,
    /// Gate: half-width of the zeroed windows in units of `r_cell` (default 1), plus 3Δt.
    pub cells: f64,
}

impl Default for LeakOptions {
    fn default() -> Self {
        Self {
            method: LeakMethod::Gate,
            iterations: 30,
            complex: true,
            cells: 1.0,
        }
    }
}

/// Half the diagonal of a voxel cell of `volume` (0 for point lists).
pub fn cell_radius(volume: &Volume) -> f64 {
    match volume.axes {
        Some(axes) => {
            let p2: f64 = (0..3)
                .map(|i| {
                    let n = volume.shape[i];
                    if n > 1 {
                        (f64::from(axes[i][1] - axes[i][0]) / (n - 1) as f64).powi(2)
                    } else {
                        0.0
                    }
                })
                .sum();
            0.5 * p2.sqrt()
        }
        None => 0.0,
    }
}
