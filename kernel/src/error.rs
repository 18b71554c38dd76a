//! Error types. Configuration errors are found once, at `try_new`; buffer errors at the
//! boundary of a call (a slice of the wrong length). No error depends on data *values*:
//! the per-row arithmetic is infallible.

use core::fmt;

/// A configuration parameter was rejected by [`Config::try_new`](crate::Config::try_new).
///
/// Each variant names the parameter (as a `&'static str` field name of
/// [`Params`](crate::Params)) so that a host can report it to the user.
///
/// ```
/// use vltm_kernel::{Config, ConfigError, Params};
/// let err = Config::try_new(&Params::new(-0.2, 100, 0.01)).unwrap_err();
/// assert_eq!(err, ConfigError::NotPositive("wavelength"));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ConfigError {
    /// The parameter must be finite (it was NaN or ±∞).
    NotFinite(&'static str),
    /// The parameter must be strictly positive.
    NotPositive(&'static str),
    /// The parameter must not be negative (zero is allowed).
    Negative(&'static str),
    /// The parameter is below its least accepted value (`margin`: `−gate_support·σ`, where
    /// the guard interval shrinks to the samples' window).
    BelowMinimum(&'static str),
    /// The parameter is finite and positive but outside what the f32 arithmetic can carry
    /// (for `d_min`: its reciprocal, the largest leg weight, must be a finite f32).
    OutOfRange(&'static str),
    /// The histogram length `nt` is zero.
    EmptyTimeAxis,
    /// The band `k_lo..=k_hi` reaches past the Nyquist bin ±N/2: the time bin Δt is too
    /// coarse for the virtual wavelength (need roughly `Δt·(1/λ + m/(2πσ)) < 1/2`).
    BandCrossesNyquist,
    /// A derived size (DFT length, band, table length) does not fit the index types.
    SizeOverflow(&'static str),
    /// The parameter (a lookup grid length) must be a power of two.
    NotPowerOfTwo(&'static str),
    /// The parameter makes a lookup grid too coarse: its interpolation error bound exceeds
    /// the tolerance, or it has fewer points than band bins or than 8 per carrier wavelength.
    TooCoarse(&'static str),
    /// The parameter (the SPAD positions of a structured slice) does not lie on the slice's
    /// lattice: a SPAD's offset from the first is not an integer multiple of `step_x`.
    NotOnLattice(&'static str),
    /// The parameter (a table of a structured slice) needs more memory than the caller
    /// offers: use the general path.
    DoesNotFit(&'static str),
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotFinite(p) => write!(f, "parameter `{p}` must be finite"),
            Self::NotPositive(p) => write!(f, "parameter `{p}` must be > 0"),
            Self::Negative(p) => write!(f, "parameter `{p}` must be >= 0"),
            Self::OutOfRange(p) => write!(f, "parameter `{p}` is out of the f32 range"),
            Self::BelowMinimum(p) => write!(
                f,
                "parameter `{p}` is below its minimum (margin >= -gate_support*sigma)"
            ),
            Self::EmptyTimeAxis => f.write_str("parameter `nt` must be > 0 (empty time axis)"),
            Self::BandCrossesNyquist => f.write_str(
                "the frequency band crosses Nyquist: the time bin `dt` is too coarse for \
                 `wavelength` (need dt*(1/wavelength + m/(2*pi*sigma)) < 1/2)",
            ),
            Self::SizeOverflow(p) => write!(f, "derived size `{p}` overflows"),
            Self::NotPowerOfTwo(p) => write!(f, "parameter `{p}` must be a power of two"),
            Self::TooCoarse(p) => write!(
                f,
                "parameter `{p}` gives a grid too coarse for the tolerance \
                 (or fewer points than band bins, or than 8 per wavelength)"
            ),
            Self::NotOnLattice(p) => write!(
                f,
                "parameter `{p}` is not on the slice's lattice (offsets must be integer \
                 multiples of `step_x`)"
            ),
            Self::DoesNotFit(p) => write!(f, "`{p}` does not fit the memory offered"),
        }
    }
}

impl core::error::Error for ConfigError {}

/// A caller-provided argument does not fit the configuration: a slice of the wrong length,
/// a non-finite position, or two probes that cannot be merged. Found at the boundary of a
/// call, never inside the per-bin loops; nothing was modified when it is returned.
///
/// ```
/// use vltm_kernel::ArgumentError;
/// let e = ArgumentError::Length { what: "histograms", expected: 8, found: 7 };
/// assert_eq!(e.to_string(), "`histograms` has 7 elements, expected 8");
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ArgumentError {
    /// A slice has the wrong number of elements.
    Length {
        /// Which argument.
        what: &'static str,
        /// The length the configuration requires.
        expected: usize,
        /// The length that was passed.
        found: usize,
    },
    /// A position has a NaN or infinite coordinate.
    NonFinite {
        /// Which argument.
        what: &'static str,
        /// Index of the offending point in its list.
        index: usize,
    },
    /// Two probes differ in kind, focus, voxels or configuration and cannot be merged.
    Incompatible(&'static str),
}

impl fmt::Display for ArgumentError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Length {
                what,
                expected,
                found,
            } => {
                write!(f, "`{what}` has {found} elements, expected {expected}")
            }
            Self::NonFinite { what, index } => {
                write!(f, "`{what}`[{index}] has a non-finite coordinate")
            }
            Self::Incompatible(why) => write!(f, "probes cannot be merged: {why}"),
        }
    }
}

impl core::error::Error for ArgumentError {}

/// Checks a length once at a call boundary.
#[inline]
pub(crate) fn check_len(
    what: &'static str,
    expected: usize,
    found: usize,
) -> Result<(), ArgumentError> {
    if expected == found {
        Ok(())
    } else {
        Err(ArgumentError::Length {
            what,
            expected,
            found,
        })
    }
}

/// Checks that every coordinate of every point is finite. (Points as `[f32; 3]`, what
/// `config::Point` stands for: `config` imports this module, so this one does not import
/// `config`.)
pub(crate) fn check_points(what: &'static str, pts: &[[f32; 3]]) -> Result<(), ArgumentError> {
    match pts.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        None => Ok(()),
        Some(index) => Err(ArgumentError::NonFinite { what, index }),
    }
}
