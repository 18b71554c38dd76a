//! The scene model: capture [`Setup`], bounce filter, rendering options and the hidden objects
//! ([`Scene`]), its JSON form and its validation.

use std::path::Path;

use serde::{Deserialize, Serialize};
use vltm_kernel::Point;

use super::noise::*;
use super::objects::*;
use crate::aperture::{Aperture, DEFAULT_LASER_ORIGIN, DEFAULT_SENSOR_ORIGIN, all_finite};
use crate::error::{Error, Result};
use crate::io::capture::Geometry;

/// Largest total number of surface sample points of a scene.
pub const MAX_POINTS: usize = 100_000;
/// Largest total number of surface sample points of a scene rendered with 5-vertex paths (a
/// laser row keeps every 2-bounce path: up to P² of them).
pub const MAX_POINTS_5: usize = 2048;

/// Largest number of histogram values (`Kl·Ks·Nt`) of a rendered capture (16 GiB of f32).
pub const MAX_VALUES: usize = 1 << 32;

/// The name used in errors about scenes built in code.
pub(super) const IN_CODE: &str = "<scene>";

// ---------------------------------------------------------------------------------------------
// scene description
// ---------------------------------------------------------------------------------------------

/// A simulated capture: setup, rendering options and hidden objects (the scene file).
///
/// Deserialises from the JSON format of the [module documentation](super); build one in code
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

pub(super) fn default_max_vertices() -> usize {
    4
}
pub(super) fn default_true() -> bool {
    true
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
    /// The scan (`"grid"`: every laser spot × every SPAD spot; `"confocal"`: as `confocal:
    /// true`; `"paired"`: one histogram per pair, laser spot `l` seen at SPAD spot `l`, both
    /// lists of one length). `None` (default): `"confocal"` if `confocal`, else `"grid"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scan: Option<ScanKind>,
    /// Bins per histogram (≥ 1).
    pub nt: usize,
    /// Bin width (m of path) (> 0).
    pub dt: f64,
    /// Path length of bin 0 (m).
    #[serde(default)]
    pub t0: f64,
    /// Laser device position (m) (y-tal `laser_xyz`).
    #[serde(default = "crate::aperture::default_laser_origin")]
    pub laser_origin: [f64; 3],
    /// Sensor device position (m) (y-tal `sensor_xyz`).
    #[serde(default = "crate::aperture::default_sensor_origin")]
    pub sensor_origin: [f64; 3],
    /// Whether path times include the device legs `d1`, `d4`.
    #[serde(default)]
    pub legs_in_time: bool,
}

/// The scan of a [`Setup`] (`"scan"` in a scene file).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScanKind {
    /// Every laser spot × every SPAD spot.
    Grid,
    /// One histogram per laser spot, SPAD at the laser spot.
    Confocal,
    /// One histogram per (laser spot `l`, SPAD spot `l`) pair: a galvo-scanned non-confocal
    /// or arbitrary scan; the spots may lie off the plane z = 0 (a relay surface that is not
    /// flat).
    Paired,
}

impl Setup {
    /// One histogram per row: a confocal or paired scan.
    pub fn one_per_row(&self) -> bool {
        self.confocal || matches!(self.scan, Some(ScanKind::Confocal | ScanKind::Paired))
    }

    /// A paired scan (`"scan": "paired"`).
    pub fn paired(&self) -> bool {
        self.scan == Some(ScanKind::Paired)
    }

    /// A paired setup: one histogram per (laser spot, SPAD spot) pair, otherwise as
    /// [`Setup::new`].
    pub fn paired_with(lasers: Aperture, spads: Aperture, nt: usize, dt: f64) -> Self {
        Self {
            scan: Some(ScanKind::Paired),
            ..Self::new(lasers, spads, nt, dt)
        }
    }

    /// A non-confocal setup with `t0 = 0`, default device positions and no legs in time.
    pub fn new(lasers: Aperture, spads: Aperture, nt: usize, dt: f64) -> Self {
        Self {
            lasers,
            spads: Some(spads),
            confocal: false,
            scan: None,
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
        let json = crate::budget::read_text(path)?;
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
        if s.confocal && matches!(s.scan, Some(ScanKind::Grid | ScanKind::Paired)) {
            return Err(Error::format(
                path,
                "setup.scan",
                "\"confocal\" or no `scan` with `confocal: true`",
                format!("{:?}", s.scan),
            ));
        }
        if s.paired() {
            let spads = s.spads.as_ref().ok_or_else(|| {
                Error::format(
                    path,
                    "setup.spads",
                    "one SPAD spot per laser spot (paired scan)",
                    "none",
                )
            })?;
            spads.validate(path, "setup.spads")?;
            let (kl, ks) = (shape_len(s.lasers.shape()), shape_len(spads.shape()));
            if kl != ks {
                return Err(Error::format(
                    path,
                    "setup.spads",
                    format!("one SPAD spot per laser spot (paired scan: {kl} laser spots)"),
                    format!("{ks} SPAD spots"),
                ));
            }
        }
        let confocal = s.confocal || s.scan == Some(ScanKind::Confocal);
        match (&s.spads, confocal) {
            _ if s.paired() => {}
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
        let ks = if s.one_per_row() {
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
        let grid_spads = !s.one_per_row() || s.paired();
        let (spads, spad_shape) = match (&s.spads, grid_spads) {
            (Some(a), true) => (to_f32(a.spots()), a.shape()),
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
            confocal: s.one_per_row(),
            nt: s.nt,
            dt: s.dt,
            t0: s.t0,
            normals: Default::default(),
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
}

pub(super) fn shape_len(s: [usize; 2]) -> usize {
    s[0].saturating_mul(s[1])
}
