//! Float64 reference of the paper's **time-domain** equations (the gated phasor, the diagonal,
//! the column, the late gate), written to be obviously correct rather than fast:
//!
//! * every gate is a literal sum over **all** `Nt` bins — no frequency band, no truncation of
//!   the Gaussian, no guard interval, no suffix sums, no phase recurrences;
//! * every distance, time and phase is computed in `f64` from the `f32` positions cast to
//!   `f64`.
//!
//! Conventions (sign convention A, as y-tal): `t_n = t0 + n·Δt`, `Ω = 2π/λ`,
//! `g(u) = exp(−u²/2σ²)`,
//!
//! ```text
//! Z_ls(τ)     = Σ_n            H_ls[n] ·      g(t_n − τ)  · e^{−iΩ(t_n − τ)}     (Z-T, Eqs. 11–14)
//! Z^ho_ls(τ)  = Σ_{n: t_n > τ} H_ls[n] · (1 − g(t_n − τ)) · e^{−iΩ(t_n − τ)}     (Eq. 18)
//! Z^none_ls(τ)= Σ_n            H_ls[n] ·                    e^{−iΩ(t_n − τ)}     (Fig. 6)
//! τ_ls(a, b)  = d1_l + |x_l − x_a| + |x_a − x_b| + |x_b − x_s| + d4_s              (a = b: diagonal)
//! A(a, b)     = Σ_l Σ_s w(|x_l − x_a|) · w(|x_b − x_s|) · Z_ls(τ_ls(a, b)),      T = |A|²
//! ```
//!
//! with `d1_l = |x_l − laser_origin|`, `d4_s = |x_s − sensor_origin|` when the time axis
//! includes the legs (else 0) and `w(d) = 1/max(d, d_min)` (paper) or `1`.
#![allow(dead_code)]

use num_complex::Complex64;
use std::f64::consts::PI;
use vltm_kernel::{Legs, Params, Weights};

/// A point in `f64`.
pub type P3 = [f64; 3];

/// An `f32` kernel point as `f64` (exact).
pub fn p64(p: [f32; 3]) -> P3 {
    p.map(f64::from)
}

/// Euclidean distance in `f64`.
pub fn dist(a: &P3, b: &P3) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The time gate of the reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gate {
    /// `g(t_n − τ)` over every bin.
    Gaussian,
    /// `[t_n > τ]·(1 − g(t_n − τ))` (Eq. 18).
    HigherOrder,
    /// No gate (monochromatic phasor).
    None,
}

/// A scan in `f64`: the virtual wave, the time axis, legs, weights, the apertures and every
/// histogram `H[(l·Ks + s)·Nt + n]`.
#[derive(Clone, Debug)]
pub struct Reference {
    /// λ [m].
    pub lambda: f64,
    /// σ [m].
    pub sigma: f64,
    /// Δt [m].
    pub dt: f64,
    /// t0 [m].
    pub t0: f64,
    /// Nt.
    pub nt: usize,
    /// `(laser_origin, sensor_origin)` when the time axis includes the legs.
    pub legs: Option<(P3, P3)>,
    /// `Some(d_min)`: `w(d) = 1/max(d, d_min)`; `None`: `w = 1`.
    pub d_min: Option<f64>,
    /// Laser spots x_l.
    pub lasers: Vec<P3>,
    /// SPAD spots x_s.
    pub spads: Vec<P3>,
    /// Histograms, laser-major then SPAD then bin.
    pub h: Vec<f64>,
}

impl Reference {
    /// The reference for the kernel parameters `p` (σ default 2λ/3 applied here), `f32`
    /// apertures and histograms `h` (already read as `f64`; a non-finite sample must be
    /// given as 0, which is what the kernel documents).
    pub fn new(p: &Params, lasers: &[[f32; 3]], spads: &[[f32; 3]], h: Vec<f64>) -> Self {
        assert_eq!(
            h.len(),
            lasers.len() * spads.len() * p.nt,
            "histogram length"
        );
        Self {
            lambda: p.wavelength,
            sigma: p.sigma.unwrap_or(2.0 * p.wavelength / 3.0),
            dt: p.dt,
            t0: p.t0,
            nt: p.nt,
            legs: match p.legs {
                Legs::WallToWall => None,
                Legs::FirstAndLast {
                    laser_origin,
                    sensor_origin,
                } => Some((laser_origin, sensor_origin)),
            },
            d_min: match p.weights {
                Weights::Inv => Some(p.d_min),
                Weights::One => None,
            },
            lasers: lasers.iter().copied().map(p64).collect(),
            spads: spads.iter().copied().map(p64).collect(),
            h,
        }
    }

    /// Histogram H_ls.
    pub fn hist(&self, l: usize, s: usize) -> &[f64] {
        let start = (l * self.spads.len() + s) * self.nt;
        &self.h[start..start + self.nt]
    }

    /// Sample time t_n.
    pub fn t(&self, n: usize) -> f64 {
        self.t0 + n as f64 * self.dt
    }

    /// The unit-amplitude Gaussian g(u).
    pub fn g(&self, u: f64) -> f64 {
        (-u * u / (2.0 * self.sigma * self.sigma)).exp()
    }

    /// Gate value at `u = t_n − τ`.
    pub fn gate(&self, gate: Gate, u: f64) -> f64 {
        match gate {
            Gate::Gaussian => self.g(u),
            Gate::HigherOrder if u > 0.0 => 1.0 - self.g(u),
            Gate::HigherOrder => 0.0,
            Gate::None => 1.0,
        }
    }

    /// The gated phasor `Σ_n H_ls[n]·gate(t_n − τ)·e^{−iΩ(t_n − τ)}`, every bin.
    pub fn z(&self, gate: Gate, l: usize, s: usize, tau: f64) -> Complex64 {
        let omega = 2.0 * PI / self.lambda;
        self.hist(l, s)
            .iter()
            .enumerate()
            .map(|(n, &h)| {
                let u = self.t(n) - tau;
                Complex64::from_polar(h * self.gate(gate, u), -omega * u)
            })
            .sum()
    }

    /// Laser leg d1_l.
    pub fn d1(&self, l: usize) -> f64 {
        self.legs.map_or(0.0, |(laser_origin, _)| {
            dist(&self.lasers[l], &laser_origin)
        })
    }

    /// Sensor leg d4_s.
    pub fn d4(&self, s: usize) -> f64 {
        self.legs.map_or(0.0, |(_, sensor_origin)| {
            dist(&self.spads[s], &sensor_origin)
        })
    }

    /// Leg weight w(d).
    pub fn w(&self, d: f64) -> f64 {
        self.d_min.map_or(1.0, |d_min| 1.0 / d.max(d_min))
    }

    /// Path time τ_ls(a, b) in the histograms' frame.
    pub fn tau(&self, l: usize, s: usize, a: &P3, b: &P3) -> f64 {
        self.d1(l) + dist(&self.lasers[l], a) + dist(a, b) + dist(b, &self.spads[s]) + self.d4(s)
    }

    /// Element amplitude `A(a, b) = Σ_l Σ_s w(|x_l − x_a|)·w(|x_b − x_s|)·Z_ls(τ_ls(a, b))`.
    pub fn amplitude(&self, gate: Gate, a: &P3, b: &P3) -> Complex64 {
        let mut acc = Complex64::new(0.0, 0.0);
        for (l, xl) in self.lasers.iter().enumerate() {
            for (s, xs) in self.spads.iter().enumerate() {
                let w = self.w(dist(xl, a)) * self.w(dist(b, xs));
                acc += self.z(gate, l, s, self.tau(l, s, a, b)) * w;
            }
        }
        acc
    }

    /// Diagonal amplitudes `A(v, v)` over `voxels`.
    pub fn diagonal(&self, gate: Gate, voxels: &[[f32; 3]]) -> Vec<Complex64> {
        voxels
            .iter()
            .map(|v| self.amplitude(gate, &p64(*v), &p64(*v)))
            .collect()
    }

    /// Column amplitudes `A(focus, b)` over `voxels`.
    pub fn column(&self, gate: Gate, focus: [f32; 3], voxels: &[[f32; 3]]) -> Vec<Complex64> {
        voxels
            .iter()
            .map(|b| self.amplitude(gate, &p64(focus), &p64(*b)))
            .collect()
    }

    /// Error scale of an element: `Σ_l Σ_s w_l w_s Σ_n |H_ls[n]|`. A gate kernel that is off by
    /// at most `ε` per sample (relative to g(0) = 1) moves `A(a, b)` by at most `ε·scale`.
    pub fn scale(&self, a: &P3, b: &P3) -> f64 {
        let mut acc = 0.0;
        for (l, xl) in self.lasers.iter().enumerate() {
            for (s, xs) in self.spads.iter().enumerate() {
                let sum_abs: f64 = self.hist(l, s).iter().map(|h| h.abs()).sum();
                acc += self.w(dist(xl, a)) * self.w(dist(b, xs)) * sum_abs;
            }
        }
        acc
    }

    /// Smallest and largest path time τ_ls(a, b) over all (l, s).
    pub fn tau_range(&self, a: &P3, b: &P3) -> (f64, f64) {
        let mut range = (f64::INFINITY, f64::NEG_INFINITY);
        for l in 0..self.lasers.len() {
            for s in 0..self.spads.len() {
                let t = self.tau(l, s, a, b);
                range = (range.0.min(t), range.1.max(t));
            }
        }
        range
    }
}

/// `erfc(x)` by composite Simpson integration of `2/√π·e^{−t²}` over `[x, x + 12]`
/// (the rest is below 1e-60); plenty for a tolerance.
pub fn erfc(x: f64) -> f64 {
    let (n, len) = (4000, 12.0);
    let h = len / n as f64;
    let f = |t: f64| (-t * t).exp();
    let mut sum = f(x) + f(x + len);
    for i in 1..n {
        sum += f(x + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    sum * h / 3.0 * 2.0 / PI.sqrt()
}
