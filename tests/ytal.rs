//! Agreement with the peer library y-tal 0.20 (`tal.reconstruct.pf_dev`) on the mitransient
//! captures in `fixtures/ytal`: y-tal's outputs are committed data files there,
//! so no Python runs at test time.
//!
//! For every capture: vltm's direct volume with y-tal's conventions — `--weights one`,
//! σ = λ (`wl_sigma = wl_mean`), `--compensate-laser`, bin k at `t_start + k·Δt`, the same
//! volume — against `ref_direct.npy` (DIRECT_LIGHT): Pearson correlation ≥ 0.99 of the
//! intensities normalised to their maximum, and the same peak voxel. Where provided, vltm's
//! un-masked two-bounce column focused at patch A against y-tal's PROJECTOR_CAMERA transient
//! sampled at t = |x_a − x_b| (`ref_ltmcol_focusA.npy`): Pearson ≥ 0.99.
//!
//! A paired, non-confocal scan on a bumpy relay surface, written by y-tal's own writer, against
//! y-tal's `fbp` (`fixtures/tal/paired*`, made by `benches/ytal_paired.py`): Pearson 0.99965
//! on the band, lookup and `Auto` paths, the same peak voxel.
//!
//! Remaining differences are conventions, not errors: y-tal's kernel envelope is
//! shifted by half a bin, its band keeps positive frequencies only and its gate is the DFT of
//! a sampled, sum-normalised kernel, in float32.

use std::path::PathBuf;
use vltm::io;
use vltm::probe::{self, ColumnGate, Exec, Shell, Wave};
use vltm::volume::Volume;
use vltm_kernel::Weights;

mod support;

/// `fixtures/ytal/<capture>/<file>`, checked (`support::fixture`).
fn data(capture: &str, file: &str) -> PathBuf {
    support::fixture(&format!("ytal/{capture}/{file}"))
}

/// |z|² of a complex64 `.npy` (C order), with its shape.
fn read_c8_intensity(path: &PathBuf) -> (Vec<f64>, Vec<usize>) {
    let (z, shape) = read_c8(path);
    (z.iter().map(|&(re, im)| re * re + im * im).collect(), shape)
}

/// The values (re, im) of a complex64 `.npy` (C order), with its shape.
fn read_c8(path: &PathBuf) -> (Vec<(f64, f64)>, Vec<usize>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&bytes[..6], b"\x93NUMPY", "{}", path.display());
    let (hlen, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        _ => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
    };
    let header = std::str::from_utf8(&bytes[start..start + hlen]).unwrap();
    assert!(
        header.contains("'descr': '<c8'") && header.contains("'fortran_order': False"),
        "{header}"
    );
    let dims = &header[header.find("'shape': (").unwrap() + 10..];
    let shape: Vec<usize> = dims[..dims.find(')').unwrap()]
        .split(',')
        .filter_map(|d| d.trim().parse().ok())
        .collect();
    let v = bytes[start + hlen..]
        .chunks_exact(8)
        .map(|c| {
            let re = f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64;
            let im = f32::from_le_bytes([c[4], c[5], c[6], c[7]]) as f64;
            (re, im)
        })
        .collect::<Vec<_>>();
    assert_eq!(v.len(), shape.iter().product::<usize>());
    (v, shape)
}

/// Pearson correlation of two images normalised to their maxima.
fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let na = a.iter().cloned().fold(0.0, f64::max);
    let nb = b.iter().cloned().fold(0.0, f64::max);
    let (a, b): (Vec<f64>, Vec<f64>) = a.iter().zip(b).map(|(x, y)| (x / na, y / nb)).unzip();
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(&b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

fn argmax(v: &[f64]) -> usize {
    (0..v.len()).max_by(|&i, &j| v[i].total_cmp(&v[j])).unwrap()
}

/// y-tal's volume for every capture: x, y = −0.75 … 0.75 step 0.1, z = 0.40 … 1.35 step 0.05.
fn volume() -> Volume {
    Volume::parse("-0.75:0.75:16,-0.75:0.75:16,0.4:1.35:20").unwrap()
}

/// The wave y-tal used for a capture (`wl_mean = wl_sigma`).
fn wave(wl: f64) -> Wave {
    Wave {
        wavelength: Some(wl),
        sigma: Some(wl),
        weights: Weights::One,
        band_half_width: 6.0,
        compensate_laser: true,
        auto_margin: true,
        crop: true,
        cosine: false,
    }
}

/// vltm's un-masked two-bounce column `T(a, ·)` over the reference volume, y-tal's wave, and
/// its count of aliased voxels.
fn column(src: &mut dyn vltm::io::RowSource, a: vltm_kernel::Point) -> (Vec<f64>, usize) {
    let o = probe::column(
        src,
        a,
        &volume(),
        ColumnGate::TwoBounce,
        Shell::ALL,
        &wave(0.4),
        Exec::default(),
    )
    .unwrap();
    (
        o.values.iter().map(|&v| v as f64).collect(),
        o.report.aliased,
    )
}

fn check_direct(name: &str, wl: f64) {
    // The streaming reader, as `vltm direct` uses it (rows read from the file on demand).
    let mut c = vltm::io::tal::open(&data(name, &format!("{name}.hdf5"))).unwrap();
    let vol = volume();
    let o = probe::direct(&mut c, &vol, &wave(wl), Exec::default()).unwrap();
    let ours: Vec<f64> = o.values.iter().map(|&v| v as f64).collect();
    let (theirs, shape) = read_c8_intensity(&data(name, "ref_direct.npy"));
    assert_eq!(shape, vol.shape);
    let r = pearson(&ours, &theirs);
    let (pa, pb) = (argmax(&ours), argmax(&theirs));
    println!(
        "{name}: Pearson {r:.5}, peak vltm {:?} y-tal {:?}",
        vol.points[pa], vol.points[pb]
    );
    assert!(r >= 0.99, "{name}: Pearson {r} < 0.99");
    assert_eq!(
        pa, pb,
        "{name}: peak voxel vltm {:?} vs y-tal {:?}",
        vol.points[pa], vol.points[pb]
    );
}

#[test]
fn direct_matches_ytal_two_patches() {
    check_direct("two_patches", 0.4);
}

#[test]
fn direct_matches_ytal_two_patches_direct_only() {
    check_direct("two_patches_direct_only", 0.4);
}

#[test]
fn direct_matches_ytal_line() {
    check_direct("line", 0.3);
}

#[test]
fn direct_matches_ytal_single() {
    check_direct("single", 0.2);
}

#[test]
fn column_matches_ytal_projector_camera() {
    for name in ["two_patches", "two_patches_direct_only"] {
        let mut c = vltm::io::tal::open(&data(name, &format!("{name}.hdf5"))).unwrap();
        let vol = volume();
        // Patch A's centre, voxel [5, 9, 6] of the reference volume.
        let a = vol.points[(5 * 16 + 9) * 20 + 6];
        assert!(
            (a[0] + 0.25).abs() < 1e-6 && (a[1] - 0.15).abs() < 1e-6 && (a[2] - 0.7).abs() < 1e-6
        );
        let (ours, aliased) = column(&mut c, a);
        let (theirs, _) = read_c8_intensity(&data(name, "ref_ltmcol_focusA.npy"));
        let r = pearson(&ours, &theirs);
        println!("{name}: column Pearson {r:.5}, aliased {aliased}");
        assert!(r >= 0.99, "{name}: column Pearson {r} < 0.99");
    }
}

/// The indirect-only column: the two captures differ only by the light that reached a second
/// hidden surface (the same random paths otherwise, `fixtures/ytal/README.md`), so the column of
/// their difference `H(two_patches) − H(two_patches_direct_only)` (the probes are linear in H)
/// is light that went from x_a to another surface. It must peak at x_b's voxel [11, 6, 12],
/// as y-tal's complex difference of its two PROJECTOR_CAMERA columns does, and agree with it
/// (Pearson ≥ 0.99 on the intensities).
#[test]
fn indirect_only_column_peaks_at_x_b_like_ytal() {
    let read = |name: &str| io::open(&data(name, &format!("{name}.hdf5"))).unwrap();
    let (full, ctrl) = (read("two_patches"), read("two_patches_direct_only"));
    assert_eq!(full.geometry, ctrl.geometry);
    let mut diff = full.clone();
    for (d, c) in diff.data.iter_mut().zip(&ctrl.data) {
        *d -= c;
    }
    let vol = volume();
    let idx = |[i, j, k]: [usize; 3]| (i * 16 + j) * 20 + k;
    let (a, b) = (vol.points[idx([5, 9, 6])], vol.points[idx([11, 6, 12])]);
    let (ours, _) = column(&mut diff, a);
    let (zf, _) = read_c8(&data("two_patches", "ref_ltmcol_focusA.npy"));
    let (zc, _) = read_c8(&data("two_patches_direct_only", "ref_ltmcol_focusA.npy"));
    let theirs: Vec<f64> = zf
        .iter()
        .zip(&zc)
        .map(|(f, c)| (f.0 - c.0).powi(2) + (f.1 - c.1).powi(2))
        .collect();
    let r = pearson(&ours, &theirs);
    let (pa, pb) = (argmax(&ours), argmax(&theirs));
    println!(
        "indirect-only column from {a:?}: peak vltm {:?}, y-tal {:?} (x_b {b:?}), Pearson {r:.5}",
        vol.points[pa], vol.points[pb]
    );
    assert_eq!(pb, idx([11, 6, 12]), "y-tal's indirect-only column peak");
    assert_eq!(
        pa,
        idx([11, 6, 12]),
        "vltm's indirect-only column peaks at {:?}",
        vol.points[pa]
    );
    assert!(r >= 0.99, "indirect-only column: Pearson {r} < 0.99");
}

/// A paired, non-confocal capture written by y-tal's own writer (`fixtures/tal/paired.hdf5`:
/// `T_Si`, `N_3` grids of 144 laser and 144 SPAD spots apart, on a bumpy relay surface; made
/// by `benches/ytal_paired.py`), imaged by `vltm direct`'s streaming tal reader against y-tal's
/// filtered backprojection `tal.reconstruct.fbp.solve(DIRECT_LIGHT)` with the same `pf`
/// filter (`wl_mean = wl_sigma = 0.15` m; vltm `--wavelength 0.15 --sigma 0.15 --weights one`,
/// no laser compensation: the histograms carry no laser falloff): Pearson ≥ 0.99 of the
/// max-normalised intensities and the same peak voxel.
#[test]
fn paired_direct_matches_ytal_fbp() {
    let mut c = vltm::io::tal::open(&support::fixture("tal/paired.hdf5")).unwrap();
    assert_eq!(c.scan_type(), vltm::io::tal::ScanType::Paired);
    assert!(vltm::io::RowSource::geometry(&c).paired_apart());
    let vol = Volume::parse("-0.4:0.4:17,-0.4:0.4:17,0.4:1.0:13").unwrap();
    let wave = Wave {
        compensate_laser: false,
        ..wave(0.15)
    };
    for path in [
        probe::EvalPath::Auto,
        probe::EvalPath::Band,
        probe::EvalPath::Lookup,
    ] {
        let exec = Exec {
            path,
            ..Exec::default()
        };
        let o = probe::direct(&mut c, &vol, &wave, exec).unwrap();
        let ours: Vec<f64> = o.values.iter().map(|&v| v as f64).collect();
        let (theirs, shape) = read_c8_intensity(&support::fixture("tal/paired_fbp.npy"));
        assert_eq!(shape, vol.shape);
        let r = pearson(&ours, &theirs);
        let (pa, pb) = (argmax(&ours), argmax(&theirs));
        println!(
            "paired ({path:?} → {:?}): Pearson {r:.5}, peak vltm {:?} y-tal {:?}",
            o.path, vol.points[pa], vol.points[pb]
        );
        assert!(r >= 0.99, "paired {path:?}: Pearson {r} < 0.99");
        assert_eq!(pa, pb, "paired {path:?}: peak voxel");
    }
}
