//! The firmware's accumulated state in vltm's partial-state format (`vltm::probe::partial`,
//! version 1), so that the host takes over what the MCU folded: `vltm merge` adds it to the
//! host's parts of the other rows and finishes the volume, and `vltm live --resume` continues
//! from it.
//!
//! The format is a JSON header and the raw accumulators:
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `VLTMPART` |
//! | 4 | version `1`, `u32` LE |
//! | 4 | header length `h`, `u32` LE |
//! | `h` | header (UTF-8 JSON) |
//! | `12·n_spads` | SPAD spots, `f32` x, y, z (columns only) |
//! | `12·n_points` | voxels, `f32` x, y, z (point lists) |
//! | `8·n_acc` | accumulators, `f64` (complex as re, im) |
//!
//! The header's capture identity and probe parameters are the host's: the host that
//! configures the MCU for a capture writes them once ([`crate::fixture`]'s templates,
//! `fixture/state_*.json`, made by `gen state-template` from the host's own partial state of the
//! same capture and probe). What only the MCU knows is filled in here: the laser rows folded,
//! the probe's counters, the column's projector-leg range and the CRC-32 of the payload. A
//! template holds each of these as a JSON string marker (`"@ROWS@"`, `"@REPORT@"`,
//! `"@LEGS@"`, `"@CRC@"`), replaced by the value.
//!
//! No allocation: the header is written in pieces to a byte sink, the numbers formatted into
//! small stack buffers ([`heapless::String`]). The payload is walked twice (CRC, then
//! writing). Cost: O(n_acc) for the CRC (bitwise CRC-32, 8 steps per byte), negligible beside a
//! scan. The same code runs on the host (`gen/` includes this file), so the host can produce
//! the bytes the firmware must write.

use core::fmt::Write as _;
use heapless::String;
use vltm_kernel::num_complex::Complex64;
use vltm_kernel::{Point, Report};

/// Magic bytes of a partial state.
pub const MAGIC: &[u8; 8] = b"VLTMPART";
/// Format version written.
pub const VERSION: u32 = 1;

/// Why a state could not be written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StateError {
    /// The template lacks a marker, or holds one twice.
    Template,
    /// A formatted value did not fit its stack buffer.
    Format,
    /// The header is longer than `u32::MAX` bytes.
    TooLong,
    /// The sink failed (semihosting I/O).
    Sink,
}

/// What the MCU knows of a probe after its rows: fills a template's markers.
pub struct StateParts<'a> {
    /// The header template (JSON with the markers).
    pub template: &'a str,
    /// Laser rows folded, `[first, end)`.
    pub rows: [usize; 2],
    /// The probe's counters.
    pub report: Report,
    /// A column's projector-leg range (`Probe::leg_range`); `None` for the diagonal, whose
    /// template has no `"@LEGS@"` marker.
    pub legs: Option<(f64, f64)>,
    /// SPAD spots (columns), written before the voxels.
    pub spads: &'a [Point],
    /// Voxels (a point list).
    pub points: &'a [Point],
    /// The probe's accumulators (`Probe::accumulators`).
    pub acc: &'a [Complex64],
}

/// CRC-32 (IEEE 802.3, reflected, the one of zip and `crc32fast`), bitwise: no table in flash.
#[derive(Clone, Copy)]
struct Crc(u32);

impl Crc {
    const fn new() -> Self {
        Self(0xFFFF_FFFF)
    }
    fn update(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u32::from(b);
            for _ in 0..8 {
                let mask = (self.0 & 1).wrapping_neg();
                self.0 = (self.0 >> 1) ^ (0xEDB8_8320 & mask);
            }
        }
    }
    const fn value(self) -> u32 {
        !self.0
    }
}

/// Calls `f` on the payload's bytes in order (SPADs, voxels, accumulators), in small pieces.
fn payload<E>(p: &StateParts<'_>, mut f: impl FnMut(&[u8]) -> Result<(), E>) -> Result<(), E> {
    for pt in p.spads.iter().chain(p.points) {
        for c in pt {
            f(&c.to_le_bytes())?;
        }
    }
    for z in p.acc {
        f(&z.re.to_le_bytes())?;
        f(&z.im.to_le_bytes())?;
    }
    Ok(())
}

/// The marker values, formatted.
struct Fills {
    rows: String<48>,
    report: String<96>,
    legs: String<64>,
    crc: String<12>,
}

fn fills(p: &StateParts<'_>) -> Result<Fills, StateError> {
    let crc = {
        let mut c = Crc::new();
        let _ = payload::<()>(p, |b| {
            c.update(b);
            Ok(())
        });
        c.value()
    };
    let mut f = Fills {
        rows: String::new(),
        report: String::new(),
        legs: String::new(),
        crc: String::new(),
    };
    let r = p.report;
    let e = |_| StateError::Format;
    write!(f.rows, "[[{},{}]]", p.rows[0], p.rows[1]).map_err(e)?;
    write!(
        f.report,
        "{{\"rows\":{},\"non_finite\":{},\"dropped\":{}}}",
        r.rows, r.non_finite, r.dropped
    )
    .map_err(e)?;
    match p.legs {
        // `{:?}` of an f64 is its shortest round-trip form with a decimal point or exponent:
        // valid JSON, read back bit for bit. No rows yet: `null`, as the host writes.
        Some((lo, hi)) if lo <= hi && lo.is_finite() && hi.is_finite() => {
            write!(f.legs, "[[{lo:?},{hi:?}]]").map_err(e)?;
        }
        Some(_) => write!(f.legs, "[null]").map_err(e)?,
        None => {}
    }
    write!(f.crc, "\"{crc:08x}\"").map_err(e)?;
    Ok(f)
}

/// The template's pieces between the markers, with each marker's fill, in order.
fn pieces<'a>(template: &'a str, f: &'a Fills, column: bool) -> Result<[&'a str; 9], StateError> {
    let markers: [(&str, &str); 4] = [
        ("\"@ROWS@\"", f.rows.as_str()),
        ("\"@REPORT@\"", f.report.as_str()),
        ("\"@LEGS@\"", f.legs.as_str()),
        ("\"@CRC@\"", f.crc.as_str()),
    ];
    // Markers in the order they appear in the template.
    let mut found: [(usize, &str, &str); 4] = [(usize::MAX, "", ""); 4];
    for (slot, (m, fill)) in found.iter_mut().zip(markers) {
        match (template.find(m), template.rfind(m)) {
            (Some(a), Some(b)) if a == b => *slot = (a, m, fill),
            (None, None) if m == "\"@LEGS@\"" && !column => {}
            _ => return Err(StateError::Template),
        }
    }
    found.sort_unstable_by_key(|s| s.0);
    let mut out = [""; 9];
    let mut at = 0;
    let mut k = 0;
    for (pos, m, fill) in found {
        if pos == usize::MAX {
            continue;
        }
        let (Some(before), Some(o)) = (template.get(at..pos), out.get_mut(k..k + 2)) else {
            return Err(StateError::Template);
        };
        o[0] = before;
        o[1] = fill;
        at = pos + m.len();
        k += 2;
    }
    let (Some(rest), Some(o)) = (template.get(at..), out.get_mut(k)) else {
        return Err(StateError::Template);
    };
    *o = rest;
    Ok(out)
}

/// Writes the state to `sink` in pieces (magic, version, header, payload).
///
/// # Errors
/// [`StateError`]: a template without its markers, a sink that failed.
pub fn write_state(
    p: &StateParts<'_>,
    mut sink: impl FnMut(&[u8]) -> Result<(), ()>,
) -> Result<(), StateError> {
    let f = fills(p)?;
    let parts = pieces(p.template, &f, p.legs.is_some())?;
    let h: usize = parts.iter().map(|s| s.len()).sum();
    let h = u32::try_from(h).map_err(|_| StateError::TooLong)?;
    let mut put = |b: &[u8]| sink(b).map_err(|()| StateError::Sink);
    put(MAGIC)?;
    put(&VERSION.to_le_bytes())?;
    put(&h.to_le_bytes())?;
    for s in parts {
        put(s.as_bytes())?;
    }
    payload(p, put)
}
