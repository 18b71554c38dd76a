//! Analytic transient simulator of point scatterers (DESIGN §B.9, `reference/sim.py`).
//!
//! Paths, times in metres of optical path from the laser spot `x_l` to the SPAD spot `x_s`
//! (wall-to-wall, `t0` = 0):
//! * 3-vertex (direct) `x_l → p → x_s`, amplitude `k_p/(d_lp²·d_ps²)`;
//! * 4-vertex `x_l → a → b → x_s` (a ≠ b), amplitude `k_a·k_b/(d_la²·d_ab²·d_bs²)`;
//!
//! with `k = albedo·area/π`. Each path deposits a Gaussian pulse of std `pulse_sigma`
//! (unit time integral, sampled at the bin times). No cosine terms, no noise.

use vltm_kernel::Point;

/// An isotropic point scatterer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scatterer {
    /// Position [m], z > 0.
    pub position: Point,
    /// Albedo (0..1).
    pub albedo: f64,
    /// Area it stands for [m²].
    pub area: f64,
}

/// Which light paths to render.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Bounces {
    /// 3-vertex paths (direct light).
    pub direct: bool,
    /// 4-vertex paths between every ordered pair of distinct scatterers.
    pub inter_reflections: bool,
}

/// Scene, apertures and time axis.
#[derive(Clone, Debug)]
pub struct PointScene {
    /// Scatterers.
    pub scatterers: Vec<Scatterer>,
    /// Laser spots on the wall.
    pub lasers: Vec<Point>,
    /// SPAD spots on the wall.
    pub spads: Vec<Point>,
    /// Bins per histogram.
    pub nt: usize,
    /// Bin width [m].
    pub dt: f64,
    /// Pulse std [m].
    pub pulse_sigma: f64,
}

fn d(a: &Point, b: &Point) -> f64 {
    ((0..3)
        .map(|i| (a[i] as f64 - b[i] as f64).powi(2))
        .sum::<f64>())
    .sqrt()
}

/// A regular `n × n` grid of spots over a `size × size` square of the wall centred at 0.
pub fn wall_grid(n: usize, size: f32) -> Vec<Point> {
    let c = |i: usize| {
        if n == 1 {
            0.0
        } else {
            -size / 2.0 + size * i as f32 / (n - 1) as f32
        }
    };
    (0..n)
        .flat_map(|i| (0..n).map(move |j| [c(i), c(j), 0.0]))
        .collect()
}

impl PointScene {
    fn deposit(&self, h: &mut [f32], t: f64, amp: f64) {
        let s = self.pulse_sigma / self.dt;
        let x = t / self.dt;
        let r = (6.0 * s).ceil() as i64 + 1;
        let norm = 1.0 / (s * (2.0 * std::f64::consts::PI).sqrt());
        let n0 = x.round() as i64;
        for n in (n0 - r).max(0)..(n0 + r + 1).min(self.nt as i64) {
            let u = (n as f64 - x) / s;
            h[n as usize] += (amp * norm * (-0.5 * u * u).exp()) as f32;
        }
    }

    /// The histograms of laser row `l` (SPAD-major, `Ks·Nt`), written into `out`.
    pub fn row(&self, l: usize, bounces: Bounces, out: &mut Vec<f32>) {
        out.clear();
        out.resize(self.spads.len() * self.nt, 0.0);
        let xl = &self.lasers[l];
        let k = |p: &Scatterer| p.albedo * p.area / std::f64::consts::PI;
        for (xs, h) in self.spads.iter().zip(out.chunks_exact_mut(self.nt)) {
            for (i, a) in self.scatterers.iter().enumerate() {
                let (dla, das) = (d(xl, &a.position), d(&a.position, xs));
                if bounces.direct {
                    self.deposit(h, dla + das, k(a) / (dla * dla * das * das));
                }
                if bounces.inter_reflections {
                    for (j, b) in self.scatterers.iter().enumerate() {
                        if i != j {
                            let (dab, dbs) = (d(&a.position, &b.position), d(&b.position, xs));
                            let amp = k(a) * k(b) / (dla * dla * dab * dab * dbs * dbs);
                            self.deposit(h, dla + dab + dbs, amp);
                        }
                    }
                }
            }
        }
    }
}
