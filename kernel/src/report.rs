//! The counters every probe returns ([`Report`]): rows folded, non-finite samples read as 0,
//! photon events dropped, and (factorised columns) aliased voxels. Returned by the band
//! probes ([`Probe`](crate::Probe), [`ColumnF32`](crate::ColumnF32)) and the lookup path
//! ([`LookupProbe`](crate::LookupProbe), [`LookupSlice`](crate::LookupSlice)). Cost: O(1) per
//! row; no memory.

use crate::band::row::Row;
use crate::sample::Sample;

/// Counters returned by [`Probe::finish`](crate::Probe::finish) and
/// [`Probe::report`](crate::Probe::report).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Report {
    /// Laser rows accumulated.
    pub rows: u64,
    /// Non-finite histogram samples seen (read as 0).
    pub non_finite: u64,
    /// Photon events dropped for an out-of-range SPAD or time bin.
    pub dropped: u64,
    /// Factorised columns only: voxels whose path times left [`Config::alias_free`](crate::Config::alias_free) for some
    /// (laser, SPAD) pair; their values include wrap-around of the band sum.
    pub aliased: usize,
}

impl Report {
    /// Counts one folded row: one more row, its non-finite samples and dropped photon events.
    #[inline]
    pub fn count_row<T: Sample>(&mut self, row: &Row<'_, T>) {
        self.rows += 1;
        self.non_finite += u64::from(row.non_finite());
        self.dropped += u64::from(row.dropped());
    }

    /// Adds the rows, non-finite samples and dropped events of another part (a merge;
    /// `aliased` is counted when a probe finishes).
    #[inline]
    pub fn add_part(&mut self, other: &Self) {
        self.rows += other.rows;
        self.non_finite += other.non_finite;
        self.dropped += other.dropped;
    }
}
