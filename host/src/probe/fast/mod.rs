//! Host-only fast paths: the same band spectra and probes as the kernel,
//! evaluated with libraries a workstation has.
//!
//! * [`band`]: stage 1 of a whole laser row as one `sgemm` (`matrixmultiply`), or
//!   [`sgemm`]'s AVX-512 product where the CPU has it (`pulp` dispatch).
//! * [`planar`]: the planar FFT convolution over a SPAD grid and wall-parallel voxel slices
//!   (`rustfft`), for the diagonal per row and for imaging factorised columns.
//! * [`confocal`]: the same FFT convolution for confocal scans (laser and SPAD at each wall
//!   point): per slice one inverse FFT of `Σ_j X̂_j·κ̂_j`, no stored kernel table (`rustfft`).
//! * [`phasor`]: the full-phasor table per histogram, 8 voxels per vector, for the diagonal of
//!   any scan (paired and confocal scans; SPAD grids off the FFT path) (`rustfft`, `pulp`
//!   dispatch).
//! * [`lookup`]: the gated baseband + lookup diagonal (§B.2.4, [`LookupDiagonal`]): one inverse FFT per SPAD and
//!   row, then a cubic interpolation per (voxel, SPAD), for any geometry (`rustfft`).
//! * `lattice`: the wall lattice and the voxel grid's layout for a 2-D convolution, shared by
//!   the FFT paths and read by the planner.
//! * [`resample`]: volumes off the wall's lattice computed on a support grid the FFT paths
//!   take and resampled to the asked voxels within a stated bound.
//! * `aligned`: the nearest grid the FFT paths take, the depths the time window reaches and
//!   the volume `vltm info` suggests (re-exported by [`crate::probe`]).
//!
//! The planner (`probe::plan`) picks a path per probe ([`crate::exec::EvalPath`]); every path is
//! checked against the float64 reference in `tests/proptest_fast.rs`.

pub(crate) mod aligned;
pub mod band;
pub mod confocal;
mod lanes;
pub(crate) mod lattice;
pub mod lookup;
pub mod phasor;
pub mod planar;
pub mod resample;
#[cfg(target_arch = "x86_64")]
pub mod sgemm;

pub use band::BandDft;
pub use confocal::Confocal;
pub use lookup::LookupDiagonal;
pub use phasor::Phasor;
pub use planar::Planar;
