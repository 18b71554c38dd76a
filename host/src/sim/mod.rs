//! Analytic transient simulator of patches, boxes and point scatterers.
//!
//! A [`Scene`] (a JSON scene file, or built in code) holds the capture setup (laser and SPAD
//! spots on the relay wall, time axis, device positions) and the hidden objects. [`Scene::render`]
//! turns it into a [`Capture`](crate::io::Capture) `H[l][s][n]`; [`Scene::source`] streams it row by row as a
//! [`RowSource`](crate::io::RowSource). The formulas and conventions are those of the numpy prototype
//! `fixtures/sim/sim.py`, whose values `fixtures/sim/make_reference.py` writes for `tests/sim.rs`
//! to check this module against.
//!
//! # Conventions
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
//! * `scan` (optional): `"grid"` (every laser spot × every SPAD spot, the default),
//!   `"confocal"` (as `confocal: true`) or `"paired"`: one histogram per pair, laser spot `l`
//!   seen at SPAD spot `l` (`lasers` and `spads` of one length: a galvo-scanned non-confocal or
//!   arbitrary scan; explicit spots may lie off z = 0, a relay surface that is not flat — the
//!   wall cosines still take the normal +z). Written as a paired capture (`confocal = 1`
//!   with the two grids apart in vltm's `.npz`).
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
//! [`Scene::load`] return an [`Error::Format`](crate::Error::Format) naming the file and the field
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

mod noise;
mod objects;
mod render;
mod scene;

pub use crate::aperture::{Aperture, DEFAULT_LASER_ORIGIN, DEFAULT_SENSOR_ORIGIN, MAX_SPOTS};
pub use noise::{MAX_COUNTS, Noise};
pub use objects::{
    Cuboid, DEFAULT_SAMPLES, MAX_SAMPLES, Object, Patch, PointScatterer, SamplePoint,
};
pub use render::SceneSource;
pub use scene::{Bounces, MAX_POINTS, MAX_POINTS_5, MAX_VALUES, ScanKind, Scene, Setup};

#[cfg(test)]
mod tests;
