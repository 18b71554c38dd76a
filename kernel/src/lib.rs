#![doc = include_str!("../README.md")]
#![no_std]

mod config;
mod error;
mod probe;
mod sample;
mod scan;
mod trig;

pub use config::{Config, Legs, Params, Point, Weights};
pub use error::{ConfigError, Error};
pub use num_complex;
pub use probe::{Gate, Probe, Report, Target};
pub use sample::Sample;
pub use scan::{Row, RowBuffer, Scan};
pub use trig::{cis_turns, cis_turns_f64};
