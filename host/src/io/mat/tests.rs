//! Tests of the MAT reader on files written here to the published format (a small v5
//! writer: numeric arrays of any storage type, structs, compressed or not).

use super::*;
use flate2::Compression;
use flate2::write::ZlibEncoder;
use std::io::Write;

/// A small-or-normal data element: tag, data, padding.
fn elem(ty: u32, data: &[u8]) -> Vec<u8> {
    let mut v = Vec::new();
    if data.len() <= 4 && !data.is_empty() {
        v.extend_from_slice(&(ty | ((data.len() as u32) << 16)).to_le_bytes());
        let mut d = data.to_vec();
        d.resize(4, 0);
        v.extend_from_slice(&d);
        return v;
    }
    v.extend_from_slice(&ty.to_le_bytes());
    v.extend_from_slice(&(data.len() as u32).to_le_bytes());
    v.extend_from_slice(data);
    v.resize(v.len().div_ceil(8) * 8, 0);
    v
}

/// The body of a miMATRIX (without its tag).
fn matrix_body(class: u8, dims: &[usize], name: &str, data: &[u8]) -> Vec<u8> {
    let mut b = elem(6, &[class, 0, 0, 0, 0, 0, 0, 0]);
    let d: Vec<u8> = dims
        .iter()
        .flat_map(|&x| (x as i32).to_le_bytes())
        .collect();
    b.extend(elem(5, &d));
    b.extend(elem(1, name.as_bytes()));
    b.extend_from_slice(data);
    b
}

fn matrix(class: u8, dims: &[usize], name: &str, data: &[u8]) -> Vec<u8> {
    elem(14, &matrix_body(class, dims, name, data))
}

/// A numeric array: class, stored as `ty` with `bytes` per value.
fn numeric(name: &str, dims: &[usize], class: u8, ty: u32, values: &[f64]) -> Vec<u8> {
    let raw: Vec<u8> = values
        .iter()
        .flat_map(|&x| match ty {
            4 => (x as u16).to_le_bytes().to_vec(),
            7 => (x as f32).to_le_bytes().to_vec(),
            9 => x.to_le_bytes().to_vec(),
            _ => unreachable!(),
        })
        .collect();
    matrix(class, dims, name, &elem(ty, &raw))
}

fn structure(name: &str, fields: &[(&str, Vec<u8>)]) -> Vec<u8> {
    let flen = 32usize;
    let mut data = elem(5, &(flen as i32).to_le_bytes());
    let mut names = Vec::new();
    for (n, _) in fields {
        let mut b = n.as_bytes().to_vec();
        b.resize(flen, 0);
        names.extend(b);
    }
    data.extend(elem(1, &names));
    for (_, f) in fields {
        data.extend_from_slice(f);
    }
    matrix(2, &[1, 1], name, &data)
}

fn compress(element: &[u8]) -> Vec<u8> {
    let mut z = ZlibEncoder::new(Vec::new(), Compression::default());
    z.write_all(element).unwrap();
    let c = z.finish().unwrap();
    let mut v = 15u32.to_le_bytes().to_vec();
    v.extend_from_slice(&(c.len() as u32).to_le_bytes());
    v.extend(c);
    v
}

fn file(elements: &[Vec<u8>]) -> Vec<u8> {
    let mut h = b"MATLAB 5.0 MAT-file, written by vltm's tests".to_vec();
    h.resize(116, b' ');
    h.extend_from_slice(&[0; 8]);
    h.extend_from_slice(&0x0100u16.to_le_bytes());
    h.extend_from_slice(b"IM");
    for e in elements {
        h.extend_from_slice(e);
    }
    h
}

fn write(dir: &std::path::Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn tmp(tag: &str) -> crate::scratch::Scratch {
    crate::scratch::Scratch::dir(&format!("mat-{tag}"))
}

/// rect_data (3, 2, 5) with value 100·i + 10·j + t.
fn stanford_elements(compressed: bool) -> Vec<Vec<u8>> {
    let (n1, n2, nt) = (3, 2, 5);
    let mut v = vec![0.0; n1 * n2 * nt];
    for t in 0..nt {
        for j in 0..n2 {
            for i in 0..n1 {
                v[i + n1 * (j + n2 * t)] = (100 * i + 10 * j + t) as f64;
            }
        }
    }
    let rect = numeric("rect_data", &[n1, n2, nt], 6, 4, &v);
    let width = numeric("width", &[1, 1], 6, 9, &[0.25]);
    if compressed {
        vec![compress(&rect), compress(&width)]
    } else {
        vec![rect, width]
    }
}

#[test]
fn stanford_layout_reads_compressed_and_plain_with_its_conventions() {
    let d = tmp("stanford");
    for compressed in [true, false] {
        let p = write(&d, "s.mat", &file(&stanford_elements(compressed)));
        let m = read(&p, &MatOptions::default()).unwrap();
        assert_eq!(m.layout, Layout::StanfordConfocal);
        let g = &m.capture.geometry;
        assert!(g.confocal && !g.legs_in_time);
        assert_eq!((g.laser_shape, g.nt, g.t0), ([3, 2], 5, 0.0));
        assert!((g.dt - 1.199_169_832e-3).abs() < 1e-12, "{}", g.dt);
        // Row l = i·2 + j at (-w + w·i, w − 2w·j): the second index runs down (y from +w to
        // −w), so that (x, y, z) is right-handed with y up; histogram 100 i + 10 j + t.
        let l = 2 * 2 + 1;
        assert_eq!(g.lasers[l], [0.25, -0.25, 0.0]);
        assert_eq!(g.lasers[0], [-0.25, 0.25, 0.0]);
        assert_eq!(m.capture.row(l), &[210.0, 211.0, 212.0, 213.0, 214.0]);
        assert!(
            m.conventions
                .iter()
                .any(|c| c.contains("assumed: 4 ps bins"))
        );
        assert_eq!(m.variables, ["rect_data 3x2x5 double", "width 1x1 double"]);
    }
    // Overrides.
    let p = write(&d, "s.mat", &file(&stanford_elements(true)));
    let o = MatOptions {
        delta_t: Some(0.002),
        t_start: Some(0.5),
        grid_width: Some(1.0),
    };
    let m = read(&p, &o).unwrap();
    let g = &m.capture.geometry;
    assert_eq!((g.dt, g.t0, g.lasers[0][0]), (0.002, 0.5, -1.0));
    assert!(m.conventions.iter().any(|c| c.contains("set by $delta_t")));
}

/// struct `dataset` of 3 lasers × 4 bins, data = 0, 1, 2, … (single).
fn phasor_dataset() -> Vec<u8> {
    let (nt, nl) = (4, 3);
    let data: Vec<f64> = (0..nt * nl).map(|k| k as f64).collect();
    let pos: Vec<f64> = (0..nl).flat_map(|l| [0.1 * l as f64, 0.2, 0.0]).collect();
    structure(
        "dataset",
        &[
            ("data", numeric("", &[nt, 1, nl], 7, 7, &data)),
            ("laserPos", numeric("", &[3, nl], 6, 9, &pos)),
            ("cameraPos", numeric("", &[3, 1], 6, 9, &[0.0, 0.0, 0.0])),
            ("laserOrigin", numeric("", &[3, 1], 6, 9, &[0.0, 0.0, 1.0])),
            ("cameraOrigin", numeric("", &[3, 1], 6, 9, &[0.1, 0.0, 1.0])),
            ("deltat", numeric("", &[1, 1], 6, 9, &[0.001])),
            ("t0", numeric("", &[1, 1], 6, 9, &[1.5])),
        ],
    )
}

#[test]
fn phasor_field_layout_reads_a_struct() {
    let d = tmp("pf");
    let p = write(&d, "pf.mat", &file(&[compress(&phasor_dataset())]));
    let m = read(&p, &MatOptions::default()).unwrap();
    assert_eq!(m.layout, Layout::PhasorField);
    let g = &m.capture.geometry;
    assert!(g.legs_in_time && !g.confocal);
    assert_eq!((g.lasers.len(), g.spads.len(), g.nt), (3, 1, 4));
    assert_eq!(g.lasers[2], [0.2, 0.2, 0.0]);
    assert_eq!((g.dt, g.t0), (0.001, 1.5));
    assert_eq!(g.sensor_origin, [0.1, 0.0, 1.0]);
    assert_eq!(m.capture.row(1), &[4.0, 5.0, 6.0, 7.0]);
}

#[test]
fn bad_files_name_the_file_and_the_variable() {
    let d = tmp("bad");
    let err = |bytes: &[u8]| {
        let p = write(&d, "b.mat", bytes);
        read(&p, &MatOptions::default()).unwrap_err().to_string()
    };
    // Unknown layout: the variables are listed.
    let e = err(&file(&[compress(&numeric(
        "foo",
        &[2, 2],
        6,
        9,
        &[1.0; 4],
    ))]));
    assert!(e.contains("b.mat") && e.contains("foo 2x2 double"), "{e}");
    // Wrong dims.
    let e = err(&file(&[
        numeric("rect_data", &[4, 0, 2], 6, 9, &[]),
        numeric("width", &[1, 1], 6, 9, &[0.2]),
    ]));
    assert!(e.contains("`rect_data`") && e.contains("dims"), "{e}");
    // Non-numeric.
    let e = err(&file(&[
        matrix(
            4,
            &[1, 3],
            "rect_data",
            &elem(4, &[b'a', 0, b'b', 0, b'c', 0]),
        ),
        numeric("width", &[1, 1], 6, 9, &[0.2]),
    ]));
    assert!(e.contains("`rect_data`") && e.contains("numeric"), "{e}");
    // Values that do not fill the dims.
    let e = err(&file(&[
        numeric("rect_data", &[2, 2, 2], 6, 9, &[1.0; 3]),
        numeric("width", &[1, 1], 6, 9, &[0.2]),
    ]));
    assert!(e.contains("`rect_data`") && e.contains("8 values"), "{e}");
    // Truncated: at every length the error names the file, never panics.
    let good = file(&stanford_elements(true));
    for cut in (0..good.len()).step_by(7) {
        let e = err(&good[..cut]);
        assert!(e.starts_with(&d.join("b.mat").display().to_string()), "{e}");
    }
    // A corrupt zlib stream inside rect_data (8x8x64 values that do not compress away).
    let v: Vec<f64> = (0..8 * 8 * 64)
        .map(|k| ((k * 7919) % 65521) as f64)
        .collect();
    let good = file(&[
        compress(&numeric("rect_data", &[8, 8, 64], 6, 4, &v)),
        numeric("width", &[1, 1], 6, 9, &[0.2]),
    ]);
    assert!(read(&write(&d, "g.mat", &good), &MatOptions::default()).is_ok());
    let mut bad = good.clone();
    // Well past the header (in the values), and in the header.
    let mid = 128 + 8 + 200;
    for b in &mut bad[mid..mid + 12] {
        *b ^= 0x5A;
    }
    let e = err(&bad);
    assert!(e.contains("b.mat") && e.contains("`rect_data`"), "{e}");
    let mut bad = good.clone();
    for b in &mut bad[128 + 8 + 4..128 + 8 + 10] {
        *b ^= 0x5A;
    }
    let e = err(&bad);
    assert!(
        e.contains("b.mat") && e.contains("variable at byte 128"),
        "{e}"
    );
    // Dims claiming more than the budget: refused before anything is allocated.
    let huge = matrix(6, &[1 << 30, 1 << 30, 8], "rect_data", &elem(9, &[0; 16]));
    let e = err(&file(&[
        compress(&huge),
        numeric("width", &[1, 1], 6, 9, &[0.2]),
    ]));
    assert!(e.contains("rect_data") && e.contains("budget"), "{e}");
}

#[test]
fn mat_v73_reads_like_v5() {
    let p =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mat/stanford_v73.mat");
    let m = read(&p, &MatOptions::default()).unwrap();
    assert_eq!(
        (m.version, m.layout),
        ("MAT v7.3 (HDF5)", Layout::StanfordConfocal)
    );
    let d = tmp("v73");
    let v5 = read(
        &write(&d, "s.mat", &file(&stanford_elements(true))),
        &MatOptions::default(),
    )
    .unwrap();
    assert_eq!(m.capture, v5.capture);
    assert_eq!(m.variables, ["rect_data 3x2x5 double", "width 1x1 double"]);
    // Truncated: an error naming the file.
    let bytes = std::fs::read(&p).unwrap();
    let t = write(&d, "t.mat", &bytes[..1500]);
    let e = read(&t, &MatOptions::default()).unwrap_err().to_string();
    assert!(e.contains("t.mat"), "{e}");
}

/// Seeds of the `mat` fuzz target (`fuzz/seeds/mat`): both layouts, compressed and plain, and
/// the v7.3 fixture. `cargo test --release -p vltm --lib -- --ignored write_mat_fuzz_seeds`.
#[test]
#[ignore = "writes fuzz/seeds/mat; run by hand"]
fn write_mat_fuzz_seeds() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let d = root.join("fuzz/seeds/mat");
    std::fs::create_dir_all(&d).unwrap();
    for (name, bytes) in [
        ("stanford_z.mat", file(&stanford_elements(true))),
        ("stanford.mat", file(&stanford_elements(false))),
        ("phasor_z.mat", file(&[compress(&phasor_dataset())])),
        ("phasor.mat", file(&[phasor_dataset()])),
    ] {
        let p = write(&d, name, &bytes);
        assert!(read(&p, &MatOptions::default()).is_ok(), "{name}");
    }
    let v73 = std::fs::read(root.join("fixtures/mat/stanford_v73.mat")).unwrap();
    write(&d, "stanford_v73.mat", &v73);
}

/// The overrides are refused, by name, for a capture that records its conventions.
#[test]
fn overrides_are_refused_by_name() {
    assert!(MatOptions::default().refuse().is_ok());
    for (o, name) in [
        (
            MatOptions {
                delta_t: Some(0.01),
                ..Default::default()
            },
            "delta_t",
        ),
        (
            MatOptions {
                t_start: Some(0.0),
                grid_width: Some(1.0),
                ..Default::default()
            },
            "t_start",
        ),
        (
            MatOptions {
                grid_width: Some(1.0),
                ..Default::default()
            },
            "grid_width",
        ),
    ] {
        let e = o.refuse().unwrap_err().to_string();
        assert_eq!(
            e,
            format!(
                "argument `{name}`: only for .mat captures (other formats record their time axis and grid)"
            )
        );
    }
}
