//! Analytic transient simulator of patches, boxes and point scatterers (DESIGN §A.5, §B.9).
//!
//! A [`Scene`] (a JSON scene file, or built in code) holds the capture setup (laser and SPAD
//! spots on the relay wall, time axis, device positions) and the hidden objects. [`Scene::render`]
//! turns it into a [`Capture`] `H[l][s][n]`; [`Scene::source`] streams it row by row as a
//! [`RowSource`]. The formulas and conventions are those of the numpy prototype
//! `reference/sim.py` beside DESIGN.md, which `fixtures/sim/make_reference.py` checks this module
//! against (`tests/sim.rs`).
//!
//! # Conventions (DESIGN §B.0)
//!
//! * The relay wall is the plane z = 0 with normal (0, 0, +1); the hidden scene is at z > 0.
//! * Lengths and times are metres of optical path (c = 1). Bin `n` is the point sample at
//!   `t0 + n·dt`.
//! * Path times run from the laser spot `x_l` to the SPAD spot `x_s`; with `legs_in_time` they
//!   also include `d1 = |laser_origin − x_l|` and `d4 = |x_s − sensor_origin|` (y-tal's
//!   `t_accounts_first_and_last_bounces`). The capture's bin 0 is at `t0`.
//! * Wall grids are regular over a `size[0] × size[1]` rectangle centred at `center`, with
//!   **inclusive end points** like `np.linspace(c − size/2, c + size/2, n)` (an axis with one
//!   spot sits at the centre, its size is ignored), flattened in **C order over (x, y)**: spot
//!   `ix·ny + iy` (tal's `X_Y_3`).
//! * Object surfaces are sampled at **cell centres** (sim.py `patch`): a patch of sides `w × h`
//!   sampled `n` gives `n × n` points `c + w·u_i·a + h·u_j·b`, `u_i = (i + ½)/n − ½`, C order over
//!   `(i, j)`, each carrying the area `w·h/n²`. The tangents are sim.py's:
//!   `a = normalise(n̂ × ŷ)` (or `n̂ × x̂` when `|n̂_y| ≥ 0.9`) and `b = n̂ × a`; so for a patch
//!   facing the wall (`n̂ ≈ −ẑ`) `w` runs along x and `h` along y.
//!
//! # Light paths
//!
//! With `k_p = albedo_p·area_p/π` for every sample point:
//!
//! | vertices | path | amplitude |
//! |---|---|---|
//! | 3 (direct) | `x_l → p → x_s` | `k_p / (d_lp² d_ps²)` |
//! | 4 | `x_l → a → b → x_s` | `k_a k_b / (d_la² d_ab² d_bs²)` |
//! | 5 | `x_l → a → b → c → x_s` | `k_a k_b k_c / (d_la² d_ab² d_bc² d_cs²)` |
//!
//! Consecutive scattering points of a 4- or 5-vertex path belong to **different objects**
//! (`object(a) ≠ object(b) ≠ object(c)`; `a` and `c` may be on the same object, even the same
//! point: `A → B → A` is a 5-vertex path), so an object never illuminates itself. A box is one
//! object (a convex box cannot light itself anyway). Coincident points of different objects
//! (distance 0) are skipped. There is no occlusion test: objects do not shadow each other.
//!
//! With `cosines` (the default) Lambertian cosine factors multiply each path, clipped at 0,
//! exactly as sim.py: the wall's emission cosine at `x_l` and reception cosine at `x_s`
//! (against the wall normal +z); at each scattering point with a normal, the cosines of the
//! incoming and the outgoing directions with its normal; i.e. every segment carries the cosines
//! at both of its ends. Point scatterers without a normal are isotropic (factor 1). Without
//! `cosines` all these factors are 1. (sim.py's explicit 5-vertex paths are isotropic; with
//! `cosines: false` this module matches them exactly.)
//!
//! Each path deposits a Gaussian pulse of standard deviation `pulse_sigma` centred at its time,
//! **sampled** at the bin times with unit sum over bins when the pulse lies inside the window
//! (sim.py `_deposit`: weight `exp(−½((n − x)/s)²)/(s√(2π))`, `x = (t − t0)/dt`, `s =
//! pulse_sigma/dt`, bins `round(x) ± (⌈6s⌉ + 1)`). So the sum of a path's bins is its amplitude.
//!
//! `bounces` selects paths: `"direct"` = 3-vertex only, `"indirect"` = 4- (and 5-) vertex only,
//! `"all"`; `max_vertices` (3, 4 or 5) is the longest path rendered. A confocal setup renders one
//! histogram per laser row, for the SPAD at the laser spot (`x_s = x_l`).
//!
//! Cost per laser row: `O(P·Ks·W)` direct, `O(P²·Ks·W)` with 4 vertices and `O(P³·Ks·W)` with 5
//! (P sample points, Ks SPADs per row, W = 2⌈6·pulse_sigma/dt⌉ + 3 bins per pulse). When many
//! paths end at the same scattering point and the pulse is at least one bin wide
//! (`pulse_sigma ≥ dt`), it is cheaper to sum their pulses once on a grid of 32 points per bin
//! and let every SPAD interpolate that sum (4-point Lagrange; the shift to each SPAD is the same
//! for all of them); the renderer picks, per end point, whichever needs fewer operations. The
//! interpolation error is below 1e-7 of a pulse's peak for `pulse_sigma ≥ dt` (f32 resolution).
//! Rows are rendered in parallel by [`Scene::render`] (rayon). Measured on 2 cores: 16×16 lasers
//! × 16×16 SPADs × 800 bins, two patches sampled 6×6, 0.7 s with up to 4 vertices and 7 s
//! with 5.
//!
//! # Noise
//!
//! With `noise`, [`Scene::render`] scales `H` so that its largest bin has the expected count
//! `peak_counts`, adds `background` expected counts to every bin and replaces each bin by a
//! Poisson sample: the capture then holds **photon counts** as `f32`, not scaled back (unlike
//! sim.py's `poisson_peak`, which divides by the scale again). Laser row `l` draws from
//! `StdRng::seed_from_u64(seed + l·0x9E37_79B9_7F4A_7C15)` (wrapping), so a render is
//! deterministic for a given seed, independent of the number of threads (for a given version of
//! `rand`). A scene with no light at all gets background counts only. [`Scene::render_row`] and
//! [`Scene::source`] are noise-free (the scale needs the whole capture's maximum); use
//! [`Noise::apply`] on a rendered buffer.
//!
//! # Scene file
//!
//! Every field, with the defaults of the optional ones (the hidden lines make it a doctest that
//! parses and renders it):
//!
//! ```
//! # let json = r#"
//! {
//!   "description": "two facing patches and a box (optional free text)",
//!   "setup": {
//!     "lasers": {"grid": [16, 16], "size": [1.0, 1.0], "center": [0.0, 0.0]},
//!     "spads":  {"points": [[0.1, 0.0, 0.0], [0.2, 0.0, 0.0]], "shape": [2, 1]},
//!     "confocal": false,
//!     "nt": 500, "dt": 0.01, "t0": 0.0,
//!     "laser_origin": [-0.5, 0.0, 0.25], "sensor_origin": [-0.5, 0.0, 0.25],
//!     "legs_in_time": false
//!   },
//!   "pulse_sigma": 0.01,
//!   "bounces": "all",
//!   "max_vertices": 4,
//!   "cosines": true,
//!   "noise": {"peak_counts": 500.0, "background": 0.0, "seed": 0},
//!   "objects": [
//!     {"type": "patch", "name": "A", "center": [-0.3, 0.0, 0.8], "normal": [0.5, 0.0, -1.0],
//!      "size": [0.2, 0.2], "albedo": 1.0, "samples": 4},
//!     {"type": "box", "name": "C", "center": [0.3, 0.0, 0.9], "size": [0.2, 0.3, 0.2],
//!      "albedo": 1.0, "samples": 4},
//!     {"type": "point", "name": "P", "center": [0.0, 0.3, 0.7], "area": 0.01, "albedo": 1.0,
//!      "normal": null}
//!   ]
//! }
//! # "#;
//! # let scene = vltm::sim::Scene::from_json_str(json, "doc.json").unwrap();
//! # assert_eq!(scene.render().unwrap().data.len(), 256 * 2 * 500);
//! ```
//!
//! * `setup.lasers`, `setup.spads`: either a wall grid `{"grid": [nx, ny], "size": [sx, sy],
//!   "center": [cx, cy]}` (`grid` and `size` also accept one number for both axes; `center`
//!   defaults to the origin, `size` may be left out when the grid is `[1, 1]`; `[n, 1]` or
//!   `[1, n]` is a 1-D array) or explicit spots `{"points": [[x, y, z], ...], "shape": [nx, ny]}`
//!   (`shape` defaults to `[K, 1]`; spots should be on the wall, z = 0, which the wall cosines
//!   assume). `spads` may be left out for a confocal setup (it is then the laser grid, and must
//!   equal it if given).
//! * `nt` ≥ 1 bins of `dt` > 0 metres, bin 0 at `t0` (default 0). `laser_origin` and
//!   `sensor_origin` (default `[-0.5, 0, 0.25]`, tal's usual device position) only matter with
//!   `legs_in_time` (default false).
//! * `pulse_sigma` > 0 (default `dt`); `bounces` `"all"` (default) | `"direct"` | `"indirect"`;
//!   `max_vertices` 3, 4 (default) or 5; `cosines` (default true); `noise` (default `null`: no
//!   noise) with `peak_counts` > 0, `background` ≥ 0 (default 0), `seed` (default 0).
//! * `objects` (may be empty): every object has a `type`, an optional unique `name` (used by
//!   [`Scene::object_centre`]), a `center` (m) and an `albedo` in [0, 1] (default 1), and must
//!   lie entirely in front of the wall (z > 0).
//!   * `"patch"`: a rectangle with `normal` (any non-zero length; usually facing the wall,
//!     negative z), `size` `[w, h]` or one number for a square (sides along the tangents `a`,
//!     `b` above), `samples` n (default 4, ≤ 1024): n × n points.
//!   * `"box"`: a box of `size` `[sx, sy, sz]` (or one number): its 6 faces are patches with
//!     outward normals (+x, −x, +y, −y, +z, −z of the box, in that order), each sampled
//!     `samples` × `samples`. Axis-aligned by default; an optional `normal` (the outward normal
//!     of its front face, like a patch's) turns it: the box's axes become `(a, −b, −n̂)` with
//!     `a`, `b` the tangents above, so `[0, 0, −1]` is the axis-aligned box and `[1, 0, −1]`
//!     turns it 45° about y.
//!   * `"point"`: one isotropic point scatterer (sim.py `point_scene`) of `area` > 0 (m²), with
//!     an optional `normal` for the cosine factors.
//!
//!   A scene has at most [`MAX_POINTS`] surface samples in total ([`MAX_POINTS_5`] with 5-vertex
//!   paths).
//!
//! Unknown fields are rejected, as are non-positive sizes, `dt`, `nt`, zero or non-finite
//! normals, objects reaching z ≤ 0, duplicate names and the like: [`Scene::from_json_str`] and
//! [`Scene::load`] return an [`Error::Format`] naming the file and the field
//! (`objects[1].size`, `setup.dt`, ...).
//!
//! # Example
//!
//! ```
//! use vltm::sim::{Aperture, Patch, Scene, Setup};
//!
//! # fn main() -> vltm::Result<()> {
//! let json = r#"{
//!     "setup": {"lasers": {"grid": [4, 4], "size": 1.0}, "spads": {"grid": [2, 2], "size": 0.5},
//!               "nt": 300, "dt": 0.01},
//!     "objects": [
//!         {"type": "patch", "name": "A", "center": [-0.3, 0, 0.8], "normal": [0, 0, -1], "size": 0.1},
//!         {"type": "point", "name": "B", "center": [0.3, 0, 0.8], "area": 0.01}
//!     ]
//! }"#;
//! let scene = Scene::from_json_str(json, "example.json")?;
//! let capture = scene.render()?;
//! assert_eq!(capture.data.len(), 16 * 4 * 300);
//! assert_eq!(scene.object_centre("B"), Some([0.3, 0.0, 0.8]));
//!
//! // The same kind of scene, built in code.
//! let setup = Setup::new(Aperture::grid([4, 4], [1.0, 1.0], [0.0, 0.0]),
//!                        Aperture::grid([2, 2], [0.5, 0.5], [0.0, 0.0]), 300, 0.01);
//! let scene = Scene::new(setup).with(Patch::new("A", [-0.3, 0.0, 0.8], [0.0, 0.0, -1.0], [0.1, 0.1]));
//! let mut row = Vec::new();
//! scene.render_row(0, &mut row)?; // noise-free laser row 0: 4 SPADs × 300 bins
//! assert_eq!(row.len(), 4 * 300);
//! # Ok(()) }
//! ```

use std::fmt;
use std::path::Path;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Poisson};
use rayon::prelude::*;
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};
use vltm_kernel::Point;

use crate::capture::{Capture, Geometry, RowSource};
use crate::error::{Error, Result};

/// Default position of the laser device (`laser_origin`) (m): tal's usual `(-0.5, 0, 0.25)`.
pub const DEFAULT_LASER_ORIGIN: [f64; 3] = [-0.5, 0.0, 0.25];
/// Default position of the sensor device (`sensor_origin`) (m): tal's usual `(-0.5, 0, 0.25)`.
pub const DEFAULT_SENSOR_ORIGIN: [f64; 3] = [-0.5, 0.0, 0.25];
/// Default samples per side of a patch or box face.
pub const DEFAULT_SAMPLES: usize = 4;
/// Largest `samples` per side accepted.
pub const MAX_SAMPLES: usize = 1024;
/// Largest total number of surface sample points of a scene.
pub const MAX_POINTS: usize = 100_000;
/// Largest total number of surface sample points of a scene rendered with 5-vertex paths (a
/// laser row keeps every 2-bounce path: up to P² of them).
pub const MAX_POINTS_5: usize = 2048;
/// Largest number of spots in a laser or SPAD aperture.
pub const MAX_SPOTS: usize = 1 << 20;
/// Largest number of histogram values (`Kl·Ks·Nt`) of a rendered capture (16 GiB of f32).
pub const MAX_VALUES: usize = 1 << 32;
/// Largest `peak_counts` / `background` accepted for Poisson noise.
pub const MAX_COUNTS: f64 = 1e15;

/// The name used in errors about scenes built in code.
const IN_CODE: &str = "<scene>";

// ---------------------------------------------------------------------------------------------
// scene description
// ---------------------------------------------------------------------------------------------

/// A simulated capture: setup, rendering options and hidden objects (the scene file).
///
/// Deserialises from the JSON format of the [module documentation](self); build one in code
/// with [`Scene::new`] and [`Scene::with`] or by filling the public fields.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Free text, ignored (for the scene file's reader).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
    /// Apertures, time axis and device positions.
    pub setup: Setup,
    /// Standard deviation of the Gaussian laser pulse (m of path); `None`: `setup.dt`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pulse_sigma: Option<f64>,
    /// Which paths to render.
    #[serde(default)]
    pub bounces: Bounces,
    /// Longest path rendered, in vertices (3, 4 or 5; wall spots included).
    #[serde(default = "default_max_vertices")]
    pub max_vertices: usize,
    /// Lambertian cosine factors at the wall and at oriented surfaces.
    #[serde(default = "default_true")]
    pub cosines: bool,
    /// Poisson noise applied by [`Scene::render`]; `None`: noise-free.
    #[serde(default)]
    pub noise: Option<Noise>,
    /// The hidden objects.
    pub objects: Vec<Object>,
}

fn default_max_vertices() -> usize {
    4
}
fn default_true() -> bool {
    true
}
fn default_laser_origin() -> [f64; 3] {
    DEFAULT_LASER_ORIGIN
}
fn default_sensor_origin() -> [f64; 3] {
    DEFAULT_SENSOR_ORIGIN
}
fn default_albedo() -> f64 {
    1.0
}
fn default_samples() -> usize {
    DEFAULT_SAMPLES
}

/// Which light paths a render includes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Bounces {
    /// Direct (3-vertex) and indirect paths up to `max_vertices`.
    #[default]
    All,
    /// 3-vertex paths `x_l → p → x_s` only.
    Direct,
    /// 4- (and, with `max_vertices` 5, 5-) vertex paths only.
    Indirect,
}

/// Capture setup: laser and SPAD spots on the wall, time axis, device positions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Setup {
    /// Laser spots.
    pub lasers: Aperture,
    /// SPAD spots; `None` only for a confocal setup (then the laser spots).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spads: Option<Aperture>,
    /// Confocal capture: one histogram per laser row, SPAD at the laser spot.
    #[serde(default)]
    pub confocal: bool,
    /// Bins per histogram (≥ 1).
    pub nt: usize,
    /// Bin width (m of path) (> 0).
    pub dt: f64,
    /// Path length of bin 0 (m).
    #[serde(default)]
    pub t0: f64,
    /// Laser device position (m) (y-tal `laser_xyz`).
    #[serde(default = "default_laser_origin")]
    pub laser_origin: [f64; 3],
    /// Sensor device position (m) (y-tal `sensor_xyz`).
    #[serde(default = "default_sensor_origin")]
    pub sensor_origin: [f64; 3],
    /// Whether path times include the device legs `d1`, `d4`.
    #[serde(default)]
    pub legs_in_time: bool,
}

impl Setup {
    /// A non-confocal setup with `t0 = 0`, default device positions and no legs in time.
    pub fn new(lasers: Aperture, spads: Aperture, nt: usize, dt: f64) -> Self {
        Self {
            lasers,
            spads: Some(spads),
            confocal: false,
            nt,
            dt,
            t0: 0.0,
            laser_origin: DEFAULT_LASER_ORIGIN,
            sensor_origin: DEFAULT_SENSOR_ORIGIN,
            legs_in_time: false,
        }
    }

    /// A confocal setup (SPAD at each laser spot), otherwise as [`Setup::new`].
    pub fn confocal(lasers: Aperture, nt: usize, dt: f64) -> Self {
        Self {
            spads: None,
            confocal: true,
            ..Self::new(lasers.clone(), lasers, nt, dt)
        }
    }
}

/// Spots on the relay wall: a regular grid or an explicit list.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RawAperture", into = "RawAperture")]
pub enum Aperture {
    /// `shape[0] × shape[1]` spots on the wall z = 0 over a `size[0] × size[1]` rectangle
    /// centred at `center`, inclusive end points, C order over (x, y).
    Grid {
        /// Spots along x and y.
        shape: [usize; 2],
        /// Extent along x and y (m) (ignored on an axis with one spot).
        size: [f64; 2],
        /// Centre (x, y) (m).
        center: [f64; 2],
    },
    /// Explicit spots, with the grid shape they are flattened from (C order).
    Points {
        /// The spots (m).
        points: Vec<[f64; 3]>,
        /// Grid shape `[nx, ny]` with `nx·ny = points.len()` (`[K, 1]` for a plain list).
        shape: [usize; 2],
    },
}

impl Aperture {
    /// A wall grid (see [`Aperture::Grid`]).
    pub fn grid(shape: [usize; 2], size: [f64; 2], center: [f64; 2]) -> Self {
        Self::Grid {
            shape,
            size,
            center,
        }
    }

    /// An explicit list of spots, shape `[K, 1]`.
    pub fn points(points: Vec<[f64; 3]>) -> Self {
        let shape = [points.len(), 1];
        Self::Points { points, shape }
    }

    /// The grid shape `[nx, ny]`.
    pub fn shape(&self) -> [usize; 2] {
        match self {
            Self::Grid { shape, .. } | Self::Points { shape, .. } => *shape,
        }
    }

    /// The spots, C order over the shape (empty for a grid with a zero dimension).
    pub fn spots(&self) -> Vec<[f64; 3]> {
        match self {
            Self::Grid {
                shape,
                size,
                center,
            } => {
                let axis = |n: usize, size: f64, c: f64| -> Vec<f64> {
                    if n == 0 {
                        return Vec::new();
                    }
                    if n == 1 {
                        return vec![c];
                    }
                    // np.linspace(-size/2, size/2, n) + c
                    let step = size / (n - 1) as f64;
                    (0..n)
                        .map(|i| {
                            let v = if i == n - 1 {
                                size / 2.0
                            } else {
                                -size / 2.0 + i as f64 * step
                            };
                            v + c
                        })
                        .collect()
                };
                let xs = axis(shape[0].min(MAX_SPOTS), size[0], center[0]);
                let ys = axis(shape[1].min(MAX_SPOTS), size[1], center[1]);
                if xs.len() * ys.len() > MAX_SPOTS {
                    return Vec::new();
                }
                xs.iter()
                    .flat_map(|&x| ys.iter().map(move |&y| [x, y, 0.0]))
                    .collect()
            }
            Self::Points { points, .. } => points.clone(),
        }
    }

    fn validate(&self, path: &Path, field: &str) -> Result<()> {
        match self {
            Self::Grid {
                shape,
                size,
                center,
            } => {
                if shape[0] == 0 || shape[1] == 0 || shape[0].saturating_mul(shape[1]) > MAX_SPOTS {
                    return Err(Error::format(
                        path,
                        &format!("{field}.grid"),
                        format!("1 to {MAX_SPOTS} spots, at least one per axis"),
                        format!("{shape:?}"),
                    ));
                }
                for axis in 0..2 {
                    let ok = size[axis].is_finite() && (shape[axis] == 1 || size[axis] > 0.0);
                    if !ok {
                        return Err(Error::format(
                            path,
                            &format!("{field}.size"),
                            "finite extents, > 0 on axes with more than one spot",
                            format!("{size:?}"),
                        ));
                    }
                }
                if !all_finite(center) {
                    return Err(Error::format(
                        path,
                        &format!("{field}.center"),
                        "finite coordinates",
                        format!("{center:?}"),
                    ));
                }
            }
            Self::Points { points, shape } => {
                if points.is_empty() || points.len() > MAX_SPOTS {
                    return Err(Error::format(
                        path,
                        &format!("{field}.points"),
                        format!("1 to {MAX_SPOTS} spots"),
                        points.len(),
                    ));
                }
                if let Some(i) = points.iter().position(|p| !all_finite(p)) {
                    return Err(Error::format(
                        path,
                        &format!("{field}.points[{i}]"),
                        "finite coordinates",
                        format!("{:?}", points[i]),
                    ));
                }
                if shape[0].checked_mul(shape[1]) != Some(points.len()) {
                    return Err(Error::format(
                        path,
                        &format!("{field}.shape"),
                        format!("a shape of {} spots", points.len()),
                        format!("{shape:?}"),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// The JSON form of an [`Aperture`] (all fields optional, checked in `try_from`).
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAperture {
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "opt_scalar_or_array"
    )]
    grid: Option<[f64; 2]>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "opt_scalar_or_array"
    )]
    size: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    center: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    points: Option<Vec<[f64; 3]>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    shape: Option<[usize; 2]>,
}

impl TryFrom<RawAperture> for Aperture {
    type Error = String;
    fn try_from(raw: RawAperture) -> Result<Self, String> {
        match (raw.grid, raw.points) {
            (Some(grid), None) => {
                if raw.shape.is_some() {
                    return Err(
                        "a grid aperture takes `grid`, `size` and `center`, not `shape`".into(),
                    );
                }
                let count = |v: f64| -> Result<usize, String> {
                    if v.fract() == 0.0 && (0.0..=MAX_SPOTS as f64).contains(&v) {
                        Ok(v as usize)
                    } else {
                        Err(format!(
                            "`grid` must hold whole numbers of spots (0..{MAX_SPOTS}), found {v}"
                        ))
                    }
                };
                Ok(Self::Grid {
                    shape: [count(grid[0])?, count(grid[1])?],
                    size: raw.size.unwrap_or([0.0; 2]),
                    center: raw.center.unwrap_or([0.0; 2]),
                })
            }
            (None, Some(points)) => {
                if raw.size.is_some() || raw.center.is_some() {
                    return Err(
                        "a point-list aperture takes `points` and `shape`, not `size`/`center`"
                            .into(),
                    );
                }
                let shape = raw.shape.unwrap_or([points.len(), 1]);
                Ok(Self::Points { points, shape })
            }
            _ => Err(
                "an aperture needs exactly one of `grid` (with `size`, `center`) or `points` \
                      (with `shape`)"
                    .into(),
            ),
        }
    }
}

impl From<Aperture> for RawAperture {
    fn from(a: Aperture) -> Self {
        match a {
            Aperture::Grid {
                shape,
                size,
                center,
            } => Self {
                grid: Some([shape[0] as f64, shape[1] as f64]),
                size: Some(size),
                center: Some(center),
                points: None,
                shape: None,
            },
            Aperture::Points { points, shape } => Self {
                grid: None,
                size: None,
                center: None,
                points: Some(points),
                shape: Some(shape),
            },
        }
    }
}

/// Poisson photon noise (see the [module documentation](self#noise)).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    /// Expected count of the largest bin of the noise-free capture (> 0).
    pub peak_counts: f64,
    /// Expected background counts added to every bin (≥ 0).
    #[serde(default)]
    pub background: f64,
    /// Random seed.
    #[serde(default)]
    pub seed: u64,
}

impl Noise {
    fn validate(&self, path: &Path, field: &str) -> Result<()> {
        if !(self.peak_counts.is_finite()
            && self.peak_counts > 0.0
            && self.peak_counts <= MAX_COUNTS)
        {
            return Err(Error::format(
                path,
                &format!("{field}.peak_counts"),
                format!("a value in (0, {MAX_COUNTS:e}]"),
                self.peak_counts,
            ));
        }
        if !(self.background.is_finite() && self.background >= 0.0 && self.background <= MAX_COUNTS)
        {
            return Err(Error::format(
                path,
                &format!("{field}.background"),
                format!("a value in [0, {MAX_COUNTS:e}]"),
                self.background,
            ));
        }
        Ok(())
    }

    /// Replaces the noise-free histograms `data` (laser rows of `row_len` values) by Poisson
    /// counts: expected value `data·peak_counts/max(data) + background` (negative and
    /// non-finite values count as 0). Row `l` uses its own seeded generator, so the result does
    /// not depend on the number of threads.
    ///
    /// # Errors
    /// [`Error::Format`] (naming `<noise>` and the field) for out-of-range parameters,
    /// [`Error::Argument`] for `row_len` = 0.
    pub fn apply(&self, data: &mut [f32], row_len: usize) -> Result<()> {
        self.validate(Path::new("<noise>"), "noise")?;
        if row_len == 0 {
            return Err(Error::arg("row_len", "expected at least one value per row"));
        }
        let max = data
            .iter()
            .filter(|v| v.is_finite())
            .fold(0.0f32, |m, &v| m.max(v));
        let scale = if max > 0.0 {
            self.peak_counts / f64::from(max)
        } else {
            0.0
        };
        let (seed, background) = (self.seed, self.background);
        data.par_chunks_mut(row_len)
            .enumerate()
            .for_each(|(l, row)| {
                let mut rng = StdRng::seed_from_u64(
                    seed.wrapping_add((l as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)),
                );
                for v in row {
                    let h = f64::from(*v);
                    let lambda = if h.is_finite() && h > 0.0 {
                        h * scale
                    } else {
                        0.0
                    } + background;
                    *v = if lambda > 0.0 {
                        match Poisson::new(lambda) {
                            Ok(p) => p.sample(&mut rng) as f32,
                            Err(_) => lambda as f32,
                        }
                    } else {
                        0.0
                    };
                }
            });
        Ok(())
    }
}

/// A hidden object.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum Object {
    /// A sampled rectangle (`"type": "patch"`).
    Patch(Patch),
    /// A box of 6 patches, axis-aligned or turned (`"type": "box"`).
    Box(Cuboid),
    /// One point scatterer (`"type": "point"`).
    Point(PointScatterer),
}

impl Object {
    /// The object's name (empty if unnamed).
    pub fn name(&self) -> &str {
        match self {
            Self::Patch(o) => &o.name,
            Self::Box(o) => &o.name,
            Self::Point(o) => &o.name,
        }
    }

    /// The object's centre (m).
    pub fn center(&self) -> [f64; 3] {
        match self {
            Self::Patch(o) => o.center,
            Self::Box(o) => o.center,
            Self::Point(o) => o.center,
        }
    }

    /// The surface samples of the object, with `group` set to `group`.
    pub fn samples(&self, group: usize) -> Vec<SamplePoint> {
        match self {
            Self::Patch(p) => {
                let n = unit(p.normal);
                sample_rect(p.center, n, p.size, p.samples, p.albedo, group)
            }
            Self::Box(b) => box_faces(b)
                .into_iter()
                .flat_map(|(c, n, sides, size)| {
                    sample_rect_along(c, n, sides, size, b.samples, b.albedo, group)
                })
                .collect(),
            Self::Point(p) => vec![SamplePoint {
                position: p.center,
                normal: p.normal.map(unit),
                area: p.area,
                albedo: p.albedo,
                group,
            }],
        }
    }

    fn sample_count(&self) -> usize {
        match self {
            Self::Patch(p) => p.samples.saturating_mul(p.samples),
            Self::Box(b) => b.samples.saturating_mul(b.samples).saturating_mul(6),
            Self::Point(_) => 1,
        }
    }

    fn validate(&self, path: &Path, i: usize) -> Result<()> {
        let f = |name: &str| format!("objects[{i}].{name}");
        let (center, albedo) = (self.center(), self.albedo());
        if !all_finite(&center) {
            return Err(Error::format(
                path,
                &f("center"),
                "finite coordinates",
                format!("{center:?}"),
            ));
        }
        if !(albedo.is_finite() && (0.0..=1.0).contains(&albedo)) {
            return Err(Error::format(
                path,
                &f("albedo"),
                "a value in [0, 1]",
                albedo,
            ));
        }
        let check_samples = |n: usize| {
            if (1..=MAX_SAMPLES).contains(&n) {
                Ok(())
            } else {
                Err(Error::format(
                    path,
                    &f("samples"),
                    format!("1 to {MAX_SAMPLES} per side"),
                    n,
                ))
            }
        };
        let positive = |v: &[f64]| v.iter().all(|x| x.is_finite() && *x > 0.0);
        let check_normal = |n: &[f64; 3]| {
            let len = dot(*n, *n).sqrt();
            if all_finite(n) && len > 0.0 && len.is_finite() {
                Ok(())
            } else {
                Err(Error::format(
                    path,
                    &f("normal"),
                    "a finite non-zero vector",
                    format!("{n:?}"),
                ))
            }
        };
        // Lowest z of the object, to check it is in front of the wall.
        let low = match self {
            Self::Patch(p) => {
                check_normal(&p.normal)?;
                if !positive(&p.size) {
                    return Err(Error::format(
                        path,
                        &f("size"),
                        "sides > 0",
                        format!("{:?}", p.size),
                    ));
                }
                check_samples(p.samples)?;
                let (a, b) = tangents(unit(p.normal));
                let mut low = f64::INFINITY;
                for (su, sv) in [(-0.5, -0.5), (-0.5, 0.5), (0.5, -0.5), (0.5, 0.5)] {
                    low = low.min(center[2] + su * p.size[0] * a[2] + sv * p.size[1] * b[2]);
                }
                low
            }
            Self::Box(b) => {
                if !positive(&b.size) {
                    return Err(Error::format(
                        path,
                        &f("size"),
                        "sides > 0",
                        format!("{:?}", b.size),
                    ));
                }
                check_samples(b.samples)?;
                if let Some(n) = &b.normal {
                    check_normal(n)?;
                }
                b.corners().iter().fold(f64::INFINITY, |m, c| m.min(c[2]))
            }
            Self::Point(p) => {
                if let Some(n) = &p.normal {
                    check_normal(n)?;
                }
                if !(p.area.is_finite() && p.area > 0.0) {
                    return Err(Error::format(path, &f("area"), "a value > 0", p.area));
                }
                center[2]
            }
        };
        if low.is_nan() || low <= 0.0 {
            return Err(Error::format(
                path,
                &f("center"),
                "an object in front of the wall (z > 0 everywhere)",
                format!("an object reaching z = {low}"),
            ));
        }
        Ok(())
    }

    fn albedo(&self) -> f64 {
        match self {
            Self::Patch(o) => o.albedo,
            Self::Box(o) => o.albedo,
            Self::Point(o) => o.albedo,
        }
    }
}

/// A rectangle sampled by `samples × samples` points at its cell centres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Patch {
    /// Name (optional, unique in the scene).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub name: String,
    /// Centre (m).
    pub center: [f64; 3],
    /// Normal (normalised when sampled).
    pub normal: [f64; 3],
    /// Sides `[w, h]` (m) along the tangents `a`, `b` (module docs); one number in JSON for a
    /// square.
    #[serde(deserialize_with = "scalar_or_array")]
    pub size: [f64; 2],
    /// Albedo in [0, 1].
    #[serde(default = "default_albedo")]
    pub albedo: f64,
    /// Samples per side.
    #[serde(default = "default_samples")]
    pub samples: usize,
}

impl Patch {
    /// A patch with albedo 1 and [`DEFAULT_SAMPLES`] samples per side.
    pub fn new(name: &str, center: [f64; 3], normal: [f64; 3], size: [f64; 2]) -> Self {
        Self {
            name: name.into(),
            center,
            normal,
            size,
            albedo: 1.0,
            samples: DEFAULT_SAMPLES,
        }
    }
}

/// A box: 6 faces with outward normals, each sampled `samples × samples`; axis-aligned unless
/// `normal` turns it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cuboid {
    /// Name (optional, unique in the scene).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub name: String,
    /// Centre (m).
    pub center: [f64; 3],
    /// Sides `[sx, sy, sz]` (m) along the box's own axes; one number in JSON for a cube.
    #[serde(deserialize_with = "scalar_or_array")]
    pub size: [f64; 3],
    /// Outward normal of the box's front face (any non-zero length); `None` (default): the
    /// axis-aligned box, whose front face (−z) faces the wall. The box's axes are
    /// `(a, −b, −n̂)`, with `(a, b)` the tangents of `n̂` (the patches' convention), so
    /// `[0, 0, −1]` is the axis-aligned box and e.g. `[1, 0, −1]` turns it 45° about y.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normal: Option<[f64; 3]>,
    /// Albedo in [0, 1].
    #[serde(default = "default_albedo")]
    pub albedo: f64,
    /// Samples per side of each face.
    #[serde(default = "default_samples")]
    pub samples: usize,
}

impl Cuboid {
    /// An axis-aligned box with albedo 1 and [`DEFAULT_SAMPLES`] samples per face side.
    pub fn new(name: &str, center: [f64; 3], size: [f64; 3]) -> Self {
        Self {
            name: name.into(),
            center,
            size,
            normal: None,
            albedo: 1.0,
            samples: DEFAULT_SAMPLES,
        }
    }

    /// The box's unit axes (local x, y, z): the world axes, or `(a, −b, −n̂)` for a `normal`.
    pub fn axes(&self) -> [[f64; 3]; 3] {
        match self.normal {
            None => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            Some(n) => {
                let n = unit(n);
                let (a, b) = tangents(n);
                [a, b.map(|c| -c), n.map(|c| -c)]
            }
        }
    }

    /// The 8 corners (m).
    pub fn corners(&self) -> [[f64; 3]; 8] {
        let u = self.axes();
        core::array::from_fn(|i| {
            let s = [i & 1, (i >> 1) & 1, (i >> 2) & 1].map(|b| if b == 1 { 0.5 } else { -0.5 });
            [0, 1, 2].map(|k| {
                self.center[k] + (0..3).map(|j| s[j] * self.size[j] * u[j][k]).sum::<f64>()
            })
        })
    }
}

/// One point scatterer standing for a small surface of `area` (sim.py `point_scene`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointScatterer {
    /// Name (optional, unique in the scene).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub name: String,
    /// Position (m).
    pub center: [f64; 3],
    /// Area it stands for (m²).
    pub area: f64,
    /// Albedo in [0, 1].
    #[serde(default = "default_albedo")]
    pub albedo: f64,
    /// Normal for the cosine factors; `None`: isotropic.
    #[serde(default)]
    pub normal: Option<[f64; 3]>,
}

impl PointScatterer {
    /// An isotropic point scatterer with albedo 1.
    pub fn new(name: &str, center: [f64; 3], area: f64) -> Self {
        Self {
            name: name.into(),
            center,
            area,
            albedo: 1.0,
            normal: None,
        }
    }
}

impl From<Patch> for Object {
    fn from(o: Patch) -> Self {
        Self::Patch(o)
    }
}
impl From<Cuboid> for Object {
    fn from(o: Cuboid) -> Self {
        Self::Box(o)
    }
}
impl From<PointScatterer> for Object {
    fn from(o: PointScatterer) -> Self {
        Self::Point(o)
    }
}

/// One surface sample of an object: what the renderer works with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplePoint {
    /// Position (m).
    pub position: [f64; 3],
    /// Unit normal, or `None` (isotropic).
    pub normal: Option<[f64; 3]>,
    /// Area it carries (m²).
    pub area: f64,
    /// Albedo.
    pub albedo: f64,
    /// Index of its object in [`Scene::objects`]: inter-reflections only link different groups.
    pub group: usize,
}

impl Scene {
    /// A scene with `setup`, no objects and the default options (pulse σ = dt, all bounces up to
    /// 4 vertices, cosines, no noise).
    pub fn new(setup: Setup) -> Self {
        Self {
            description: String::new(),
            setup,
            pulse_sigma: None,
            bounces: Bounces::All,
            max_vertices: default_max_vertices(),
            cosines: true,
            noise: None,
            objects: Vec::new(),
        }
    }

    /// Adds an object (builder style).
    #[must_use]
    pub fn with(mut self, object: impl Into<Object>) -> Self {
        self.objects.push(object.into());
        self
    }

    /// Parses and validates a scene from JSON; `path` names the origin in errors.
    ///
    /// # Errors
    /// [`Error::Format`] naming `path` and the field: malformed JSON, unknown fields or object
    /// types, and every check of [`Scene::validate`].
    pub fn from_json_str(json: &str, path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let scene: Self = serde_json::from_str(json)
            .map_err(|e| Error::format(path, "scene", "a vltm scene file (see `vltm::sim`)", e))?;
        scene.validate(path)?;
        Ok(scene)
    }

    /// Reads, parses and validates a scene file.
    ///
    /// # Errors
    /// [`Error::Io`] if the file cannot be read, else as [`Scene::from_json_str`].
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let json = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::from_json_str(&json, path)
    }

    /// The standard deviation of the pulse (m): `pulse_sigma`, or `setup.dt` when unset.
    pub fn pulse_sigma(&self) -> f64 {
        self.pulse_sigma.unwrap_or(self.setup.dt)
    }

    /// Checks every field (see the module documentation); `path` names the origin in errors.
    ///
    /// # Errors
    /// [`Error::Format`] naming `path` and the offending field.
    pub fn validate(&self, path: &Path) -> Result<()> {
        let s = &self.setup;
        s.lasers.validate(path, "setup.lasers")?;
        match (&s.spads, s.confocal) {
            (Some(spads), confocal) => {
                spads.validate(path, "setup.spads")?;
                if confocal
                    && (spads.spots() != s.lasers.spots() || spads.shape() != s.lasers.shape())
                {
                    return Err(Error::format(
                        path,
                        "setup.spads",
                        "the laser spots (confocal setup) or no `spads`",
                        "different spots",
                    ));
                }
            }
            (None, false) => {
                return Err(Error::format(
                    path,
                    "setup.spads",
                    "SPAD spots (the setup is not confocal)",
                    "none",
                ));
            }
            (None, true) => {}
        }
        if s.nt == 0 {
            return Err(Error::format(path, "setup.nt", "at least 1 bin", 0));
        }
        if !(s.dt.is_finite() && s.dt > 0.0) {
            return Err(Error::format(path, "setup.dt", "a finite value > 0", s.dt));
        }
        if !s.t0.is_finite() {
            return Err(Error::format(path, "setup.t0", "a finite value", s.t0));
        }
        for (name, o) in [
            ("setup.laser_origin", &s.laser_origin),
            ("setup.sensor_origin", &s.sensor_origin),
        ] {
            if !all_finite(o) {
                return Err(Error::format(
                    path,
                    name,
                    "finite coordinates",
                    format!("{o:?}"),
                ));
            }
        }
        let kl = shape_len(s.lasers.shape());
        let ks = if s.confocal {
            1
        } else {
            s.spads.as_ref().map_or(0, |a| shape_len(a.shape()))
        };
        let values = kl.checked_mul(ks).and_then(|v| v.checked_mul(s.nt));
        if values.is_none_or(|v| v > MAX_VALUES) {
            return Err(Error::format(
                path,
                "setup.nt",
                format!("at most {MAX_VALUES} histogram values (lasers × SPADs × nt)"),
                format!("{kl} × {ks} × {}", s.nt),
            ));
        }
        let sigma = self.pulse_sigma();
        if !(sigma.is_finite() && sigma > 0.0 && sigma / s.dt <= 1e6) {
            return Err(Error::format(
                path,
                "pulse_sigma",
                "a finite value > 0 (at most 10⁶ bins)",
                sigma,
            ));
        }
        if !(3..=5).contains(&self.max_vertices) {
            return Err(Error::format(
                path,
                "max_vertices",
                "3, 4 or 5",
                self.max_vertices,
            ));
        }
        if self.bounces == Bounces::Indirect && self.max_vertices < 4 {
            return Err(Error::format(
                path,
                "max_vertices",
                "4 or 5 for `\"bounces\": \"indirect\"`",
                self.max_vertices,
            ));
        }
        if let Some(noise) = &self.noise {
            noise.validate(path, "noise")?;
        }
        let mut points = 0usize;
        for (i, o) in self.objects.iter().enumerate() {
            o.validate(path, i)?;
            if !o.name().is_empty() && self.objects[..i].iter().any(|p| p.name() == o.name()) {
                return Err(Error::format(
                    path,
                    &format!("objects[{i}].name"),
                    "a unique name",
                    format!("a second `{}`", o.name()),
                ));
            }
            points = points.saturating_add(o.sample_count());
        }
        if points > MAX_POINTS {
            return Err(Error::format(
                path,
                "objects",
                format!("at most {MAX_POINTS} surface samples in total"),
                points,
            ));
        }
        if points > MAX_POINTS_5 && self.max_vertices == 5 && self.bounces != Bounces::Direct {
            return Err(Error::format(
                path,
                "max_vertices",
                format!("at most 4 with more than {MAX_POINTS_5} surface samples"),
                format!("5 with {points} samples"),
            ));
        }
        Ok(())
    }

    /// The capture geometry of the setup (spots rounded to `f32`, as the kernel sees them).
    /// Does not validate: an invalid setup gives a geometry that [`Geometry::validate`] rejects.
    pub fn geometry(&self) -> Geometry {
        let s = &self.setup;
        let to_f32 =
            |v: Vec<[f64; 3]>| -> Vec<Point> { v.iter().map(|p| p.map(|c| c as f32)).collect() };
        let lasers = to_f32(s.lasers.spots());
        let (spads, spad_shape) = match (&s.spads, s.confocal) {
            (Some(a), false) => (to_f32(a.spots()), a.shape()),
            _ => (lasers.clone(), s.lasers.shape()),
        };
        Geometry {
            lasers,
            laser_shape: s.lasers.shape(),
            spads,
            spad_shape,
            laser_origin: s.laser_origin,
            sensor_origin: s.sensor_origin,
            legs_in_time: s.legs_in_time,
            confocal: s.confocal,
            nt: s.nt,
            dt: s.dt,
            t0: s.t0,
        }
    }

    /// All surface samples, object by object (group = object index). Does not validate.
    pub fn sample_points(&self) -> Vec<SamplePoint> {
        self.objects
            .iter()
            .enumerate()
            .flat_map(|(g, o)| o.samples(g))
            .collect()
    }

    /// The object called `name`.
    pub fn object(&self, name: &str) -> Option<&Object> {
        self.objects.iter().find(|o| o.name() == name)
    }

    /// The centre of the object called `name`, as a kernel point (the demo's ground truth).
    pub fn object_centre(&self, name: &str) -> Option<Point> {
        self.object(name).map(|o| o.center().map(|c| c as f32))
    }

    /// Validates the scene and precomputes what rendering rows needs (per-point distances and
    /// factors to every laser and SPAD spot). Use it to stream many rows.
    ///
    /// # Errors
    /// As [`Scene::validate`] (errors name `<scene>`).
    pub fn source(&self) -> Result<SceneSource> {
        self.validate(Path::new(IN_CODE))?;
        Ok(SceneSource::new(self))
    }

    /// Renders the whole capture (rows in parallel), with noise if `noise` is set.
    ///
    /// # Errors
    /// As [`Scene::validate`] (errors name `<scene>`).
    pub fn render(&self) -> Result<Capture> {
        self.render_with_progress(false)
    }

    /// [`Scene::render`] with a progress bar over the laser rows on stderr when `progress`
    /// (hidden when stderr is not a terminal).
    ///
    /// # Errors
    /// As [`Scene::render`].
    pub fn render_with_progress(&self, progress: bool) -> Result<Capture> {
        let src = self.source()?;
        let geometry = src.geometry.clone();
        let row_len = geometry.spads_per_row() * geometry.nt;
        let mut data = vec![0.0f32; geometry.lasers.len() * row_len];
        let exec = crate::ltm::Exec {
            progress,
            ..Default::default()
        };
        let bar = crate::ltm::progress_bar(exec, geometry.lasers.len(), "simulate");
        data.par_chunks_mut(row_len).enumerate().for_each_init(
            Scratch::default,
            |scratch, (l, out)| {
                src.tables.row(l, scratch, out);
                bar.inc(1);
            },
        );
        bar.finish_and_clear();
        if let Some(noise) = &self.noise {
            noise.apply(&mut data, row_len)?;
        }
        Capture::new(geometry, data, Path::new(IN_CODE))
    }

    /// Renders laser row `l` noise-free into `out` (resized to `spads_per_row·nt`, SPAD-major)
    /// and returns the laser spot. Precomputes the scene each call: to stream many rows use
    /// [`Scene::source`].
    ///
    /// # Errors
    /// As [`Scene::validate`]; [`Error::Argument`] if `l` is not a laser row.
    pub fn render_row(&self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        self.source()?.read_row(l, out)
    }
}

// ---------------------------------------------------------------------------------------------
// sampling
// ---------------------------------------------------------------------------------------------

fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|c| c.is_finite())
}

fn shape_len(s: [usize; 2]) -> usize {
    s[0].saturating_mul(s[1])
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = dot(v, v).sqrt();
    v.map(|c| c / n)
}

/// sim.py's patch tangents: `a = n × ŷ` (or `n × x̂` near ±ŷ), `b = n × a`.
fn tangents(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let a = if n[1].abs() < 0.9 {
        cross(n, [0.0, 1.0, 0.0])
    } else {
        cross(n, [1.0, 0.0, 0.0])
    };
    let a = unit(a);
    (a, cross(n, a))
}

/// `n × n` cell-centre samples of the rectangle `c + w·u·a + h·v·b` (sim.py `patch`).
fn sample_rect(
    c: [f64; 3],
    n: [f64; 3],
    size: [f64; 2],
    samples: usize,
    albedo: f64,
    group: usize,
) -> Vec<SamplePoint> {
    sample_rect_along(c, n, tangents(n), size, samples, albedo, group)
}

/// [`sample_rect`] with the rectangle's sides along `(a, b)` (unit, ⊥ `n`) instead of the
/// tangents of `n`.
fn sample_rect_along(
    c: [f64; 3],
    n: [f64; 3],
    (a, b): ([f64; 3], [f64; 3]),
    size: [f64; 2],
    samples: usize,
    albedo: f64,
    group: usize,
) -> Vec<SamplePoint> {
    let m = samples.max(1);
    let area = size[0] * size[1] / (m * m) as f64;
    let u = |i: usize| (i as f64 + 0.5) / m as f64 - 0.5;
    let mut out = Vec::with_capacity(m * m);
    for i in 0..m {
        for j in 0..m {
            let (su, sv) = (size[0] * u(i), size[1] * u(j));
            let position = [0, 1, 2].map(|k| c[k] + su * a[k] + sv * b[k]);
            out.push(SamplePoint {
                position,
                normal: Some(n),
                area,
                albedo,
                group,
            });
        }
    }
    out
}

/// A face of a box: centre, outward normal, the directions of its sides, their lengths.
type Face = ([f64; 3], [f64; 3], ([f64; 3], [f64; 3]), [f64; 2]);

/// The faces of a box, along its axes `u` (+u₀, −u₀, +u₁, −u₁, +u₂, −u₂): sides along sim.py's
/// tangents of the face normal for an axis-aligned box (as the reference), along the box's
/// other two axes for a turned one.
fn box_faces(b: &Cuboid) -> Vec<Face> {
    let u = b.axes();
    let mut faces = Vec::with_capacity(6);
    for axis in 0..3 {
        for sign in [1.0, -1.0] {
            let n = u[axis].map(|x| sign * x);
            let c = [0, 1, 2].map(|k| b.center[k] + sign * b.size[axis] / 2.0 * u[axis][k]);
            let (j, k) = ((axis + 1) % 3, (axis + 2) % 3);
            faces.push(if b.normal.is_none() {
                let (ta, tb) = tangents(n);
                let extent = |t: [f64; 3]| (0..3).map(|i| t[i].abs() * b.size[i]).sum::<f64>();
                (c, n, (ta, tb), [extent(ta), extent(tb)])
            } else {
                (c, n, (u[j], u[k]), [b.size[j], b.size[k]])
            });
        }
    }
    faces
}

// ---------------------------------------------------------------------------------------------
// rendering
// ---------------------------------------------------------------------------------------------

/// A validated scene prepared for rendering rows: implements [`RowSource`] (noise-free).
#[derive(Clone, Debug)]
pub struct SceneSource {
    geometry: Geometry,
    tables: Tables,
    scratch: Scratch,
}

impl SceneSource {
    fn new(scene: &Scene) -> Self {
        let geometry = scene.geometry();
        let tables = Tables::new(scene, &geometry);
        Self {
            geometry,
            tables,
            scratch: Scratch::default(),
        }
    }

    /// Number of surface sample points.
    pub fn points(&self) -> usize {
        self.tables.pts.len()
    }
}

impl RowSource for SceneSource {
    fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        let kl = self.geometry.lasers.len();
        if l >= kl {
            return Err(Error::arg(
                "row",
                format!("laser row {l} is out of range 0..{kl}"),
            ));
        }
        out.clear();
        out.resize(self.geometry.spads_per_row() * self.geometry.nt, 0.0);
        self.tables.row(l, &mut self.scratch, out);
        Ok(self.geometry.lasers[l])
    }
}

/// Per-thread scratch of the row renderer.
#[derive(Clone, Debug, Default)]
struct Scratch {
    /// Row accumulator, `ns × nt`, f64.
    acc: Vec<f64>,
    /// Light arriving at each point after two bounces: (time, amplitude incl. k of the point).
    second: Vec<Vec<(f64, f64)>>,
    /// Light arriving at the current end point.
    arrivals: Vec<(f64, f64)>,
    /// Paths arriving at the current end point pre-summed on the fine grid: (u0, F).
    fine: (i64, Vec<f64>),
}

/// Sampled Gaussian pulse (sim.py `_deposit`) on a grid of unit spacing: the histogram bins,
/// or the fine grid of [`FINE`] points per bin.
#[derive(Clone, Debug)]
struct Pulse {
    /// σ in grid steps.
    s: f64,
    /// 1/s².
    inv_s2: f64,
    /// Peak weight (1/(σ_bins·√(2π)) on both grids: unit sum over histogram bins).
    norm: f64,
    /// Half window in grid steps: ⌈6s⌉ + 1.
    r: usize,
    /// `c[k] = exp(−(2k+1)/(2s²))`: ratio of neighbouring weights (recurrence).
    c: Vec<f64>,
}

impl Pulse {
    fn new(s: f64, norm: f64) -> Self {
        let inv_s2 = 1.0 / (s * s);
        let r = (6.0 * s).ceil() as usize + 1;
        let c = (0..=r)
            .map(|k| (-((2 * k + 1) as f64) * 0.5 * inv_s2).exp())
            .collect();
        Self {
            s,
            inv_s2,
            norm,
            r,
            c,
        }
    }

    /// Adds `amp·norm·exp(−½((n − x)/s)²)` into `h[n]` for `n = round(x) ± r` (inside `h`).
    #[inline]
    fn deposit(&self, h: &mut [f64], x: f64, amp: f64) {
        let nt = h.len() as i64;
        let n0 = x.round_ties_even();
        let rf = self.r as f64;
        if !(n0 + rf >= 0.0 && n0 - rf < nt as f64) {
            return; // outside the window (or NaN)
        }
        let f = x - n0; // in [−½, ½]
        let n0 = n0 as i64;
        let r = self.r as i64;
        let a = amp * self.norm;
        if self.s >= 0.5 {
            // w_k = a·exp(−½(k − f)²/s²) by recurrence: w_{k+1} = w_k·c_k·e^{f/s²},
            // w_{−(m+1)} = w_{−m}·c_m·e^{−f/s²}. Every factor is bounded for s ≥ ½.
            let w0 = a * (-0.5 * f * f * self.inv_s2).exp();
            let up = (f * self.inv_s2).exp();
            let down = 1.0 / up;
            let mut w = w0;
            for k in 0..=r {
                let n = n0 + k;
                if n >= nt {
                    break;
                }
                if n >= 0 {
                    h[n as usize] += w;
                }
                w *= self.c[k as usize] * up;
            }
            let mut w = w0;
            for m in 0..r {
                w *= self.c[m as usize] * down;
                let n = n0 - 1 - m;
                if n < 0 {
                    break;
                }
                if n < nt {
                    h[n as usize] += w;
                }
            }
        } else {
            for k in -r..=r {
                let n = n0 + k;
                if (0..nt).contains(&n) {
                    let z = k as f64 - f;
                    h[n as usize] += a * (-0.5 * z * z * self.inv_s2).exp();
                }
            }
        }
    }
}

/// Fine-grid points per histogram bin for paths pre-summed at their end point.
const FINE: i64 = 32;

/// How the paths arriving at one end point are deposited (see [`Tables::row`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    /// Choose per end point by operation count.
    Auto,
    /// One sampled pulse per path and SPAD (exact sim.py `_deposit`).
    Direct,
    /// Pre-summed on the fine grid, interpolated per SPAD (pulses of σ ≥ 1 bin only).
    #[cfg_attr(not(test), allow(dead_code))]
    Fine,
}

/// Precomputed per-point quantities.
#[derive(Clone, Debug)]
struct Tables {
    pts: Vec<[f64; 3]>,
    nrm: Vec<Option<[f64; 3]>>,
    /// albedo·area/π.
    k: Vec<f64>,
    group: Vec<usize>,
    /// `[l][p]`: `d1_l + |x_l − p| − t0`.
    tl: Vec<f64>,
    /// `[l][p]`: laser-leg factor (cosines)/d².
    gl: Vec<f64>,
    /// `[p][s]`: `|p − x_s| + d4_s`.
    ts: Vec<f64>,
    /// `[p][s]`: SPAD-leg factor (cosines)/d².
    gs: Vec<f64>,
    ks: usize,
    confocal: bool,
    cosines: bool,
    direct: bool,
    four: bool,
    five: bool,
    nt: usize,
    inv_dt: f64,
    /// The pulse on the histogram bins.
    pulse: Pulse,
    /// The pulse on the fine grid (`None` if σ < 1 bin: then every deposit is direct).
    fine: Option<Pulse>,
    mode: Mode,
}

impl Tables {
    fn new(scene: &Scene, geo: &Geometry) -> Self {
        let samples = scene.sample_points();
        let pts: Vec<[f64; 3]> = samples.iter().map(|p| p.position).collect();
        let nrm: Vec<Option<[f64; 3]>> = samples.iter().map(|p| p.normal).collect();
        let k = samples
            .iter()
            .map(|p| p.albedo * p.area / std::f64::consts::PI)
            .collect();
        let group = samples.iter().map(|p| p.group).collect();
        let cosines = scene.cosines;
        let f64s = |v: &[Point]| -> Vec<[f64; 3]> { v.iter().map(|p| p.map(f64::from)).collect() };
        let (lasers, spads) = (f64s(&geo.lasers), f64s(&geo.spads));
        let dist = |a: [f64; 3], b: [f64; 3]| dot(sub(a, b), sub(a, b)).sqrt();
        let d1: Vec<f64> = lasers
            .iter()
            .map(|&x| {
                if geo.legs_in_time {
                    dist(x, geo.laser_origin)
                } else {
                    0.0
                }
            })
            .collect();
        let d4: Vec<f64> = spads
            .iter()
            .map(|&x| {
                if geo.legs_in_time {
                    dist(x, geo.sensor_origin)
                } else {
                    0.0
                }
            })
            .collect();
        // Leg wall spot x ↔ point p: distance and factor cos_wall·cos_p/d² (sim.py gl, gs).
        let leg = |x: [f64; 3], p: usize| -> (f64, f64) {
            let v = sub(pts[p], x);
            let d2 = dot(v, v);
            let d = d2.sqrt();
            if d2.is_nan() || d2 <= 0.0 {
                return (d, 0.0);
            }
            let mut g = 1.0 / d2;
            if cosines {
                g *= (v[2] / d).max(0.0);
                if let Some(n) = nrm[p] {
                    g *= (-dot(n, v) / d).max(0.0);
                }
            }
            (d, g)
        };
        let np = pts.len();
        let (mut tl, mut gl) = (vec![0.0; lasers.len() * np], vec![0.0; lasers.len() * np]);
        for (l, &x) in lasers.iter().enumerate() {
            for p in 0..np {
                let (d, g) = leg(x, p);
                tl[l * np + p] = d1[l] + d - geo.t0;
                gl[l * np + p] = g;
            }
        }
        let ks = spads.len();
        let (mut ts, mut gs) = (vec![0.0; ks * np], vec![0.0; ks * np]);
        for p in 0..np {
            for (s, &x) in spads.iter().enumerate() {
                let (d, g) = leg(x, p);
                ts[p * ks + s] = d + d4[s];
                gs[p * ks + s] = g;
            }
        }
        let s = scene.pulse_sigma() / geo.dt;
        let norm = 1.0 / (s * (2.0 * std::f64::consts::PI).sqrt());
        let (direct, indirect) = match scene.bounces {
            Bounces::All => (true, true),
            Bounces::Direct => (true, false),
            Bounces::Indirect => (false, true),
        };
        Self {
            pts,
            nrm,
            k,
            group,
            tl,
            gl,
            ts,
            gs,
            ks,
            confocal: geo.confocal,
            cosines,
            direct,
            four: indirect && scene.max_vertices >= 4,
            five: indirect && scene.max_vertices >= 5,
            nt: geo.nt,
            inv_dt: 1.0 / geo.dt,
            pulse: Pulse::new(s, norm),
            fine: (s >= 1.0).then(|| Pulse::new(s * FINE as f64, norm)),
            mode: Mode::Auto,
        }
    }

    /// The segment `i → j` between points of different objects: `(d_ij, factor/d_ij²)` with the
    /// cosines at both ends, or `None` if it carries no light.
    #[inline]
    fn link(&self, i: usize, j: usize) -> Option<(f64, f64)> {
        if self.group[i] == self.group[j] {
            return None;
        }
        let v = sub(self.pts[j], self.pts[i]);
        let d2 = dot(v, v);
        if d2.is_nan() || d2 <= 0.0 {
            return None;
        }
        let d = d2.sqrt();
        let mut g = 1.0 / d2;
        if self.cosines {
            if let Some(n) = self.nrm[i] {
                g *= (dot(n, v) / d).max(0.0);
            }
            if let Some(n) = self.nrm[j] {
                g *= (-dot(n, v) / d).max(0.0);
            }
        }
        (g > 0.0).then_some((d, g))
    }

    /// Renders laser row `l` (noise-free) into `out` (`spads_per_row·nt`).
    ///
    /// For every end point `j` (the last scattering point) the paths arriving there are
    /// collected as (time from the laser spot to `j`, amplitude up to `j`); each SPAD then sees
    /// them shifted by `|j − x_s| (+ d4)` and scaled by its leg factor.
    fn row(&self, l: usize, scratch: &mut Scratch, out: &mut [f32]) {
        let nt = self.nt;
        let np = self.pts.len();
        let spads = if self.confocal { l..l + 1 } else { 0..self.ks };
        let Scratch {
            acc,
            second,
            arrivals,
            fine,
        } = scratch;
        acc.clear();
        acc.resize(spads.len() * nt, 0.0);
        let tl = &self.tl[l * np..(l + 1) * np];
        let gl = &self.gl[l * np..(l + 1) * np];
        // Light leaving the laser spot and scattered once at p: (time, k_p·g_lp).
        let first = |p: usize| (tl[p], self.k[p] * gl[p]);
        // Light arriving at b after a → b: (time, k_a·g_la·g_ab·k_b) over every a.
        let push_second = |b: usize, into: &mut Vec<(f64, f64)>| {
            for a in 0..np {
                let (t, amp) = first(a);
                if amp == 0.0 {
                    continue;
                }
                if let Some((d, g)) = self.link(a, b) {
                    into.push((t + d, amp * g * self.k[b]));
                }
            }
        };
        if self.five {
            second.resize_with(np, Vec::new);
            for (b, list) in second.iter_mut().enumerate() {
                list.clear();
                push_second(b, list);
            }
        }
        for j in 0..np {
            arrivals.clear();
            if self.direct {
                let (t, amp) = first(j);
                if amp != 0.0 {
                    arrivals.push((t, amp));
                }
            }
            if self.five {
                arrivals.extend_from_slice(&second[j]);
                for (b, list) in second.iter().enumerate() {
                    if list.is_empty() {
                        continue;
                    }
                    if let Some((d, g)) = self.link(b, j) {
                        let f = g * self.k[j];
                        arrivals.extend(list.iter().map(|&(t, amp)| (t + d, amp * f)));
                    }
                }
            } else if self.four {
                push_second(j, arrivals);
            }
            if arrivals.is_empty() {
                continue;
            }
            let ts = &self.ts[j * self.ks..(j + 1) * self.ks];
            let gs = &self.gs[j * self.ks..(j + 1) * self.ks];
            if self.presum(arrivals, spads.len(), fine) {
                let (u0, fine) = (fine.0, &fine.1);
                let len = fine.len() as i64;
                for (h, s) in acc.chunks_exact_mut(nt).zip(spads.clone()) {
                    let g = gs[s];
                    if g != 0.0 {
                        interpolate(h, fine, u0, len, ts[s] * self.inv_dt, g);
                    }
                }
            } else {
                for (h, s) in acc.chunks_exact_mut(nt).zip(spads.clone()) {
                    let g = gs[s];
                    if g == 0.0 {
                        continue;
                    }
                    let t = ts[s];
                    for &(ta, amp) in arrivals.iter() {
                        self.pulse.deposit(h, (ta + t) * self.inv_dt, amp * g);
                    }
                }
            }
        }
        for (o, &a) in out.iter_mut().zip(acc.iter()) {
            *o = a as f32;
        }
    }

    /// Decides whether to pre-sum `arrivals` (for `ns` SPADs) on the fine grid and, if so,
    /// fills `fine = (u0, F)`: `F[k] = Σ_a amp_a·pulse(u0 + k/FINE − y_a)`, `y_a` the arrival
    /// time in bins, `u0` an integer bin. Pre-summing costs one fine-grid pulse per path, then
    /// a 4-tap interpolation per bin and SPAD, instead of one pulse per path and SPAD.
    fn presum(&self, arrivals: &[(f64, f64)], ns: usize, fine: &mut (i64, Vec<f64>)) -> bool {
        let Some(fp) = &self.fine else { return false };
        if self.mode == Mode::Direct || arrivals.len() < 2 {
            return false;
        }
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &(t, _) in arrivals {
            lo = lo.min(t * self.inv_dt);
            hi = hi.max(t * self.inv_dt);
        }
        let margin = self.pulse.r as f64 + 3.0;
        let span = hi - lo + 2.0 * margin + 1.0; // bins
        if !(span.is_finite() && span * (FINE as f64) < (1u64 << 20) as f64) {
            return false;
        }
        let (m, w, ns) = (
            arrivals.len() as f64,
            (2 * self.pulse.r + 1) as f64,
            ns as f64,
        );
        let direct = m * ns * (2.0 * w + 30.0);
        let presum = m * (2.0 * w * FINE as f64 + 30.0) + ns * (span + w) * 10.0;
        if self.mode == Mode::Auto && presum >= direct {
            return false;
        }
        let u0 = (lo - margin).floor() as i64;
        let len = ((hi + margin).ceil() as i64 - u0) * FINE + 1;
        fine.0 = u0;
        fine.1.clear();
        fine.1.resize(len as usize, 0.0);
        for &(t, amp) in arrivals {
            fp.deposit(
                &mut fine.1,
                (t * self.inv_dt - u0 as f64) * FINE as f64,
                amp,
            );
        }
        true
    }
}

/// Adds `g·F(n − z)` into every bin `n` of `h`, `F` sampled at `u0 + k/FINE` (length `len`),
/// by 4-point Lagrange interpolation. `z·FINE`'s fractional part is the same for every bin, so
/// the weights are computed once.
fn interpolate(h: &mut [f64], f: &[f64], u0: i64, len: i64, z: f64, g: f64) {
    let zq = z * FINE as f64;
    if !zq.is_finite() || zq.abs() > 1e15 {
        return;
    }
    let cz = zq.ceil();
    let t = cz - zq; // in [0, 1): F at fine index k + t
    let cz = cz as i64;
    let w = [
        -t * (t - 1.0) * (t - 2.0) / 6.0 * g,
        (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0 * g,
        -(t + 1.0) * t * (t - 2.0) / 2.0 * g,
        (t + 1.0) * t * (t - 1.0) / 6.0 * g,
    ];
    // Fine index of bin n: k = (n − u0)·FINE − cz; taps k−1 ..= k+2 inside 0..len.
    let lo = (u0 + (1 + cz + FINE - 1).div_euclid(FINE)).max(0);
    let hi = (u0 + (len - 3 + cz).div_euclid(FINE)).min(h.len() as i64 - 1);
    for n in lo..=hi {
        let k = ((n - u0) * FINE - cz) as usize;
        let v = w[0] * f[k - 1] + w[1] * f[k] + w[2] * f[k + 1] + w[3] * f[k + 2];
        h[n as usize] += v;
    }
}

// ---------------------------------------------------------------------------------------------
// serde helpers: one number or an array of N numbers
// ---------------------------------------------------------------------------------------------

struct ScalarOrArray<const N: usize>;

impl<'de, const N: usize> Visitor<'de> for ScalarOrArray<N> {
    type Value = [f64; N];

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a number or an array of {N} numbers")
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
        Ok([v; N])
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
        Ok([v as f64; N])
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
        Ok([v as f64; N])
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut out = [0.0; N];
        for (i, o) in out.iter_mut().enumerate() {
            *o = seq
                .next_element()?
                .ok_or_else(|| de::Error::invalid_length(i, &self))?;
        }
        if seq.next_element::<de::IgnoredAny>()?.is_some() {
            return Err(de::Error::invalid_length(N + 1, &self));
        }
        Ok(out)
    }
}

fn scalar_or_array<'de, D: Deserializer<'de>, const N: usize>(d: D) -> Result<[f64; N], D::Error> {
    d.deserialize_any(ScalarOrArray::<N>)
}

fn opt_scalar_or_array<'de, D: Deserializer<'de>, const N: usize>(
    d: D,
) -> Result<Option<[f64; N]>, D::Error> {
    scalar_or_array(d).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(pulse_bins: f64, max_vertices: usize) -> Scene {
        let mut scene = Scene::new(Setup::new(
            Aperture::grid([4, 3], [1.0, 0.8], [0.0, 0.0]),
            Aperture::grid([6, 6], [1.0, 1.0], [0.05, 0.0]),
            400,
            0.01,
        ))
        .with(Patch {
            samples: 3,
            ..Patch::new("A", [-0.3, 0.0, 0.6], [0.4, 0.0, -1.0], [0.2, 0.15])
        })
        .with(Patch {
            samples: 3,
            albedo: 0.5,
            ..Patch::new("B", [0.3, 0.1, 0.7], [-0.3, 0.0, -1.0], [0.2, 0.2])
        })
        .with(Cuboid {
            samples: 2,
            ..Cuboid::new("C", [0.0, -0.3, 0.9], [0.1, 0.1, 0.2])
        })
        .with(PointScatterer::new("P", [0.05, 0.3, 0.5], 0.01));
        scene.pulse_sigma = Some(pulse_bins * 0.01);
        scene.max_vertices = max_vertices;
        scene.setup.t0 = 0.3;
        scene
    }

    fn render_with(scene: &Scene, mode: Mode) -> Vec<f32> {
        let mut src = scene.source().unwrap();
        src.tables.mode = mode;
        let mut all = Vec::new();
        let mut row = Vec::new();
        for l in 0..src.geometry.lasers.len() {
            src.read_row(l, &mut row).unwrap();
            all.extend_from_slice(&row);
        }
        all
    }

    #[test]
    fn presummed_paths_match_direct_deposits() {
        for (pulse, max_vertices) in [(1.0, 4), (1.0, 5), (1.7, 5), (4.2, 4)] {
            let scene = scene(pulse, max_vertices);
            let direct = render_with(&scene, Mode::Direct);
            let fine = render_with(&scene, Mode::Fine);
            let auto = render_with(&scene, Mode::Auto);
            assert_eq!(auto, scene.render().unwrap().data);
            let peak = direct.iter().fold(0.0f32, |m, &v| m.max(v));
            for (name, other) in [("fine", &fine), ("auto", &auto)] {
                let worst = direct
                    .iter()
                    .zip(other)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0f32, f32::max);
                println!(
                    "σ = {pulse} bins, {max_vertices} vertices, {name}: {:.2e}",
                    worst / peak
                );
                assert!(
                    worst <= 2e-7 * peak,
                    "σ = {pulse} bins, {max_vertices} vertices, {name}: {:.2e}",
                    worst / peak
                );
            }
            // The indirect part alone, relative to its own peak.
            let mut indirect = scene.clone();
            indirect.bounces = Bounces::Indirect;
            let (d, f) = (
                render_with(&indirect, Mode::Direct),
                render_with(&indirect, Mode::Fine),
            );
            let peak = d.iter().fold(0.0f32, |m, &v| m.max(v));
            assert!(peak > 0.0);
            let worst = d
                .iter()
                .zip(&f)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            println!(
                "σ = {pulse} bins, {max_vertices} vertices, indirect only, fine: {:.2e}",
                worst / peak
            );
            assert!(
                worst <= 1e-6 * peak,
                "indirect, σ = {pulse} bins: {:.2e}",
                worst / peak
            );
        }
    }

    #[test]
    fn pulse_recurrence_matches_the_formula() {
        for s in [0.3, 0.5, 0.9, 1.0, 1.5, 7.3, 40.0] {
            let norm = 1.0 / (s * (2.0 * std::f64::consts::PI).sqrt());
            let p = Pulse::new(s, norm);
            for x in [150.0, 150.5, 150.49, 151.37, 3.2, 296.8, -2.0] {
                let mut h = vec![0.0; 300];
                p.deposit(&mut h, x, 2.0);
                let n0 = f64::round_ties_even(x);
                for (n, &v) in h.iter().enumerate() {
                    let inside = (n as f64 - n0).abs() <= p.r as f64;
                    let want = if inside {
                        2.0 * norm * (-0.5 * ((n as f64 - x) / s).powi(2)).exp()
                    } else {
                        0.0
                    };
                    assert!(
                        (v - want).abs() <= 1e-12 * 2.0 * norm,
                        "s {s} x {x} n {n}: {v} vs {want}"
                    );
                }
                if s >= 1.0 && (20.0..280.0).contains(&x) && s < 10.0 {
                    // Unit sum up to the aliasing term 2·exp(−2π²s²) (1e-8 at s = 1).
                    assert!(
                        (h.iter().sum::<f64>() - 2.0).abs() < 2e-7,
                        "unit sum, s {s}"
                    );
                }
            }
        }
    }

    #[test]
    fn scenes_round_trip_through_json() {
        let mut scene = scene(1.3, 5);
        scene.noise = Some(Noise {
            peak_counts: 300.0,
            background: 0.1,
            seed: 3,
        });
        scene.pulse_sigma = Some(0.013); // (serde_json's float parsing may be 1 ulp off)
        scene.setup.spads = Some(Aperture::points(vec![[0.1, 0.0, 0.0], [0.2, 0.1, 0.0]]));
        scene.description = "round trip".into();
        let json = serde_json::to_string_pretty(&scene).unwrap();
        assert_eq!(Scene::from_json_str(&json, "rt.json").unwrap(), scene);
    }
}
