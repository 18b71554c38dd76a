//! The geometry of a **structured slice** for the lookup path ([`LookupSlice`](crate::LookupSlice)):
//! a plane of voxels on a regular lattice ([`Lattice`]) and SPADs on a line commensurate
//! with it, validated once into a [`SliceLayout`] (which sizes the slice tables).
//!
//! # When it applies
//!
//! # When it applies
//!
//! Voxel `(ix, iy)` (index `iy·nx + ix`) is `o + ix·a + iy·b` ([`Lattice`]), and every SPAD is
//! `s_k = s_0 + m_k·a` for an integer `m_k` (checked to `f32` rounding by
//! [`SliceLayout::try_new`], [`ConfigError::NotOnLattice`] otherwise). Then
//! `v − s_k = (o − s_0) + (ix − m_k)·a + iy·b` depends only on `(ix − m_k, iy)`: the distinct
//! SPAD legs `d_vs` fill a table of `ny × (nx + max m − min m)` entries instead of `Kv·Ks`
//! (for 64 × 64 voxels and 28 SPADs at the lattice pitch: 5 824 entries, 93 KB, instead of
//! 114 688 pairs, 1.8 MB). When the table does not fit the memory the caller offers,
//! [`SliceLayout::try_new`] says so ([`ConfigError::DoesNotFit`]) and the caller uses the
//! general [`LookupProbe`](crate::LookupProbe).
//!
//! Cost: `O(Ks)` once; no memory (the layout is `Copy`; the tables it sizes are filled by
//! [`LookupSlice::new`](crate::LookupSlice::new)).

use super::grid::LookupGrid;
use crate::band::scan::Scan;
use crate::config::Point;
use crate::error::ConfigError;

/// A plane of voxels on a regular lattice: voxel `(ix, iy)`, index `iy·nx + ix`, at
/// `origin + ix·step_x + iy·step_y` (m).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Lattice {
    /// Voxel (0, 0) (m).
    pub origin: Point,
    /// From voxel `(ix, iy)` to `(ix + 1, iy)` (m); the SPAD line's direction.
    pub step_x: Point,
    /// From voxel `(ix, iy)` to `(ix, iy + 1)` (m).
    pub step_y: Point,
    /// Voxels along `step_x` (≥ 1).
    pub nx: usize,
    /// Voxels along `step_y` (≥ 1).
    pub ny: usize,
}

impl Lattice {
    /// Number of voxels `nx·ny`.
    #[allow(clippy::len_without_is_empty)]
    pub const fn len(&self) -> usize {
        self.nx.saturating_mul(self.ny)
    }

    /// Voxel `(ix, iy)` in `f64` (the table's position).
    pub(super) fn point64(&self, ix: f64, iy: f64) -> [f64; 3] {
        let mut p = [0.0; 3];
        for (k, c) in p.iter_mut().enumerate() {
            *c = f64::from(self.origin[k])
                + ix * f64::from(self.step_x[k])
                + iy * f64::from(self.step_y[k]);
        }
        p
    }

    /// Voxel number `i` (`iy·nx + ix`), rounded to `f32`: the voxel list the general path
    /// ([`LookupProbe`](crate::LookupProbe)) takes for the same slice.
    pub fn point(&self, i: usize) -> Point {
        let nx = self.nx.max(1);
        let p = self.point64((i % nx) as f64, (i / nx) as f64);
        [p[0] as f32, p[1] as f32, p[2] as f32]
    }
}

/// The validated layout of a structured slice for one scan and lookup grid: `Copy`, no
/// tables. See the module docs.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SliceLayout {
    pub(super) grid: LookupGrid,
    pub(super) lattice: Lattice,
    pub(super) ks: usize,
    /// Smallest and largest SPAD lattice offset `m_k`.
    pub(super) m_min: i64,
    pub(super) m_max: i64,
    /// Table entries per voxel row: `nx + m_max − m_min`.
    pub(super) width: usize,
}

/// Largest table (entries) and lattice offset accepted: indices stay exact in `f32`.
const MAX_ENTRIES: usize = 1 << 22;

impl SliceLayout {
    /// Checks that the scan's SPADs lie on `lattice`'s x lattice and that the slice tables
    /// fit `capacity` `f32` (pass `usize::MAX` to only validate).
    ///
    /// # Errors
    /// [`ConfigError`] naming the parameter: `nx`/`ny` zero ([`ConfigError::NotPositive`]);
    /// a non-finite `origin`, `step_x`, `step_y` or SPAD ([`ConfigError::NotFinite`]); a zero
    /// `step_x` ([`ConfigError::NotPositive`]); a SPAD off the lattice
    /// ([`ConfigError::NotOnLattice`]`("spads")`); tables over 2²² entries
    /// ([`ConfigError::SizeOverflow`]) or over `capacity` ([`ConfigError::DoesNotFit`]`("slice
    /// tables")`).
    pub fn try_new(
        scan: &Scan<'_>,
        grid: &LookupGrid,
        lattice: &Lattice,
        capacity: usize,
    ) -> Result<Self, ConfigError> {
        if lattice.nx == 0 {
            return Err(ConfigError::NotPositive("nx"));
        }
        if lattice.ny == 0 {
            return Err(ConfigError::NotPositive("ny"));
        }
        for (p, name) in [
            (lattice.origin, "origin"),
            (lattice.step_x, "step_x"),
            (lattice.step_y, "step_y"),
        ] {
            if !p.iter().all(|c| c.is_finite()) {
                return Err(ConfigError::NotFinite(name));
            }
        }
        let a = lattice.step_x.map(f64::from);
        let a2 = a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
        if a2 <= 0.0 {
            return Err(ConfigError::NotPositive("step_x"));
        }
        let spads = scan.spads();
        let s0 = spads.first().copied().unwrap_or([0.0; 3]).map(f64::from);
        let (mut m_min, mut m_max) = (0i64, 0i64);
        for s in spads {
            if !s.iter().all(|c| c.is_finite()) {
                return Err(ConfigError::NotFinite("spads"));
            }
            let m = lattice_offset(&a, a2, &s0, s).ok_or(ConfigError::NotOnLattice("spads"))?;
            m_min = m_min.min(m);
            m_max = m_max.max(m);
        }
        let span = (m_max - m_min) as usize;
        let width = lattice
            .nx
            .checked_add(span)
            .ok_or(ConfigError::SizeOverflow("slice tables"))?;
        let entries = width
            .checked_mul(lattice.ny)
            .filter(|&e| e <= MAX_ENTRIES && lattice.len() <= MAX_ENTRIES)
            .ok_or(ConfigError::SizeOverflow("slice tables"))?;
        if 4 * (entries + spads.len()) > capacity {
            return Err(ConfigError::DoesNotFit("slice tables"));
        }
        Ok(Self {
            grid: *grid,
            lattice: *lattice,
            ks: spads.len(),
            m_min,
            m_max,
            width,
        })
    }

    /// Length in `f32` of the slice tables: `4·Ks + 4·ny·width`.
    pub const fn tables_len(&self) -> usize {
        4 * (self.ks + self.width * self.lattice.ny)
    }
    /// The lattice.
    pub const fn lattice(&self) -> &Lattice {
        &self.lattice
    }
    /// Table entries per voxel row, `nx + max m − min m`.
    pub const fn width(&self) -> usize {
        self.width
    }
}

/// `m` with `s = s0 + m·a` to `f32` rounding, or `None`.
pub(super) fn lattice_offset(a: &[f64; 3], a2: f64, s0: &[f64; 3], s: &Point) -> Option<i64> {
    let d = [
        f64::from(s[0]) - s0[0],
        f64::from(s[1]) - s0[1],
        f64::from(s[2]) - s0[2],
    ];
    let m = libm::round((d[0] * a[0] + d[1] * a[1] + d[2] * a[2]) / a2);
    if m.is_nan() || m.abs() > MAX_ENTRIES as f64 {
        return None;
    }
    let mut scale = 0.0f64;
    let mut resid = 0.0f64;
    for k in 0..3 {
        let r = d[k] - m * a[k];
        resid = resid.max(libm::fabs(r));
        scale = scale
            .max(libm::fabs(s0[k]))
            .max(libm::fabs(f64::from(s[k])))
            .max(libm::fabs(m * a[k]));
    }
    // A few f32 ulps of the coordinates: what rounding the positions to f32 leaves.
    (resid <= 8.0 * f64::from(f32::EPSILON) * scale).then_some(m as i64)
}
