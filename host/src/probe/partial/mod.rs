//! Partial accumulators: a probe run over a part of a scan's laser rows keeps its
//! accumulator state as a [`Partial`] instead of finishing it, so a scan can be split by rows
//! across processes and machines, the parts [merged](Partial::merge) by addition and the sum
//! [finished](Partial::finish) into the same volume as one pass (bit-identical where the
//! summation order is the same, else to float rounding).
//!
//! A part records the capture's identity (file size, dimensions, time axis, an FNV-1a hash
//! of the geometry) and the probe's kind and parameters (the user's wave options, the
//! resolved kernel configuration, the volume, focus, gate, shell, Γ, evaluation path);
//! merging parts that differ in any of them, or whose row ranges overlap, is an error, and so
//! is finishing a state whose rows do not cover the scan.
//!
//! # File format
//!
//! [`Partial::to_bytes`] writes the container of [`crate::io::state`] (magic `VLTMPART`,
//! version, JSON header, SPAD spots, volume points, a matrix's foci, the accumulators, a
//! CRC-32); the header holds the fields below.
//!
//! State per probe (`f64`): direct light `2·Kv`; higher-order column `2·Kv`; factorised
//! column (two-bounce) `2J(Ks+1)`, un-gated `2Ks`; in-focus indirect light `|Γ|·2J(Ks+1)`
//! (leak-corrected or not: the gate corrects each row from Γ and the geometry alone, and the
//! header sums the energy read and removed, `report.leak_total`/`leak_cut`); the matrix
//! `n_from·2J(Ks+1)` (one factorised column per focus, imaged over the `to` voxels when
//! finished).
//! Merging is one addition per `f64`; finishing costs what finishing one pass costs (the
//! imaging of factorised columns). Memory: the state, twice while merging two parts.

mod accumulate;
mod head;
mod names;
mod part;

pub use crate::io::state::{MAGIC, VERSION};
pub use accumulate::accumulate;
pub use part::{Finished, Partial, Task};
