//! Helpers of the partial-state format ([`super`]): the FNV-1a hashes of the capture's
//! geometry and of point sets, the names of weights, gates and paths as the JSON header
//! spells them, and the conversions of shells, leg ranges and complex accumulators to and
//! from the header and the `f64` body. Pure functions, no allocation beyond their results.

use crate::error::{Error, Result};
use crate::exec::EvalPath;
use crate::io::capture::Geometry;
use crate::probe::column::Shell;
use crate::probe::gate::ColumnGate;
use num_complex::Complex64;
use vltm_kernel::{Point, Weights};

/// FNV-1a, 64 bits.
pub(super) fn fnv(bytes: impl IntoIterator<Item = u8>) -> u64 {
    bytes.into_iter().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

pub(super) fn point_bytes(pts: &[Point]) -> impl Iterator<Item = u8> + '_ {
    pts.iter().flatten().flat_map(|c| c.to_le_bytes())
}

pub(super) fn geometry_hash(g: &Geometry) -> String {
    let mut b: Vec<u8> = point_bytes(&g.lasers)
        .chain(point_bytes(&g.spads))
        .collect();
    for n in g.laser_shape.iter().chain(&g.spad_shape).chain([&g.nt]) {
        b.extend((*n as u64).to_le_bytes());
    }
    for x in g
        .laser_origin
        .iter()
        .chain(&g.sensor_origin)
        .chain([&g.dt, &g.t0])
    {
        b.extend(x.to_le_bytes());
    }
    b.extend([u8::from(g.legs_in_time), u8::from(g.confocal)]);
    format!("{:016x}", fnv(b))
}

pub(super) fn weights_name(w: Weights) -> &'static str {
    match w {
        Weights::Inv => "inv",
        Weights::One => "one",
    }
}

pub(super) fn parse_weights(s: &str) -> Result<Weights> {
    match s {
        "inv" => Ok(Weights::Inv),
        "one" => Ok(Weights::One),
        _ => Err(Error::arg("weights", format!("unknown weights `{s}`"))),
    }
}

pub(super) fn gate_name(g: ColumnGate) -> &'static str {
    match g {
        ColumnGate::TwoBounce => "two-bounce",
        ColumnGate::HigherOrder => "higher-order",
        ColumnGate::None => "none",
    }
}

pub(super) fn parse_gate(s: &str) -> Option<ColumnGate> {
    match s {
        "two-bounce" => Some(ColumnGate::TwoBounce),
        "higher-order" => Some(ColumnGate::HigherOrder),
        "none" => Some(ColumnGate::None),
        _ => None,
    }
}

pub(super) fn parse_path(s: &str) -> Option<EvalPath> {
    [
        EvalPath::Band,
        EvalPath::Planar,
        EvalPath::Lookup,
        EvalPath::Phasor,
        EvalPath::Auto,
    ]
    .into_iter()
    .find(|p| p.name() == s)
}

pub(super) fn shell_head(s: Shell) -> (f32, Option<f32>) {
    (s.r0, s.r1.is_finite().then_some(s.r1))
}

pub(super) fn shell_of(s: (f32, Option<f32>)) -> Shell {
    Shell {
        r0: s.0,
        r1: s.1.unwrap_or(f32::INFINITY),
    }
}

pub(super) fn leg_head(l: (f64, f64)) -> Option<[f64; 2]> {
    (l.0 <= l.1).then_some([l.0, l.1])
}

pub(super) fn leg_of(l: Option<[f64; 2]>) -> (f64, f64) {
    l.map_or((f64::INFINITY, f64::NEG_INFINITY), |[a, b]| (a, b))
}

pub(super) fn complex(acc: &[f64]) -> Vec<Complex64> {
    acc.chunks_exact(2)
        .map(|z| Complex64::new(z[0], z[1]))
        .collect()
}

pub(super) fn flat(acc: &[Complex64]) -> Vec<f64> {
    acc.iter().flat_map(|z| [z.re, z.im]).collect()
}
