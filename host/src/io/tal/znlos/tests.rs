//! Unit tests of the Z-NLOS reader: every axis order gives the same rows, from files written
//! to y-tal's description with the pure-Rust writer `hdf5-pure`.

use super::*;

fn scratch(test: &str) -> crate::scratch::Scratch {
    crate::scratch::Scratch::dir(&format!("znlos-{test}"))
}

/// The value of laser (ix, iy), SPAD (sx, sy), bin n, colour c, bounce b.
fn value(ix: usize, iy: usize, sx: usize, sy: usize, n: usize, c: usize, b: usize) -> f32 {
    (n * 10_000 + ix * 1000 + iy * 100 + sx * 10 + sy) as f32
        * [0.5, 0.25, 0.25][c]
        * [0.5, 0.1, 0.1, 0.1, 0.1, 0.1][b]
}

/// `data` of `layout` for lasers (lx, ly), SPADs (sx, sy), nt bins, 3 colours, 6 bounces.
fn data(layout: ZnlosLayout, l: [usize; 2], s: [usize; 2], nt: usize) -> (Vec<f32>, Vec<usize>) {
    let (lx, ly, sx, sy) = (l[0], l[1], s[0], s[1]);
    let shape = match layout {
        ZnlosLayout::Rows7 => vec![ly, lx, sy, sx, 6, nt, 3],
        ZnlosLayout::Time7 => vec![3, nt, 6, sy, sx, ly, lx],
        ZnlosLayout::Rows5 => vec![sx, sy, 6, nt, 3],
        ZnlosLayout::Time5 => vec![3, nt, 6, sy, sx],
    };
    let n: usize = shape.iter().product();
    let mut v = Vec::with_capacity(n);
    let mut idx = vec![0usize; shape.len()];
    for _ in 0..n {
        let i = |r: &[usize]| r.to_vec();
        let [a, b, c, d, e, f, g] = match layout {
            ZnlosLayout::Rows7 => {
                // (ly, lx, sy, sx, b, t, c)
                let k = i(&idx);
                [k[1], k[0], k[3], k[2], k[5], k[6], k[4]]
            }
            ZnlosLayout::Time7 => {
                let k = i(&idx);
                [k[6], k[5], k[4], k[3], k[1], k[0], k[2]]
            }
            ZnlosLayout::Rows5 => {
                let k = i(&idx);
                [0, 0, k[0], k[1], k[3], k[4], k[2]]
            }
            ZnlosLayout::Time5 => {
                let k = i(&idx);
                [0, 0, k[4], k[3], k[1], k[0], k[2]]
            }
        };
        v.push(value(a, b, c, d, e, f, g));
        for k in (0..idx.len()).rev() {
            idx[k] += 1;
            if idx[k] < shape[k] {
                break;
            }
            idx[k] = 0;
        }
    }
    (v, shape)
}

fn at(i: usize, j: usize) -> [f32; 3] {
    [0.1 * i as f32 - 0.3, 0.1 * j as f32 - 0.2, 0.0]
}

fn grid(nx: usize, ny: usize, transposed: bool) -> (Vec<f32>, Vec<usize>) {
    points(nx, ny, transposed, at)
}

/// Values `f(i, j)` (3 each) of an `nx × ny` grid, stored `(X, Y, 3)` or `(3, Y, X)`.
fn points(
    nx: usize,
    ny: usize,
    transposed: bool,
    f: impl Fn(usize, usize) -> [f32; 3],
) -> (Vec<f32>, Vec<usize>) {
    let mut v = Vec::new();
    if transposed {
        for c in 0..3 {
            for j in 0..ny {
                for i in 0..nx {
                    v.push(f(i, j)[c]);
                }
            }
        }
        (v, vec![3, ny, nx])
    } else {
        for i in 0..nx {
            for j in 0..ny {
                v.extend(f(i, j));
            }
        }
        (v, vec![nx, ny, 3])
    }
}

fn write(
    path: &Path,
    layout: ZnlosLayout,
    l: [usize; 2],
    s: [usize; 2],
    nt: usize,
    skip: &str,
    transposed: bool,
) {
    builder(layout, l, s, nt, skip, transposed)
        .write(path)
        .unwrap();
}

/// The file of [`write`], not written yet.
fn builder(
    layout: ZnlosLayout,
    l: [usize; 2],
    s: [usize; 2],
    nt: usize,
    skip: &str,
    transposed: bool,
) -> hdf5_pure::FileBuilder {
    use hdf5_pure::FileBuilder;
    let mut b = FileBuilder::new();
    if skip != "data" {
        let (v, shape) = data(layout, l, s, nt);
        b.create_dataset("data")
            .with_f32_data(&v)
            .with_shape(&u(&shape));
    }
    let lgrid = if matches!(layout, ZnlosLayout::Rows5 | ZnlosLayout::Time5) {
        grid(s[0], s[1], transposed)
    } else {
        grid(l[0], l[1], transposed)
    };
    for (name, (v, shape)) in [
        ("cameraGridPositions", grid(s[0], s[1], transposed)),
        ("laserGridPositions", lgrid),
    ] {
        if skip != name {
            b.create_dataset(name)
                .with_f32_data(&v)
                .with_shape(&u(&shape));
        }
    }
    for (name, v) in [
        ("cameraPosition", [0.5f32, 0.1, 0.4]),
        ("laserPosition", [-0.5, 0.0, 0.25]),
    ] {
        if skip != name {
            b.create_dataset(name).with_f32_data(&v).with_shape(&[3, 1]);
        }
    }
    for (name, v) in [("deltaT", 0.01f64), ("t0", 1.25)] {
        if skip != name {
            b.create_dataset(name).with_f64_data(&[v]).with_shape(&[1]);
        }
    }
    b
}

/// `laserGridNormals` / `cameraGridNormals` are read as y-tal's converter reads them (the
/// tal grids' normals, laid out as the positions, stored either way; grids of 2×5 and 4×2,
/// no axis of 3 that would make the layout ambiguous), per point; a normal of zero length
/// is an error naming the dataset.
#[test]
fn grid_normals_are_read_as_ytal_converts_them() {
    let dir = scratch("normals");
    let ln = |i: usize, j: usize| [0.02 * i as f32, 0.01 * j as f32, 1.0];
    let cn = |i: usize, j: usize| [-0.03 * j as f32, 0.05 * i as f32, 1.0];
    for transposed in [false, true] {
        let mut b = builder(ZnlosLayout::Rows7, [2, 5], [4, 2], 4, "", transposed);
        for (name, (v, shape)) in [
            ("laserGridNormals", points(2, 5, transposed, ln)),
            ("cameraGridNormals", points(4, 2, transposed, cn)),
        ] {
            b.create_dataset(name)
                .with_f32_data(&v)
                .with_shape(&u(&shape));
        }
        let p = dir.join(format!("n{transposed}.hdf5"));
        b.write(&p).unwrap();
        let r = open(&p).unwrap();
        let g = r.geometry();
        let ij = |p: Point| {
            (
                ((p[0] + 0.3) / 0.1).round() as usize,
                ((p[1] + 0.2) / 0.1).round() as usize,
            )
        };
        assert_eq!(g.normals.lasers.len(), 10);
        assert_eq!(g.normals.spads.len(), 8);
        for (p, n) in g.lasers.iter().zip(&g.normals.lasers) {
            let (i, j) = ij(*p);
            assert_eq!(*n, ln(i, j), "laser at {p:?}");
        }
        for (p, n) in g.spads.iter().zip(&g.normals.spads) {
            let (i, j) = ij(*p);
            assert_eq!(*n, cn(i, j), "SPAD at {p:?}");
        }
        assert!(!g.normals.flat());
    }
    let mut b = builder(ZnlosLayout::Rows7, [2, 5], [4, 2], 4, "", false);
    let (v, shape) = points(2, 5, false, |i, j| {
        if (i, j) == (1, 2) { [0.0; 3] } else { ln(i, j) }
    });
    b.create_dataset("laserGridNormals")
        .with_f32_data(&v)
        .with_shape(&u(&shape));
    let p = dir.join("zero.hdf5");
    b.write(&p).unwrap();
    match open(&p).unwrap_err() {
        Error::Format { field, .. } => assert_eq!(field, "laserGridNormals"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn every_axis_order_gives_the_same_rows() {
    let dir = scratch("orders");
    let (l, s, nt) = ([4, 2], [2, 4], 5);
    for (layout, tr) in [(ZnlosLayout::Rows7, false), (ZnlosLayout::Time7, true)] {
        let p = dir.join(format!("{layout:?}.hdf5"));
        write(&p, layout, l, s, nt, "", tr);
        let mut r = open(&p).unwrap();
        assert_eq!(r.layout(), layout);
        assert_eq!(r.scan_type(), ScanType::Exhaustive);
        let g = r.geometry().clone();
        assert_eq!((g.laser_shape, g.spad_shape), ([4, 2], [2, 4]));
        assert_eq!(g.lasers[1], at(0, 1));
        assert_eq!(g.lasers[2 * 2 + 1], at(2, 1));
        assert_eq!(g.spads[4 + 3], at(1, 3));
        assert_eq!((g.nt, g.dt, g.t0), (5, 0.01, 1.25));
        assert!(g.legs_in_time && !g.confocal);
        assert_eq!(g.laser_origin, [-0.5, 0.0, 0.25]);
        assert_eq!(g.sensor_origin, [0.5, 0.1f32 as f64, 0.4f32 as f64]);
        let mut row = Vec::new();
        for li in [7, 0, 3] {
            r.read_row(li, &mut row).unwrap();
            let (ix, iy) = (li / 2, li % 2);
            for sx in 0..2 {
                for sy in 0..4 {
                    for n in 0..nt {
                        // Σ colours Σ bounces of the pattern = the base value × 1 × 1.
                        let want = (n * 10_000 + ix * 1000 + iy * 100 + sx * 10 + sy) as f32;
                        let got = row[(sx * 4 + sy) * nt + n];
                        assert!(
                            (got - want).abs() <= 1e-6 * want.max(1.0),
                            "{layout:?} {li} {sx} {sy} {n}: {got} {want}"
                        );
                    }
                }
            }
        }
    }
    // Confocal, both orders.
    for (layout, tr) in [(ZnlosLayout::Rows5, true), (ZnlosLayout::Time5, false)] {
        let p = dir.join(format!("{layout:?}.hdf5"));
        write(&p, layout, l, [3, 3], nt, "", tr);
        let mut r = open(&p).unwrap();
        assert_eq!((r.layout(), r.scan_type()), (layout, ScanType::Confocal));
        let mut row = Vec::new();
        for li in 0..9 {
            r.read_row(li, &mut row).unwrap();
            assert_eq!(row.len(), nt);
            for (n, &got) in row.iter().enumerate() {
                let want = (n * 10_000 + (li / 3) * 10 + li % 3) as f32;
                assert!(
                    (got - want).abs() <= 1e-6 * want.max(1.0),
                    "{layout:?} {li} {n}"
                );
            }
        }
    }
    // One laser point: tal single, by reciprocity.
    let p = dir.join("single.hdf5");
    write(&p, ZnlosLayout::Rows7, [1, 1], s, nt, "", false);
    let r = open(&p).unwrap();
    assert_eq!(r.scan_type(), ScanType::Single);
    assert_eq!(
        (r.geometry().lasers.len(), r.geometry().spads.len()),
        (8, 1)
    );
}

/// Every axis order, with sizes that do not divide the blocks: rows read in small blocks (in
/// order, backwards, and one twice) are bit for bit the rows of one whole read (the file in
/// one block) and the sums of the pattern over colours and bounces taken in file order.
#[test]
fn blocks_of_rows_equal_a_whole_read() {
    let dir = scratch("blocks");
    let nt = 37;
    for (layout, l, s) in [
        (ZnlosLayout::Rows7, [3, 5], [5, 3]),
        (ZnlosLayout::Time7, [3, 5], [5, 3]),
        (ZnlosLayout::Rows5, [1, 1], [5, 5]),
        (ZnlosLayout::Time5, [1, 1], [5, 5]),
        (ZnlosLayout::Rows7, [1, 1], [5, 3]),
        (ZnlosLayout::Time7, [1, 1], [3, 5]),
    ] {
        let p = dir.join(format!("{layout:?}.hdf5"));
        write(&p, layout, l, s, nt, "", false);
        let whole = read_all(&p).unwrap();
        let g = whole.geometry.clone();
        let (kl, ks) = (g.lasers.len(), g.spads_per_row());
        let exhaustive = l != [1, 1];
        assert_eq!(
            (kl, ks),
            if exhaustive {
                (15, 15)
            } else {
                (s[0] * s[1], 1)
            }
        );
        // The sums in file order: bounces then colours (laser first), colours then bounces
        // (time first).
        let want = |li: usize, si: usize, n: usize| -> f32 {
            let (ix, iy, sx, sy) = if exhaustive {
                (li / l[1], li % l[1], si / s[1], si % s[1])
            } else {
                (0, 0, li / s[1], li % s[1])
            };
            let mut acc = 0.0f32;
            for a in 0..6 * 3 {
                let (c, b) = if layout.streams() {
                    (a % 3, a / 3)
                } else {
                    (a / 6, a % 6)
                };
                acc += value(ix, iy, sx, sy, n, c, b);
            }
            acc
        };
        // A single scan's rows are scaled by the laser falloff (reciprocity): only the
        // blocks are compared there.
        let single = open(&p).unwrap().scan_type() == ScanType::Single;
        assert_eq!(
            single,
            !exhaustive && matches!(layout, ZnlosLayout::Rows7 | ZnlosLayout::Time7)
        );
        for li in (0..kl).filter(|_| !single) {
            for si in 0..ks {
                for n in 0..nt {
                    let got = whole.row(li)[si * nt + n];
                    assert_eq!(
                        got.to_bits(),
                        want(li, si, n).to_bits(),
                        "{layout:?} {li} {si} {n}"
                    );
                }
            }
        }
        // Blocks of one row and runs of one histogram or plane (1000 bytes); runs that split
        // a row (30 000, laser first); blocks that do not divide the rows.
        let mut uneven = false;
        for bytes in [1000, 30_000, 100_000] {
            let mut r = open(&p).unwrap();
            r.block_bytes = bytes;
            let b = r.source().block_rows();
            uneven |= b < kl && kl % b != 0;
            let order = (0..kl).chain((0..kl).rev()).chain([kl / 2, kl / 2]);
            let mut row = Vec::new();
            for li in order {
                r.read_row(li, &mut row).unwrap();
                assert!(
                    row.iter()
                        .zip(whole.row(li))
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{layout:?} block of {bytes} bytes: row {li}"
                );
            }
        }
        assert!(uneven, "{layout:?}: no block size leaves a partial block");
    }
}

#[test]
fn bad_files_name_the_dataset() {
    let dir = scratch("bad");
    for skip in [
        "data",
        "deltaT",
        "t0",
        "cameraGridPositions",
        "laserPosition",
    ] {
        let p = dir.join(format!("{skip}.hdf5"));
        write(&p, ZnlosLayout::Rows7, [2, 2], [2, 2], 4, skip, false);
        match open(&p).unwrap_err() {
            Error::Format { field, .. } => assert_eq!(field, skip),
            other => panic!("{skip}: {other:?}"),
        }
    }
    // Shapes y-tal does not recognise, and grids that do not match.
    let p = dir.join("shape.hdf5");
    let mut b = hdf5_pure::FileBuilder::new();
    b.create_dataset("data")
        .with_f32_data(&[0.0; 24])
        .with_shape(&[2, 3, 4]);
    b.write(&p).unwrap();
    match open(&p).unwrap_err() {
        Error::Format { field, found, .. } => assert_eq!(
            (field.as_str(), found.as_str()),
            ("data", "shape [2, 3, 4]")
        ),
        other => panic!("{other:?}"),
    }
    let p = dir.join("grid.hdf5");
    write(&p, ZnlosLayout::Rows5, [1, 1], [3, 3], 4, "", false);
    // Rewrite with a 2×2 camera grid for a 3×3 data.
    let mut b = hdf5_pure::FileBuilder::new();
    let (v, shape) = data(ZnlosLayout::Rows5, [1, 1], [3, 3], 4);
    b.create_dataset("data")
        .with_f32_data(&v)
        .with_shape(&u(&shape));
    let (g, gs) = grid(2, 2, false);
    b.create_dataset("cameraGridPositions")
        .with_f32_data(&g)
        .with_shape(&u(&gs));
    b.create_dataset("laserGridPositions")
        .with_f32_data(&g)
        .with_shape(&u(&gs));
    b.create_dataset("cameraPosition")
        .with_f32_data(&[0.0, 0.0, 1.0])
        .with_shape(&[3]);
    b.create_dataset("laserPosition")
        .with_f32_data(&[0.0, 0.0, 1.0])
        .with_shape(&[3]);
    b.create_dataset("deltaT")
        .with_f64_data(&[0.01])
        .with_shape(&[]);
    b.create_dataset("t0").with_f64_data(&[0.0]).with_shape(&[]);
    b.write(&p).unwrap();
    match open(&p).unwrap_err() {
        Error::Format { field, .. } => assert_eq!(field, "cameraGridPositions"),
        other => panic!("{other:?}"),
    }
}

fn u(s: &[usize]) -> Vec<u64> {
    s.iter().map(|&d| d as u64).collect()
}

/// Truncated and corrupted copies of a Z-NLOS file, in a streamed and a read-whole order:
/// an error or a capture, never a panic; a truncated file is always an error.
#[test]
fn corrupt_files_are_errors_not_panics() {
    let dir = scratch("corrupt");
    for layout in [ZnlosLayout::Rows7, ZnlosLayout::Time7] {
        let p = dir.join("orig.hdf5");
        write(&p, layout, [2, 2], [2, 3], 4, "", false);
        let orig = std::fs::read(&p).unwrap();
        let n = orig.len();
        let c = dir.join("c.hdf5");
        let attempt = |bytes: &[u8]| -> Result<Capture> {
            std::fs::write(&c, bytes).unwrap();
            read_all(&c)
        };
        assert!(attempt(&orig).is_ok());
        for cut in (0..n).step_by(61).chain([n - 1]) {
            let r = attempt(&orig[..cut]);
            assert!(r.is_err(), "{layout:?}: truncated at {cut} of {n}: read");
        }
        let (mut errors, mut reads) = (0, 0);
        for i in (0..n).step_by(13) {
            for flip in [0x01u8, 0xFF] {
                let mut bad = orig.clone();
                bad[i] ^= flip;
                match attempt(&bad) {
                    Ok(_) => reads += 1,
                    Err(e) => {
                        assert!(!e.to_string().is_empty());
                        errors += 1;
                    }
                }
            }
        }
        println!("{layout:?}: {errors} errors, {reads} reads of {n}-byte corruptions");
        assert!(errors > 0);
    }
}

/// Writes small Z-NLOS files of every axis order to `fuzz/seeds/tal` (the `tal` fuzz target
/// opens either HDF5 layout). `cargo test --release -p vltm --lib -- --ignored
/// write_znlos_fuzz_seeds`.
#[test]
#[ignore = "writes fuzz/seeds/tal; run by hand"]
fn write_znlos_fuzz_seeds() {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/seeds/tal");
    std::fs::create_dir_all(&d).unwrap();
    for (name, layout) in [
        ("znlos_rows7.hdf5", ZnlosLayout::Rows7),
        ("znlos_time7.hdf5", ZnlosLayout::Time7),
        ("znlos_rows5.hdf5", ZnlosLayout::Rows5),
        ("znlos_time5.hdf5", ZnlosLayout::Time5),
    ] {
        let p = d.join(name);
        write(&p, layout, [2, 2], [2, 2], 4, "", false);
        assert!(read_all(&p).is_ok(), "{name}");
    }
}
