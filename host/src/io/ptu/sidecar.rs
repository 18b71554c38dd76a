//! The JSON sidecar that describes a PTU scan (rows, SPAD channels, time axis, geometry) and
//! its validation against the file's header ([`Sidecar`]).

use std::path::Path;

use serde::{Deserialize, Serialize};
use vltm_kernel::Point;

use super::header::*;
use crate::aperture::Aperture;
use crate::error::{Error, Result};
use crate::io::capture::Geometry;

/// What to do with photons on channels that no SPAD maps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Unmapped {
    /// Fail with an error naming the channel and the record (default).
    #[default]
    Error,
    /// Drop them, counted in [`Counts::unmapped`](super::Counts::unmapped).
    Drop,
}

pub(super) fn default_marker() -> u32 {
    1
}
pub(super) fn default_rebin() -> u32 {
    1
}

/// The scan description that goes with a PTU file (a JSON file; format in the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sidecar {
    /// Number of laser rows (= laser spots); `None`: the number of laser spots.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rows: Option<usize>,
    /// The marker input (1..=4) whose markers start laser rows.
    #[serde(default = "default_marker")]
    pub row_marker: u32,
    /// Laser spots; row `l` is spot `l`.
    pub lasers: Aperture,
    /// SPAD spots; `None` only for a confocal scan.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spads: Option<Aperture>,
    /// Confocal scan: one histogram per row, SPAD at the laser spot.
    #[serde(default)]
    pub confocal: bool,
    /// 0-based detector channel of each SPAD; `None`: SPAD `s` on channel `s`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub channels: Option<Vec<u32>>,
    /// What to do with photons on channels no SPAD maps.
    #[serde(default)]
    pub unmapped_channels: Unmapped,
    /// Histogram bins per SPAD (≥ 1).
    pub nt: usize,
    /// Path length (m) of raw dtime bin 0, after all delays.
    pub t0: f64,
    /// Width of one raw dtime bin (m of path); `None`: `MeasDesc_Resolution·c`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bin_width: Option<f64>,
    /// Raw dtime bins per histogram bin (≥ 1).
    #[serde(default = "default_rebin")]
    pub rebin: u32,
    /// The first raw dtime bin kept.
    #[serde(default)]
    pub first_dtime: u32,
    /// Laser device position (m).
    #[serde(default = "crate::aperture::default_laser_origin")]
    pub laser_origin: [f64; 3],
    /// Sensor device position (m).
    #[serde(default = "crate::aperture::default_sensor_origin")]
    pub sensor_origin: [f64; 3],
    /// Whether path lengths include the device legs.
    #[serde(default)]
    pub legs_in_time: bool,
}

/// The sidecar resolved against a header: everything the binning loop needs.
#[derive(Clone, Debug)]
pub(super) struct Plan {
    pub(super) geometry: Geometry,
    pub(super) rows: usize,
    pub(super) ks: usize,
    pub(super) row_bits: u8,
    pub(super) spad_of_channel: [Option<usize>; CHANNELS],
    pub(super) first: u64,
    pub(super) rebin: u64,
    pub(super) end: u64,
    pub(super) unmapped_error: bool,
}

pub(super) fn spots_of(a: &Aperture, path: &Path, field: &str) -> Result<(Vec<Point>, [usize; 2])> {
    let shape = a.shape();
    let spots = a.spots();
    if spots.is_empty() || shape[0].checked_mul(shape[1]) != Some(spots.len()) {
        return Err(Error::format(
            path,
            field,
            "a non-empty grid or point list whose shape matches its spots",
            format!("shape {shape:?} with {} spots", spots.len()),
        ));
    }
    if let Aperture::Grid {
        shape,
        size,
        center,
    } = a
    {
        let ok = (0..2).all(|i| size[i].is_finite() && (shape[i] == 1 || size[i] > 0.0))
            && center.iter().all(|c| c.is_finite());
        if !ok {
            return Err(Error::format(
                path,
                field,
                "finite sizes (> 0 on axes with more than one spot) and centre",
                format!("size {size:?}, center {center:?}"),
            ));
        }
    }
    if let Some(i) = spots.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::format(
            path,
            field,
            "finite coordinates",
            format!("{:?} at spot {i}", spots[i]),
        ));
    }
    Ok((spots.iter().map(|p| p.map(|c| c as f32)).collect(), shape))
}

impl Sidecar {
    /// Parses a sidecar; `path` names it in errors.
    ///
    /// # Errors
    /// [`Error::Format`] (field `sidecar`) for malformed JSON, unknown or missing fields (keys
    /// that start with `_` are notes, ignored).
    pub fn from_json_str(json: &str, path: impl AsRef<Path>) -> Result<Self> {
        // Keys starting with `_` are notes (the template's `_help`, `_nt`, …): dropped.
        let parsed = serde_json::from_str::<serde_json::Value>(json).and_then(|mut v| {
            if let Some(m) = v.as_object_mut() {
                m.retain(|k, _| !k.starts_with('_'));
            }
            serde_json::from_value(v)
        });
        parsed.map_err(|e| {
            Error::format(
                path.as_ref(),
                "sidecar",
                "a PTU sidecar (JSON, see vltm::io::ptu)",
                e.to_string(),
            )
        })
    }

    /// Reads a sidecar file.
    ///
    /// # Errors
    /// [`Error::Io`] if unreadable, else as [`Sidecar::from_json_str`].
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        if let Err(e) = std::fs::metadata(path)
            && e.kind() == std::io::ErrorKind::NotFound
        {
            return Err(Error::io(path, missing_sidecar(path)));
        }
        let json = crate::budget::read_text(path)?;
        Self::from_json_str(&json, path)
    }

    /// The sidecar as pretty-printed JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a sidecar always serialises")
    }

    /// The capture geometry the rows will have, for a file with this `header`.
    ///
    /// # Errors
    /// [`Error::Format`] naming the sidecar's field for invalid values (module docs).
    pub fn geometry(&self, header: &Header, path: &Path) -> Result<Geometry> {
        Ok(self.plan(header, path)?.geometry)
    }

    pub(super) fn plan(&self, header: &Header, path: &Path) -> Result<Plan> {
        let (lasers, laser_shape) = spots_of(&self.lasers, path, "lasers")?;
        let (spads, spad_shape) = match (&self.spads, self.confocal) {
            (Some(a), false) => spots_of(a, path, "spads")?,
            (None, false) => {
                return Err(Error::format(
                    path,
                    "spads",
                    "SPAD spots (required unless confocal)",
                    "none",
                ));
            }
            (Some(a), true) => {
                let s = spots_of(a, path, "spads")?;
                if s.0 != lasers {
                    return Err(Error::format(
                        path,
                        "spads",
                        "the laser spots (confocal) or no `spads`",
                        "different spots",
                    ));
                }
                s
            }
            (None, true) => (lasers.clone(), laser_shape),
        };
        let rows = lasers.len();
        if let Some(r) = self.rows
            && r != rows
        {
            return Err(Error::format(
                path,
                "rows",
                format!("the number of laser spots, {rows}"),
                r,
            ));
        }
        if !(1..=MAX_MARKER).contains(&self.row_marker) {
            return Err(Error::format(
                path,
                "row_marker",
                format!("a marker input 1..={MAX_MARKER}"),
                self.row_marker,
            ));
        }
        let ks = if self.confocal { 1 } else { spads.len() };
        if self.nt == 0 {
            return Err(Error::format(path, "nt", "at least one bin", 0));
        }
        if self.rebin == 0 {
            return Err(Error::format(path, "rebin", "at least 1", 0));
        }
        if !self.t0.is_finite() {
            return Err(Error::format(
                path,
                "t0",
                "a finite path length (m)",
                self.t0,
            ));
        }
        let width = match self.bin_width {
            Some(w) if w.is_finite() && w > 0.0 => w,
            Some(w) => {
                return Err(Error::format(
                    path,
                    "bin_width",
                    "a finite width > 0 (m)",
                    w,
                ));
            }
            None => header.resolution * SPEED_OF_LIGHT,
        };
        for (name, v) in [
            ("laser_origin", &self.laser_origin),
            ("sensor_origin", &self.sensor_origin),
        ] {
            if !v.iter().all(|c| c.is_finite()) {
                return Err(Error::format(
                    path,
                    name,
                    "finite coordinates",
                    format!("{v:?}"),
                ));
            }
        }
        let channels: Vec<u32> = match &self.channels {
            Some(c) => c.clone(),
            None => (0..ks as u32).collect(),
        };
        if channels.len() != ks {
            return Err(Error::format(
                path,
                "channels",
                format!("one channel per SPAD ({ks})"),
                format!("{} channels", channels.len()),
            ));
        }
        let mut spad_of_channel = [None; CHANNELS];
        for (s, &c) in channels.iter().enumerate() {
            let slot = spad_of_channel.get_mut(c as usize).ok_or_else(|| {
                Error::format(
                    path,
                    "channels",
                    format!("detector channels 0..{CHANNELS}"),
                    format!("channel {c} for SPAD {s}"),
                )
            })?;
            if slot.is_some() {
                return Err(Error::format(
                    path,
                    "channels",
                    "one SPAD per channel",
                    format!("channel {c} given twice"),
                ));
            }
            *slot = Some(s);
        }
        let rebin = u64::from(self.rebin);
        let first = u64::from(self.first_dtime);
        let nt = self.nt as u64;
        let end = nt
            .checked_mul(rebin)
            .and_then(|n| n.checked_add(first))
            .ok_or_else(|| Error::format(path, "nt", "a window that fits in 64 bits", nt))?;
        let geometry = Geometry {
            lasers,
            laser_shape,
            spads,
            spad_shape,
            laser_origin: self.laser_origin,
            sensor_origin: self.sensor_origin,
            legs_in_time: self.legs_in_time,
            confocal: self.confocal,
            nt: self.nt,
            dt: width * f64::from(self.rebin),
            t0: self.t0 + (f64::from(self.first_dtime) + f64::from(self.rebin - 1) / 2.0) * width,
            normals: Default::default(),
        };
        geometry.validate(path)?;
        Ok(Plan {
            geometry,
            rows,
            ks,
            row_bits: 1 << (self.row_marker - 1),
            spad_of_channel,
            first,
            rebin,
            end,
            unmapped_error: self.unmapped_channels == Unmapped::Error,
        })
    }
}

/// The error of a missing sidecar: what it is and where its fields are described.
fn missing_sidecar(path: &Path) -> std::io::Error {
    let name = |p: &Path| {
        p.file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned()
    };
    let ptu = name(&path.with_extension("ptu"));
    std::io::Error::new(
        std::io::ErrorKind::NotFound,
        format!(
            "No such file or directory: a PicoQuant capture F.ptu needs a JSON sidecar F.json beside it \
             describing the scan (rows, SPADs, time axis; here {ptu} and {}): its fields are in \
             docs/formats.md (PTU sidecar)",
            name(path)
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Keys starting with `_` (the template's notes) are ignored; other unknown keys are
    /// still refused, naming the key.
    #[test]
    fn notes_are_ignored_unknown_fields_refused() {
        let base = r#""lasers": {"points": [[0, 0, 0]]}, "spads": {"points": [[0.1, 0, 0]]},
            "nt": 8, "t0": 0.5"#;
        let s = Sidecar::from_json_str(
            &format!(r#"{{"_help": "x", "_nt": "bins", {base}}}"#),
            "s.json",
        )
        .unwrap();
        assert_eq!(s.nt, 8);
        let e = Sidecar::from_json_str(&format!(r#"{{"nts": 3, {base}}}"#), "s.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("s.json") && e.contains("nts"), "{e}");
    }
}
