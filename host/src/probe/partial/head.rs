//! The header of a partial state: the capture's identity, the probe, its wave and kernel
//! configuration, the volume and the counters (serialised as the state file's JSON header).

use serde::{Deserialize, Serialize};
use vltm_kernel::{Config, Legs, Point};

use super::names::*;

/// The capture's identity: parts of different captures do not merge.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) struct Identity {
    pub(super) file_bytes: u64,
    pub(super) lasers: usize,
    pub(super) laser_shape: [usize; 2],
    pub(super) spads: usize,
    pub(super) spad_shape: [usize; 2],
    pub(super) nt: usize,
    pub(super) dt: f64,
    pub(super) t0: f64,
    pub(super) confocal: bool,
    pub(super) legs_in_time: bool,
    pub(super) geometry_fnv64: String,
}

/// The first field in which `a` and `b` (serialised) differ, as `prefix.field: a vs b`
/// (nested objects down to the first differing leaf, `probe.wave.sigma: 0.08 vs null`),
/// skipping the top-level fields `skip` says match; `None` when none does.
pub(super) fn first_difference<T: Serialize + PartialEq>(
    prefix: &str,
    a: &T,
    b: &T,
    skip: impl Fn(&str) -> bool,
) -> Option<String> {
    pub(super) fn walk(
        path: &str,
        x: &serde_json::Value,
        y: &serde_json::Value,
        skip: &dyn Fn(&str) -> bool,
    ) -> Option<String> {
        use serde_json::Value::Object;
        match (x, y) {
            (Object(x), Object(y)) => x.iter().find_map(|(k, v)| {
                let w = y.get(k).unwrap_or(&serde_json::Value::Null);
                if skip(k) {
                    return None;
                }
                walk(&format!("{path}.{k}"), v, w, &|_| false)
            }),
            _ => (x != y).then(|| format!("{path}: {x} vs {y}")),
        }
    }
    match (serde_json::to_value(a), serde_json::to_value(b)) {
        (Ok(x), Ok(y)) => walk(prefix, &x, &y, &skip),
        _ => (a != b).then(|| prefix.to_string()),
    }
}

impl Identity {
    /// The first field in which `b` is another capture than `self`, with both values
    /// (`capture.nt: 128 vs 64`); `None` for the same capture. A `file_bytes` of 0 (a
    /// stream's state, written before its final size was known) matches any size.
    pub(super) fn differs(&self, b: &Self) -> Option<String> {
        let unknown = self.file_bytes == 0 || b.file_bytes == 0;
        first_difference("capture", self, b, |k| k == "file_bytes" && unknown)
    }
}

/// The probe's kind and parameters: parts with other parameters do not merge.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) struct ProbeHead {
    pub(super) kind: String,
    pub(super) path: String,
    pub(super) wave: WaveHead,
    pub(super) config: ConfigHead,
    pub(super) volume: VolumeHead,
    pub(super) focus: Option<Point>,
    pub(super) gate: Option<String>,
    /// `[r0, r1]`, `r1` null for infinity.
    pub(super) shell: Option<(f32, Option<f32>)>,
    /// Γ as voxel indices (indirect light).
    pub(super) gamma: Option<Vec<usize>>,
    /// Leak-corrected (gate method, default options) indirect light.
    #[serde(default)]
    pub(super) leak: bool,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) struct WaveHead {
    pub(super) wavelength: Option<f64>,
    pub(super) sigma: Option<f64>,
    pub(super) weights: String,
    pub(super) band_half_width: f64,
    pub(super) compensate_laser: bool,
    pub(super) auto_margin: bool,
}

/// The resolved kernel parameters ([`Params`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) struct ConfigHead {
    pub(super) wavelength: f64,
    pub(super) sigma: Option<f64>,
    pub(super) band_half_width: f64,
    pub(super) gate_support: f64,
    pub(super) margin: f64,
    pub(super) nt: usize,
    pub(super) dt: f64,
    pub(super) t0: f64,
    /// `[laser_origin, sensor_origin]` when the time axis includes the device legs.
    pub(super) legs: Option<[[f64; 3]; 2]>,
    pub(super) weights: String,
    pub(super) d_min: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) struct VolumeHead {
    pub(super) shape: [usize; 3],
    pub(super) axes: Option<[[f32; 2]; 3]>,
    pub(super) points_fnv64: String,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub(super) struct Counters {
    pub(super) rows: u64,
    pub(super) non_finite: u64,
    pub(super) dropped: u64,
    /// `Σ H²` read and zeroed by the leak gate ([`GateEnergy`]).
    #[serde(default)]
    pub(super) leak_total: f64,
    #[serde(default)]
    pub(super) leak_cut: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) struct Head {
    pub(super) capture: Identity,
    pub(super) probe: ProbeHead,
    pub(super) rows: Vec<[usize; 2]>,
    pub(super) report: Counters,
    /// Per factorised column: the projector leg range `[min, max]`, null before any row.
    pub(super) legs: Vec<Option<[f64; 2]>>,
    pub(super) n_spads: usize,
    pub(super) n_points: usize,
    /// Foci of a matrix (their points follow the volume's).
    #[serde(default)]
    pub(super) n_from: usize,
    pub(super) n_acc: usize,
    /// CRC-32 of the bytes after the header, 8 hex digits.
    pub(super) crc32: String,
    pub(super) capture_name: String,
}

pub(super) fn config_head(cfg: &Config) -> ConfigHead {
    let p = cfg.params();
    ConfigHead {
        wavelength: p.wavelength,
        sigma: p.sigma,
        band_half_width: p.band_half_width,
        gate_support: p.gate_support,
        margin: p.margin,
        nt: p.nt,
        dt: p.dt,
        t0: p.t0,
        legs: match p.legs {
            Legs::WallToWall => None,
            Legs::FirstAndLast {
                laser_origin,
                sensor_origin,
            } => Some([laser_origin, sensor_origin]),
        },
        weights: weights_name(p.weights).into(),
        d_min: p.d_min,
    }
}
