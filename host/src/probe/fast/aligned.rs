//! The aligned volume: for a wall-parallel voxel grid that the FFT paths (planar, confocal)
//! cannot take because its x–y pitch does not divide the wall's, the nearest grid that they
//! can take — the same first voxel and extent (to within one pitch), the pitch `p/r` with
//! `r = max(1, round(p / p_v))` (`p` the wall's pitch, `p_v` the asked one). The probes report
//! it ([`crate::probe::Output::aligned`]) when a slower path ran, so that the user can type it.
//! Cost O(1).

use crate::io::capture::Geometry;
use crate::volume::Volume;
use vltm_kernel::Point;

/// The wall lattice's pitch along x and y (the SPADs, or the scanned points of a confocal
/// capture; C order over the grid shape), 0 along an axis of one point.
fn wall_pitch(g: &Geometry) -> [f64; 2] {
    let (pts, shape) = if g.confocal {
        (&g.lasers, g.laser_shape)
    } else {
        (&g.spads, g.spad_shape)
    };
    let d = |a: Point, b: Point| {
        (0..3)
            .map(|i| f64::from(a[i] - b[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let px = if shape[0] > 1 && pts.len() > shape[1] {
        d(pts[0], pts[shape[1]])
    } else {
        0.0
    };
    let py = if shape[1] > 1 && pts.len() > 1 {
        d(pts[0], pts[1])
    } else {
        0.0
    };
    [px, py]
}

/// The `--volume` SPEC of the grid nearest to `volume` whose x–y pitch divides the wall's
/// (module docs), or `None` when `volume` is a point list, already aligned, or the wall has no
/// pitch along an axis the volume spans.
pub fn aligned_volume(g: &Geometry, volume: &Volume) -> Option<String> {
    let axes = volume.axes?;
    let p = wall_pitch(g);
    let mut changed = false;
    let mut spec = Vec::with_capacity(3);
    for i in 0..3 {
        let [a32, b32] = axes[i];
        let [a, b] = axes[i].map(f64::from);
        let n = volume.shape[i];
        if i == 2 || n < 2 {
            spec.push(format!("{a32}:{b32}:{n}"));
            continue;
        }
        if p[i] <= 0.0 {
            return None;
        }
        let pv = (b - a) / (n - 1) as f64;
        let r = (p[i] / pv.abs()).round().max(1.0);
        let step = p[i] / r * pv.signum();
        let m = ((b - a) / step).round() as usize + 1;
        let end = a + (m - 1) as f64 * step;
        if m != n || (end - b).abs() > 1e-3 * p[i] {
            changed = true;
        }
        let end = if end.abs() < 5e-8 { 0.0 } else { end };
        let end = format!("{end:.7}");
        let end = end.trim_end_matches('0').trim_end_matches('.');
        spec.push(format!("{a32}:{end}:{m}"));
    }
    changed.then(|| spec.join(","))
}

/// The depths `[z_near, z_far]` (m) the capture's time window reaches: the depths whose
/// nearest 3-bounce path lies in the window `t0 ..= t0 + (nt − 1)·Δt`. A voxel at depth `z`
/// seen through the pair (laser spot `x_l`, SPAD spot `x_s`) has its shortest path
/// `|x_l − x_v| + |x_v − x_s|` (plus the device legs when the time axis holds them) at the
/// voxel between the two spots: `√(d² + (2z − z_l − z_s)²)`, `d` the spots' x–y distance
/// (`2z` for a voxel in front of a spot). `z_far` is the deepest depth whose shortest path over
/// the pairs is at most the window's end; `z_near` the shallowest whose shortest path over
/// every pair is at least the window's start (nearer voxels arrive before the window opens),
/// and never nearer than `step` in front of the relay surface's highest spot nor at z ≤ 0.
/// `None` when the window reaches no depth beyond that. Cost O(pairs).
pub fn window_depths(g: &Geometry, step: f64) -> Option<(f64, f64)> {
    let (t_min, t_max) = (g.t0, g.t0 + (g.nt.max(1) - 1) as f64 * g.dt);
    let p64 = |p: &Point| p.map(f64::from);
    let dist = |a: [f64; 3], b: [f64; 3]| vltm_kernel::geometry::dist64_f64(&a, &b);
    let top = g
        .lasers
        .iter()
        .chain(&g.spads)
        .map(|p| f64::from(p[2]))
        .fold(f64::NEG_INFINITY, f64::max);
    // The depth at which the pair's shortest path is `t` (the surface's top when it is longer
    // there already); `None` when it is longer than `t` at every depth in front of the wall.
    let depth = |l: [f64; 3], s: [f64; 3], t: f64| {
        let legs = if g.legs_in_time {
            dist(g.laser_origin, l) + dist(s, g.sensor_origin)
        } else {
            0.0
        };
        let d2 = (l[0] - s[0]).powi(2) + (l[1] - s[1]).powi(2);
        let r = t - legs;
        if r < 0.0 || r * r < d2 {
            return None;
        }
        let z = 0.5 * (l[2] + s[2] + (r * r - d2).sqrt());
        Some(z.max(top))
    };
    let (mut near, mut far) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    for (l, x_l) in g.lasers.iter().enumerate() {
        for x_s in g.row_spads(l) {
            let (a, b) = (p64(x_l), p64(x_s));
            near = near.max(depth(a, b, t_min).unwrap_or(top));
            if let Some(z) = depth(a, b, t_max) {
                far = far.max(z);
            }
        }
    }
    let near = near.max(top + step).max(step);
    (far.is_finite() && far > near).then_some((near, far))
}

/// The `--volume` SPEC `vltm info` suggests for a capture: x–y the wall's lattice (its
/// extent and pitch: the FFT paths take it) or, on a wall that is not a lattice, the spots'
/// extent at half the default wavelength; z the depths the time window reaches
/// ([`window_depths`]) at the same step (at most 512 slices, and within
/// [`crate::volume::MAX_VOXELS`]). `None` when the window reaches no depth in front of the
/// wall. Cost O(pairs).
pub fn suggested_volume(g: &Geometry) -> Option<String> {
    let wall = if g.confocal { &g.lasers } else { &g.spads };
    let lam = crate::probe::wave::default_wavelength(g);
    let xy: [(f64, f64, usize); 2] =
        match crate::probe::fast::lattice::wall_lattice(wall, 1e-5 * lam) {
            Ok((origin, pitch, n, _)) => {
                [0, 1].map(|i| (origin[i], origin[i] + (n[i] - 1) as f64 * pitch[i], n[i]))
            }
            Err(_) => [0, 1].map(|i| {
                let (a, b) = g
                    .lasers
                    .iter()
                    .chain(&g.spads)
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                        (a.min(f64::from(p[i])), b.max(f64::from(p[i])))
                    });
                let n = ((b - a) / (0.5 * lam)).round().clamp(0.0, 255.0) as usize + 1;
                (a, b, n)
            }),
        };
    let pitches: Vec<f64> = xy
        .iter()
        .filter(|a| a.2 > 1)
        .map(|&(a, b, n)| (b - a).abs() / (n - 1) as f64)
        .collect();
    let step = if pitches.is_empty() {
        0.5 * lam
    } else {
        pitches.iter().sum::<f64>() / pitches.len() as f64
    };
    let (near, far) = window_depths(g, step)?;
    // Rounded inward to 0.1 mm, so that the printed range lies in the reachable one.
    let (z0, z1) = ((near * 1e4).ceil() / 1e4, (far * 1e4).floor() / 1e4);
    if z1 <= z0 {
        return None;
    }
    let most = (crate::volume::MAX_VOXELS / (xy[0].2 * xy[1].2).max(1)).clamp(1, 512);
    let nz = (((z1 - z0) / step).round() as usize + 1).clamp(2, most.max(2));
    let f = |x: f64| {
        let t = format!("{:.7}", if x.abs() < 5e-8 { 0.0 } else { x });
        t.trim_end_matches('0').trim_end_matches('.').to_string()
    };
    let axis = |(a, b, n): (f64, f64, usize)| format!("{}:{}:{n}", f(a), f(b));
    Some(format!(
        "{},{},{}",
        axis(xy[0]),
        axis(xy[1]),
        axis((z0, z1, nz))
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wall(n: usize, half: f32) -> Geometry {
        let pitch = 2.0 * half / (n - 1) as f32;
        let pts: Vec<Point> = (0..n * n)
            .map(|i| {
                [
                    -half + (i / n) as f32 * pitch,
                    -half + (i % n) as f32 * pitch,
                    0.0,
                ]
            })
            .collect();
        Geometry {
            lasers: pts.clone(),
            laser_shape: [n, n],
            spads: pts,
            spad_shape: [n, n],
            laser_origin: [0.0; 3],
            sensor_origin: [0.0; 3],
            legs_in_time: false,
            confocal: true,
            nt: 10,
            dt: 0.01,
            t0: 0.0,
            normals: Default::default(),
        }
    }

    /// A wider view at nearly the wall's pitch gets the wall's pitch; a coarser one the wall's;
    /// a finer one a divisor; the wall's own grid and point lists get none.
    #[test]
    fn aligned_grids() {
        let g = wall(64, 0.2);
        let p = 0.4 / 63.0;
        let v = Volume::grid([-0.35, -0.35, 0.4], [0.35, 0.35, 1.0], [112, 112, 36]).unwrap();
        let s = aligned_volume(&g, &v).unwrap();
        let w = Volume::parse(&s).unwrap();
        assert_eq!(w.shape, [111, 111, 36], "{s}");
        let pitch = |v: &Volume| {
            f64::from(v.axes.unwrap()[0][1] - v.axes.unwrap()[0][0]) / (v.shape[0] - 1) as f64
        };
        assert!((pitch(&w) - p).abs() < 1e-7, "{s}");
        let coarse = Volume::grid([-0.35, -0.35, 0.4], [0.35, 0.35, 1.0], [64, 64, 36]).unwrap();
        let c = Volume::parse(&aligned_volume(&g, &coarse).unwrap()).unwrap();
        assert!((pitch(&c) - p).abs() < 1e-7);
        let fine = Volume::grid([-0.1, -0.1, 0.4], [0.1, 0.1, 1.0], [70, 70, 2]).unwrap();
        let f = Volume::parse(&aligned_volume(&g, &fine).unwrap()).unwrap();
        assert!((pitch(&f) - p / 2.0).abs() < 1e-7, "{:?}", f.shape);
        let own = Volume::grid([-0.2, -0.2, 0.4], [0.2, 0.2, 1.0], [64, 64, 36]).unwrap();
        assert_eq!(aligned_volume(&g, &own), None);
        let list = Volume::points(vec![[0.0, 0.0, 0.5]]).unwrap();
        assert_eq!(aligned_volume(&g, &list), None);
    }

    /// The window's depths: `t/2` in front of a spot at each end of the window (wall to
    /// wall), less half the shortest device legs when the time axis holds them; the near end
    /// one step in front of the wall when the window opens there; none when the window ends
    /// before any depth.
    #[test]
    fn window_depths_follow_the_time_axis() {
        let mut g = wall(8, 0.2);
        (g.t0, g.nt, g.dt) = (0.8, 100, 0.01);
        let (a, b) = window_depths(&g, 0.05).unwrap();
        assert!(
            (a - 0.4).abs() < 1e-6 && (b - 0.895).abs() < 1e-6,
            "{a} {b}"
        );
        let v = Volume::parse(&suggested_volume(&g).unwrap()).unwrap();
        let z = v.axes.unwrap()[2];
        assert!(
            f64::from(z[0]) >= 0.4 - 1e-6 && f64::from(z[1]) <= 0.895 + 1e-6,
            "{z:?}"
        );
        assert_eq!(&v.shape[..2], &[8, 8]);
        g.t0 = 0.0;
        let (a, _) = window_depths(&g, 0.05).unwrap();
        assert!((a - 0.05).abs() < 1e-9, "{a}");
        // Device legs: 0.5 m to the nearest spot each way, so 1 m less of the path.
        g.legs_in_time = true;
        g.laser_origin = [0.0, 0.0, -0.5];
        g.sensor_origin = [0.0, 0.0, -0.5];
        (g.t0, g.nt) = (1.8, 100);
        let (a, b) = window_depths(&g, 0.05).unwrap();
        let near = |p: &Point| -> f64 {
            0.5 * (1.8 - 2.0 * f64::from(p[0] * p[0] + p[1] * p[1] + 0.25).sqrt())
        };
        let best = g.lasers.iter().map(near).fold(f64::NEG_INFINITY, f64::max);
        assert!((a - best).abs() < 1e-6, "{a} {best}");
        assert!(b > a && b < 0.5 * (2.79 - 1.0) + 1e-6, "{b}");
        g.nt = 1;
        g.t0 = 0.5; // shorter than the legs
        assert_eq!(window_depths(&g, 0.05), None);
        assert_eq!(suggested_volume(&g), None);
    }
}
