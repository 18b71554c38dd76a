//! The exit sign of the Stanford confocal captures (`fixtures/real/data_exit_sign.mat`)
//! imaged on its own tilted plane, where its letters are legible (docs/real-data.md).
//!
//! ```sh
//! cargo run --release --example exit_sign -- fixtures/real/data_exit_sign.mat docs/real-exit-sign.png
//! ```
//!
//! Two passes of `vltm::probe::direct`, λ = 0.04 m, σ = 0.02 m (a virtual pulse of half a
//! wavelength: a band wide enough that the rough retro-reflective face does not break into
//! speckle, as it does at σ = λ), no lens weights, the authors' preprocessing (first 600 bins
//! dropped, 4 bins summed):
//!
//! 1. a wall-parallel slab over the scanned square, z 0.70–0.92 m every 5 mm (confocal FFT
//!    path); per (x, y) the depth of the brightest slice, and a least-squares plane
//!    `z = a + b·x + c·y` through them, weighted by that brightness, over the pixels above a
//!    quarter of the maximum;
//! 2. the same 64×64 (x, y) grid on five copies of that plane 5 mm apart (−1…+1 cm along z),
//!    a point list (band or lookup path). The figure's front view is the maximum over these
//!    five, its top view the five offsets (labelled with their depth at x = y = 0);
//! 3. for contrast, each voxel divided by the front view blurred with a Gaussian of 6 grid
//!    steps (7.6 cm): the sign's brightness falls by half from its centre to its edges, which
//!    hides 2 cm strokes on a linear colour scale. The title says so.
//!
//! The figure is vltm's front view, drawn as a camera on the relay wall looking in sees the
//! scene (x increasing to the left, y up), so the sign's face, turned to the wall, reads EXIT.
//! It is written all or nothing; the plane and the timing go to stderr.

use std::path::{Path, PathBuf};
use std::time::Instant;
use vltm::exec::Exec;
use vltm::export::figure::Figure;
use vltm::io::mat::{self, MatOptions};
use vltm::io::prep::{Background, Bound, Prep, Prepared};
use vltm::probe::{self, Wave};
use vltm::volume::Volume;
use vltm_kernel::Weights;

/// The authors' preprocessing: bins 0..600 dropped, 4 bins summed.
const AUTHORS: Prep = Prep {
    t_min: Some(Bound::Bins(600)),
    t_max: None,
    rebin: 4,
    background: Background::None,
};

/// Grid points per wall axis.
const N: usize = 64;
/// Plane offsets along z (m) of the second pass.
const OFFSETS: [f32; 5] = [-0.01, -0.005, 0.0, 0.005, 0.01];

fn direct(path: &Path, volume: &Volume) -> vltm::error::Result<probe::Output> {
    let m = mat::read(path, &MatOptions::default())?;
    let mut cap = m.capture;
    let mut src = Prepared::new(&mut cap, AUTHORS, None)?;
    let wave = Wave {
        wavelength: Some(0.04),
        sigma: Some(0.02),
        weights: Weights::One,
        ..Wave::default()
    };
    probe::direct(&mut src, volume, &wave, Exec::default())
}

/// Weighted least-squares plane `z = a + b·x + c·y` through `(x, y, z, weight)`.
fn fit_plane(pts: &[[f64; 4]]) -> [f64; 3] {
    let mut m = [[0.0f64; 4]; 3];
    for &[x, y, z, w] in pts {
        let r = [1.0, x, y];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += w * r[i] * r[j];
            }
            m[i][3] += w * r[i] * z;
        }
    }
    // Gauss–Jordan on the 3×4 normal equations (symmetric positive definite).
    for c in 0..3 {
        let p = m[c][c];
        for v in &mut m[c] {
            *v /= p;
        }
        let pivot = m[c];
        for (r, row) in m.iter_mut().enumerate() {
            if r != c {
                let f = row[c];
                for (v, pv) in row.iter_mut().zip(pivot) {
                    *v -= f * pv;
                }
            }
        }
    }
    [m[0][3], m[1][3], m[2][3]]
}

/// `values` (C order over `(N, N, nz)`) divided per (x, y) column by the front view (maximum
/// over z) blurred with a Gaussian of `s` grid steps (truncated at 3s, renormalised at the
/// edges).
fn local_contrast(values: &[f32], nz: usize, s: f64) -> Vec<f32> {
    let front: Vec<f64> = values
        .chunks_exact(nz)
        .map(|c| f64::from(c.iter().fold(0.0f32, |a, &b| a.max(b))))
        .collect();
    let r = (3.0 * s).ceil() as isize;
    let k: Vec<f64> = (-r..=r)
        .map(|d| (-(d * d) as f64 / (2.0 * s * s)).exp())
        .collect();
    let pass = |src: &[f64], along_x: bool| -> Vec<f64> {
        let mut out = vec![0.0; N * N];
        for ix in 0..N {
            for iy in 0..N {
                let (mut acc, mut wsum) = (0.0, 0.0);
                for (t, &kw) in k.iter().enumerate() {
                    let d = t as isize - r;
                    let (jx, jy) = if along_x {
                        (ix as isize + d, iy as isize)
                    } else {
                        (ix as isize, iy as isize + d)
                    };
                    if (0..N as isize).contains(&jx) && (0..N as isize).contains(&jy) {
                        acc += kw * src[jx as usize * N + jy as usize];
                        wsum += kw;
                    }
                }
                out[ix * N + iy] = acc / wsum;
            }
        }
        out
    };
    let blur = pass(&pass(&front, true), false);
    let floor = 1e-3 * blur.iter().fold(0.0f64, |a, &b| a.max(b));
    values
        .chunks_exact(nz)
        .zip(&blur)
        .flat_map(|(c, &b)| c.iter().map(move |&v| (f64::from(v) / b.max(floor)) as f32))
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 3 {
        return Err("usage: exit_sign DATA_EXIT_SIGN.mat OUT.png".into());
    }
    let (input, png) = (PathBuf::from(&args[1]), PathBuf::from(&args[2]));
    let w = mat::read(&input, &MatOptions::default())?
        .capture
        .geometry
        .lasers
        .last()
        .ok_or("no wall points")?[0];
    let t = Instant::now();

    // Pass 1: the depth of the brightest slice per (x, y), and a plane through them.
    let (z0, z1, nz) = (0.70f32, 0.92f32, 45usize);
    let slab = Volume::grid([-w, -w, z0], [w, w, z1], [N, N, nz])?;
    let o = direct(&input, &slab)?;
    let top = o.values.iter().fold(0.0f32, |a, &b| a.max(b));
    let mut pts = Vec::new();
    for (p, col) in o.values.chunks_exact(nz).enumerate() {
        let (k, &v) = col
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .ok_or("empty column")?;
        if v >= 0.25 * top {
            let q = slab.points[p * nz + k];
            pts.push([
                f64::from(q[0]),
                f64::from(q[1]),
                f64::from(q[2]),
                f64::from(v),
            ]);
        }
    }
    let [a, b, c] = fit_plane(&pts);
    eprintln!(
        "pass 1 ({:?} path, {} slices): plane z = {a:.4} {b:+.4}·x {c:+.4}·y m through {} pixels",
        o.path,
        nz,
        pts.len()
    );

    // Pass 2: the 64×64 grid on five copies of the plane.
    let step = 2.0 * f64::from(w) / (N - 1) as f64;
    let mut points = Vec::with_capacity(N * N * OFFSETS.len());
    for ix in 0..N {
        let x = -f64::from(w) + step * ix as f64;
        for iy in 0..N {
            let y = -f64::from(w) + step * iy as f64;
            for d in OFFSETS {
                points.push([x as f32, y as f32, (a + b * x + c * y) as f32 + d]);
            }
        }
    }
    let plane = Volume::points(points)?;
    let o = direct(&input, &plane)?;
    eprintln!(
        "pass 2 ({:?} path): {} voxels; {:.1} s for both passes",
        o.path,
        plane.len(),
        t.elapsed().as_secs_f64()
    );
    let values = local_contrast(&o.values, OFFSETS.len(), 6.0);
    let a = a as f32;
    let mut fig = Figure::new(
        &values,
        [N, N, OFFSETS.len()],
        [-w, w],
        [-w, w],
        [a + OFFSETS[0], a + OFFSETS[OFFSETS.len() - 1]],
    );
    fig.title = format!(
        "exit sign, direct light (lambda 0.04 m, sigma 0.02 m) on the plane z = {a:.3} {b:+.3}x {c:+.3}y m, +-1 cm; divided by the front view blurred over 7.6 cm"
    );
    fig.write_png(&png)?;
    eprintln!("wrote {}", png.display());
    Ok(())
}
