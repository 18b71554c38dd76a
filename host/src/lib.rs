//! vltm host library: wraps the no_std [`vltm_kernel`] for use on a workstation.
//!
//! This first version holds a small analytic transient simulator of point scatterers
//! ([`sim`]) that produces a capture **row by row** (one laser position at a time, the way
//! the kernel consumes it), and [`stream`], which runs kernel probes over such a source with
//! `Vec`-backed memory. Capture readers, the full scene simulator and the command line with
//! figures come next (see the workspace README).

pub mod sim;
pub mod stream;

pub use vltm_kernel as kernel;
