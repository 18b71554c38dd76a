//! Binning the photon stream into laser rows: [`PtuSource`], a [`RowSource`] over a PTU file
//! and its sidecar, and [`read_all`].

use std::fs::File;
use std::io::{BufRead, BufReader, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use vltm_kernel::Point;

use super::binning::{Binner, Counts};
use super::decode::*;
use super::header::*;
use super::sidecar::*;
use crate::budget;
use crate::error::{Error, Result};
use crate::io::capture::{Capture, Geometry, RowSource, check_row};

/// Laser rows binned from a PTU file's photons: a [`RowSource`] (conventions in the module
/// docs). Rows are read in one streaming pass; an earlier row rewinds and rescans.
#[derive(Debug)]
pub struct PtuSource<R = BufReader<File>> {
    path: PathBuf,
    header: Header,
    sidecar: Sidecar,
    plan: Plan,
    records: Records<R>,
    data_start: u64,
    /// Row markers consumed: the reader is just after the `markers_seen`-th one.
    markers_seen: usize,
    /// The reader is past the last row or an error: the next row rewinds.
    exhausted: bool,
    counts: Counts,
    bins: Binner,
}

impl PtuSource<BufReader<File>> {
    /// Opens a PTU file with its sidecar.
    ///
    /// # Errors
    /// [`Error::Io`] if a file cannot be read; header and sidecar errors (module docs).
    pub fn open(ptu: impl AsRef<Path>, sidecar: impl AsRef<Path>) -> Result<Self> {
        let (ptu, sidecar_path) = (ptu.as_ref(), sidecar.as_ref());
        // The capture first: a missing .ptu is named as such, not as its missing sidecar.
        crate::budget::regular_file(ptu)?;
        let sidecar = Sidecar::load(sidecar_path)?;
        let f = File::open(ptu).map_err(|e| Error::io(ptu, e))?;
        Self::from_reader(BufReader::new(f), ptu, sidecar, sidecar_path)
    }
}

impl<R: BufRead + Seek> PtuSource<R> {
    /// A source over `reader`, positioned at the start of a PTU header. `path` and
    /// `sidecar_path` name the file and the sidecar in errors.
    ///
    /// # Errors
    /// As [`PtuSource::open`].
    pub fn from_reader(
        mut reader: R,
        path: impl Into<PathBuf>,
        sidecar: Sidecar,
        sidecar_path: &Path,
    ) -> Result<Self> {
        let path = path.into();
        let start = reader.stream_position().map_err(|e| Error::io(&path, e))?;
        let header = Header::read(&mut reader, &path)?;
        let plan = sidecar.plan(&header, sidecar_path)?;
        // The row's photon counts and the f32 row handed out, sized by the sidecar.
        let bins = Binner::new(&plan, &sidecar, sidecar_path)?;
        let records = Records::new(reader, &header, path.clone());
        Ok(Self {
            data_start: start + header.data_offset,
            path,
            header,
            sidecar,
            plan,
            records,
            markers_seen: 0,
            exhausted: false,
            counts: Counts::default(),
            bins,
        })
    }

    /// The file's header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The sidecar.
    pub fn sidecar(&self) -> &Sidecar {
        &self.sidecar
    }

    /// Laser rows (= laser spots).
    pub fn rows(&self) -> usize {
        self.plan.rows
    }

    /// Counts of the current pass over the file (restart when a row rewinds it).
    pub fn counts(&self) -> Counts {
        Counts {
            overflow_records: self.records.overflow_records(),
            reserved_records: self.records.reserved_records(),
            ..self.counts
        }
    }

    fn rewind(&mut self) -> Result<()> {
        self.records
            .reader
            .seek(SeekFrom::Start(self.data_start))
            .map_err(|e| Error::io(&self.path, e))?;
        self.records.restart();
        self.markers_seen = 0;
        self.exhausted = false;
        self.counts = Counts::default();
        Ok(())
    }

    fn too_few_markers(&self) -> Error {
        Error::format(
            &self.path,
            "markers",
            format!(
                "{} row markers (marker input {}), one per laser row of the sidecar",
                self.plan.rows, self.sidecar.row_marker
            ),
            format!("{} before the end of the records", self.markers_seen),
        )
    }

    fn read_row_counts(&mut self, l: usize) -> Result<()> {
        check_row(l, self.plan.rows)?;
        if self.exhausted || self.markers_seen > l + 1 {
            self.rewind()?;
        }
        let r = self.bin_row(l);
        // After an error or the last row the reader is not at a row start: rewind next time.
        self.exhausted = r.is_err() || l + 1 == self.plan.rows;
        r
    }

    /// Bins row `l` from a position at or before its row marker.
    fn bin_row(&mut self, l: usize) -> Result<()> {
        let bits = self.plan.row_bits;
        // Skip to the start of row l.
        while self.markers_seen <= l {
            match self.records.next_event()? {
                None => return Err(self.too_few_markers()),
                Some(Event::Marker { bits: b, .. }) if b & bits != 0 => self.markers_seen += 1,
                Some(Event::Marker { .. }) => self.counts.other_markers += 1,
                Some(Event::Photon { .. }) if self.markers_seen == 0 => {
                    self.counts.before_first_marker += 1;
                }
                Some(Event::Photon { .. }) => self.counts.skipped_rows += 1,
            }
        }
        self.bins.clear();
        loop {
            match self.records.next_event()? {
                None if l + 1 < self.plan.rows => return Err(self.too_few_markers()),
                None => return Ok(()),
                Some(Event::Marker { bits: b, .. }) if b & bits != 0 => {
                    if l + 1 == self.plan.rows {
                        return Err(Error::format(
                            &self.path,
                            "markers",
                            format!(
                                "{} row markers (marker input {}), one per laser row of the \
                                 sidecar",
                                self.plan.rows, self.sidecar.row_marker
                            ),
                            format!(
                                "more: an extra row marker at record {}",
                                self.records.records_read() - 1
                            ),
                        ));
                    }
                    self.markers_seen += 1;
                    return Ok(());
                }
                Some(Event::Marker { .. }) => self.counts.other_markers += 1,
                Some(Event::Photon { channel, dtime, .. }) => {
                    let records = &self.records;
                    let at = || format!("record {}", records.records_read() - 1);
                    self.bins
                        .photon(channel, dtime, &mut self.counts, &self.path, at)?;
                }
            }
        }
    }
}

impl<R: BufRead + Seek> RowSource for PtuSource<R> {
    fn geometry(&self) -> &Geometry {
        &self.plan.geometry
    }

    /// Bins laser row `l` (see the module docs for the streaming order and its costs).
    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        self.read_row_counts(l)?;
        out.clear();
        out.extend(self.bins.values());
        Ok(self.plan.geometry.lasers[l])
    }
}

/// Reads a whole PTU capture: every laser row, in one pass.
///
/// # Errors
/// As [`PtuSource::open`] and [`RowSource::read_row`].
pub fn read_all(ptu: impl AsRef<Path>, sidecar: impl AsRef<Path>) -> Result<Capture> {
    let ptu = ptu.as_ref();
    let mut src = PtuSource::open(ptu, sidecar)?;
    collect(&mut src, ptu)
}

pub(super) fn collect<R: BufRead + Seek>(src: &mut PtuSource<R>, path: &Path) -> Result<Capture> {
    let n = src.rows().saturating_mul(src.bins.len());
    budget::check(
        || {
            format!(
                "H of {} samples binned from {}",
                budget::count(n as u128),
                path.display()
            )
        },
        budget::bytes(n, 4),
    )?;
    let mut data = Vec::with_capacity(n);
    let mut row = Vec::new();
    for l in 0..src.rows() {
        src.read_row(l, &mut row)?;
        data.extend_from_slice(&row);
    }
    Capture::new(src.geometry().clone(), data, path)
}
