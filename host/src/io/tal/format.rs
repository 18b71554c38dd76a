//! tal's vocabulary: the options mapping a capture onto vltm's conventions ([`TalOptions`]),
//! the axis orders of `H` ([`HFormat`]) and the scan types ([`ScanType`]).

/// How to map a tal capture onto vltm's conventions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TalOptions {
    /// Put sample `n` at the centre of tal's bin `n` (`t0 = t_start + Δt/2`) instead
    /// of its start (`t0 = t_start`, y-tal's `pf_dev`). Default `false`; see the
    /// module docs, *Time axis*.
    pub bin_centre: bool,
}

impl TalOptions {
    /// y-tal's reading, bin `k` at `t_start + k·Δt` (the default).
    pub const YTAL: Self = Self { bin_centre: false };
    /// Box-filter centres, bin `k` at `t_start + (k + ½)·Δt`.
    pub const BIN_CENTRE: Self = Self { bin_centre: true };
}

impl Default for TalOptions {
    fn default() -> Self {
        Self::YTAL
    }
}

/// tal's `HFormat`: the axis order of `H` (time first in every format).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HFormat {
    /// `T_Sx_Sy` = 1: `(Nt, Sx, Sy)`, one histogram per sensor point (confocal or single).
    TSxSy,
    /// `T_Lx_Ly_Sx_Sy` = 2: `(Nt, Lx, Ly, Sx, Sy)`, exhaustive.
    TLxLySxSy,
    /// `T_Si` = 3: `(Nt, Si)`, one histogram per sensor point (confocal or single).
    TSi,
    /// `T_Li_Si` = 4: `(Nt, Li, Si)`, exhaustive over point lists.
    TLiSi,
}

impl HFormat {
    /// The format of tal's enum value `v` (`tal.enums.HFormat`), if known (0 is `UNKNOWN`).
    pub fn from_tal(v: i64) -> Option<Self> {
        match v {
            1 => Some(Self::TSxSy),
            2 => Some(Self::TLxLySxSy),
            3 => Some(Self::TSi),
            4 => Some(Self::TLiSi),
            _ => None,
        }
    }

    /// tal's enum value of the format.
    pub fn tal_value(self) -> i64 {
        match self {
            Self::TSxSy => 1,
            Self::TLxLySxSy => 2,
            Self::TSi => 3,
            Self::TLiSi => 4,
        }
    }

    /// tal's name of the format (`T_Lx_Ly_Sx_Sy`, ...).
    pub fn tal_name(self) -> &'static str {
        match self {
            Self::TSxSy => "T_Sx_Sy",
            Self::TLxLySxSy => "T_Lx_Ly_Sx_Sy",
            Self::TSi => "T_Si",
            Self::TLiSi => "T_Li_Si",
        }
    }

    /// Rank of `H` in this format.
    pub fn rank(self) -> usize {
        match self {
            Self::TLxLySxSy => 5,
            Self::TSxSy | Self::TLiSi => 3,
            Self::TSi => 2,
        }
    }

    /// Number of `H` axes after time that index a row (the laser, or the sensor point of the
    /// one-histogram-per-point formats).
    pub(super) fn row_axes(self) -> usize {
        match self {
            Self::TLxLySxSy | Self::TSxSy => 2,
            Self::TLiSi | Self::TSi => 1,
        }
    }
}

/// tal's `scan_type`, as inferred from `H_format` and the grids (module docs, *Scan types*).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScanType {
    /// Every laser spot × every SPAD spot.
    Exhaustive,
    /// One laser spot, the SPAD grid scanned; presented by reciprocity as the SPAD grid's spots
    /// as lasers × one SPAD at the laser spot.
    Single,
    /// The SPAD looks at the laser spot.
    Confocal,
    /// One laser spot and one SPAD spot per histogram, apart (y-tal's
    /// `is_laser_paired_to_sensor()` without `is_confocal()`): galvo-scanned non-confocal
    /// systems, arbitrary scanning. Presented as a paired [`Geometry`](crate::io::Geometry)
    /// (one histogram per row, [`Geometry::confocal`](crate::io::Geometry::confocal)).
    Paired,
}
