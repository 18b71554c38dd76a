//! Results out: intensity volumes as `.npy` ([`npy`]) and HDF5 ([`h5`]), and
//! maximum-intensity-projection PNG figures ([`figure`]).
//!
//! Outputs take plain slices of intensities and a [`Volume`](crate::volume::Volume): nothing
//! here imports the readers, the simulator or the probes.

pub mod figure;
pub mod h5;
pub mod npy;
