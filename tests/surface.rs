//! `vltm surface` through the command line: the image on the fitted plane and the depth map
//! are written with the volume's shape, the summary names the plane, and bad options are
//! refused in one line before any work, naming the option. (The plane and the legibility of
//! a real sign are checked in `tests/real.rs`; the fit and the contrast step in the unit tests
//! of `vltm::probe::surface`.)

mod support;

use support::cmd::{TempDir, vltm};

/// Around patch A of the two-patch fixture: a slab in front of and behind it.
const SLAB: &str = "--volume=-0.65:-0.25:9,-0.2:0.2:9,0.5:1.1:25";

#[test]
fn surface_writes_the_image_on_its_plane_and_the_depth_map() {
    let t = TempDir::new("surface", "ok");
    let cap = support::fixture("two_patches.npz");
    let (out, png, depth) = (t.s("s.npy"), t.s("s.png"), t.s("d.npy"));
    let o = vltm(&[
        "surface",
        cap.to_str().unwrap(),
        SLAB,
        "--layers",
        "3",
        "--contrast",
        "0.1",
        "--out",
        &out,
        "--png",
        &png,
        "--depth",
        &depth,
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        text.contains("surface: plane z = ") && text.contains("of 81 columns"),
        "{text}"
    );
    let (image, shape) = vltm::export::npy::read_f32(&out).unwrap();
    assert_eq!(shape, [9, 9, 3]);
    assert!(image.iter().all(|v| v.is_finite()) && image.iter().any(|&v| v > 0.0));
    let (d, shape) = vltm::export::npy::read_f32(&depth).unwrap();
    assert_eq!(shape, [9, 9]);
    // Depths are slices of the slab; the brightest column is at patch A (-0.45, 0, ~0.8 m).
    assert!(d.iter().all(|z| (0.5..=1.1).contains(z)), "{d:?}");
    let a = d[4 * 9 + 4];
    assert!((0.7..=0.9).contains(&a), "depth at patch A's centre: {a}");
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
}

#[test]
fn bad_options_are_refused_naming_them() {
    let t = TempDir::new("surface", "bad");
    let cap = support::fixture("two_patches.npz");
    let cap = cap.to_str().unwrap();
    let out = t.s("x.npy");
    let cases: [(&[&str], &str); 6] = [
        (&["--floor", "1.5"], "`--floor`"),
        (&["--thickness=-1"], "`--thickness`"),
        (&["--layers", "0"], "`--layers`"),
        (&["--contrast", "0"], "`--contrast`"),
        (&["--depth", "d.png"], "`--depth`"),
        (&["--rows", "0:8"], "`--rows`"),
    ];
    for (extra, flag) in cases {
        let mut args = vec!["surface", cap, SLAB, "--out", &out];
        args.extend_from_slice(extra);
        let o = vltm(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {err}");
        assert!(
            err.contains(flag) && err.lines().count() == 1,
            "{extra:?}: {err}"
        );
        assert!(
            !std::path::Path::new(&out).exists(),
            "{extra:?} wrote an output"
        );
    }
    // A list of points has no columns to fit.
    let o = vltm(&[
        "surface",
        cap,
        "--volume",
        "0,0,0.8;0.1,0,0.8",
        "--out",
        &out,
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("grid volume"), "{err}");
}
