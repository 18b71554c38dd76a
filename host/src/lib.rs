//! vltm host library: wraps the no_std [`vltm_kernel`] for use on a workstation.
//!
//! * [`capture`]: the capture model (geometry, time axis) and row access ([`capture::RowSource`]).
//! * [`sim`]: an analytic transient simulator of patches and boxes, from a scene file.
//! * [`volume`]: voxel grids (`SPEC`) and point lists.
//! * [`fast`]: host fast paths (stage 1 as a matrix product, the planar FFT convolution).
//! * [`ltm`]: the high-level probes (direct, column, in-focus indirect), multi-threaded.
//! * [`demo`]: the built-in scene of `vltm demo`.
//! * [`tal`]: y-tal / mitransient `HDF5_TAL` captures, streamed by laser row.
//! * [`figure`], [`npy`], [`h5`]: maximum-intensity-projection PNGs, `.npy` and HDF5 volumes.

pub mod capture;
pub mod demo;
pub mod error;
pub mod fast;
pub mod figure;
pub mod h5;
pub mod ltm;
pub mod npy;
pub mod ptu;
pub mod sim;
pub mod tal;
pub mod volume;

pub use error::{Error, Result};
pub use vltm_kernel as kernel;
