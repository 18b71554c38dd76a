//! Unit tests of the confocal FFT convolution (`super`).

use super::*;
use vltm_kernel::Params;

/// The convolution equals the direct sum `Σ_j Σ_l HG_l[j]·w(d)²·e^{iν_j 2d}` in `f64`
/// on a small grid with a half-pitch voxel grid (polyphase) and two slices: a volume
/// centred on the wall (mirrored kernel rows and columns) and one shifted off the
/// mirror (every offset computed).
#[test]
fn equals_the_direct_sum() {
    // Sub-grids split into runs of bins (8 sub-grids) and not (16, with twins), on 1 and 2
    // threads.
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            for x0 in [-0.2f32, -0.2131] {
                equals_the_direct_sum_at(x0, 4, 7, 2, 0);
            }
            // A square wall and grid: the phases (0, 1) and (1, 0) are twins.
            equals_the_direct_sum_at(-0.2, 5, 9, 4, 4);
        });
    }
}

/// The image is the same bit for bit on 1, 2 and 3 threads, with the sub-grids split into
/// runs of bins (whose split never depends on the number of threads) and without.
#[test]
fn same_image_on_any_number_of_threads() {
    let image = |threads: usize, nz: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| equals_the_direct_sum_at(-0.2131, 4, 7, nz, 0))
    };
    let bits = |a: &[Complex64]| -> Vec<(u64, u64)> {
        a.iter().map(|c| (c.re.to_bits(), c.im.to_bits())).collect()
    };
    for (nz, runs) in [(1, true), (16, false)] {
        let cfg = test_config();
        let jobs = nz * 4;
        let split = IMAGE_TASKS.div_ceil(jobs).min(cfg.bins().div_ceil(16)) > 1;
        assert_eq!(split, runs, "{nz} slices: runs of bins {runs}");
        let one = bits(&image(1, nz));
        for threads in [2, 3] {
            assert!(
                one == bits(&image(threads, nz)),
                "{nz} slices, {threads} threads"
            );
        }
    }
}

/// Twins are found only on a square layout with swapped offsets.
#[test]
fn twins_need_a_square_layout() {
    let wall = |ny: usize| -> Vec<Point> {
        (0..5)
            .flat_map(|i| (0..ny).map(move |k| [0.1 * i as f32 - 0.2, 0.1 * k as f32 - 0.2, 0.0]))
            .collect()
    };
    let grid = |y0: f32| -> Vec<Point> {
        (0..9)
            .flat_map(|i| (0..9).map(move |k| [0.05 * i as f32 - 0.2, y0 + 0.05 * k as f32, 0.3]))
            .collect()
    };
    let count = |w: &[Point], v: &[Point]| {
        let lay = layout(w, v, [9, 9, 1], 1e-6).unwrap();
        twins(&lay, 1e-7).iter().flatten().count()
    };
    assert_eq!(count(&wall(5), &grid(-0.2)), 1);
    assert_eq!(count(&wall(4), &grid(-0.2)), 0, "a 5×4 wall");
    assert_eq!(count(&wall(5), &grid(-0.19)), 0, "offsets not swapped");
}

/// Offsets mirror about an integer centre within the tolerance, and only then.
#[test]
fn mirrored_offsets() {
    // d = −2 pitches: centre 4, offsets a = −3..=5; a = −1, 0, 1 copy 5, 4, 3.
    let k = AxisKernel::new(4, 6, 16, -0.2, 0.1, 1e-9);
    assert_eq!(k.computed.len(), 6);
    assert_eq!(k.copies.len(), 3);
    for &(dst, src) in &k.copies {
        let off = |i: usize| -0.2 + 0.1 * (if i < 8 { i as f64 } else { i as f64 - 16.0 });
        assert!(
            (off(dst).abs() - off(src).abs()).abs() < 1e-12,
            "{dst} {src}"
        );
        assert!(
            k.computed.iter().any(|c| c.0 == src),
            "the source is computed"
        );
    }
    let off = AxisKernel::new(4, 6, 16, -0.2 + 1e-6, 0.1, 1e-9);
    assert!(off.copies.is_empty() && off.computed.len() == 9);
}

/// The configuration of the tests on a small grid (λ = σ = 0.1 m, 120 bins of 0.01 m).
fn test_config() -> Config {
    Config::try_new(&Params {
        sigma: Some(0.1),
        ..Params::new(0.1, 120, 0.01)
    })
    .unwrap()
}

/// [`equals_the_direct_sum`] on one layout; returns the image.
fn equals_the_direct_sum_at(
    x0: f32,
    wall_ny: usize,
    ny: usize,
    nz: usize,
    twins: usize,
) -> Vec<Complex64> {
    let cfg = test_config();
    let wall: Vec<Point> = (0..5)
        .flat_map(|i| (0..wall_ny).map(move |k| [0.1 * i as f32 - 0.2, 0.1 * k as f32, 0.0]))
        .collect();
    let nx = 9;
    let voxels: Vec<Point> = (0..nx)
        .flat_map(|i| {
            (0..ny).flat_map(move |k| {
                (0..nz).map(move |z| [x0 + 0.05 * i as f32, 0.05 * k as f32, 0.3 + 0.1 * z as f32])
            })
        })
        .collect();
    let c = Confocal::new(&cfg, &wall, &voxels, [nx, ny, nz]).unwrap();
    assert_eq!(c.shape().2, nz * 2 * 2, "depths × 2×2 phases");
    assert_eq!(c.twin.iter().flatten().count(), twins);
    let j_n = cfg.bins();
    let hg: Vec<Complex32> = (0..wall.len() * j_n)
        .map(|i| {
            let a = (i * 7919 % 1009) as f32 / 1009.0;
            Complex32::new(a - 0.5, (i * 31 % 17) as f32 / 17.0 - 0.5)
        })
        .collect();
    let mut spectra = c.spectra();
    for (l, h) in hg.chunks_exact(j_n).enumerate() {
        c.place(&mut spectra, l, h);
    }
    c.forward(&mut spectra);
    let mut skip = vec![false; voxels.len()];
    skip[3] = true;
    let mut acc = vec![Complex64::new(0.0, 0.0); voxels.len()];
    c.image(None, &spectra, &skip, &mut acc);
    let mut worst = 0.0f64;
    let mut scale = 0.0f64;
    for (i, (v, a)) in voxels.iter().zip(&acc).enumerate() {
        if skip[i] {
            continue;
        }
        let mut s = Complex64::new(0.0, 0.0);
        for (x, h) in wall.iter().zip(hg.chunks_exact(j_n)) {
            let d = (0..3)
                .map(|i| (f64::from(v[i]) - f64::from(x[i])).powi(2))
                .sum::<f64>()
                .sqrt();
            let w = f64::from(cfg.weight(d as f32));
            for (j, h) in h.iter().enumerate() {
                let ph = cfg.nu(j) * 2.0 * d;
                s += Complex64::new(h.re as f64, h.im as f64) * Complex64::from_polar(w * w, ph);
            }
        }
        scale = scale.max(s.norm());
        worst = worst.max((s - a).norm());
    }
    assert_eq!(acc[3], Complex64::new(0.0, 0.0), "skipped voxel untouched");
    assert!(scale > 1.0, "a real signal: {scale}");
    assert!(worst <= 2e-5 * scale, "worst {worst:e} of {scale:e}");
    acc
}
