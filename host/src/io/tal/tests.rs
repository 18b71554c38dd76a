//! Unit tests of the `HDF5_TAL` reader.

use super::*;

/// A capture of the repository's `fixtures/ytal`, checked before use: a missing file, or one
/// whose SHA-256 differs from its line in `fixtures/SHA256SUMS`, fails with a message naming
/// it and saying how to restore it.
fn shared(capture: &str) -> PathBuf {
    use sha2::Digest;
    let fixtures = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../fixtures"));
    let rel = format!("ytal/{capture}/{capture}.hdf5");
    let path = fixtures.join(&rel);
    let restore = format!("restore it with `git checkout -- fixtures/{rel}`");
    let bytes = std::fs::read(&path)
        .unwrap_or_else(|e| panic!("fixture fixtures/{rel} is missing ({e}): {restore}"));
    let sums = std::fs::read_to_string(fixtures.join("SHA256SUMS"))
        .expect("fixtures/SHA256SUMS (git checkout -- fixtures/SHA256SUMS)");
    let want = sums
        .lines()
        .find_map(|l| l.split_once("  ").filter(|(_, n)| n.trim() == rel))
        .map(|(sum, _)| sum.to_string())
        .unwrap_or_else(|| panic!("fixtures/SHA256SUMS has no line for {rel}"));
    let got: String = sha2::Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_eq!(got, want, "fixture fixtures/{rel} is damaged: {restore}");
    path
}

/// A fresh scratch directory for one test.
fn scratch(test: &str) -> crate::scratch::Scratch {
    crate::scratch::Scratch::dir(&format!("tal-{test}"))
}

/// The format error's field, or a failure message.
fn format_field(r: Result<impl std::fmt::Debug>) -> String {
    match r {
        Err(Error::Format { field, .. }) => field,
        other => panic!("expected a format error, got {other:?}"),
    }
}

const ORIGIN: [f64; 3] = [-0.5, 0.0, 0.25];

#[test]
fn shared_captures_open_with_the_readme_geometry() {
    for name in ["two_patches", "two_patches_direct_only"] {
        let r = open(&shared(name)).unwrap();
        assert_eq!(r.h_shape(), [400, 8, 8, 8, 8]);
        assert_eq!(r.h_format(), HFormat::TLxLySxSy);
        assert_eq!(r.scan_type(), ScanType::Exhaustive);
        let g = r.geometry();
        assert_eq!((g.lasers.len(), g.laser_shape), (64, [8, 8]));
        assert_eq!((g.spads.len(), g.spad_shape), (64, [8, 8]));
        // Cell centres ±0.1 … ±0.7, first index along +x (`l = ix·8 + iy`).
        assert_eq!(g.lasers[0], [-0.7, -0.7, 0.0]);
        assert_eq!(g.lasers[1], [-0.7, -0.5, 0.0]);
        assert_eq!(g.lasers[8], [-0.5, -0.7, 0.0]);
        assert_eq!(g.spads[63], [0.7, 0.7, 0.0]);
        assert_eq!((g.nt, g.dt, g.t0), (400, 0.01, 1.0));
        assert_eq!((g.laser_origin, g.sensor_origin), (ORIGIN, ORIGIN));
        assert!(!g.legs_in_time && !g.confocal);
    }

    let r = open(&shared("line")).unwrap();
    assert_eq!(r.h_shape(), [400, 12, 12, 12, 1]);
    assert_eq!(r.scan_type(), ScanType::Exhaustive);
    let g = r.geometry();
    assert_eq!((g.lasers.len(), g.laser_shape), (144, [12, 12]));
    assert_eq!((g.spads.len(), g.spad_shape), (12, [12, 1]));
    assert!(g.spads.iter().all(|s| s[1] == 0.0 && s[2] == 0.0));
    assert!((g.spads[0][0] + 0.733_333_3).abs() < 1e-6);
    assert_eq!((g.nt, g.dt, g.t0), (400, 0.01, 0.9));
    assert_eq!(g.spads_per_row(), 12);

    // tal `single`: one laser spot, 16×16 SPADs → 16×16 lasers × 1 SPAD at the spot.
    let r = open(&shared("single")).unwrap();
    assert_eq!(r.h_shape(), [300, 16, 16]);
    assert_eq!(r.h_format(), HFormat::TSxSy);
    assert_eq!(r.scan_type(), ScanType::Single);
    let g = r.geometry();
    assert_eq!((g.lasers.len(), g.laser_shape), (256, [16, 16]));
    assert_eq!(
        (g.spads.clone(), g.spad_shape),
        (vec![[0.25, -0.15, 0.0]], [1, 1])
    );
    assert_eq!(g.lasers[0], [-0.75, -0.75, 0.0]);
    assert_eq!(g.lasers[10 * 16 + 6], [0.25, -0.15, 0.0]);
    assert_eq!((g.nt, g.dt, g.t0), (300, 0.01, 1.5));
    assert_eq!((g.laser_origin, g.sensor_origin), (ORIGIN, ORIGIN));
    assert!(!g.confocal && !g.legs_in_time);
}

#[test]
fn streamed_rows_equal_read_all_in_any_order() {
    for name in ["two_patches", "line", "single"] {
        let c = read_all(&shared(name)).unwrap();
        let mut r = open(&shared(name)).unwrap();
        assert_eq!(r.geometry(), &c.geometry);
        let kl = c.geometry.lasers.len();
        let mut row = Vec::new();
        for l in (0..kl).rev().step_by(3).chain([0, kl / 2]) {
            let x = r.read_row(l, &mut row).unwrap();
            assert_eq!(x, c.geometry.lasers[l]);
            assert_eq!(row.as_slice(), c.row(l), "{name}: row {l}");
        }
    }
}

/// Values read with h5py (`f["H"][t, lx, ly, sx, sy]`, float32 bit patterns) and the f64
/// sums of all of `H` (`H.astype(np.float64).sum()`).
#[test]
fn values_match_h5py() {
    let at = |c: &Capture, l: usize, s: usize, n: usize| c.row(l)[s * c.geometry.nt + n];
    let c = read_all(&shared("two_patches")).unwrap();
    // H[150, 3, 5, 2, 6] = 8.838952e-05, H[120, 4, 4, 4, 4] = 8.68398e-05, the maximum
    // H[167, 1, 4, 1, 4] = 0.0071075666, H[200, 0, 7, 7, 0] = 0.
    assert_eq!(at(&c, 3 * 8 + 5, 2 * 8 + 6, 150).to_bits(), 951_672_259);
    assert_eq!(at(&c, 4 * 8 + 4, 4 * 8 + 4, 120).to_bits(), 951_459_267);
    assert_eq!(at(&c, 8 + 4, 8 + 4, 167).to_bits(), 1_005_119_127);
    assert_eq!(at(&c, 7, 7 * 8, 200), 0.0);
    let max = c.data.iter().copied().fold(f32::MIN, f32::max);
    assert_eq!(max.to_bits(), 1_005_119_127);
    let sum: f64 = c.data.iter().map(|&h| f64::from(h)).sum();
    assert!((sum / 12.316_197_417_224_396 - 1.0).abs() < 1e-12, "{sum}");

    let c = read_all(&shared("line")).unwrap();
    // H[130, 2, 9, 5, 0] = 0.00010940093, H[250, 11, 0, 0, 0] = 4.121247e-09.
    assert_eq!(at(&c, 2 * 12 + 9, 5, 130).to_bits(), 954_560_045);
    assert_eq!(at(&c, 11 * 12, 0, 250).to_bits(), 831_363_807);
    let sum: f64 = c.data.iter().map(|&h| f64::from(h)).sum();
    assert!((sum / 32.913_522_176_732_46 - 1.0).abs() < 1e-12, "{sum}");

    // single: H[45, 3, 3] = 0.0002095045 times c'(S[3, 3]) / c(x0); c(x0) = 0.47982221114
    // (numpy, float64), c'(S[3, 3]) = 1.80698418831.
    let c = read_all(&shared("single")).unwrap();
    let g = &c.geometry;
    let raw = f64::from(f32::from_bits(962_309_744));
    let c0 = 0.479_822_211_140_720_4;
    let cs = g.laser_falloff(g.lasers[3 * 16 + 3]);
    assert!((cs - 1.806_984_188_306_343_8).abs() < 1e-9, "{cs}");
    assert_eq!(at(&c, 3 * 16 + 3, 0, 45), (raw * cs / c0) as f32);
    // Σ_l Σ_t H[t, l]·c'(S_l)/c(x0) = 1.4848346794 (numpy); after --compensate-laser every
    // row is H / c(x0): Σ = 0.8313117163, y-tal's compensate_laser_cos_dsqr.
    let kl = g.lasers.len();
    let sum: f64 = c.data.iter().map(|&h| f64::from(h)).sum();
    assert!((sum / 1.484_834_679_407_712_3 - 1.0).abs() < 1e-6, "{sum}");
    let comp: f64 = (0..kl)
        .map(|l| c.row(l).iter().map(|&h| f64::from(h)).sum::<f64>() / g.laser_falloff(g.lasers[l]))
        .sum();
    assert!(
        (comp / 0.831_311_716_266_990_7 - 1.0).abs() < 1e-6,
        "{comp}"
    );
}

#[test]
fn bin_centre_moves_t0_by_half_a_bin_only() {
    let a = read_all_with(&shared("line"), TalOptions::YTAL).unwrap();
    let b = read_all_with(&shared("line"), TalOptions::BIN_CENTRE).unwrap();
    assert_eq!(TalOptions::default(), TalOptions::YTAL);
    assert!((b.geometry.t0 - 0.905).abs() < 1e-12);
    assert_eq!(a.data, b.data);
    assert_eq!(
        Geometry {
            t0: a.geometry.t0,
            ..b.geometry
        },
        a.geometry
    );
}

#[test]
fn capture_open_dispatches_hdf5_and_h5() {
    let a = crate::io::open(&shared("single")).unwrap();
    let dir = scratch("h5");
    let p = dir.join("copy.H5");
    std::fs::copy(shared("single"), &p).unwrap();
    let b = crate::io::open(&p).unwrap();
    assert_eq!(a, b);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn bad_row_and_missing_file() {
    let mut r = open(&shared("single")).unwrap();
    let mut row = Vec::new();
    assert!(matches!(
        r.read_row(256, &mut row),
        Err(Error::Argument { .. })
    ));
    let e = open(Path::new("/nonexistent/x.hdf5")).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e}");
    assert!(e.to_string().contains("/nonexistent/x.hdf5"));
}

/// Truncated and byte-corrupted copies: every outcome is `Ok` or an `Error`, never a panic;
/// every truncation and a broken signature are errors.
#[test]
fn corrupt_files_are_errors_not_panics() {
    let orig = std::fs::read(shared("single")).unwrap();
    let n = orig.len();
    let dir = scratch("corrupt");
    let p = dir.join("c.hdf5");
    let attempt = |bytes: &[u8]| -> Result<Capture> {
        std::fs::write(&p, bytes).unwrap();
        read_all(&p)
    };
    // H's data starts at byte 2048 (h5py), the other datasets and the metadata follow it.
    for cut in [
        0,
        1,
        7,
        8,
        100,
        512,
        1000,
        2047,
        2048,
        2049,
        4096,
        n / 2,
        309_248,
        n - 100,
        n - 1,
    ] {
        let r = attempt(&orig[..cut]);
        assert!(r.is_err(), "truncated at {cut} of {n}: read");
        assert!(!r.unwrap_err().to_string().is_empty());
    }
    let mut bad = orig.clone();
    bad[1] ^= 0xFF; // the "\x89HDF" signature
    let e = attempt(&bad).unwrap_err();
    assert!(
        matches!(e, Error::Format { ref field, .. } if field == "(file)"),
        "{e}"
    );
    let mut errors = 0;
    let positions = (0..2048).step_by(16).chain((309_248..n).step_by(64));
    for (k, i) in positions.enumerate() {
        let mut b = orig.clone();
        b[i] ^= [0xFF, 0x01, 0x80][k % 3];
        if let Err(e) = attempt(&b) {
            errors += 1;
            assert!(e.to_string().contains("c.hdf5"), "{e}");
        }
    }
    assert!(errors > 50, "only {errors} corrupt copies were refused");
    let _ = std::fs::remove_dir_all(dir);
}

/// What a synthetic tal file holds (written with `hdf5-pure`).
struct Spec {
    h_shape: Vec<u64>,
    h_format: i32,
    /// Write `H_format` as tal's named enum (else a plain int32).
    enum_names: Option<Vec<(&'static str, i32)>>,
    h_f64: bool,
    h_int: bool,
    chunks: Option<Vec<u64>>,
    /// Filters of a chunked `H`: any of "shuffle", "fletcher32", "deflate" ("" for none).
    filters: &'static str,
    laser_grid: (Vec<f32>, Vec<u64>),
    sensor_grid: (Vec<f32>, Vec<u64>),
    laser_grid_format: Option<i32>,
    laser_xyz: [f32; 3],
    sensor_xyz: [f32; 3],
    delta_t: f64,
    t_start: f64,
    legs: u8,
    skip: &'static str,
    /// Further f32 datasets `(name, values, shape)` (`laser_grid_normals`).
    extra: Vec<(&'static str, Vec<f32>, Vec<u64>)>,
}

/// Value of `H` at `(t, a, b, ...)` in C order: `t·10⁴ + (flat index of the rest)`.
fn pattern(shape: &[u64]) -> Vec<f64> {
    let rest: u64 = shape[1..].iter().product();
    (0..shape[0] * rest)
        .map(|i| ((i / rest) * 10_000 + i % rest) as f64)
        .collect()
}

/// `n` grid points `(x_i, y_j, 0)` on a 0.1 m pitch, shape `(nx, ny, 3)` or `(n, 3)`.
fn grid(nx: u64, ny: u64, n3: bool, dx: f32) -> (Vec<f32>, Vec<u64>) {
    let mut v = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            v.extend([0.1 * i as f32 - 0.2 + dx, 0.1 * j as f32 - 0.1, 0.0]);
        }
    }
    let shape = if n3 {
        vec![nx * ny, 3]
    } else {
        vec![nx, ny, 3]
    };
    (v, shape)
}

impl Spec {
    fn exhaustive() -> Self {
        Self {
            h_shape: vec![5, 3, 2, 4, 2],
            h_format: 2,
            enum_names: None,
            h_f64: false,
            h_int: false,
            chunks: None,
            filters: "deflate",
            laser_grid: grid(3, 2, false, 0.0),
            sensor_grid: grid(4, 2, false, 0.0),
            laser_grid_format: None,
            laser_xyz: [-0.5, 0.0, 0.25],
            sensor_xyz: [0.5, 0.125, 0.375],
            delta_t: 0.02,
            t_start: 0.5,
            legs: 1,
            skip: "",
            extra: Vec::new(),
        }
    }

    fn write(&self, path: &Path) {
        use hdf5_pure::{EnumTypeBuilder, FileBuilder};
        let mut b = FileBuilder::new();
        let h = pattern(&self.h_shape);
        if self.skip != "H" {
            let d = b.create_dataset("H");
            if self.h_int {
                d.with_i32_data(&h.iter().map(|&x| x as i32).collect::<Vec<_>>());
            } else if self.h_f64 {
                d.with_f64_data(&h);
            } else {
                d.with_f32_data(&h.iter().map(|&x| x as f32).collect::<Vec<_>>());
            }
            d.with_shape(&self.h_shape);
            if let Some(c) = &self.chunks {
                d.with_chunks(c);
                if self.filters.contains("shuffle") {
                    d.with_shuffle();
                }
                if self.filters.contains("deflate") {
                    d.with_deflate(4);
                }
                if self.filters.contains("fletcher32") {
                    d.with_fletcher32();
                }
            }
        }
        if self.skip != "H_format" {
            let d = b.create_dataset("H_format");
            match &self.enum_names {
                Some(names) => {
                    let t = names
                        .iter()
                        .fold(EnumTypeBuilder::i32_based(), |t, &(n, v)| t.value(n, v))
                        .build()
                        .unwrap();
                    d.with_enum_i32_data(t, &[self.h_format]);
                }
                None => {
                    d.with_i32_data(&[self.h_format]);
                }
            }
            d.with_shape(&[1]);
        }
        for (name, (v, shape)) in [
            ("laser_grid_xyz", &self.laser_grid),
            ("sensor_grid_xyz", &self.sensor_grid),
        ] {
            if self.skip != name {
                b.create_dataset(name).with_f32_data(v).with_shape(shape);
            }
        }
        if let Some(g) = self.laser_grid_format {
            b.create_dataset("laser_grid_format")
                .with_i32_data(&[g])
                .with_shape(&[1]);
        }
        for (name, v) in [
            ("laser_xyz", self.laser_xyz),
            ("sensor_xyz", self.sensor_xyz),
        ] {
            if self.skip != name {
                b.create_dataset(name).with_f32_data(&v).with_shape(&[3]);
            }
        }
        for (name, v) in [("delta_t", self.delta_t), ("t_start", self.t_start)] {
            if self.skip != name {
                b.create_dataset(name).with_f64_data(&[v]).with_shape(&[]);
            }
        }
        if self.skip != "t_accounts_first_and_last_bounces" {
            b.create_dataset("t_accounts_first_and_last_bounces")
                .with_u8_data(&[self.legs])
                .with_shape(&[]);
        }
        for (name, v, shape) in &self.extra {
            b.create_dataset(name).with_f32_data(v).with_shape(shape);
        }
        b.write(path).unwrap();
    }

    fn open(&self, dir: &Path, name: &str) -> Result<TalReader> {
        let p = dir.join(format!("{name}.hdf5"));
        self.write(&p);
        open(&p)
    }
}

/// Checks every row of `r` against the pattern: row `l`, SPAD `s`, bin `n` holds
/// `n·10⁴ + index(l, s)` times `scale(l)`.
fn check_rows(r: &mut TalReader, index: impl Fn(usize, usize) -> usize) {
    let g = r.geometry().clone();
    let mut row = Vec::new();
    for l in 0..g.lasers.len() {
        assert_eq!(r.read_row(l, &mut row).unwrap(), g.lasers[l]);
        for s in 0..g.spads_per_row() {
            for n in 0..g.nt {
                let want = (n * 10_000 + index(l, s)) as f32;
                assert_eq!(row[s * g.nt + n], want, "row {l}, SPAD {s}, bin {n}");
            }
        }
    }
}

#[test]
fn synthetic_formats_stream_the_right_values() {
    let dir = scratch("formats");
    // T_Lx_Ly_Sx_Sy, contiguous f32, and chunked + gzip f64, with the named tal enum.
    let mut spec = Spec::exhaustive();
    spec.enum_names = Some(vec![
        ("UNKNOWN", 0),
        ("T_Sx_Sy", 1),
        ("T_Lx_Ly_Sx_Sy", 2),
        ("T_Si", 3),
        ("T_Li_Si", 4),
    ]);
    for (k, chunks) in [None, Some(vec![2, 1, 2, 4, 2])].into_iter().enumerate() {
        spec.chunks = chunks;
        spec.h_f64 = k == 1;
        let mut r = spec.open(&dir, &format!("exhaustive{k}")).unwrap();
        assert_eq!(r.chunks.is_some(), k == 1);
        let g = r.geometry().clone();
        assert_eq!((g.laser_shape, g.spad_shape, g.nt), ([3, 2], [4, 2], 5));
        assert_eq!((g.dt, g.t0, g.legs_in_time), (0.02, 0.5, true));
        assert_eq!(
            (g.laser_origin, g.sensor_origin),
            ([-0.5, 0.0, 0.25], [0.5, 0.125, 0.375])
        );
        check_rows(&mut r, |l, s| l * 8 + s);
    }

    // Rows of 120 kB: both lines of 5 rows in one block (BLOCK_BYTES); rows read in a
    // scrambled order (each jump restarts the read-ahead).
    let mut spec = Spec::exhaustive();
    spec.h_shape = vec![30, 2, 5, 10, 100];
    spec.laser_grid = grid(2, 5, false, 0.0);
    spec.sensor_grid = grid(10, 100, false, 0.0);
    let mut r = spec.open(&dir, "blocks").unwrap();
    assert_eq!(r.block_range(3), (0, 10));
    // Rows of 4 MB: four rows per block within a line; lines of 5 end in a partial block.
    let dims = [1000, 3, 5, 10, 100];
    let blocks: Vec<_> = (0..15)
        .map(|l| super::block_range(&dims, HFormat::TLxLySxSy, 1000, None, l))
        .collect();
    assert_eq!(
        &blocks[..7],
        &[(0, 4), (0, 4), (0, 4), (0, 4), (4, 5), (5, 9), (5, 9)]
    );
    // Rows of 40 kB, lines of 5: whole lines, as many as fit in BLOCK_BYTES.
    let dims = [100, 300, 5, 10, 10];
    let b = super::block_range(&dims, HFormat::TLxLySxSy, 100, None, 7);
    assert_eq!((b.0 % 5, b.1 - b.0), (0, BLOCK_BYTES / 40_000 / 5 * 5));
    let mut row = Vec::new();
    for l in [9, 0, 4, 5, 3, 8, 1, 2, 7, 6, 6, 9] {
        r.read_row(l, &mut row).unwrap();
        for s in [0, 1, 499, 999] {
            for n in [0, 17, 29] {
                assert_eq!(row[s * 30 + n], (n * 10_000 + l * 1000 + s) as f32);
            }
        }
    }
    check_rows(&mut r, |l, s| l * 1000 + s);

    // T_Li_Si with N_3 grids.
    let mut spec = Spec::exhaustive();
    spec.h_shape = vec![4, 6, 3];
    spec.h_format = 4;
    spec.laser_grid = grid(3, 2, true, 0.0);
    spec.sensor_grid = grid(3, 1, true, 0.0);
    spec.laser_grid_format = Some(1);
    let mut r = spec.open(&dir, "lisi").unwrap();
    assert_eq!(r.scan_type(), ScanType::Exhaustive);
    assert_eq!(
        (r.geometry().laser_shape, r.geometry().spad_shape),
        ([6, 1], [3, 1])
    );
    check_rows(&mut r, |l, s| l * 3 + s);

    // T_Sx_Sy confocal (laser grid = sensor grid) and T_Si confocal.
    let mut spec = Spec::exhaustive();
    spec.h_shape = vec![6, 3, 2];
    spec.h_format = 1;
    spec.laser_grid = grid(3, 2, false, 0.0);
    spec.sensor_grid = grid(3, 2, false, 0.0);
    let mut r = spec.open(&dir, "confocal").unwrap();
    assert_eq!(r.scan_type(), ScanType::Confocal);
    assert!(r.geometry().confocal && r.geometry().spads_per_row() == 1);
    assert_eq!(r.geometry().laser_shape, [3, 2]);
    check_rows(&mut r, |l, _| l);
    spec.h_shape = vec![6, 6];
    spec.h_format = 3;
    spec.laser_grid = grid(3, 2, true, 0.0);
    spec.sensor_grid = grid(3, 2, true, 0.0);
    let mut r = spec.open(&dir, "confocal_si").unwrap();
    assert_eq!(r.scan_type(), ScanType::Confocal);
    assert_eq!(r.geometry().laser_shape, [6, 1]);
    check_rows(&mut r, |l, _| l);

    // Paired scans (y-tal's `is_laser_paired_to_sensor()` without `is_confocal()`): T_Si with
    // N_3 grids of one length, and T_Sx_Sy with X_Y_3 grids of one shape. Row `l` is the
    // histogram of pair `l`, laser `lasers[l]`, SPAD `spads[l]`.
    for (name, fmt, h_shape, n3) in [
        ("paired_si", 3, vec![6, 6], true),
        ("paired_sxsy", 1, vec![6, 3, 2], false),
    ] {
        let mut spec = Spec::exhaustive();
        spec.h_shape = h_shape;
        spec.h_format = fmt;
        spec.sensor_grid = grid(3, 2, n3, 0.0);
        spec.laser_grid = grid(3, 2, n3, 0.05);
        let mut r = spec.open(&dir, name).unwrap();
        assert_eq!(r.scan_type(), ScanType::Paired, "{name}");
        let g = r.geometry().clone();
        assert!(g.confocal && g.paired_apart() && !g.coincident());
        assert_eq!(
            (g.spads_per_row(), g.lasers.len(), g.spads.len()),
            (1, 6, 6)
        );
        assert_eq!(g.lasers[4], [0.05, -0.1, 0.0], "{name}");
        assert_eq!(g.spads[4], [0.0, -0.1, 0.0], "{name}");
        assert_eq!(g.row_spads(4), &[[0.0, -0.1, 0.0]]);
        check_rows(&mut r, |l, _| l);
    }

    // T_Si single: one laser point → the sensor points become lasers, with the factor.
    spec.laser_grid = (vec![0.05, 0.02, 0.0], vec![1, 1, 3]);
    let mut r = spec.open(&dir, "single_si").unwrap();
    assert_eq!(r.scan_type(), ScanType::Single);
    let g = r.geometry().clone();
    assert_eq!(
        (g.spads.clone(), g.spad_shape),
        (vec![[0.05, 0.02, 0.0]], [1, 1])
    );
    assert_eq!(
        (g.laser_origin, g.sensor_origin),
        ([0.5, 0.125, 0.375], [-0.5, 0.0, 0.25])
    );
    let physical = Geometry {
        laser_origin: [-0.5, 0.0, 0.25],
        ..g.clone()
    };
    let c0 = physical.laser_falloff(g.spads[0]);
    let mut row = Vec::new();
    for l in 0..6 {
        r.read_row(l, &mut row).unwrap();
        let k = g.laser_falloff(g.lasers[l]) / c0;
        for (n, &h) in row.iter().enumerate() {
            assert_eq!(h, (((n * 10_000 + l) as f64) * k) as f32);
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn malformed_fields_name_the_field() {
    let dir = scratch("malformed");
    let case = |name: &str, edit: &dyn Fn(&mut Spec)| {
        let mut s = Spec::exhaustive();
        edit(&mut s);
        format_field(s.open(&dir, name))
    };
    for missing in [
        "H",
        "H_format",
        "laser_grid_xyz",
        "sensor_grid_xyz",
        "laser_xyz",
        "sensor_xyz",
        "delta_t",
        "t_start",
        "t_accounts_first_and_last_bounces",
    ] {
        assert_eq!(case(missing, &|s| s.skip = missing), missing);
    }
    assert_eq!(case("dt_nan", &|s| s.delta_t = f64::NAN), "delta_t");
    assert_eq!(case("dt_inf", &|s| s.delta_t = f64::INFINITY), "delta_t");
    assert_eq!(case("dt_zero", &|s| s.delta_t = 0.0), "delta_t");
    assert_eq!(case("t0_nan", &|s| s.t_start = f64::NAN), "t_start");
    assert_eq!(case("fmt_unknown", &|s| s.h_format = 0), "H_format");
    assert_eq!(case("fmt_7", &|s| s.h_format = 7), "H_format");
    // An enum whose names disagree with tal's numbering.
    assert_eq!(
        case("fmt_names", &|s| s.enum_names =
            Some(vec![("T_Si", 2), ("T_Lx_Ly_Sx_Sy", 3)])),
        "H_format"
    );
    assert_eq!(case("rank", &|s| s.h_format = 4), "H");
    assert_eq!(case("int_h", &|s| s.h_int = true), "H");
    assert_eq!(
        case("lgrid", &|s| s.laser_grid = grid(2, 3, false, 0.0)),
        "laser_grid_xyz"
    );
    assert_eq!(
        case("sgrid", &|s| s.sensor_grid = grid(4, 1, false, 0.0)),
        "sensor_grid_xyz"
    );
    assert_eq!(
        case("grid_rank", &|s| s.laser_grid =
            (vec![0.0; 18], vec![6, 3, 1])),
        "laser_grid_xyz"
    );
    assert_eq!(
        case("grid_fmt", &|s| s.laser_grid_format = Some(1)),
        "laser_grid_format"
    );
    // A paired T_Si scan whose laser list is longer than its sensor list (y-tal's
    // `is_laser_paired_to_sensor()` is false, and it is neither single nor confocal).
    assert_eq!(
        case("paired_lengths", &|s| {
            s.h_shape = vec![5, 6];
            s.h_format = 3;
            s.sensor_grid = grid(6, 1, true, 0.0);
            s.laser_grid = grid(7, 1, true, 0.05);
        }),
        "laser_grid_xyz"
    );
    // The same length but another grid format (X_Y_3 against N_3): not paired for y-tal.
    assert_eq!(
        case("paired_formats", &|s| {
            s.h_shape = vec![5, 6];
            s.h_format = 3;
            s.sensor_grid = grid(6, 1, true, 0.0);
            s.laser_grid = grid(3, 2, false, 0.05);
        }),
        "laser_grid_xyz"
    );
    // NaN in a paired laser point.
    assert_eq!(
        case("paired_nan", &|s| {
            s.h_shape = vec![5, 6];
            s.h_format = 3;
            s.sensor_grid = grid(6, 1, true, 0.0);
            let mut l = grid(6, 1, true, 0.05);
            l.0[4] = f32::NAN;
            s.laser_grid = l;
        }),
        "laser_grid"
    );
    // The single-scan reciprocity factor needs both devices off the wall plane.
    let single = |s: &mut Spec| {
        s.h_shape = vec![5, 3, 2];
        s.h_format = 1;
        s.sensor_grid = grid(3, 2, false, 0.0);
        s.laser_grid = (vec![0.0, 0.0, 0.0], vec![1, 1, 3]);
    };
    let laser_in_wall = |s: &mut Spec| {
        single(s);
        s.laser_xyz = [-0.5, 0.0, 0.0];
    };
    let sensor_in_wall = |s: &mut Spec| {
        single(s);
        s.sensor_xyz = [0.5, 0.0, 0.0];
    };
    assert_eq!(case("laser_in_wall", &laser_in_wall), "laser_xyz");
    assert_eq!(case("sensor_in_wall", &sensor_in_wall), "sensor_xyz");
    let mut s = Spec::exhaustive();
    single(&mut s);
    assert_eq!(
        s.open(&dir, "single_ok").unwrap().scan_type(),
        ScanType::Single
    );
    let _ = std::fs::remove_dir_all(dir);
}

/// The same capture as a time-first tal file (contiguous, as tal writes it, and gzip-chunked)
/// and as an uncompressed `.npz` built independently in vltm's row order: every streamed row
/// is bit-identical. 27 MB of `H`, so the contiguous file takes two blocks of whole lines read
/// with one positional read per bin, 33 bins = one whole group of 32 and one partial; 200
/// SPADs = 12 whole tiles of 16 and 8 left over. Rows are read in order, then a few again out
/// of order (each restarts the reader).
#[test]
fn tal_rows_equal_npz_rows_contiguous_and_chunked() {
    let dir = scratch("tal_vs_npz");
    let mut spec = Spec::exhaustive();
    spec.h_shape = vec![33, 64, 16, 10, 20];
    spec.laser_grid = grid(64, 16, false, 0.0);
    spec.sensor_grid = grid(10, 20, false, 0.0);
    let (nt, kl, ks) = (33, 64 * 16, 200);
    let contiguous = spec.open(&dir, "contiguous").unwrap();
    let g = contiguous.geometry().clone();
    assert_eq!((g.nt, g.lasers.len(), g.spads_per_row()), (nt, kl, ks));
    assert_eq!(contiguous.block_range(0), (0, 624));
    assert_eq!(contiguous.block_range(1000), (624, kl));
    // vltm's order, data[(l·Ks + s)·Nt + n] = H[n, l, s] of `pattern`.
    let mut data = vec![0.0f32; kl * ks * nt];
    for (i, x) in data.iter_mut().enumerate() {
        let (n, ls) = (i % nt, i / nt);
        *x = (n * 10_000 + ls) as f32;
    }
    let npz = dir.join("capture.npz");
    crate::io::npz::write_with(&Capture::new(g, data, &npz).unwrap(), &npz, false).unwrap();
    let mut reference = crate::io::npz::open_stream(&npz).unwrap().unwrap();
    spec.chunks = Some(vec![8, 4, 4, 10, 20]);
    let chunked = spec.open(&dir, "chunked").unwrap();
    assert!(chunked.raw.is_none() && contiguous.raw.is_some());
    assert!(chunked.chunks.is_some() && contiguous.chunks.is_none());
    let (mut want, mut row) = (Vec::new(), Vec::new());
    for mut r in [contiguous, chunked] {
        for l in (0..kl).chain([700, 3, 3, 1023, 0]) {
            reference.read_row(l, &mut want).unwrap();
            r.read_row(l, &mut row).unwrap();
            assert_eq!(row.len(), ks * nt);
            let same = row
                .iter()
                .zip(&want)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "row {l} of {}", r.path().display());
        }
    }
}

/// A chunked `H` decoded chunk by chunk (`chunks`): chunk shapes that do not divide the
/// dimensions (edge chunks on every axis), a single chunk, unfiltered chunks, shuffle +
/// deflate, f64 values, and fletcher32 (not decoded here: read through the crate) all give
/// rows bit-identical to the contiguous file's, read in order and out of order.
#[test]
fn chunked_h_decoded_chunk_by_chunk_equals_contiguous() {
    let dir = scratch("chunk_path");
    let mut spec = Spec::exhaustive();
    spec.h_shape = vec![33, 12, 5, 10, 20];
    spec.laser_grid = grid(12, 5, false, 0.0);
    spec.sensor_grid = grid(10, 20, false, 0.0);
    let mut reference = spec.open(&dir, "contiguous").unwrap();
    let kl = reference.geometry().lasers.len();
    let ks = reference.geometry().spads_per_row();
    let mut want: Vec<Vec<f32>> = Vec::new();
    for l in 0..kl {
        let mut row = Vec::new();
        reference.read_row(l, &mut row).unwrap();
        want.push(row);
    }
    let cases: [(&str, [u64; 5], &str, bool, bool); 8] = [
        ("divides", [11, 4, 5, 10, 20], "deflate", false, true),
        ("edges", [8, 5, 2, 3, 7], "deflate", false, true),
        ("one_bin", [1, 12, 5, 10, 20], "deflate", false, true),
        ("single", [33, 12, 5, 10, 20], "deflate", false, true),
        ("raw", [16, 3, 4, 10, 20], "", false, true),
        ("shuffle", [16, 3, 5, 4, 20], "shuffle+deflate", false, true),
        ("f64", [7, 5, 2, 4, 9], "shuffle+deflate", true, true),
        (
            "fletcher",
            [16, 3, 5, 10, 20],
            "fletcher32+deflate",
            false,
            false,
        ),
    ];
    let mut row = Vec::new();
    for (name, chunks, filters, f64, decoded) in cases {
        spec.chunks = Some(chunks.to_vec());
        spec.filters = filters;
        spec.h_f64 = f64;
        let mut r = spec.open(&dir, name).unwrap();
        assert_eq!(r.chunks.is_some(), decoded, "{name}");
        assert!(r.raw.is_none());
        for l in (0..kl).chain([37, 2, 2, kl - 1, 0, 20]) {
            r.read_row(l, &mut row).unwrap();
            assert_eq!(row.len(), ks * 33);
            let same = row
                .iter()
                .zip(&want[l])
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "{name}: row {l}");
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// A chunk whose stored bytes are corrupt is an error naming `H` and the chunk when its
/// rows are read; a chunk index pointing outside the file is refused at open.
#[test]
fn corrupt_chunks_are_errors() {
    let dir = scratch("chunk_corrupt");
    let mut spec = Spec::exhaustive();
    spec.h_shape = vec![33, 12, 5, 10, 20];
    spec.laser_grid = grid(12, 5, false, 0.0);
    spec.sensor_grid = grid(10, 20, false, 0.0);
    spec.chunks = Some(vec![8, 4, 5, 10, 20]);
    let good = dir.join("good.hdf5");
    spec.write(&good);
    let r = open(&good).unwrap();
    let spans = r.chunks.as_ref().unwrap().stored_spans();
    assert_eq!(spans.len(), 5 * 3);
    let bytes = std::fs::read(&good).unwrap();

    // Garbage in the middle of the first chunk's deflate stream.
    let (address, len) = spans[0];
    let mut b = bytes.clone();
    let mid = address as usize + len / 2;
    b[mid..mid + 16].iter_mut().for_each(|x| *x ^= 0x5a);
    let bad = dir.join("bad_chunk.hdf5");
    std::fs::write(&bad, &b).unwrap();
    let mut r = open(&bad).unwrap();
    let mut row = Vec::new();
    let e = r.read_row(0, &mut row).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("bad_chunk.hdf5") && text.contains("`H`") && text.contains("chunk at"),
        "{text}"
    );
    // Rows of other bands still read (the reader restarts at their block).
    r.read_row(kl_of(&r) - 1, &mut row).unwrap();

    // The first chunk's address moved past the end of the file (the index re-sealed where
    // it carries a checksum would still be refused by the range check; here the crate's
    // checksum or the range check refuses it).
    let mut b = bytes.clone();
    let at: Vec<usize> = (0..b.len() - 8)
        .filter(|&i| b[i..i + 8] == address.to_le_bytes())
        .collect();
    assert!(!at.is_empty());
    for i in at {
        b[i..i + 8].copy_from_slice(&(bytes.len() as u64 + 4096).to_le_bytes());
    }
    let moved = dir.join("moved.hdf5");
    std::fs::write(&moved, &b).unwrap();
    assert_eq!(format_field(open(&moved)), "H");

    // Truncated inside the chunks: whatever fails first (an index past the end, a chunk
    // outside the file) is an error, never a panic.
    for cut in [address as usize + len / 2, bytes.len() - 100] {
        let t = dir.join("cut.hdf5");
        std::fs::write(&t, &bytes[..cut]).unwrap();
        let result = open(&t)
            .and_then(|mut r| (0..kl_of(&r)).try_for_each(|l| r.read_row(l, &mut row).map(|_| ())));
        assert!(result.is_err(), "cut at {cut}");
    }
    let _ = std::fs::remove_dir_all(dir);
}

fn kl_of(r: &TalReader) -> usize {
    r.geometry().lasers.len()
}

/// Files written by h5py (`fixtures/tal/make_chunked.py`): a version 1 B-tree chunk index,
/// the index every h5py or y-tal file has, with edge chunks on every axis and shuffle + gzip.
/// With every chunk written, `H` is decoded chunk by chunk and every value is the pattern;
/// with one chunk never written, the reader falls back to the crate, which reads it as the
/// fill value 0.
#[test]
fn h5py_v1_btree_chunks() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/tal");
    for (name, decoded) in [
        ("h5py_chunked.hdf5", true),
        ("h5py_chunked_hole.hdf5", false),
    ] {
        let mut r = open(&dir.join(name)).unwrap();
        assert_eq!(r.chunks.is_some(), decoded, "{name}");
        let g = r.geometry().clone();
        assert_eq!((g.lasers.len(), g.spads_per_row(), g.nt), (6, 20, 9));
        let mut row = Vec::new();
        // In order, then out of order (the reader restarts at the row's block).
        for l in (0..6).chain([4, 0, 5]) {
            r.read_row(l, &mut row).unwrap();
            for s in 0..20 {
                for n in 0..9 {
                    let hole = !decoded && (l, s, n) == (5, 19, 8);
                    let want = if hole {
                        0.0
                    } else {
                        (n * 10_000 + l * 20 + s) as f32
                    };
                    assert_eq!(row[s * 9 + n], want, "{name}: row {l}, SPAD {s}, bin {n}");
                }
            }
        }
    }
}

/// Reads every row of the file at `path`, opened inside a pool of `threads` threads (the
/// number of threads that decode a band of chunks), with the number of decoding threads.
fn rows_with_threads(path: &Path, threads: usize) -> Result<(usize, Vec<Vec<f32>>)> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let mut r = pool.install(|| open(path))?;
    let workers = r.chunks.as_ref().map_or(0, |c| c.workers());
    assert!(r.reads_in_parallel() == r.chunks.is_some());
    let mut rows = Vec::new();
    for l in 0..kl_of(&r) {
        let mut row = Vec::new();
        r.read_row(l, &mut row)?;
        rows.push(row);
    }
    Ok((workers, rows))
}

/// A gzip-chunked `H` (the path-traced fixtures: tal files rewritten with shuffle + gzip 9)
/// decodes each band on as many threads as the pool that opened it: 1, 2 or 3 threads give
/// the same rows, bit for bit; and on a synthetic file with 9 time chunks, a corrupt chunk
/// that a helper thread (not the reader thread) decodes is still an error naming `H` and the
/// chunk.
#[test]
fn chunked_rows_identical_on_any_number_of_decoding_threads() {
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fixtures/pathtraced/corner_all/corner_all.hdf5");
    let (w1, one) = rows_with_threads(&fixture, 1).unwrap();
    assert_eq!(w1, 1, "a pool of one thread decodes on one");
    for threads in [2, 3] {
        let (w, rows) = rows_with_threads(&fixture, threads).unwrap();
        assert!(w > 1 && w <= threads, "{threads} threads: {w} workers");
        assert_eq!(rows.len(), one.len());
        for (l, (a, b)) in rows.iter().zip(&one).enumerate() {
            let same =
                a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
            assert!(same, "{threads} threads: row {l} differs from one thread's");
        }
    }
    assert!(one.iter().flatten().any(|&x| x != 0.0));

    let dir = scratch("chunk_threads");
    let mut spec = Spec::exhaustive();
    spec.h_shape = vec![33, 12, 5, 10, 20];
    spec.laser_grid = grid(12, 5, false, 0.0);
    spec.sensor_grid = grid(10, 20, false, 0.0);
    spec.chunks = Some(vec![4, 4, 5, 10, 20]);
    let good = dir.join("good.hdf5");
    spec.write(&good);
    let (w1, want) = rows_with_threads(&good, 1).unwrap();
    let (w4, got) = rows_with_threads(&good, 4).unwrap();
    assert_eq!((w1, w4), (1, 4));
    assert!(
        want.iter()
            .flatten()
            .zip(got.iter().flatten())
            .all(|(x, y)| x.to_bits() == y.to_bits())
    );
    // Chunks in C order of the grid (9 time chunks × 3 bands): the last time chunk of band
    // 0 is decoded by the last of 4 workers.
    let spans = open(&good).unwrap().chunks.as_ref().unwrap().stored_spans();
    assert_eq!(spans.len(), 9 * 3);
    let (address, len) = spans[8 * 3];
    let mut b = std::fs::read(&good).unwrap();
    let mid = address as usize + len / 2;
    b[mid..mid + 16].iter_mut().for_each(|x| *x ^= 0x5a);
    let bad = dir.join("bad_late_chunk.hdf5");
    std::fs::write(&bad, &b).unwrap();
    let text = rows_with_threads(&bad, 4).unwrap_err().to_string();
    assert!(
        text.contains("bad_late_chunk.hdf5")
            && text.contains("`H`")
            && text.contains("chunk at [32, 0, 0, 0, 0]"),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

/// A capture written by y-tal's own `write_capture` with its optional fields left `None`
/// (`fixtures/tal/make_null_fields.py`): the normals, `scene_info` and `volume_format` are
/// datasets with a null dataspace, read as absent (a flat wall, +z), and the rows are the
/// file's values (`H[t, x, y] = exp(−((t − 12 − 2x)/2)²/2)`).
#[test]
fn ytal_null_fields_are_absent() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/tal/ytal_null_fields.hdf5");
    let mut r = open(&path).unwrap();
    let g = r.geometry().clone();
    assert!(g.confocal);
    assert_eq!((g.lasers.len(), g.nt), (16, 32));
    assert!(g.normals.flat() && g.normals.lasers.is_empty() && g.normals.spads.is_empty());
    assert!(g.not_flat().is_none());
    let mut row = Vec::new();
    let x = r.read_row(5, &mut row).unwrap();
    for (t, v) in row.iter().enumerate() {
        let want = (-0.5 * ((t as f32 - 12.0 - 2.0 * x[0]) / 2.0).powi(2)).exp();
        assert!((v - want).abs() <= 1e-6, "bin {t}: {v} vs {want}");
    }
    let c = read_all(&path).unwrap();
    assert_eq!(c.geometry.lasers.len(), 16);
}

/// `laser_grid_normals` / `sensor_grid_normals` (y-tal's fields, of their grid's shape):
/// read per point into [`Geometry::normals`] (swapped with the grids for tal's `single`
/// scan), all-+z normals are the flat default, and a zero-length, NaN or misshapen normal is a
/// one-line error naming the field.
#[test]
fn grid_normals_are_read_and_checked() {
    let dir = scratch("normals");
    let tilted = |n: usize| -> Vec<f32> {
        (0..n)
            .flat_map(|i| [0.1 * i as f32, -0.05, 1.0])
            .collect::<Vec<_>>()
    };
    let mut spec = Spec::exhaustive();
    spec.h_shape = vec![6, 6];
    spec.h_format = 3;
    spec.sensor_grid = grid(3, 2, true, 0.0);
    spec.laser_grid = grid(3, 2, true, 0.05);
    spec.extra = vec![("laser_grid_normals", tilted(6), vec![6, 3])];
    let r = spec.open(&dir, "paired").unwrap();
    let g = r.geometry();
    assert_eq!(g.normals.lasers.len(), 6);
    assert_eq!(g.normals.lasers[2], [0.2, -0.05, 1.0]);
    assert!(g.normals.spads.is_empty());
    let n = g.laser_normal(2);
    assert!(((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) - 1.0).abs() < 1e-12);
    assert_eq!(g.spad_normal(2), [0.0, 0.0, 1.0]);
    assert!(g.not_flat().is_some_and(|w| w.contains("normals")));
    // +z everywhere (what y-tal writes for a flat wall): the default.
    let up: Vec<f32> = (0..6).flat_map(|_| [0.0, 0.0, 1.0]).collect();
    spec.extra = vec![
        ("laser_grid_normals", up.clone(), vec![6, 3]),
        ("sensor_grid_normals", up.clone(), vec![6, 3]),
    ];
    assert!(spec.open(&dir, "up").unwrap().geometry().normals.flat());
    // tal `single`: the sensor grid's normals become the lasers'.
    let mut single = Spec::exhaustive();
    single.h_shape = vec![6, 6];
    single.h_format = 3;
    single.sensor_grid = grid(3, 2, true, 0.0);
    single.laser_grid = (vec![0.05, 0.02, 0.0], vec![1, 3]);
    single.extra = vec![
        ("sensor_grid_normals", tilted(6), vec![6, 3]),
        ("laser_grid_normals", vec![0.0, 0.3, 1.0], vec![1, 3]),
    ];
    let r = single.open(&dir, "single").unwrap();
    assert_eq!(r.scan_type(), ScanType::Single);
    let g = r.geometry().clone();
    assert_eq!(g.normals.lasers[5], [0.5, -0.05, 1.0]);
    assert_eq!(g.normals.spads, vec![[0.0, 0.3, 1.0]]);
    // The reciprocity factor c'(S_l)/c(x0) takes the spots' own normals (so that
    // `--compensate-laser`, which divides by c'(S_l) with the same normal, leaves H/c(x0)):
    // computed here from the definition, |v·n̂|/d³.
    let f = |o: [f64; 3], x: Point, n: [f64; 3]| {
        let v: Vec<f64> = (0..3).map(|i| o[i] - f64::from(x[i])).collect();
        let d = v.iter().map(|c| c * c).sum::<f64>().sqrt();
        let nn = n.iter().map(|c| c * c).sum::<f64>().sqrt();
        (v[0] * n[0] + v[1] * n[1] + v[2] * n[2]).abs() / nn / d.powi(3)
    };
    let c0 = f([-0.5, 0.0, 0.25], [0.05, 0.02, 0.0], [0.0, 0.3, 1.0]);
    let mut r = r;
    let mut row = Vec::new();
    let mut worst = 0.0f64;
    for l in 0..6 {
        r.read_row(l, &mut row).unwrap();
        let n = [0.1 * l as f64, -0.05, 1.0];
        let k = f([0.5, 0.125, 0.375], g.lasers[l], n) / c0;
        let flat = g.laser_falloff(g.lasers[l]) / c0;
        assert!(
            (k / flat - 1.0).abs() > 1e-3 || l == 0,
            "row {l}: normals change k"
        );
        for (n, &h) in row.iter().enumerate() {
            let want = (n * 10_000 + l) as f64 * k;
            worst = worst.max((f64::from(h) - want).abs() / want.abs().max(1.0));
        }
    }
    assert!(worst < 1e-6, "{worst}");
    // Bad normals: one line naming the field.
    for (name, v, shape, why) in [
        (
            "laser_grid_normals",
            vec![0.0; 18],
            vec![6, 3],
            "non-zero length",
        ),
        (
            "sensor_grid_normals",
            [up.clone(), vec![f32::NAN, 0.0, 1.0]].concat()[3..].to_vec(),
            vec![6, 3],
            "non-zero length",
        ),
        (
            "laser_grid_normals",
            up[..15].to_vec(),
            vec![5, 3],
            "one normal per point",
        ),
    ] {
        spec.extra = vec![(name, v, shape)];
        let e = spec.open(&dir, "bad").unwrap_err().to_string();
        assert!(
            e.contains(name) && e.contains(why) && !e.contains('\n'),
            "{name}: {e}"
        );
    }
}
