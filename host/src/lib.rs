#![doc = include_str!("../README.md")]

pub mod aperture;
pub mod atomic;
pub mod budget;
pub mod demo;
pub mod error;
pub mod exec;
pub mod export;
pub mod info;
pub mod io;
pub mod live;
pub mod probe;
#[cfg(test)]
pub(crate) mod scratch;
pub mod sim;
pub mod timings;
pub mod volume;

pub use error::{Error, Result};
pub use exec::{EvalPath, Exec, Progress};
pub use vltm_kernel as kernel;
