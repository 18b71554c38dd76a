#![doc = include_str!("../README.md")]
#![no_std]

mod config;
mod error;
mod fixed;
mod lookup;
mod probe;
mod sample;
mod scan;
mod trig;

pub use self::fixed::{
    CIS_ERR, FixedColumn, FixedConfig, FixedDiagonal, FixedLimits, FixedPhotons, FixedRow,
    FixedRowBuffer, FixedScan, cis_q15,
};
/// The Q1.15 type of the fixed-point tables (from the `fixed` crate 1.31).
pub use ::fixed::types::I1F15;
pub use config::{Config, Legs, Params, Point, Weights};
pub use error::{ConfigError, Error};
pub use lookup::{Lookup, LookupGrid, LookupParams, LookupProbe, lagrange4};
pub use num_complex;
pub use probe::{Gate, Probe, Report, Target};
pub use sample::Sample;
pub use scan::{Row, RowBuffer, Scan};
pub use trig::{cis_small_turns, cis_turns, cis_turns_f64};
