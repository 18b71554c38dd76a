//! Spots on the relay wall, shared by the simulator's scenes and the PTU sidecar: apertures
//! (regular grids or point lists, [`Aperture`]), the default device positions, and the JSON
//! forms they take (a number or an array of numbers). Lengths in metres; the wall is z = 0.

use std::fmt;
use std::path::Path;

use crate::error::{Error, Result};

use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

/// Default position of the laser device (`laser_origin`) (m): tal's usual `(-0.5, 0, 0.25)`.
pub const DEFAULT_LASER_ORIGIN: [f64; 3] = [-0.5, 0.0, 0.25];
/// Default position of the sensor device (`sensor_origin`) (m): tal's usual `(-0.5, 0, 0.25)`.
pub const DEFAULT_SENSOR_ORIGIN: [f64; 3] = [-0.5, 0.0, 0.25];

/// [`DEFAULT_LASER_ORIGIN`], the serde default of every JSON form with a `laser_origin`
/// (a PTU sidecar, a scene's setup).
pub fn default_laser_origin() -> [f64; 3] {
    DEFAULT_LASER_ORIGIN
}

/// [`DEFAULT_SENSOR_ORIGIN`], the serde default of every JSON form with a `sensor_origin`.
pub fn default_sensor_origin() -> [f64; 3] {
    DEFAULT_SENSOR_ORIGIN
}

/// Largest number of spots in a laser or SPAD aperture.
pub const MAX_SPOTS: usize = 1 << 20;

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

    pub(crate) fn validate(&self, path: &Path, field: &str) -> Result<()> {
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
pub(crate) struct RawAperture {
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

pub(crate) fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|c| c.is_finite())
}

// ---------------------------------------------------------------------------------------------
// serde helpers: one number or an array of N numbers
// ---------------------------------------------------------------------------------------------

pub(crate) struct ScalarOrArray<const N: usize>;

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

pub(crate) fn scalar_or_array<'de, D: Deserializer<'de>, const N: usize>(
    d: D,
) -> Result<[f64; N], D::Error> {
    d.deserialize_any(ScalarOrArray::<N>)
}

pub(crate) fn opt_scalar_or_array<'de, D: Deserializer<'de>, const N: usize>(
    d: D,
) -> Result<Option<[f64; N]>, D::Error> {
    scalar_or_array(d).map(Some)
}
