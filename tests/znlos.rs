//! Zaragoza Z-NLOS HDF5 captures through the command line, written to y-tal's description
//! (`tal/io/format.py`, `__convert_dict_znlos_to_tal`) with the pure-Rust writer `hdf5-pure`
//! from captures rendered by vltm's simulator:
//!
//! * the same capture in every Z-NLOS axis order gives `vltm direct` volumes equal to those
//!   of the original `.npz` (exhaustive and confocal);
//! * Z-NLOS times include the device legs: a capture rendered with the legs in its times,
//!   stored as Z-NLOS, images like the same scene rendered wall to wall;
//! * `vltm info` names the layout and the conventions; bad files exit 1 with one line naming
//!   the file and the dataset.
//!
//! With `VLTM_ZNLOS_KEEP=DIR` the files are also written to `DIR` (with the originals as
//! `.npz`), for `tests/reference/znlos_ytal.py`, which reads them with y-tal's own reader.

mod support;

use std::path::{Path, PathBuf};
use support::cmd::{TempDir, vltm};
use vltm::io::{self, Capture};
use vltm::sim::Scene;

/// Around patch A and B of `fixtures/scenes/two_patches.json`: 13 × 3 × 8 voxels.
const SPEC: &str = "-0.6:0.6:13,-0.1:0.1:3,0.5:1.2:8";
const SHAPE: [usize; 3] = [13, 3, 8];

/// Which of y-tal's four axis orders.
#[derive(Clone, Copy, Debug)]
enum Order {
    /// `(ly, lx, sy, sx, bounces, t, colours)`, grids `(X, Y, 3)`.
    Rows7,
    /// `(colours, t, bounces, sy, sx, ly, lx)`, grids `(3, Y, X)`.
    Time7,
    /// `(sx, sy, bounces, t, colours)` (confocal), grids `(X, Y, 3)`.
    Rows5,
    /// `(colours, t, bounces, sy, sx)` (confocal), grids `(3, Y, X)`.
    Time5,
}

/// Fractions of each sample put in each colour and each bounce (they sum to 1).
const COLOURS: [f32; 3] = [0.5, 0.25, 0.25];
const BOUNCES: [f32; 6] = [0.5, 0.125, 0.125, 0.125, 0.0625, 0.0625];

fn ok(args: &[&str]) -> String {
    let o = vltm(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "vltm {args:?} failed: {err}");
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The two-patch scene on an 8×8 grid (lasers × SPADs, or confocal), its times with the
/// device legs (`legs`) or wall to wall.
fn scene(confocal: bool, legs: bool) -> Capture {
    let json = std::fs::read_to_string(support::fixture("scenes/two_patches.json")).expect("scene");
    let mut v: serde_json::Value = serde_json::from_str(&json).expect("json");
    let setup = &mut v["setup"];
    if confocal {
        setup.as_object_mut().expect("setup").remove("spads");
        setup["confocal"] = true.into();
    }
    if legs {
        // Legs of 0.3–1.1 m each: start later, run longer.
        setup["legs_in_time"] = true.into();
        setup["t0"] = 1.4.into();
        setup["nt"] = 290.into();
    }
    Scene::from_json_str(&v.to_string(), "two_patches.json")
        .expect("scene")
        .render()
        .expect("render")
}

fn u(s: &[usize]) -> Vec<u64> {
    s.iter().map(|&d| d as u64).collect()
}

/// Writes `c` (legs in its times) as a Z-NLOS file in `order`, with every dataset y-tal's
/// converter reads; `skip` leaves one out, `bad_shape` writes `data` with 4 bounces (which
/// y-tal's tests reject for 7 axes; 5 axes are told apart by their grid axes only).
fn write_znlos(c: &Capture, order: Order, path: &Path, skip: &str, bad_shape: bool) {
    assert!(c.geometry.legs_in_time, "Z-NLOS times include the legs");
    write_znlos_colours(c, order, path, skip, bad_shape, &COLOURS);
}

/// [`write_znlos`] with the fractions `colours` of each sample in each colour (one per
/// colour), whatever the capture's legs.
fn write_znlos_colours(
    c: &Capture,
    order: Order,
    path: &Path,
    skip: &str,
    bad_shape: bool,
    colours: &[f32],
) {
    let g = &c.geometry;
    let nc = colours.len();
    let (nt, [lx, ly], [sx, sy]) = (g.nt, g.laser_shape, g.spad_shape);
    let nb = if bad_shape { 4 } else { 6 };
    let shape: Vec<usize> = match order {
        Order::Rows7 => vec![ly, lx, sy, sx, nb, nt, nc],
        Order::Time7 => vec![nc, nt, nb, sy, sx, ly, lx],
        Order::Rows5 => vec![lx, ly, nb, nt, nc],
        Order::Time5 => vec![nc, nt, nb, ly, lx],
    };
    let n: usize = shape.iter().product();
    let mut data = vec![0.0f32; n];
    let mut idx = vec![0usize; shape.len()];
    for x in data.iter_mut() {
        let k = &idx;
        // (ix, iy, isx, isy, t, colour, bounce) of this element.
        let (ix, iy, isx, isy, t, col, b) = match order {
            Order::Rows7 => (k[1], k[0], k[3], k[2], k[5], k[6], k[4]),
            Order::Time7 => (k[6], k[5], k[4], k[3], k[1], k[0], k[2]),
            Order::Rows5 => (k[0], k[1], 0, 0, k[3], k[4], k[2]),
            Order::Time5 => (k[4], k[3], 0, 0, k[1], k[0], k[2]),
        };
        let (l, s) = (ix * ly + iy, isx * sy + isy);
        *x = c.row(l)[s * nt + t] * colours[col] * BOUNCES[b % 6];
        for a in (0..idx.len()).rev() {
            idx[a] += 1;
            if idx[a] < shape[a] {
                break;
            }
            idx[a] = 0;
        }
    }
    let transposed = matches!(order, Order::Time7 | Order::Time5);
    let grid = |pts: &[vltm_kernel::Point], [nx, ny]: [usize; 2]| -> (Vec<f32>, Vec<usize>) {
        if transposed {
            let mut v = Vec::new();
            for comp in [0, 1, 2] {
                for j in 0..ny {
                    for i in 0..nx {
                        v.push(pts[i * ny + j][comp]);
                    }
                }
            }
            (v, vec![3, ny, nx])
        } else {
            (pts.iter().flatten().copied().collect(), vec![nx, ny, 3])
        }
    };
    let normals = |[nx, ny]: [usize; 2]| -> (Vec<f32>, Vec<usize>) {
        let pts = vec![[0.0f32, 0.0, 1.0]; nx * ny];
        grid(&pts, [nx, ny])
    };
    let mut b = hdf5_pure::FileBuilder::new();
    let mut put = |name: &str, v: &[f32], shape: &[usize]| {
        if name != skip {
            b.create_dataset(name)
                .with_f32_data(v)
                .with_shape(&u(shape));
        }
    };
    put("data", &data, &shape);
    let (v, s) = grid(&g.spads, g.spad_shape);
    put("cameraGridPositions", &v, &s);
    let (v, s) = grid(&g.lasers, g.laser_shape);
    put("laserGridPositions", &v, &s);
    let (v, s) = normals(g.spad_shape);
    put("cameraGridNormals", &v, &s);
    let (v, s) = normals(g.laser_shape);
    put("laserGridNormals", &v, &s);
    let f3 = |p: [f64; 3]| p.map(|x| x as f32);
    put("cameraPosition", &f3(g.sensor_origin), &[3, 1]);
    put("laserPosition", &f3(g.laser_origin), &[1, 3]);
    put("hiddenVolumePosition", &[0.0, 0.0, 0.8], &[3]);
    put("hiddenVolumeRotation", &[0.0, 0.0, 0.0], &[3]);
    put("hiddenVolumeSize", &[0.5], &[1]);
    put("cameraGridSize", &[1.0, 1.0], &[2]);
    put("isConfocal", &[if g.confocal { 1.0 } else { 0.0 }], &[1]);
    if skip != "deltaT" {
        b.create_dataset("deltaT")
            .with_f64_data(&[g.dt])
            .with_shape(&[1, 1]);
    }
    if skip != "t0" {
        b.create_dataset("t0")
            .with_f64_data(&[g.t0])
            .with_shape(&[]);
    }
    b.write(path).expect("write Z-NLOS");
}

fn direct(cap: &Path, out: &Path) -> Vec<f32> {
    probe(&["direct"], cap, out)
}

/// `vltm CMD… CAP --volume SPEC --out OUT`, the volume read back.
fn probe(cmd: &[&str], cap: &Path, out: &Path) -> Vec<f32> {
    let mut args = vec![cmd[0], cap.to_str().expect("utf-8")];
    args.extend(&cmd[1..]);
    args.extend(["--volume", SPEC, "--out", out.to_str().expect("utf-8")]);
    ok(&args);
    let (v, s) = vltm::export::npy::read_f32(out).expect("npy");
    assert_eq!(s, SHAPE);
    v
}

fn max_rel(a: &[f32], b: &[f32]) -> f64 {
    let m = b.iter().fold(0.0f64, |m, &x| m.max(f64::from(x).abs()));
    assert!(m > 0.0, "empty image");
    a.iter()
        .zip(b)
        .fold(0.0f64, |d, (&x, &y)| d.max(f64::from(x - y).abs()))
        / m
}

fn pearson(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (
        a.iter().map(|&x| f64::from(x)).sum::<f64>() / n,
        b.iter().map(|&x| f64::from(x)).sum::<f64>() / n,
    );
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a.iter().zip(b) {
        let (x, y) = (f64::from(x) - ma, f64::from(y) - mb);
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    }
    sab / (saa * sbb).sqrt()
}

fn argmax(v: &[f32]) -> usize {
    v.iter()
        .enumerate()
        .fold((0, f32::MIN), |a, (i, &x)| if x > a.1 { (i, x) } else { a })
        .0
}

/// Copies `files` to `$VLTM_ZNLOS_KEEP` if set (for the y-tal cross-check script).
fn keep(files: &[&Path]) {
    if let Some(dir) = std::env::var_os("VLTM_ZNLOS_KEEP") {
        let dir = PathBuf::from(dir);
        std::fs::create_dir_all(&dir).expect("keep dir");
        for f in files {
            std::fs::copy(f, dir.join(f.file_name().expect("name"))).expect("keep");
        }
    }
}

/// Every axis order, exhaustive and confocal: `vltm direct` (and `column`, `indirect`,
/// `direct --swap-roles`) on the Z-NLOS file equals the same on the original capture; and the legs are compensated: the capture rendered
/// with legs images like the one rendered wall to wall.
#[test]
fn direct_on_znlos_equals_direct_on_the_original() {
    let t = TempDir::new("znlos", "direct");
    for (confocal, orders) in [
        (false, [Order::Rows7, Order::Time7]),
        (true, [Order::Rows5, Order::Time5]),
    ] {
        let kind = if confocal { "confocal" } else { "exhaustive" };
        let c = scene(confocal, true);
        let orig = t.path(&format!("{kind}.npz"));
        io::npz::write(&c, &orig).expect("npz");
        let want = direct(&orig, &t.path("orig.npy"));
        let mut kept = vec![orig.clone()];
        for order in orders {
            let z = t.path(&format!("{kind}_{order:?}.hdf5"));
            write_znlos(&c, order, &z, "", false);
            let got = direct(&z, &t.path("z.npy"));
            let d = max_rel(&got, &want);
            println!("{kind} {order:?}: max |Z-NLOS − original| / max = {d:.2e}");
            assert!(d <= 1e-5, "{kind} {order:?}: {d:e}");
            // The rows themselves.
            let r = io::open(&z).expect("read Z-NLOS");
            assert_eq!(r.geometry, c.geometry, "{kind} {order:?}");
            let dd = r.data.iter().zip(&c.data).fold(0.0f32, |m, (a, b)| {
                m.max((a - b).abs() / b.abs().max(1e-30))
            });
            assert!(
                dd <= 1e-6,
                "{kind} {order:?}: samples differ by {dd:e} (relative)"
            );
            // The other probes (and a capture read whole for --swap-roles); a confocal
            // capture has no camera aperture for them.
            let others: &[&[&str]] = if confocal {
                &[]
            } else {
                &[
                    &["column", "--focus", "-0.45,0,0.8"],
                    &["indirect", "--epsilon", "0.2", "--min-separation", "0.3"],
                    &["direct", "--swap-roles"],
                ]
            };
            for cmd in others {
                let a = probe(cmd, &orig, &t.path("a.npy"));
                let b = probe(cmd, &z, &t.path("b.npy"));
                let d = max_rel(&b, &a);
                println!("{kind} {order:?} {cmd:?}: max |Z-NLOS − original| / max = {d:.2e}");
                assert!(d <= 1e-5, "{kind} {order:?} {cmd:?}: {d:e}");
            }
            kept.push(z);
        }
        keep(&kept.iter().map(PathBuf::as_path).collect::<Vec<_>>());

        // The same scene rendered wall to wall (no legs in the times).
        let wall = t.path(&format!("{kind}_wall.npz"));
        io::npz::write(&scene(confocal, false), &wall).expect("npz");
        let w = direct(&wall, &t.path("wall.npy"));
        // Pearson, and the Z-NLOS image's peak voxel is the wall-to-wall one's within 1 %
        // (the two patches are mirror images: their peaks are nearly equal).
        let p = pearson(&want, &w);
        let wmax = w[argmax(&w)];
        let at = w[argmax(&want)] / wmax;
        println!(
            "{kind}: legs in time (Z-NLOS) vs wall to wall: Pearson {p:.6}, peaks {} {}, wall-to-wall image at the Z-NLOS peak {at:.4} of its max, max |diff| / max {:.2e}",
            argmax(&want),
            argmax(&w),
            max_rel(&want, &w)
        );
        assert!(p >= 0.999 && at >= 0.99, "{kind}: Pearson {p}, {at}");
    }
}

/// `vltm info` names the layout, the scan and the conventions applied.
#[test]
fn info_names_the_layout_and_conventions() {
    let t = TempDir::new("znlos", "info");
    let c = scene(false, true);
    for (order, mem) in [
        (Order::Rows7, "streamed by row"),
        (Order::Time7, "read whole on the first row"),
    ] {
        let z = t.path("z.hdf5");
        write_znlos(&c, order, &z, "", false);
        let out = ok(&["info", z.to_str().expect("utf-8")]);
        print!("{out}");
        for want in [
            "Zaragoza Z-NLOS",
            &format!("layout {order:?}"),
            "tal scan     exhaustive",
            "device legs  included in the times",
            "deltaT = 0.02 m and t0 = 1.4 m",
            "summed       colours and bounces",
            mem,
            "lasers       64 = 8x8",
        ] {
            assert!(out.contains(want), "info lacks `{want}`:\n{out}");
        }
    }
}

/// Missing datasets and shapes y-tal does not recognise: exit 1, one line naming the file
/// and the dataset.
#[test]
fn bad_znlos_files_exit_1_naming_the_dataset() {
    let t = TempDir::new("znlos", "bad");
    let c = scene(false, true);
    for (skip, bad_shape, field) in [
        ("deltaT", false, "deltaT"),
        ("t0", false, "t0"),
        ("cameraGridPositions", false, "cameraGridPositions"),
        ("laserPosition", false, "laserPosition"),
        ("", true, "data"),
        ("data", false, "(layout)"),
    ] {
        let z = t.path(&format!("bad_{skip}{bad_shape}.hdf5"));
        let order = if bad_shape {
            Order::Time7
        } else {
            Order::Rows7
        };
        write_znlos(&c, order, &z, skip, bad_shape);
        let zs = z.to_str().expect("utf-8");
        for cmd in [vec!["info", zs], vec!["direct", zs, "--volume", SPEC]] {
            let o = vltm(&cmd);
            let err = String::from_utf8_lossy(&o.stderr).into_owned();
            assert_eq!(o.status.code(), Some(1), "{cmd:?}: {err}");
            let lines: Vec<&str> = err.lines().collect();
            assert_eq!(lines.len(), 1, "{cmd:?}: {err}");
            assert!(
                lines[0].starts_with("vltm: ") && lines[0].contains(zs) && lines[0].contains(field),
                "{cmd:?}: {err}"
            );
            println!("{field}: {}", lines[0]);
        }
    }
}

/// Not a test: writes the reading benchmark's Z-NLOS files (docs/performance.md, "Reading Z-NLOS HDF5") from
/// the capture `$VLTM_ZNLOS_BENCH` (an `.npz`, e.g. exh16's): `<stem>_<order>.hdf5` beside it
/// for the orders of its scan, with `$VLTM_ZNLOS_COLOURS` colours (default 1; 3 makes 18
/// values per sample) and 6 bounces, each sample split in power-of-two fractions so that the
/// sums are exact.
///
/// ```sh
/// VLTM_ZNLOS_BENCH=/tmp/exh16.npz cargo test --release --test znlos -- --ignored write_bench
/// ```
#[test]
#[ignore = "writes benchmark files; needs $VLTM_ZNLOS_BENCH"]
fn write_bench_files() {
    let Some(src) = std::env::var_os("VLTM_ZNLOS_BENCH") else {
        panic!("set VLTM_ZNLOS_BENCH to an .npz capture");
    };
    let src = PathBuf::from(src);
    let nc: usize = std::env::var("VLTM_ZNLOS_COLOURS").map_or(1, |v| v.parse().expect("colours"));
    let colours: Vec<f32> = match nc {
        1 => vec![1.0],
        3 => COLOURS.to_vec(),
        _ => panic!("VLTM_ZNLOS_COLOURS is 1 or 3"),
    };
    let c = io::open(&src).expect("capture");
    let orders = if c.geometry.confocal {
        [Order::Rows5, Order::Time5]
    } else {
        [Order::Rows7, Order::Time7]
    };
    let stem = src
        .file_stem()
        .expect("name")
        .to_string_lossy()
        .into_owned();
    for order in orders {
        let z = src.with_file_name(format!("{stem}_c{nc}_{order:?}.hdf5"));
        write_znlos_colours(&c, order, &z, "", false, &colours);
        println!("wrote {}", z.display());
    }
}
