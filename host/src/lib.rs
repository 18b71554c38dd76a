//! vltm host library: wraps the no_std [`vltm_kernel`] for use on a workstation.
//!
//! * [`capture`]: the capture model (geometry, time axis) and row access ([`capture::RowSource`]).
//! * [`sim`]: an analytic transient simulator of patches and boxes, from a scene file.
//! * [`stream`]: runs kernel probes over a row source.
//! * [`figure`], [`npy`]: maximum-intensity-projection PNGs and `.npy` volumes.

pub mod capture;
pub mod error;
pub mod figure;
pub mod ltm;
pub mod npy;
pub mod pointsim;
pub mod sim;
pub mod stream;
pub mod volume;

pub use error::{Error, Result};
pub use vltm_kernel as kernel;
