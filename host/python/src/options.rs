//! The probes' keywords as the library's options: the wave options and the evaluation path,
//! shells and gates, each checked with an error naming its keyword.

use crate::arg;
use pyo3::prelude::*;
use vltm::exec::EvalPath;
use vltm::probe::{ColumnGate, Shell, Wave};
use vltm_kernel::Weights;

/// The wave options and the evaluation path, from Python keywords.
pub(crate) fn wave_of(
    wavelength: Option<f64>,
    sigma: Option<f64>,
    weights: &str,
    band: f64,
    compensate_laser: bool,
    crop: bool,
    path: &str,
) -> PyResult<(Wave, EvalPath)> {
    let (weights, cosine) = match weights {
        "inv" => (Weights::Inv, false),
        "one" => (Weights::One, false),
        "cos" => (Weights::Inv, true),
        w => {
            return Err(arg(
                "weights",
                format!("expected inv, one or cos, found `{w}`"),
            ));
        }
    };
    let path = match path {
        "auto" => EvalPath::Auto,
        "band" => EvalPath::Band,
        "planar" => EvalPath::Planar,
        "lookup" => EvalPath::Lookup,
        "phasor" => EvalPath::Phasor,
        p => {
            return Err(arg(
                "path",
                format!("expected auto, band, planar, lookup or phasor, found `{p}`"),
            ));
        }
    };
    let wave = Wave {
        wavelength,
        sigma,
        weights,
        cosine,
        band_half_width: band,
        compensate_laser,
        auto_margin: true,
        crop,
    };
    Ok((wave, path))
}

/// `(r0, r1)` in metres as a shell (`None`: none), checked; errors name `name`.
pub(crate) fn shell_of(name: &str, shell: Option<(f32, f32)>) -> PyResult<Option<Shell>> {
    match shell {
        None => Ok(None),
        Some((r0, r1)) if r0 >= 0.0 && r1 > r0 => Ok(Some(Shell { r0, r1 })),
        Some((r0, r1)) => Err(arg(
            name,
            format!("expected (r0, r1) with 0 <= r0 < r1 in metres, found ({r0}, {r1})"),
        )),
    }
}

/// A column's gate: two-bounce, higher-order or none.
pub(crate) fn column_gate(gate: &str) -> PyResult<ColumnGate> {
    match gate {
        "two-bounce" => Ok(ColumnGate::TwoBounce),
        "higher-order" => Ok(ColumnGate::HigherOrder),
        "none" => Ok(ColumnGate::None),
        g => Err(arg(
            "gate",
            format!("expected two-bounce, higher-order or none, found `{g}`"),
        )),
    }
}

/// The diagonal's gates: `gaussian` is direct light.
pub(crate) fn diagonal_gate(gate: &str) -> PyResult<ColumnGate> {
    match gate {
        "gaussian" => Ok(ColumnGate::TwoBounce),
        "higher-order" => Ok(ColumnGate::HigherOrder),
        "none" => Ok(ColumnGate::None),
        g => Err(arg(
            "gate",
            format!("expected gaussian, none or higher-order, found `{g}`"),
        )),
    }
}
