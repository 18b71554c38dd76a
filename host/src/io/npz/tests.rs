//! Tests of the `.npz` reader, writer and stream.

use super::*;
use crate::error::{Error, Result};
use crate::io::capture::RowSource;
use ndarray::{ArrayD, IxDyn};
use ndarray_npy::NpzWriter;
use std::fs::File;
use std::path::Path;
use std::path::PathBuf;

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fixtures/two_patches.npz")
}

/// A per-histogram paired archive as numpy writes it (`np.savez(H=..., laser_xyz=...,
/// sensor_xyz=..., ...)`), with `edit` applied to the arrays first.
fn write_paired(p: &Path, edit: impl FnOnce(&mut Vec<(&'static str, ArrayD<f64>)>)) {
    let k = 5;
    let nt = 7;
    let pts = |dx: f64, dz: f64| {
        ArrayD::from_shape_fn(IxDyn(&[k, 3]), move |i| match i[1] {
            0 => 0.1 * i[0] as f64 + dx,
            1 => -0.05,
            _ => dz * (i[0] % 2) as f64,
        })
    };
    let mut arrays: Vec<(&'static str, ArrayD<f64>)> = vec![
        ("laser_xyz", pts(0.0, 0.03)),
        ("sensor_xyz", pts(0.02, -0.04)),
        (
            "laser_normals",
            ArrayD::from_shape_fn(IxDyn(&[k, 3]), |i| f64::from(u8::from(i[1] == 2))),
        ),
        ("delta_t", ndarray::arr0(0.01).into_dyn()),
        ("t_start", ndarray::arr0(0.5).into_dyn()),
    ];
    edit(&mut arrays);
    let mut w = NpzWriter::new(File::create(p).unwrap());
    let h = ArrayD::from_shape_fn(IxDyn(&[k, nt]), |i| (i[0] * 100 + i[1]) as f32);
    w.add_array("H", &h).unwrap();
    for (name, a) in &arrays {
        if name.starts_with("t_accounts") {
            w.add_array(*name, &a.mapv(|x| x as u8)).unwrap();
        } else {
            w.add_array(*name, a).unwrap();
        }
    }
    w.finish().unwrap();
}

/// The per-histogram paired form reads as a paired geometry (row `l` = pair `l`, its own
/// laser and SPAD spot, on a relay surface that is not flat), in memory and streamed;
/// vltm's own layout writes and reads it back unchanged.
#[test]
fn paired_per_histogram_form() {
    let dir = std::env::temp_dir().join(format!("vltm-paired-npz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("paired.npz");
    write_paired(&p, |_| {});
    let c = read(&p).unwrap();
    let g = &c.geometry;
    assert!(g.confocal && g.paired_apart());
    assert_eq!((g.lasers.len(), g.spads.len(), g.nt), (5, 5, 7));
    assert_eq!(g.lasers[3], [0.3, -0.05, 0.03]);
    assert_eq!(g.spads[3], [0.32, -0.05, -0.04]);
    assert_eq!((g.dt, g.t0, g.legs_in_time), (0.01, 0.5, false));
    assert_eq!(c.row(3), &[300.0, 301.0, 302.0, 303.0, 304.0, 305.0, 306.0]);
    let mut s = open_stream(&p).unwrap().expect("stored H streams");
    let mut row = Vec::new();
    assert_eq!(s.read_row(3, &mut row).unwrap(), g.lasers[3]);
    assert_eq!(row, c.row(3));
    // vltm's layout: confocal = 1 with two different grids of one shape.
    let q = dir.join("vltm.npz");
    write(&c, &q).unwrap();
    assert_eq!(read(&q).unwrap(), c);
    let _ = std::fs::remove_dir_all(dir);
}

/// Per-pair normals (`laser_normals`, `sensor_normals`) that are not all +z are kept per
/// point in the geometry (all-+z ones are the flat default), and vltm's layout writes them
/// as `laser_grid_normals` / `sensor_grid_normals` and reads them back unchanged; a NaN
/// normal is a one-line error naming its key.
#[test]
fn paired_normals_are_kept_and_written() {
    let dir = std::env::temp_dir().join(format!("vltm-paired-nrm-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("paired.npz");
    let tilt = |a: f64| {
        ArrayD::from_shape_fn(IxDyn(&[5, 3]), move |i| match i[1] {
            0 => a * i[0] as f64,
            1 => 0.0,
            _ => 1.0,
        })
    };
    write_paired(&p, |a| {
        a.retain(|(n, _)| *n != "laser_normals");
        a.push(("laser_normals", tilt(0.1)));
        a.push(("sensor_normals", tilt(-0.2)));
    });
    let c = read(&p).unwrap();
    let g = &c.geometry;
    assert_eq!(g.normals.lasers[3], [0.3f32, 0.0, 1.0]);
    assert_eq!(g.normals.spads[3], [-0.6f32, 0.0, 1.0]);
    assert!(g.not_flat().is_some());
    let q = dir.join("vltm.npz");
    write(&c, &q).unwrap();
    assert_eq!(read(&q).unwrap(), c);
    // The layout without normals (+z) reads back with none, as before.
    write_paired(&p, |_| {});
    assert!(read(&p).unwrap().geometry.normals.flat());
    write_paired(&p, |a| {
        a.retain(|(n, _)| *n != "laser_normals");
        let mut t = tilt(0.1);
        t[&[1usize, 2][..]] = f64::NAN;
        a.push(("sensor_normals", t));
    });
    let e = read(&p).unwrap_err().to_string();
    assert!(e.contains("sensor_normals") && !e.contains('\n'), "{e}");
    let _ = std::fs::remove_dir_all(dir);
}

/// Bad paired input: one line naming the key, for lists of different lengths, NaN points,
/// zero-length normals, an H that does not hold one histogram per pair, and legs in time
/// without device positions.
#[test]
fn paired_bad_input_names_the_key() {
    let dir = std::env::temp_dir().join(format!("vltm-paired-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let set = |a: &mut Vec<(&'static str, ArrayD<f64>)>, k: &'static str, v: ArrayD<f64>| {
        a.retain(|(n, _)| *n != k);
        a.push((k, v));
    };
    type Edit = Box<dyn Fn(&mut Vec<(&'static str, ArrayD<f64>)>)>;
    let cases: Vec<(&str, Edit, &str)> = vec![
        (
            "lengths",
            Box::new(move |a| set(a, "sensor_xyz", ArrayD::zeros(IxDyn(&[4, 3])))),
            "sensor_xyz",
        ),
        (
            "nan",
            Box::new(move |a| {
                let mut l = a.iter().find(|(n, _)| *n == "laser_xyz").unwrap().1.clone();
                l[&[2usize, 1][..]] = f64::NAN;
                set(a, "laser_xyz", l);
            }),
            "laser_xyz",
        ),
        (
            "normal",
            Box::new(move |a| set(a, "laser_normals", ArrayD::zeros(IxDyn(&[5, 3])))),
            "laser_normals",
        ),
        (
            "shape",
            Box::new(move |a| set(a, "laser_xyz", ArrayD::zeros(IxDyn(&[5, 2])))),
            "laser_xyz",
        ),
        (
            "legs",
            Box::new(move |a| {
                set(
                    a,
                    "t_accounts_first_and_last_bounces",
                    ndarray::arr0(1.0).into_dyn(),
                );
            }),
            "t_accounts_first_and_last_bounces",
        ),
    ];
    for (name, edit, key) in cases {
        let p = dir.join(format!("{name}.npz"));
        write_paired(&p, |a| edit(a));
        let e = read(&p).unwrap_err();
        let msg = e.to_string();
        assert!(
            matches!(&e, Error::Format { field, .. } if field == key),
            "{name}: {msg}"
        );
        assert!(!msg.contains('\n'), "{name}: {msg}");
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// An uncompressed archive streams the same rows as the in-memory reader; a compressed
/// one is not streamed; a truncated one is rejected by name.
#[test]
fn npz_stream_equals_read() {
    let c = read(&fixture()).unwrap();
    assert!(open_stream(&fixture()).unwrap().is_none(), "compressed");
    let dir = std::env::temp_dir().join(format!("vltm-stream-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("c.npz");
    write_with(&c, &p, false).unwrap();
    let mut s = open_stream(&p).unwrap().expect("stored H streams");
    assert_eq!(s.geometry(), &c.geometry);
    let mut row = Vec::new();
    for l in [0, 17, c.geometry.lasers.len() - 1] {
        let x = s.read_row(l, &mut row).unwrap();
        assert_eq!(x, c.geometry.lasers[l]);
        assert_eq!(row.as_slice(), c.row(l));
    }
    assert!(s.read_row(c.geometry.lasers.len(), &mut row).is_err());
    // Cut the file inside H: the archive or H is reported, never a short row.
    let bytes = std::fs::read(&p).unwrap();
    let t = dir.join("t.npz");
    std::fs::write(&t, &bytes[..bytes.len() / 2]).unwrap();
    let e = open_stream(&t).and_then(|s| s.ok_or(crate::Error::arg("x", "none")));
    assert!(e.is_err(), "truncated archive accepted");
    std::fs::remove_dir_all(&dir).ok();
}

/// A flipped byte inside the stored `H` is caught by the CRC-32, whether the rows are read
/// in order or skipping around; the intact file passes both ways, and a second pass too.
#[test]
fn streamed_rows_are_crc_checked() {
    let c = read(&fixture()).unwrap();
    let dir = std::env::temp_dir().join(format!("vltm-crc-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("c.npz");
    write_with(&c, &p, false).unwrap();
    let kl = c.geometry.lasers.len();
    let pass = |path: &Path, order: &[usize]| -> Result<()> {
        let mut s = open_stream(path)?.expect("stored");
        let mut row = Vec::new();
        for &l in order {
            s.read_row(l, &mut row)?;
        }
        Ok(())
    };
    let in_order: Vec<usize> = (0..kl).chain(0..kl).collect();
    let skipping: Vec<usize> = (0..kl).rev().collect();
    pass(&p, &in_order).unwrap();
    pass(&p, &skipping).unwrap();
    let mut bytes = std::fs::read(&p).unwrap();
    // A byte in the middle of H (H is the first and by far the largest member).
    let at = bytes.len() / 3;
    bytes[at] ^= 0x40;
    let bad = dir.join("bad.npz");
    std::fs::write(&bad, &bytes).unwrap();
    for order in [&in_order, &skipping] {
        let e = pass(&bad, order).unwrap_err().to_string();
        assert!(e.contains("CRC-32") && e.contains("bad.npz"), "{e}");
    }
    // In batches (parallel positional reads): the same rows; the flipped byte caught.
    let batches = |path: &Path, batch: usize| -> Result<Vec<f32>> {
        let mut s = open_stream(path)?.expect("stored");
        let mut all = Vec::new();
        let mut rows: Vec<(vltm_kernel::Point, Vec<f32>)> = Vec::new();
        for start in (0..kl).step_by(batch) {
            rows.resize_with((start + batch).min(kl) - start, || ([0.0; 3], Vec::new()));
            s.read_rows(start, &mut rows)?;
            for (i, (x, h)) in rows.iter().enumerate() {
                assert_eq!(*x, c.geometry.lasers[start + i]);
                all.extend_from_slice(h);
            }
        }
        Ok(all)
    };
    for batch in [1, 3, 8, kl] {
        assert_eq!(batches(&p, batch).unwrap(), c.data, "batch {batch}");
        let e = batches(&bad, batch).unwrap_err().to_string();
        assert!(e.contains("CRC-32") && e.contains("bad.npz"), "{e}");
    }
    let mut s = open_stream(&p).unwrap().expect("stored");
    let mut two = vec![([0.0; 3], Vec::new()); 2];
    assert!(s.read_rows(kl - 1, &mut two).is_err(), "a row past the end");
    std::fs::remove_dir_all(&dir).ok();
}
