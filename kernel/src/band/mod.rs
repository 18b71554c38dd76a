//! The **band path** in floating point: each laser row's histograms turned into their band
//! spectra once (stage 1), then the LTM elements accumulated from them (stage 2) with the
//! gated phasor as a sum over the `J` band bins. Units, error bounds, cost and memory are in
//! the module docs of each file:
//!
//! | file | items |
//! |---|---|
//! | `scan.rs` | [`Scan`]: configuration, SPAD positions and band tables in caller memory; the band transform (two-stage or direct DFT) |
//! | `row.rs` | [`RowBuffer`] → [`Row`]: stage 1 per laser row (band spectra `HG` with gate and legs folded in, un-gated values, leg offsets), from histograms or photon events |
//! | `probe.rs` | [`Probe`]: a [`Target`] × [`Gate`] over a voxel list with `f64` accumulators |
//! | `column32.rs` | [`ColumnF32`]: the factorised Gaussian column with `f32` Kahan-compensated state, finished by the band sum or the lookup path |
//!
//! The lookup path ([`crate::LookupProbe`], [`crate::LookupSlice`]) reads the same rows; the
//! fixed-point path ([`crate::FixedScan`] …) has its own stage 1.

pub(crate) mod column32;
pub(crate) mod probe;
pub(crate) mod row;
pub(crate) mod scan;

pub use column32::ColumnF32;
pub use probe::{Gate, Probe, Target};
pub use row::{Row, RowBuffer};
pub use scan::Scan;
