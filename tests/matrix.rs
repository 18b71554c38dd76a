//! The LTM as a matrix on the path-traced y-tal capture `two_patches` (`fixtures/ytal/`):
//! `probe::matrix` on Γ×Γ equals the column probe element by element, relighting with a
//! one-hot pattern equals the column and with two foci the sum of their amplitudes, and the
//! streamed row `T(·, x_b)` equals the column of the transposed capture (`--swap-roles`).

mod support;

use std::path::PathBuf;

use vltm::io::{self, RowSource};
use vltm::probe::{self, ColumnGate, EvalPath, Exec, Pattern, Shell, Wave};
use vltm::volume::Volume;
use vltm_kernel::Point;

/// The volume of the y-tal references (16 × 16 × 20 voxels, y-tal's).
const SPEC: &str = "-0.75:0.75:16,-0.75:0.75:16,0.4:1.35:20";
/// Patch A's and patch B's centres (`two_patches/scene.json`).
const X_A: Point = [-0.25, 0.15, 0.7];
const X_B: Point = [0.35, -0.15, 1.0];

fn capture() -> PathBuf {
    support::fixture("ytal/two_patches/two_patches.hdf5")
}

fn source() -> Box<dyn RowSource> {
    io::open_source(&capture()).expect("the two_patches capture of fixtures/ytal")
}

/// The band path: the reference every other path is checked against, and the one the
/// matrix uses.
fn band() -> Exec<'static> {
    Exec {
        path: EvalPath::Band,
        ..Exec::default()
    }
}

/// Γ of the references' volume at the default ε (as `vltm indirect` computes it).
fn gamma_points(wave: &Wave) -> Vec<Point> {
    let vol = Volume::parse(SPEC).expect("spec");
    let d = probe::direct(&mut *source(), &vol, wave, Exec::default()).expect("direct");
    let g = probe::gamma_mask(&d.values, 0.1);
    vol.points
        .iter()
        .zip(&g)
        .filter_map(|(p, &k)| k.then_some(*p))
        .collect()
}

/// |x − y| / max(|y|, tiny).
fn rel(x: f64, y: f64) -> f64 {
    (x - y).abs() / y.abs().max(f64::MIN_POSITIVE)
}

/// `vltm matrix --from gamma --to gamma` on `two_patches`: every element equals the column
/// probe `T(x_a, ·)` imaged over Γ, to 1e-6 relative (the target of issue 13).
#[test]
fn matrix_on_gamma_equals_the_column_probes() {
    let wave = Wave::default();
    let gamma = gamma_points(&wave);
    assert!(gamma.len() > 100, "Γ has {} voxels", gamma.len());
    let m = probe::matrix(&mut *source(), &gamma, &gamma, &wave, Exec::default()).expect("matrix");
    assert_eq!((m.n_from, m.n_to, m.passes), (gamma.len(), gamma.len(), 1));
    assert_eq!(m.report.rows, 64);
    let t = m.intensities();
    let to = Volume::points(gamma.clone()).expect("Γ as a point list");
    let (mut worst, mut worst_rel_max, mut compared) = (0.0f64, 0.0f64, 0usize);
    for (i, a) in gamma.iter().enumerate() {
        let col = probe::column(
            &mut *source(),
            *a,
            &to,
            ColumnGate::TwoBounce,
            Shell::ALL,
            &wave,
            band(),
        )
        .expect("column");
        let cmax = col.values.iter().copied().fold(0.0f32, f32::max) as f64;
        for (k, &c) in col.values.iter().enumerate() {
            let x = t[i * gamma.len() + k] as f64;
            worst = worst.max(rel(x, c as f64));
            worst_rel_max = worst_rel_max.max((x - c as f64).abs() / cmax);
            compared += 1;
        }
    }
    println!(
        "Γ×Γ = {0}×{0} elements ({compared} compared with {0} column probes): largest relative \
         difference {worst:.2e} per element, {worst_rel_max:.2e} of the column's maximum",
        gamma.len()
    );
    assert_eq!(compared, gamma.len() * gamma.len());
    assert!(worst <= 1e-6, "matrix vs column: {worst:.3e} relative");
}

/// Relighting: a one-hot pattern is the column; two foci give the sum of their amplitudes
/// (complex, so the intensity is not the sum of intensities); the weights scale amplitudes.
#[test]
fn relighting_is_linear_in_the_pattern() {
    let wave = Wave::default();
    let vol = Volume::parse("-0.75:0.75:8,-0.75:0.75:8,0.4:1.35:10").expect("spec");
    // One-hot: the column at x_a.
    let one = Pattern::parse("-0.25,0.15,0.7,1").expect("pattern");
    let r = probe::relight(&mut *source(), &one, &vol, &wave, Exec::default()).expect("relight");
    let col = probe::column(
        &mut *source(),
        X_A,
        &vol,
        ColumnGate::TwoBounce,
        Shell::ALL,
        &wave,
        band(),
    )
    .expect("column");
    let worst = r
        .output
        .values
        .iter()
        .zip(&col.values)
        .map(|(&x, &y)| rel(x as f64, y as f64))
        .fold(0.0, f64::max);
    println!("one-hot pattern vs column: largest relative difference {worst:.2e}");
    assert!(worst <= 1e-6, "one-hot relight vs column: {worst:.3e}");
    assert_eq!(r.passes, 1);
    // Two foci, weights 1 and −0.5: amplitudes add (against the matrix's rows).
    let two = Pattern::parse("-0.25,0.15,0.7,1;0.35,-0.15,1.0,-0.5").expect("pattern");
    let r2 = probe::relight(&mut *source(), &two, &vol, &wave, Exec::default()).expect("relight");
    let m = probe::matrix(
        &mut *source(),
        &[X_A, X_B],
        &vol.points,
        &wave,
        Exec::default(),
    )
    .expect("matrix");
    let n = vol.len();
    let (mut worst_amp, mut worst_int, mut coherent) = (0.0f64, 0.0f64, 0.0f64);
    for k in 0..n {
        let (a, b) = (m.amplitudes[k], m.amplitudes[n + k]);
        let (re, im) = (
            f64::from(a.re) - 0.5 * f64::from(b.re),
            f64::from(a.im) - 0.5 * f64::from(b.im),
        );
        let z = r2.amplitudes[k];
        let scale = (re * re + im * im).sqrt();
        worst_amp = worst_amp.max(((z.re - re).powi(2) + (z.im - im).powi(2)).sqrt() / scale);
        worst_int = worst_int.max(rel(r2.output.values[k] as f64, re * re + im * im));
        // How far the intensity is from the sum of intensities (interference).
        let incoherent = f64::from(a.norm_sqr()) + 0.25 * f64::from(b.norm_sqr());
        coherent = coherent.max(rel(re * re + im * im, incoherent));
    }
    println!(
        "two foci (w = 1, -0.5): amplitudes vs A(x_a,·) - 0.5·A(x_b,·) {worst_amp:.2e}, \
         intensities {worst_int:.2e}; interference changes intensities by up to {coherent:.2} relative to the sum of intensities"
    );
    // The matrix stores f32 amplitudes: 1e-6 is 16 ulp of f32; an intensity |A|² carries
    // twice its amplitude's relative error.
    assert!(
        worst_amp <= 1e-6 && worst_int <= 2e-6,
        "{worst_amp:.3e} {worst_int:.3e}"
    );
    assert!(coherent > 0.1, "the test needs interfering foci");
}

/// A row `T(·, x_b)` streamed by laser rows equals the column at x_b of the transposed
/// capture (`--swap-roles`, which holds the whole capture in memory).
#[test]
fn row_equals_the_swapped_column() {
    let wave = Wave::default();
    let vol = Volume::parse(SPEC).expect("spec");
    let r = probe::row(&mut *source(), X_B, &vol, &wave, Exec::default()).expect("row");
    let full = io::open(&capture()).expect("capture");
    let mut swapped = io::swap_roles(&full).expect("swap");
    let c = probe::column(
        &mut swapped,
        X_B,
        &vol,
        ColumnGate::TwoBounce,
        Shell::ALL,
        &wave,
        band(),
    )
    .expect("swapped column");
    assert_eq!(r.config.bins(), c.config.bins(), "same band");
    assert_eq!(r.report.aliased, 0);
    let cmax = c.values.iter().copied().fold(0.0f32, f32::max) as f64;
    let (mut worst, mut worst_of_max) = (0.0f64, 0.0f64);
    for (&x, &y) in r.values.iter().zip(&c.values) {
        if (y as f64) > 1e-3 * cmax {
            worst = worst.max(rel(x as f64, y as f64));
        }
        worst_of_max = worst_of_max.max((x as f64 - y as f64).abs() / cmax);
    }
    let peak = |v: &[f32]| (0..v.len()).max_by(|&i, &j| v[i].total_cmp(&v[j])).unwrap();
    println!(
        "row vs swapped column over {} voxels: {worst:.2e} relative (voxels above 1e-3 of the \
         maximum), {worst_of_max:.2e} of the maximum; peaks at voxel {} / {}",
        vol.len(),
        peak(&r.values),
        peak(&c.values)
    );
    assert_eq!(peak(&r.values), peak(&c.values));
    assert!(
        worst <= 1e-5 && worst_of_max <= 1e-6,
        "{worst:.3e} {worst_of_max:.3e}"
    );
}
