//! Writing synthetic HydraHarp V2 T3 files and their sidecars from a [`Capture`]
//! ([`write_t3`], [`write_t3_to`]).

use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use vltm_kernel::Point;

use super::header::*;
use super::sidecar::*;
use crate::aperture::Aperture;
use crate::atomic::Transaction;
use crate::error::{Error, Result};
use crate::io::capture::Capture;

/// Writes PTU header tags.
pub(super) struct TagWriter<W> {
    pub(super) w: W,
}

impl<W: Write> TagWriter<W> {
    pub(super) fn raw(
        &mut self,
        name: &str,
        index: i32,
        ty: u32,
        value: [u8; 8],
    ) -> io::Result<()> {
        let mut ident = [0u8; 32];
        let n = name.len().min(31);
        ident[..n].copy_from_slice(&name.as_bytes()[..n]);
        self.w.write_all(&ident)?;
        self.w.write_all(&index.to_le_bytes())?;
        self.w.write_all(&ty.to_le_bytes())?;
        self.w.write_all(&value)
    }
    pub(super) fn int(&mut self, name: &str, v: i64) -> io::Result<()> {
        self.raw(name, -1, tag_type::INT8, v.to_le_bytes())
    }
    pub(super) fn float(&mut self, name: &str, v: f64) -> io::Result<()> {
        self.raw(name, -1, tag_type::FLOAT8, v.to_le_bytes())
    }
    /// An `AnsiString`, NUL-terminated and padded to a multiple of 8 bytes as PicoQuant does.
    pub(super) fn string(&mut self, name: &str, s: &str) -> io::Result<()> {
        let len = (s.len() + 1).div_ceil(8) * 8;
        self.raw(name, -1, tag_type::ANSI_STRING, (len as i64).to_le_bytes())?;
        self.w.write_all(s.as_bytes())?;
        self.w.write_all(&vec![0u8; len - s.len()])
    }
}

/// A HydraHarp-family T3 record from its fields.
pub(super) fn ht3(special: bool, channel: u8, dtime: u16, nsync: u16) -> u32 {
    (u32::from(special) << 31)
        | (u32::from(channel & 0x3F) << 25)
        | (u32::from(dtime & 0x7FFF) << 10)
        | u32::from(nsync & 0x03FF)
}

/// Options of [`write_t3`].
#[derive(Clone, Debug, PartialEq)]
pub struct T3WriteOptions {
    /// Sync period, `MeasDesc_GlobalResolution` (s). Default 50 ns (20 MHz).
    pub sync_period: f64,
    /// Marker input (1..=4) of the row markers. Default 1.
    pub row_marker: u32,
    /// Sync periods between consecutive photons of a row. Default 1.
    pub syncs_per_photon: u32,
    /// Sync periods between the last photon of a row and the next row's marker (exercises
    /// multi-overflow records). Default 5000.
    pub syncs_between_rows: u64,
    /// Where [`write_t3`] writes the sidecar; `None`: the PTU path with extension `.json`.
    pub sidecar: Option<PathBuf>,
}

impl Default for T3WriteOptions {
    fn default() -> Self {
        Self {
            sync_period: 50e-9,
            row_marker: 1,
            syncs_per_photon: 1,
            syncs_between_rows: 5000,
            sidecar: None,
        }
    }
}

/// What [`write_t3`] / [`write_t3_to`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct T3Written {
    /// The sidecar that reads the file back as the capture.
    pub sidecar: Sidecar,
    /// Where [`write_t3`] wrote the sidecar (`None` from [`write_t3_to`]).
    pub sidecar_path: Option<PathBuf>,
    /// Records in the file (`TTResult_NumberOfRecords`).
    pub records: u64,
    /// Photon records.
    pub photons: u64,
    /// Row marker records (one per laser row).
    pub markers: u64,
    /// Overflow records.
    pub overflow_records: u64,
}

/// Emits the records of a capture, keeping the overflow state.
pub(super) struct Emitter<'a> {
    overflow: u64,
    records: u64,
    overflow_records: u64,
    sink: &'a mut dyn FnMut(u32) -> Result<()>,
}

impl Emitter<'_> {
    /// Emits overflow records up to sync `t`, then `make(t − overflow)`.
    fn at(&mut self, t: u64, make: impl Fn(u16) -> u32) -> Result<()> {
        while t - self.overflow >= 1024 {
            let n = ((t - self.overflow) / 1024).min(1023);
            (self.sink)(ht3(true, 0x3F, 0, n as u16))?;
            self.overflow += 1024 * n;
            self.records += 1;
            self.overflow_records += 1;
        }
        (self.sink)(make((t - self.overflow) as u16))?;
        self.records += 1;
        Ok(())
    }
}

pub(super) fn emit(
    capture: &Capture,
    opts: &T3WriteOptions,
    path: &Path,
    sink: &mut dyn FnMut(u32) -> Result<()>,
) -> Result<T3Written> {
    let g = &capture.geometry;
    let (ks, nt) = (g.spads_per_row(), g.nt);
    let bits = 1u8 << (opts.row_marker - 1);
    let mut e = Emitter {
        overflow: 0,
        records: 0,
        overflow_records: 0,
        sink,
    };
    let (mut t, mut photons) = (0u64, 0u64);
    for l in 0..g.lasers.len() {
        e.at(t, |nsync| ht3(true, bits, 0, nsync))?;
        t += 1;
        for (i, &v) in capture.row(l).iter().enumerate() {
            let r = v.round();
            if !(0.0..=u32::MAX as f32).contains(&r) {
                return Err(Error::format(
                    path,
                    "H",
                    "finite photon counts ≥ 0 (rounded) below 2^32",
                    format!("{v} at laser {l}, SPAD {}, bin {}", i / nt, i % nt),
                ));
            }
            let (s, n) = ((i / nt) as u8, (i % nt) as u16);
            for _ in 0..r as u64 {
                e.at(t, |nsync| ht3(false, s, n, nsync))?;
                t += u64::from(opts.syncs_per_photon);
                photons += 1;
            }
        }
        t += opts.syncs_between_rows;
    }
    let to64 = |p: &Point| p.map(f64::from);
    let sidecar = Sidecar {
        rows: Some(g.lasers.len()),
        row_marker: opts.row_marker,
        lasers: Aperture::Points {
            points: g.lasers.iter().map(to64).collect(),
            shape: g.laser_shape,
        },
        spads: (!g.confocal).then(|| Aperture::Points {
            points: g.spads.iter().map(to64).collect(),
            shape: g.spad_shape,
        }),
        confocal: g.confocal,
        channels: Some((0..ks as u32).collect()),
        unmapped_channels: Unmapped::Error,
        nt,
        t0: g.t0,
        bin_width: Some(g.dt),
        rebin: 1,
        first_dtime: 0,
        laser_origin: g.laser_origin,
        sensor_origin: g.sensor_origin,
        legs_in_time: g.legs_in_time,
    };
    Ok(T3Written {
        sidecar,
        sidecar_path: None,
        records: e.records,
        photons,
        markers: g.lasers.len() as u64,
        overflow_records: e.overflow_records,
    })
}

/// Writes `capture` as a synthetic HydraHarp V2 T3 PTU stream to `w` and returns the
/// matching sidecar (not written) and record counts. `path` names the output in errors.
///
/// Each laser row is a row marker (input `opts.row_marker`) followed by, for every SPAD `s`
/// (on channel `s`) and bin `n`, `round(H[l][s][n])` photon records with `dtime = n`, one every
/// `opts.syncs_per_photon` sync periods; overflow records (V2, with counts) are emitted
/// whenever the 10-bit `nsync` would wrap. `MeasDesc_Resolution` is `dt/c`; the sidecar gives
/// the bin width `dt` and `t0` explicitly, so the rows read back equal the rounded histograms
/// and the geometry equals the capture's.
///
/// # Errors
/// [`Error::Argument`] for a capture the format cannot hold (more than 64 SPADs per row, more
/// than 32768 bins) or bad options; [`Error::Format`] (field `H`) for a count that is not
/// finite, negative or ≥ 2^32 after rounding; [`Error::Io`] if writing fails.
pub fn write_t3_to<W: Write>(
    capture: &Capture,
    w: W,
    opts: &T3WriteOptions,
    path: &Path,
) -> Result<T3Written> {
    let g = &capture.geometry;
    g.validate(path)?;
    let want = g.lasers.len() * g.spads_per_row() * g.nt;
    if capture.data.len() != want {
        return Err(Error::format(
            path,
            "H",
            format!("{want} values"),
            capture.data.len(),
        ));
    }
    if g.spads_per_row() > CHANNELS {
        return Err(Error::arg(
            "capture",
            format!(
                "{} SPADs per row: a T3 file has at most {CHANNELS} channels",
                g.spads_per_row()
            ),
        ));
    }
    if g.nt > 0x8000 {
        return Err(Error::arg(
            "capture",
            format!("{} bins: a HydraHarp T3 record holds at most 32768", g.nt),
        ));
    }
    if !(opts.sync_period.is_finite() && opts.sync_period > 0.0) {
        return Err(Error::arg(
            "sync_period",
            format!("a finite period > 0 (s), not {}", opts.sync_period),
        ));
    }
    if !(1..=MAX_MARKER).contains(&opts.row_marker) {
        return Err(Error::arg(
            "row_marker",
            format!("a marker input 1..={MAX_MARKER}, not {}", opts.row_marker),
        ));
    }
    let resolution = g.dt / SPEED_OF_LIGHT;
    // Pass 1 counts the records (and checks the counts); pass 2 writes them.
    let written = emit(capture, opts, path, &mut |_| Ok(()))?;

    let io = |e: io::Error| Error::io(path, e);
    let mut tw = TagWriter {
        w: BufWriter::new(w),
    };
    tw.w.write_all(&MAGIC).map_err(io)?;
    tw.w.write_all(b"1.0.00\0\0").map_err(io)?;
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64());
    let max_channel = g.spads_per_row() as i64;
    (|| -> io::Result<()> {
        tw.string(
            "File_Comment",
            "synthetic HydraHarp V2 T3 capture written by vltm (see its .json sidecar)",
        )?;
        tw.raw(
            "File_CreatingTime",
            -1,
            tag_type::DATETIME,
            (now / 86_400.0 + 25_569.0).to_le_bytes(),
        )?;
        tw.string("CreatorSW_Name", "vltm")?;
        tw.string("CreatorSW_Version", env!("CARGO_PKG_VERSION"))?;
        tw.string("HW_Type", "HydraHarp")?;
        tw.int("HW_InpChannels", max_channel + 1)?;
        tw.int("Measurement_Mode", 3)?;
        tw.int("Measurement_SubMode", 0)?;
        tw.int("HWSync_Divider", 1)?;
        tw.int("TTResult_SyncRate", (1.0 / opts.sync_period).round() as i64)?;
        tw.float("MeasDesc_GlobalResolution", opts.sync_period)?;
        tw.float("MeasDesc_Resolution", resolution)?;
        tw.int("MeasDesc_BinningFactor", 1)?;
        tw.int(
            "TTResultFormat_TTTRRecType",
            i64::from(RecordType::HydraHarpV2T3.code()),
        )?;
        tw.int("TTResultFormat_BitsPerRecord", 32)?;
        tw.int("TTResult_NumberOfRecords", written.records as i64)?;
        tw.raw("Header_End", -1, tag_type::EMPTY8, [0; 8])
    })()
    .map_err(io)?;
    let out = &mut tw.w;
    emit(capture, opts, path, &mut |rec| {
        out.write_all(&rec.to_le_bytes()).map_err(io)
    })?;
    tw.w.flush().map_err(io)?;
    Ok(written)
}

/// Writes `capture` as a synthetic HydraHarp V2 T3 PTU file at `path` (see [`write_t3_to`])
/// and its sidecar (`opts.sidecar`, default `path` with extension `.json`), so that
/// [`read_all`](super::read_all)`(path, sidecar)` gives back the capture with its histograms rounded to whole
/// photons.
///
/// # Errors
/// As [`write_t3_to`]; [`Error::Argument`] if the sidecar path is the PTU path.
pub fn write_t3(
    capture: &Capture,
    path: impl AsRef<Path>,
    opts: &T3WriteOptions,
) -> Result<T3Written> {
    let mut t = Transaction::new();
    let written = stage_t3(&mut t, capture, path, opts)?;
    t.commit()?;
    Ok(written)
}

/// [`write_t3`] as two files (the PTU stream and its sidecar) of a [`Transaction`], written
/// on its commit, all or nothing with the transaction's other files.
///
/// # Errors
/// As [`write_t3`].
pub fn stage_t3(
    t: &mut Transaction,
    capture: &Capture,
    path: impl AsRef<Path>,
    opts: &T3WriteOptions,
) -> Result<T3Written> {
    let path = path.as_ref();
    let sidecar_path = opts
        .sidecar
        .clone()
        .unwrap_or_else(|| path.with_extension("json"));
    if sidecar_path == path {
        return Err(Error::arg(
            "sidecar",
            format!(
                "{}: the sidecar would overwrite the PTU file",
                path.display()
            ),
        ));
    }
    let mut written = None;
    t.stage(path, |f| {
        written = Some(write_t3_to(capture, BufWriter::new(f), opts, path)?);
        Ok(())
    })?;
    let mut written = written.ok_or_else(|| Error::arg("ptu", "nothing written"))?;
    let json = written.sidecar.to_json() + "\n";
    t.stage(&sidecar_path, |f| {
        f.write_all(json.as_bytes())
            .map_err(|e| Error::io(&sidecar_path, e))
    })?;
    written.sidecar_path = Some(sidecar_path);
    Ok(written)
}
