//! A template sidecar for a PTU file that has none: every field with a `_help` note beside
//! it, pre-filled with what the file knows (the bin width from `MeasDesc_Resolution`, the
//! channels photons arrived on, the marker inputs seen and how often, the time bins used);
//! the geometry (laser and SPAD spots, `t0`) is the user's to fill in. Keys that start with
//! `_` are ignored when a sidecar is read ([`Sidecar::from_json_str`](super::Sidecar)).

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::{Value, json};

use super::decode::{Event, open};
use super::header::SPEED_OF_LIGHT;
use crate::error::Result;

/// What a pass over the records saw.
#[derive(Default)]
struct Seen {
    photons: u64,
    channels: BTreeMap<u8, u64>,
    markers: BTreeMap<u8, u64>,
    max_dtime: u16,
}

/// The template sidecar of `ptu` as pretty-printed JSON (one pass over its records).
///
/// # Errors
/// The errors of reading the PTU file ([`open`](super::open) and its records).
pub fn template(ptu: &Path) -> Result<String> {
    let (header, records) = open(ptu)?;
    let mut seen = Seen::default();
    for e in records {
        match e? {
            Event::Photon { channel, dtime, .. } => {
                seen.photons += 1;
                *seen.channels.entry(channel).or_default() += 1;
                seen.max_dtime = seen.max_dtime.max(dtime);
            }
            Event::Marker { bits, .. } => {
                for m in 0..4u8 {
                    if bits & (1 << m) != 0 {
                        *seen.markers.entry(m + 1).or_default() += 1;
                    }
                }
            }
        }
    }
    let name = ptu.file_name().unwrap_or_default().to_string_lossy();
    let bin = header.resolution * SPEED_OF_LIGHT;
    let (marker, rows) = seen
        .markers
        .iter()
        .max_by_key(|(_, n)| **n)
        .map_or((1, None), |(m, n)| (*m, Some(*n)));
    let markers = if seen.markers.is_empty() {
        "no markers in this file".to_string()
    } else {
        seen.markers
            .iter()
            .map(|(m, n)| format!("input {m}: {n} markers"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let channels: Vec<u8> = seen.channels.keys().copied().collect();
    let per_channel = seen
        .channels
        .iter()
        .map(|(c, n)| format!("{c}: {n}"))
        .collect::<Vec<_>>()
        .join(", ");
    let nt = usize::from(seen.max_dtime) + 1;
    let ks = channels.len().max(1);
    // Written by hand so that each note stays beside its field (a JSON map sorts its keys).
    let mut out = String::from("{\n");
    let mut entry = |key: &str, value: &Value| {
        let v = serde_json::to_string(value).expect("JSON values serialise");
        out.push_str(&format!("  {}: {v},\n", Value::String(key.to_string())));
    };
    entry(
        "_help",
        &Value::String(format!(
            "The sidecar of {name}: fill in the fields marked FILL IN (the scan's geometry), \
             check the others; keys starting with _ are notes, ignored when read. The fields \
             are described in docs/formats.md (PTU sidecar)."
        )),
    );
    let mut put = |key: &str, help: String, value: Value| {
        entry(&format!("_{key}"), &Value::String(help));
        entry(key, &value);
    };
    put(
        "rows",
        format!(
            "laser rows (one per laser spot, in scan order); {} marker(s) on input {marker} \
             in this file",
            rows.unwrap_or(0)
        ),
        json!(rows.unwrap_or(1)),
    );
    put(
        "row_marker",
        format!("the marker input (1..4) whose markers start laser rows; seen: {markers}"),
        json!(marker),
    );
    put(
        "lasers",
        "FILL IN: the laser spots on the wall z = 0 (m), one per row: a grid {\"grid\": [nx, ny], \
         \"size\": [w, h], \"center\": [x, y]} or {\"points\": [[x, y, z], ...]}"
            .to_string(),
        json!({"grid": [rows.unwrap_or(1), 1], "size": [0.0, 0.0], "center": [0.0, 0.0]}),
    );
    put(
        "spads",
        "FILL IN: the SPAD spots (m), one per channel below, as `lasers`; leave out for a \
         confocal scan"
            .to_string(),
        json!({"grid": [ks, 1], "size": [0.0, 0.0], "center": [0.0, 0.0]}),
    );
    put(
        "confocal",
        "true: one histogram per row, the SPAD at the laser spot (then no `spads`)".to_string(),
        json!(false),
    );
    put(
        "channels",
        format!(
            "0-based detector channel of each SPAD, in the order of `spads`; photons seen per \
             channel: {}",
            if per_channel.is_empty() {
                "none".to_string()
            } else {
                per_channel
            }
        ),
        json!(channels),
    );
    put(
        "unmapped_channels",
        "photons on a channel no SPAD maps: \"error\" (stop, naming the record) or \"drop\""
            .to_string(),
        json!("error"),
    );
    put(
        "nt",
        format!(
            "histogram bins per SPAD; the largest dtime in this file is {} (of {} photons)",
            seen.max_dtime, seen.photons
        ),
        json!(nt),
    );
    put(
        "t0",
        "FILL IN: path length (m) of raw dtime bin 0, after all delays".to_string(),
        json!(0.0),
    );
    put(
        "bin_width",
        format!(
            "width of one raw dtime bin (m of path): MeasDesc_Resolution {:e} s × c",
            header.resolution
        ),
        json!(bin),
    );
    put(
        "rebin",
        "raw dtime bins per histogram bin (>= 1)".to_string(),
        json!(1),
    );
    put(
        "first_dtime",
        "the first raw dtime bin kept".to_string(),
        json!(0),
    );
    put(
        "laser_origin",
        "the laser device's position (m)".to_string(),
        json!(crate::aperture::default_laser_origin()),
    );
    put(
        "sensor_origin",
        "the sensor device's position (m)".to_string(),
        json!(crate::aperture::default_sensor_origin()),
    );
    put(
        "legs_in_time",
        "true when the path lengths include the device legs (device → wall, wall → device)"
            .to_string(),
        json!(false),
    );
    let end = out.trim_end_matches(",\n").len();
    out.truncate(end);
    out.push_str("\n}\n");
    Ok(out)
}
