//! Photons to a laser row's histograms, the one binner of both PTU readers ([`Binner`]: the
//! offline [`PtuSource`](super::PtuSource) and the [`Follower`](super::Follower) of a stream
//! still being written), and the counts of what happened to the records of a pass
//! ([`Counts`]).
//!
//! The conventions are the module docs' of [`crate::io::ptu`]: photon channel `c` goes to SPAD
//! `s` where `channels[s] = c` (a photon on a channel no SPAD maps is an error, field
//! `channels`, or dropped and counted); raw dtime bin `k` goes to histogram bin
//! `(k − first_dtime) / rebin` when `first_dtime ≤ k < first_dtime + nt·rebin` (else dropped
//! and counted); counts are `u32` per bin, saturating, handed out as `f32`. Memory: one row,
//! `Ks·Nt` `u32`. Cost: a table look-up, a comparison and a division per photon.

use std::path::Path;

use super::header::CHANNELS;
use super::sidecar::{Plan, Sidecar};
use crate::budget;
use crate::error::{Error, Result};

/// What happened to the records of the current pass over a file ([`PtuSource::counts`],
/// [`Follower::counts`]).
///
/// [`PtuSource::counts`]: super::PtuSource::counts
/// [`Follower::counts`]: super::Follower::counts
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// Photons binned into rows that were read.
    pub binned: u64,
    /// Photons before the first row marker (dropped).
    pub before_first_marker: u64,
    /// Photons of rows passed over to reach a later row (not binned).
    pub skipped_rows: u64,
    /// Photons with dtime outside the kept window (dropped).
    pub outside_window: u64,
    /// Photons on unmapped channels (dropped, with `"unmapped_channels": "drop"`).
    pub unmapped: u64,
    /// Marker records without the row bit (ignored).
    pub other_markers: u64,
    /// Overflow records.
    pub overflow_records: u64,
    /// Reserved special records (ignored).
    pub reserved_records: u64,
}

/// One laser row's histograms (`Ks·Nt` photon counts, SPAD-major), filled photon by photon
/// under a sidecar's plan (module docs).
#[derive(Clone, Debug)]
pub(super) struct Binner {
    hist: Vec<u32>,
    nt: usize,
    spad_of_channel: [Option<usize>; CHANNELS],
    /// Kept raw dtime bins `first..end`, `rebin` per histogram bin.
    first: u64,
    end: u64,
    rebin: u64,
    /// A photon on an unmapped channel is an error (else it is dropped and counted).
    unmapped_error: bool,
    /// The sidecar's channels, as the error names them.
    channels: Vec<u32>,
}

impl Binner {
    /// An empty row for `plan`, made from `sidecar` (read from `sidecar_path`).
    ///
    /// # Errors
    /// The memory budget, naming the sidecar: the row's counts and the `f32` row handed out
    /// (8 bytes per bin).
    pub(super) fn new(plan: &Plan, sidecar: &Sidecar, sidecar_path: &Path) -> Result<Self> {
        let row = plan.ks.saturating_mul(plan.geometry.nt);
        budget::check(
            || {
                format!(
                    "a laser row of {} bins ({} SPADs × nt {}) described by {}",
                    budget::count(row as u128),
                    plan.ks,
                    plan.geometry.nt,
                    sidecar_path.display()
                )
            },
            budget::bytes(row, 8),
        )?;
        Ok(Self {
            hist: vec![0; row],
            nt: plan.geometry.nt,
            spad_of_channel: plan.spad_of_channel,
            first: plan.first,
            end: plan.end,
            rebin: plan.rebin,
            unmapped_error: plan.unmapped_error,
            channels: sidecar
                .channels
                .clone()
                .unwrap_or_else(|| (0..plan.ks as u32).collect()),
        })
    }

    /// Bins of the row (`Ks·Nt`).
    pub(super) fn len(&self) -> usize {
        self.hist.len()
    }

    /// Empties the row (the start of the next one).
    pub(super) fn clear(&mut self) {
        self.hist.fill(0);
    }

    /// Bins a photon on `channel` at raw bin `dtime` into the row: `true` when it lands in a
    /// histogram (counted in [`Counts::binned`]), `false` when it is dropped (counted in
    /// [`Counts::unmapped`] or [`Counts::outside_window`]).
    ///
    /// # Errors
    /// [`Error::Format`] (`channels`) on `path` for a photon on a channel no SPAD maps, unless
    /// the sidecar drops them; `at()` says where the photon is (`record 12`).
    #[inline]
    pub(super) fn photon(
        &mut self,
        channel: u8,
        dtime: u16,
        counts: &mut Counts,
        path: &Path,
        at: impl FnOnce() -> String,
    ) -> Result<bool> {
        let Some(s) = self.spad_of_channel[usize::from(channel) % CHANNELS] else {
            if self.unmapped_error {
                return Err(Error::format(
                    path,
                    "channels",
                    format!(
                        "photons only on the sidecar's channels {:?} (or \"unmapped_channels\": \
                         \"drop\")",
                        self.channels
                    ),
                    format!("a photon on channel {channel} at {}", at()),
                ));
            }
            counts.unmapped += 1;
            return Ok(false);
        };
        let k = u64::from(dtime);
        if k < self.first || k >= self.end {
            counts.outside_window += 1;
            return Ok(false);
        }
        let n = ((k - self.first) / self.rebin) as usize;
        let bin = &mut self.hist[s * self.nt + n];
        *bin = bin.saturating_add(1);
        counts.binned += 1;
        Ok(true)
    }

    /// The row's counts as `f32` (exact up to 2^24 photons per bin), SPAD-major.
    pub(super) fn values(&self) -> impl Iterator<Item = f32> + '_ {
        self.hist.iter().map(|&c| c as f32)
    }
}
