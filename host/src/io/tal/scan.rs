//! From a capture's `H` axes and grids to vltm's [`Geometry`]: the scan type (exhaustive,
//! confocal, tal `single` by reciprocity), the device positions and the time axis. Shared by
//! the `HDF5_TAL` reader and the Z-NLOS reader ([`super::znlos`]), whose files map onto the
//! same tal fields (y-tal's `tal/io/format.py`).

use super::fields::{Grid, allclose};
use super::{HFormat, ScanType, TalOptions};
use crate::error::{Error, Result};
use crate::io::capture::{Geometry, Normals, unit};
use std::path::Path;
use vltm_kernel::Point;

/// A capture's description in tal's terms.
pub(super) struct Meta {
    /// tal's `H_format`.
    pub(super) format: HFormat,
    /// `H`'s axes after time (`[Lx, Ly, Sx, Sy]`, `[Li, Si]`, `[Sx, Sy]` or `[Si]`).
    pub(super) lead: Vec<usize>,
    /// Bins per histogram.
    pub(super) nt: usize,
    /// `laser_grid_xyz`.
    pub(super) lgrid: Grid,
    /// `sensor_grid_xyz`.
    pub(super) sgrid: Grid,
    /// `laser_xyz`.
    pub(super) laser_xyz: [f64; 3],
    /// `sensor_xyz`.
    pub(super) sensor_xyz: [f64; 3],
    /// `delta_t` (m).
    pub(super) dt: f64,
    /// `t_start` (m).
    pub(super) t_start: f64,
    /// `t_accounts_first_and_last_bounces`.
    pub(super) legs_in_time: bool,
    /// The file's names of `laser_xyz` and `sensor_xyz` (for errors).
    pub(super) xyz_names: [&'static str; 2],
    /// `laser_grid_normals` and `sensor_grid_normals` where the file has them (same format
    /// and shape as their grids; absent: +z).
    pub(super) normals: [Option<Grid>; 2],
}

/// The scan a [`Meta`] describes.
pub(super) struct Scan {
    pub(super) scan: ScanType,
    pub(super) geometry: Geometry,
    /// `c(x0)` of a single scan (the physical laser's falloff at its one spot), else `None`.
    pub(super) single_falloff: Option<f64>,
}

/// Builds the geometry (module docs of [`super`], *Scan types* and *Time axis*).
///
/// # Errors
/// [`Error::Format`] naming the grid or position that does not fit.
pub(super) fn build(path: &Path, m: Meta, options: TalOptions) -> Result<Scan> {
    let Meta {
        format,
        lead,
        nt,
        lgrid,
        sgrid,
        laser_xyz,
        sensor_xyz,
        dt,
        t_start,
        legs_in_time,
        xyz_names,
        normals: [lnormals, snormals],
    } = m;
    let lnormals = checked_normals(path, lnormals, &lgrid)?;
    let snormals = checked_normals(path, snormals, &sgrid)?;
    let (scan, lasers, laser_shape, spads, spad_shape) = match format {
        HFormat::TLxLySxSy => {
            let l = lgrid.fit(path, [lead[0], lead[1]])?;
            let s = sgrid.fit(path, [lead[2], lead[3]])?;
            (ScanType::Exhaustive, lgrid.points, l, sgrid.points, s)
        }
        HFormat::TLiSi => {
            let l = lgrid.count(path, lead[0])?;
            let s = sgrid.count(path, lead[1])?;
            (ScanType::Exhaustive, lgrid.points, l, sgrid.points, s)
        }
        HFormat::TSxSy | HFormat::TSi => {
            let s = if format == HFormat::TSxSy {
                sgrid.fit(path, [lead[0], lead[1]])?
            } else {
                sgrid.count(path, lead[0])?
            };
            if allclose(&sgrid.points, &lgrid.points) {
                let pts = sgrid.points;
                (ScanType::Confocal, pts.clone(), s, pts, s)
            } else if lgrid.points.len() == 1 && sgrid.points.len() != 1 {
                (ScanType::Single, sgrid.points, s, lgrid.points, [1, 1])
            } else if lgrid.xy == sgrid.xy && lgrid.shape == sgrid.shape {
                // y-tal's `is_laser_paired_to_sensor()`: the same grid format and shape. One
                // histogram per (laser point, sensor point) pair, both moving.
                (ScanType::Paired, lgrid.points, s, sgrid.points, s)
            } else {
                return Err(Error::format(
                    path,
                    lgrid.field,
                    format!(
                        "one point (tal scan_type single), or a grid of the sensor grid's format \
                         and shape (paired, confocal when the points coincide) for H_format {}",
                        format.tal_name()
                    ),
                    format!(
                        "{} points {} against the sensor grid's {} points {}",
                        lgrid.points.len(),
                        grid_form(&lgrid),
                        sgrid.points.len(),
                        grid_form(&sgrid)
                    ),
                ));
            }
        }
    };
    let single = scan == ScanType::Single;
    let (laser_origin, sensor_origin, normals) = if single {
        (
            sensor_xyz,
            laser_xyz,
            Normals::from_lists(snormals, lnormals),
        )
    } else {
        (
            laser_xyz,
            sensor_xyz,
            Normals::from_lists(lnormals, snormals),
        )
    };
    let geometry = Geometry {
        lasers,
        laser_shape,
        spads,
        spad_shape,
        laser_origin,
        sensor_origin,
        legs_in_time,
        confocal: matches!(scan, ScanType::Confocal | ScanType::Paired),
        nt,
        dt,
        t0: if options.bin_centre {
            t_start + 0.5 * dt
        } else {
            t_start
        },
        normals,
    };
    geometry.validate(path)?;

    let single_falloff = if single {
        let physical = Geometry {
            laser_origin: laser_xyz,
            ..geometry.clone()
        };
        // The one laser spot x0 with its own normal (now the capture's SPAD spot).
        let c0 = physical.falloff(geometry.spads[0], geometry.spad_normal(0));
        if !(c0.is_finite() && c0 > 0.0) {
            return Err(Error::format(
                path,
                xyz_names[0],
                "a laser off the wall plane (the single-scan reciprocity factor divides by its cos θ / d²)",
                format!("{laser_xyz:?}"),
            ));
        }
        let sensor_ok = (0..geometry.lasers.len()).all(|l| {
            let c = geometry.laser_falloff_at(l);
            c.is_finite() && c > 0.0
        });
        if !sensor_ok {
            return Err(Error::format(
                path,
                xyz_names[1],
                "a sensor off the wall plane (it is the laser of the reciprocal single scan)",
                format!("{sensor_xyz:?}"),
            ));
        }
        Some(c0)
    } else {
        None
    };
    Ok(Scan {
        scan,
        geometry,
        single_falloff,
    })
}

/// A grid's stored form for messages: `(X, Y, 3)` or `(N, 3)`.
fn grid_form(g: &Grid) -> String {
    if g.xy {
        format!("as ({}, {}, 3)", g.shape[0], g.shape[1])
    } else {
        format!("as ({}, 3)", g.points.len())
    }
}

/// The normals of `grid` (empty when the file has none), checked: the grid's format and
/// shape, finite and of non-zero length. One-line errors name the normals' field.
fn checked_normals(path: &Path, normals: Option<Grid>, grid: &Grid) -> Result<Vec<Point>> {
    let Some(n) = normals else {
        return Ok(Vec::new());
    };
    if n.xy != grid.xy || n.shape != grid.shape {
        return Err(Error::format(
            path,
            n.field,
            format!(
                "one normal per point of {} ({})",
                grid.field,
                grid_form(grid)
            ),
            grid_form(&n),
        ));
    }
    if let Some(i) = n.points.iter().position(|v| unit(v).is_none()) {
        return Err(Error::format(
            path,
            n.field,
            "finite normals of non-zero length",
            format!("{:?} at index {i}", n.points[i]),
        ));
    }
    Ok(n.points)
}
