#![doc = include_str!("../README.md")]
#![no_std]

mod band;
mod config;
mod error;
mod fixed;
pub mod geometry;
mod lookup;
pub mod phase;
mod report;
mod sample;

pub use self::fixed::{
    CIS_ERR, FixedColumn, FixedConfig, FixedDiagonal, FixedLimits, FixedLookup, FixedLookupGrid,
    FixedLookupProbe, FixedPhotons, FixedRow, FixedRowBuffer, FixedScan, LAGRANGE_Q15_ERR, cis_q15,
    lagrange4_q15,
};
/// The Q1.15 type of the fixed-point tables (from the `fixed` crate 1.31).
pub use ::fixed::types::I1F15;
pub use band::{ColumnF32, Gate, Probe, Row, RowBuffer, Scan, Target};
pub use config::{Config, Legs, Params, Point, Weights};
pub use error::{ArgumentError, ConfigError};
pub use lookup::{
    GridReader, Interpolant, Lattice, Lookup, LookupGrid, LookupParams, LookupProbe, LookupSlice,
    SliceLayout, lagrange4,
};
pub use num_complex;
pub use phase::{cis_small_turns, cis_turns, cis_turns_f64};
pub use report::Report;
pub use sample::Sample;
