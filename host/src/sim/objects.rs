//! The hidden objects (patches, boxes, point scatterers) and their surface sampling into
//! [`SamplePoint`]s; small vector helpers. Lengths in metres.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::aperture::{all_finite, scalar_or_array};
use crate::error::{Error, Result};

/// Default samples per side of a patch or box face.
pub const DEFAULT_SAMPLES: usize = 4;
/// Largest `samples` per side accepted.
pub const MAX_SAMPLES: usize = 1024;

pub(super) fn default_albedo() -> f64 {
    1.0
}
pub(super) fn default_samples() -> usize {
    DEFAULT_SAMPLES
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

    pub(super) fn sample_count(&self) -> usize {
        match self {
            Self::Patch(p) => p.samples.saturating_mul(p.samples),
            Self::Box(b) => b.samples.saturating_mul(b.samples).saturating_mul(6),
            Self::Point(_) => 1,
        }
    }

    pub(super) fn validate(&self, path: &Path, i: usize) -> Result<()> {
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

    pub(super) fn albedo(&self) -> f64 {
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
    /// Index of its object in [`Scene::objects`](super::Scene::objects): inter-reflections only link different groups.
    pub group: usize,
}

pub(super) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(super) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(super) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(super) fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = dot(v, v).sqrt();
    v.map(|c| c / n)
}

/// sim.py's patch tangents: `a = n × ŷ` (or `n × x̂` near ±ŷ), `b = n × a`.
pub(super) fn tangents(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let a = if n[1].abs() < 0.9 {
        cross(n, [0.0, 1.0, 0.0])
    } else {
        cross(n, [1.0, 0.0, 0.0])
    };
    let a = unit(a);
    (a, cross(n, a))
}

/// `n × n` cell-centre samples of the rectangle `c + w·u·a + h·v·b` (sim.py `patch`).
pub(super) fn sample_rect(
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
pub(super) fn sample_rect_along(
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
pub(super) type Face = ([f64; 3], [f64; 3], ([f64; 3], [f64; 3]), [f64; 2]);

/// The faces of a box, along its axes `u` (+u₀, −u₀, +u₁, −u₁, +u₂, −u₂): sides along sim.py's
/// tangents of the face normal for an axis-aligned box (as the reference), along the box's
/// other two axes for a turned one.
pub(super) fn box_faces(b: &Cuboid) -> Vec<Face> {
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
