//! Unit tests of the analysis by synthesis: surfel checks, the fit recovering what the
//! renderer made (reflectances, delay, response width), the subtraction, the refinement.

use super::render::{Renderer, SUB, bin, blurred_prefix, kernel};
use super::*;
use crate::io::capture::Capture;
use crate::sim::{Aperture, Scene, Setup};

const EXEC: Exec<'static> = Exec {
    progress: None,
    path: crate::exec::EvalPath::Auto,
};

fn geometry() -> Geometry {
    let mut g = Scene::new(Setup::new(
        Aperture::grid([4, 4], [1.0, 1.0], [0.0, 0.0]),
        Aperture::grid([4, 4], [1.0, 1.0], [0.0, 0.0]),
        300,
        0.01,
    ))
    .geometry();
    g.t0 = 1.0;
    g
}

/// Two small tilted patches facing the wall, 5 × 5 surfels each, one cluster each, one patch
/// each.
fn patches(dz: f64) -> Surfels {
    let (mut p, mut n, mut a, mut c) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (ci, (x0, z0, tilt)) in [(-0.2, 0.8 + dz, 0.3f64), (0.25, 0.95 + dz, -0.2)]
        .into_iter()
        .enumerate()
    {
        let len = (1.0 + tilt * tilt).sqrt();
        for i in 0..5 {
            for j in 0..5 {
                let (u, v) = (i as f64 * 0.03 - 0.06, j as f64 * 0.03 - 0.06);
                p.push([x0 + u, v, z0 + tilt * u]);
                n.push([tilt / len, 0.0, -1.0 / len]);
                a.push(0.03 * 0.03 * len);
                c.push(ci);
            }
        }
    }
    let mut s = Surfels::new(p, n, a, c).unwrap();
    s.patches = vec![0..25, 25..50];
    s
}

/// A capture rendered by the model itself: reflectance per cluster, a delay (fine samples)
/// and a response width (bins).
fn render(g: &Geometry, s: &Surfels, albedo: &[f64], shift: isize, width: f64) -> Capture {
    let scale = (0..g.lasers.len()).map(|l| g.laser_falloff_at(l)).collect();
    let r = Renderer::new(g, s.clone(), scale, 4.0);
    let kern = kernel(width * SUB as f64);
    let (mut fine, mut pre, mut m) = (Vec::new(), Vec::new(), vec![0.0; g.nt]);
    let mut data = vec![0.0f32; g.lasers.len() * g.spads.len() * g.nt];
    for l in 0..g.lasers.len() {
        let row = r.laser_row(g, l);
        for sp in 0..g.spads.len() {
            r.spad(g, &row, sp, &mut fine);
            let out = &mut data[(l * g.spads.len() + sp) * g.nt..][..g.nt];
            for (c, a) in albedo.iter().enumerate() {
                blurred_prefix(&fine[c * r.nf..(c + 1) * r.nf], &kern, &mut pre);
                bin(&pre, r.pad, shift, &mut m);
                out.iter_mut()
                    .zip(&m)
                    .for_each(|(o, x)| *o += (a * x) as f32);
            }
        }
    }
    Capture::new(g.clone(), data, std::path::Path::new("rendered")).unwrap()
}

fn energy(c: &mut dyn RowSource) -> f64 {
    let mut row = Vec::new();
    (0..c.geometry().lasers.len())
        .map(|l| {
            c.read_row(l, &mut row).unwrap();
            row.iter().map(|x| f64::from(*x).powi(2)).sum::<f64>()
        })
        .sum()
}

#[test]
fn surfels_are_checked() {
    let ok = || {
        (
            vec![[0.0, 0.0, 1.0]],
            vec![[0.0, 0.0, -1.0]],
            vec![1e-4],
            vec![0],
        )
    };
    assert!(Surfels::new(vec![], vec![], vec![], vec![]).is_err());
    let (p, n, a, _) = ok();
    assert!(Surfels::new(p, n, a, vec![1]).is_err(), "cluster 0 empty");
    let (p, _, a, c) = ok();
    assert!(
        Surfels::new(p, vec![[0.0, 0.0, -2.0]], a, c).is_err(),
        "not unit"
    );
    let (p, n, _, c) = ok();
    assert!(Surfels::new(p, n, vec![0.0], c).is_err(), "zero area");
    let (_, n, a, c) = ok();
    assert!(Surfels::new(vec![[f64::NAN, 0.0, 1.0]], n, a, c).is_err());
    let (p, n, a, c) = ok();
    assert!(Surfels::new(p, n, a, c).is_ok());
}

#[test]
fn the_fit_recovers_what_the_renderer_made_and_subtracts_it() {
    let g = geometry();
    let s = patches(0.0);
    let mut cap = render(&g, &s, &[2.0, 0.5], 3, 0.5);
    let before = energy(&mut cap);
    let opts = SynthOptions {
        per_histogram: false,
        ..SynthOptions::default()
    };
    let m = SynthModel::fit(&mut cap, s.clone(), &opts, EXEC).unwrap();
    assert_eq!(m.width, 0.5);
    assert_eq!(m.shift, 3.0 / SUB as f64);
    assert!((m.albedo[0] / 2.0 - 1.0).abs() < 1e-5, "{:?}", m.albedo);
    assert!((m.albedo[1] / 0.5 - 1.0).abs() < 1e-5, "{:?}", m.albedo);
    assert!(m.explained > 1.0 - 1e-9, "{}", m.explained);
    let after = energy(&mut Synthesized::new(&mut cap, &m));
    assert!(after < 1e-10 * before, "{after} of {before}");
    // Per histogram: the same, and a wrong albedo in the global fit does not matter.
    let m = SynthModel::fit(&mut cap, s, &SynthOptions::default(), EXEC).unwrap();
    let after = energy(&mut Synthesized::new(&mut cap, &m));
    assert!(after < 1e-10 * before, "{after} of {before}");
}

/// The model's histograms kept by the fit and the same histograms rendered again per row
/// (when the budget holds only the tables) subtract the same values, bit for bit.
#[test]
fn kept_model_histograms_equal_a_render_per_row() {
    let g = geometry();
    let s = patches(0.0);
    let mut cap = render(&g, &s, &[2.0, 0.5], 3, 0.5);
    // Noise the model does not hold, so that the per-histogram gains differ.
    for (i, x) in cap.data.iter_mut().enumerate() {
        *x += 1e-4 * ((i * 7919 % 101) as f32 / 101.0);
    }
    let kept = SynthModel::fit(&mut cap, s.clone(), &SynthOptions::default(), EXEC).unwrap();
    let tables = Renderer::table_bytes(s.len(), g.spads.len());
    let opts = SynthOptions {
        max_bytes: tables,
        ..SynthOptions::default()
    };
    let again = SynthModel::fit(&mut cap, s, &opts, EXEC).unwrap();
    assert!(!kept.kept.is_empty() && again.kept.is_empty());
    assert_eq!(kept.explained, again.explained);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut subtracted = 0.0f64;
    for l in 0..g.lasers.len() {
        Synthesized::new(&mut cap, &kept)
            .read_row(l, &mut a)
            .unwrap();
        Synthesized::new(&mut cap, &again)
            .read_row(l, &mut b)
            .unwrap();
        assert_eq!(a, b, "row {l}");
        let mut raw = Vec::new();
        cap.read_row(l, &mut raw).unwrap();
        subtracted += raw
            .iter()
            .zip(&a)
            .map(|(x, y)| f64::from(x - y).abs())
            .sum::<f64>();
    }
    assert!(subtracted > 0.0, "the model subtracted nothing");
}

#[test]
fn light_the_model_does_not_hold_is_kept() {
    let g = geometry();
    let s = patches(0.0);
    let direct = render(&g, &s, &[2.0, 0.5], 0, 0.0);
    // "Indirect" light: a late bump in every histogram, 200 bins after t0, far from the
    // direct returns.
    let mut all = direct.clone();
    let nt = g.nt;
    for h in all.data.chunks_mut(nt) {
        h[250] += 1e-3;
    }
    let m = SynthModel::fit(&mut all, s, &SynthOptions::default(), EXEC).unwrap();
    let mut c = Synthesized::new(&mut all, &m);
    let mut row = Vec::new();
    for l in 0..g.lasers.len() {
        c.read_row(l, &mut row).unwrap();
        for h in row.chunks(nt) {
            assert!((h[250] - 1e-3).abs() < 1e-6, "{}", h[250]);
        }
    }
}

#[test]
fn the_refinement_finds_the_surface_and_never_loses_ground() {
    let g = geometry();
    let mut cap = render(&g, &patches(0.0), &[1.0, 1.0], 0, 0.0);
    let off = patches(0.012);
    let scale: Vec<f64> = (0..g.lasers.len()).map(|l| g.laser_falloff_at(l)).collect();
    let r = refine(&mut cap, &off, &scale, 5, 0.01, EXEC).unwrap();
    assert!(r.after > r.before, "{} -> {}", r.before, r.after);
    // Unblurred returns binned whole: a depth a fraction of a millimetre off moves some of
    // them across a bin edge, so the explained energy stays below 1.
    assert!(r.after > 0.9, "{}", r.after);
    // The patches' centres moved back to within 1 mm of their true depth (their tilts may
    // differ a little: unblurred returns binned whole leave a flat residual around the truth).
    let truth = patches(0.0);
    for r_ in &r.surfels.patches {
        let mean = |pts: &[[f64; 3]]| pts[r_.clone()].iter().map(|p| p[2]).sum::<f64>() / 25.0;
        let (got, want) = (mean(&r.surfels.points), mean(&truth.points));
        assert!((got - want).abs() < 1e-3, "{got} vs {want}");
    }
}

#[test]
fn surfels_from_a_direct_volume_lie_on_its_bright_depths() {
    let vol = crate::volume::Volume::parse("-0.2:0.2:5,-0.2:0.2:5,0.5:1.5:11").unwrap();
    // A plane z = 1 + 0.2 x seen as a Gaussian ridge along z.
    let values: Vec<f32> = vol
        .points
        .iter()
        .map(|p| {
            let z = 1.0 + 0.2 * p[0];
            (-((p[2] - z) / 0.1).powi(2)).exp()
        })
        .collect();
    let s = Surfels::from_direct(&vol, &values, 0.1, 2, 0.0).unwrap();
    assert_eq!(s.patches.len(), 25);
    assert_eq!(s.clusters, 1);
    for (p, n) in s.points.iter().zip(&s.normals) {
        assert!((p[2] - (1.0 + 0.2 * p[0])).abs() < 0.01, "{p:?}");
        assert!(
            n[2] < 0.0 && n[0] > 0.0,
            "{n:?} faces the wall, tilted with the plane"
        );
    }
    assert!(
        Surfels::from_direct(&vol, &values, 0.1, 2, 1.2).is_err(),
        "behind the wall"
    );
    assert!(
        Surfels::from_direct(&vol, &values, 0.0, 2, 0.0).is_err(),
        "epsilon"
    );
}

/// A facet through `centre` turned `yaw` radians about +y (normal toward the wall), `w × h`
/// metres about its centre.
fn facet(centre: [f64; 3], yaw: f64, w: f64, h: f64, cluster: usize) -> Facet {
    let normal = [yaw.sin(), 0.0, -yaw.cos()];
    let v = [0.0, 1.0, 0.0];
    let u = [-normal[2], 0.0, normal[0]];
    Facet {
        centre,
        normal,
        u,
        v,
        extent: [-0.5 * w, 0.5 * w, -0.5 * h, 0.5 * h],
        cluster,
    }
}

/// Facet options growing at most `n` facets, 40 sweeps.
fn grown(n: usize) -> FacetOptions {
    FacetOptions {
        sweeps: 40,
        grow: n,
        ..FacetOptions::default()
    }
}

fn facet_surfels(f: &[Facet]) -> Surfels {
    FacetFit {
        facets: f.to_vec(),
        amplitudes: vec![1.0; f.len()],
        before: 0.0,
        after: 0.0,
        sweeps: 0,
        grown: 0,
    }
    .surfels(0.01, true)
    .unwrap()
}

/// Column patches (one surfel each, `pitch` apart in x and y) sampling the depth map of
/// `planes`: per column the nearest plane's depth whose x range holds it.
fn columns(planes: &[(f64, f64, f64, f64)], pitch: f64) -> Surfels {
    // Each plane: z = z0 + slope · x over x ∈ [x0, x1].
    let (mut p, mut n, mut a, mut c) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for i in -8..=8 {
        let x = i as f64 * pitch;
        let Some(&(z0, slope, _, _)) = planes.iter().find(|q| x >= q.2 && x <= q.3) else {
            continue;
        };
        for j in -4..=4 {
            let y = j as f64 * pitch;
            let len = (1.0 + slope * slope).sqrt();
            p.push([x, y, z0 + slope * x]);
            n.push([slope / len, 0.0, -1.0 / len]);
            a.push(pitch * pitch);
            c.push(0);
        }
    }
    let k = p.len();
    let mut s = Surfels::new(p, n, a, c).unwrap();
    s.patches = (0..k).map(|i| i..i + 1).collect();
    s
}

#[test]
fn facets_split_a_fold_and_keep_a_plane_whole() {
    // One plane tilted 30°: one facet, its normal exact.
    let t = 30f64.to_radians().tan();
    let one = facets_from_surfels(&columns(&[(0.9, t, -0.4, 0.4)], 0.05), 0.01, 0.05).unwrap();
    assert_eq!(one.len(), 1);
    let n = one[0].normal;
    let want = [t, 0.0, -1.0].map(|x| x / (1.0 + t * t).sqrt());
    assert!((0..3).all(|i| (n[i] - want[i]).abs() < 1e-9), "{n:?}");
    // The plane's extent along u: 0.8 m of columns, in x, widened by half a pitch each side,
    // measured along the tilted plane.
    let wu = one[0].extent[1] - one[0].extent[0];
    assert!(
        (wu - (0.8 * (1.0 + t * t).sqrt() + 0.05)).abs() < 1e-9,
        "{wu}"
    );
    // A concave 90° fold (the corner): two facets at ±45°.
    let fold = columns(&[(1.0, 1.0, -0.4, 0.0), (1.0, -1.0, 0.0 + 1e-9, 0.4)], 0.05);
    let two = facets_from_surfels(&fold, 0.01, 0.05).unwrap();
    assert_eq!(two.len(), 2, "{two:?}");
    for f in &two {
        assert!(
            (f.normal[0].abs() - 0.5f64.sqrt()).abs() < 1e-6,
            "{:?}",
            f.normal
        );
        assert!(f.normal[2] < 0.0, "faces the wall");
    }
    // A plane bent by 20° (a blurred edge, not a fold) stays one facet.
    let s20 = 20f64.to_radians().tan();
    let bent = columns(&[(1.0, 0.0, -0.4, 0.0), (1.0, s20, 1e-9, 0.4)], 0.05);
    assert_eq!(facets_from_surfels(&bent, 0.005, 0.05).unwrap().len(), 1);
    // Bad input.
    let mut bare = fold.clone();
    bare.patches.clear();
    assert!(
        facets_from_surfels(&bare, 0.01, 0.05).is_err(),
        "no patches"
    );
    assert!(facets_from_surfels(&fold, 0.0, 0.05).is_err(), "split 0");
    assert!(
        facets_from_surfels(&fold, 0.01, f64::NAN).is_err(),
        "pitch NaN"
    );
    let few = columns(&[(1.0, 0.0, -0.01, 0.01)], 0.05);
    let few = Surfels {
        patches: few.patches[..3].to_vec(),
        ..few
    };
    assert!(facets_from_surfels(&few, 0.01, 0.05).is_err(), "3 columns");
}

#[test]
fn refined_facets_find_the_pose_and_edges_the_capture_was_rendered_with() {
    let g = geometry();
    let scale: Vec<f64> = (0..g.lasers.len()).map(|l| g.laser_falloff_at(l)).collect();
    let truth = facet([0.05, 0.0, 0.8], 20f64.to_radians(), 0.3, 0.3, 0);
    let mut cap = render(&g, &facet_surfels(&[truth]), &[1.0], 0, 0.0);
    // Start 1 cm off along the normal, 3° off in yaw, the edges 2–4 cm off.
    let mut start = facet([0.05, 0.0, 0.81], 23f64.to_radians(), 0.34, 0.26, 0);
    start.extent[0] -= 0.02;
    let fit = refine_facets(&mut cap, &[start], &scale, &grown(0), EXEC).unwrap();
    assert!(fit.before < 0.9, "the start is off: {}", fit.before);
    assert!(
        fit.after > 0.995,
        "explained {} -> {}",
        fit.before,
        fit.after
    );
    let f = fit.facets[0];
    let cos: f64 = (0..3).map(|i| f.normal[i] * truth.normal[i]).sum();
    // Measured: 1.1° and 0.2 mm; the 4 × 4 wall constrains the tilt less than the offset.
    assert!(cos.acos().to_degrees() < 1.5, "normal {:?}", f.normal);
    let off: f64 = (0..3)
        .map(|i| (f.centre[i] - truth.centre[i]) * truth.normal[i])
        .sum();
    assert!(off.abs() < 0.003, "offset {off}");
    assert!(
        (f.area() - truth.area()).abs() < 0.1 * truth.area(),
        "area {}",
        f.area()
    );
}

#[test]
fn a_face_the_direct_light_missed_is_grown_from_its_neighbour() {
    let g = geometry();
    let scale: Vec<f64> = (0..g.lasers.len()).map(|l| g.laser_falloff_at(l)).collect();
    // A convex 90° edge facing the wall (a box's corner): faces at −45° and +45°.
    let a = facet(
        [-0.1, 0.0, 0.8],
        -45f64.to_radians(),
        0.2 * 2f64.sqrt(),
        0.3,
        0,
    );
    let b = facet(
        [0.1, 0.0, 0.8],
        45f64.to_radians(),
        0.2 * 2f64.sqrt(),
        0.3,
        0,
    );
    let mut cap = render(&g, &facet_surfels(&[a, b]), &[1.0, 1.0], 0, 0.0);
    let alone = refine_facets(&mut cap, &[a], &scale, &grown(0), EXEC).unwrap();
    let fit = refine_facets(&mut cap, &[a], &scale, &FacetOptions::default(), EXEC).unwrap();
    assert!(fit.grown >= 1, "grown {}", fit.grown);
    assert!(
        fit.after > 0.999 && alone.after < 0.98,
        "explained alone {}, grown {}",
        alone.after,
        fit.after
    );
    // The grown facet is b's plane.
    let f = fit.facets[1];
    let cos: f64 = (0..3).map(|i| f.normal[i] * b.normal[i]).sum();
    assert!(cos.acos().to_degrees() < 3.0, "grown normal {:?}", f.normal);
}

#[test]
fn facet_refinement_refuses_bad_input() {
    let g = geometry();
    let scale: Vec<f64> = (0..g.lasers.len()).map(|l| g.laser_falloff_at(l)).collect();
    let f = facet([0.0, 0.0, 0.8], 0.0, 0.2, 0.2, 0);
    let mut cap = render(&g, &facet_surfels(&[f]), &[1.0], 0, 0.0);
    assert!(
        refine_facets(&mut cap, &[], &scale, &grown(0), EXEC).is_err(),
        "no facet"
    );
    assert!(
        refine_facets(&mut cap, &[f], &scale[1..], &grown(0), EXEC).is_err(),
        "scale"
    );
    let mut bad = |o: FacetOptions| refine_facets(&mut cap, &[f], &scale, &o, EXEC).is_err();
    assert!(
        bad(FacetOptions {
            pitch: 0.0,
            ..grown(0)
        }),
        "pitch"
    );
    assert!(
        bad(FacetOptions {
            grow_gain: 1.0,
            ..grown(0)
        }),
        "grow_gain"
    );
    assert!(
        bad(FacetOptions {
            bounds: Some([[0.0, 0.0, 2.0], [1.0, 1.0, 1.0]]),
            ..grown(0)
        }),
        "bounds"
    );
    let g0 = geometry();
    let mut dark = Capture::new(
        g0.clone(),
        vec![0.0; g0.lasers.len() * g0.spads.len() * g0.nt],
        std::path::Path::new("dark"),
    )
    .unwrap();
    assert!(
        refine_facets(&mut dark, &[f], &scale, &grown(0), EXEC).is_err(),
        "no energy"
    );
    let w = geometry_wavelength(&g).unwrap();
    assert!((w - 0.5 / 3.0).abs() < 1e-6, "{w}");
}

/// The normal equations of a histogram bin and sum only the bins a cluster's support
/// reaches: against the plain sums over every bin they are the same numbers, for delays
/// that move the returns across the window and out of it at both ends, with and without a
/// blur (equal as numbers: an empty sum is −0); the bins left out are zero, and the spans
/// are not the whole window.
#[test]
fn normal_equations_skip_only_zero_bins() {
    let g = geometry();
    let r = Renderer::new(&g, patches(0.0), vec![1.0; g.lasers.len()], 4.0);
    let c_n = r.surfels.clusters;
    let hist: Vec<f32> = (0..g.nt).map(|i| ((i * 37) % 11) as f32 - 3.0).collect();
    let (mut gm, mut b) = (vec![0.0; c_n * c_n], vec![0.0; c_n]);
    let mut full = vec![0.0; g.nt];
    let mut narrower = false;
    for width in [0.0, 0.75] {
        let kern = kernel(width * SUB as f64);
        let mut sc = Scratch::default();
        let row = r.laser_row(&g, 5);
        sc.render(&r, &g, &row, 6, &kern);
        for shift in (-2400..=2400).step_by(37) {
            sc.normal(r.pad, shift, &hist, &mut gm, &mut b);
            let bins: Vec<Vec<f64>> = (0..c_n)
                .map(|c| {
                    bin(&sc.prefix[c], r.pad, shift, &mut full);
                    full.clone()
                })
                .collect();
            for i in 0..c_n {
                let (n0, n1) = sc.spans[i];
                narrower |= n1 - n0 < g.nt;
                assert!(
                    bins[i][..n0]
                        .iter()
                        .chain(&bins[i][n1..])
                        .all(|x| *x == 0.0),
                    "a nonzero bin outside [{n0}, {n1}) at shift {shift}"
                );
                let want: f64 = bins[i]
                    .iter()
                    .zip(&hist)
                    .map(|(m, y)| m * f64::from(*y))
                    .sum();
                assert!(b[i] == want, "b[{i}] at shift {shift}: {} != {want}", b[i]);
                for j in 0..c_n {
                    let want: f64 = bins[i].iter().zip(&bins[j]).map(|(x, y)| x * y).sum();
                    assert!(gm[i * c_n + j] == want, "G[{i}, {j}] at shift {shift}");
                }
            }
        }
    }
    assert!(narrower, "every span was the whole window");
}
