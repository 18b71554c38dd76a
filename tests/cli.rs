//! The `vltm` command line on the committed fixtures (`fixtures/README.md`): every subcommand
//! runs and writes readable outputs; bad arguments exit with code 2 and bad data with code 1,
//! each with a one-line error starting with `vltm: `.
//!
//! **Which binary.** Cargo sets `CARGO_BIN_EXE_vltm` only for the tests of the package that owns
//! the binary (`host/`), not for this root package. So `support::vltm_bin` runs
//! `cargo build -p vltm-cli --bin vltm` once per test process (a `OnceLock`), with the cargo that
//! runs the tests (`$CARGO`), the profile and the target directory of this test executable
//! (`<target>/<dir>/deps/cli-<hash>` → `<target>/<dir>/vltm`; `debug/` → `--profile test`,
//! `release/` → `--profile release`), and uses the resulting path. That always tests the
//! current sources (a stale `target/release/vltm` cannot slip through) and is a no-op when the
//! binary is up to date. (Cargo releases the build-directory lock before it runs test
//! executables, so the nested build does not wait on the outer `cargo test`; checked with
//! cargo 1.95.) `VLTM_BIN=/path/to/vltm`
//! overrides it (e.g. for cross-compiled or installed binaries).
//!
//! Outputs go to unique temporary directories under `std::env::temp_dir()` (process id + test
//! name; `support::cmd::TempDir`), removed at the end of each test.

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;
use support::cmd::{TempDir, npz_fixture, read_npy, text, vltm_in};

use vltm::io;
use vltm::probe::{self, Exec, Wave};
use vltm::volume::Volume;

/// A small volume around the two patches of the fixtures: 13 × 3 × 8 voxels, 10 cm pitch.
const SPEC: &str = "-0.6:0.6:13,-0.1:0.1:3,0.5:1.2:8";
const SHAPE: [usize; 3] = [13, 3, 8];
/// Patch A of `fixtures/scenes/two_patches.json`.
const FOCUS: &str = "-0.45,0,0.8";

/// Runs `vltm args…` and asserts success; returns stdout.
fn ok(cwd: &Path, args: &[&str]) -> String {
    let o = vltm_in(cwd, args);
    assert!(
        o.status.success(),
        "vltm {args:?} failed ({:?}):\n{}",
        o.status.code(),
        text(&o.stderr)
    );
    text(&o.stdout)
}

/// Runs `vltm args…` and asserts exit code `code` and a one-line stderr starting with
/// `vltm: `; returns that line.
fn fails(cwd: &Path, args: &[&str], code: i32) -> String {
    let o = vltm_in(cwd, args);
    let err = text(&o.stderr);
    assert_eq!(
        o.status.code(),
        Some(code),
        "vltm {args:?}: expected exit code {code}, stderr: {err}"
    );
    let lines: Vec<&str> = err.lines().collect();
    assert!(
        lines.len() == 1 && lines[0].starts_with("vltm: "),
        "vltm {args:?}: expected one line starting with `vltm: `, found {} line(s):\n{err}",
        lines.len()
    );
    println!("exit {code}: vltm {args:?}\n  {}", lines[0]);
    lines[0].to_string()
}

/// Reads a `.npy` volume and checks its shape and that every value is finite; returns it.
fn npy(path: &Path, shape: [usize; 3]) -> Vec<f32> {
    let (v, s) = read_npy(path);
    assert_eq!(s, shape, "{}: shape", path.display());
    assert!(
        v.iter().all(|x| x.is_finite()),
        "{}: non-finite values",
        path.display()
    );
    v
}

/// CRC-32 (IEEE), as PNG chunks use.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// Checks a PNG's structure (the `image` crate is not a dependency of this package): the
/// signature, an `IHDR` first with a non-empty size, at least one `IDAT`, `IEND` last, and
/// every chunk's CRC. Returns (width, height).
fn png(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let what = path.display();
    assert!(
        b.starts_with(b"\x89PNG\r\n\x1a\n"),
        "{what}: not a PNG signature"
    );
    let (mut at, mut chunks) = (8, Vec::new());
    while at < b.len() {
        assert!(at + 12 <= b.len(), "{what}: truncated chunk at byte {at}");
        let len = u32::from_be_bytes(b[at..at + 4].try_into().expect("4 bytes")) as usize;
        let end = at + 8 + len;
        assert!(end + 4 <= b.len(), "{what}: truncated chunk at byte {at}");
        let crc = u32::from_be_bytes(b[end..end + 4].try_into().expect("4 bytes"));
        assert_eq!(crc32(&b[at + 4..end]), crc, "{what}: bad CRC at byte {at}");
        chunks.push((b[at + 4..at + 8].to_vec(), at + 8, len));
        at = end + 4;
    }
    let names: Vec<&[u8]> = chunks.iter().map(|c| c.0.as_slice()).collect();
    assert_eq!(names.first(), Some(&&b"IHDR"[..]), "{what}: IHDR first");
    assert_eq!(names.last(), Some(&&b"IEND"[..]), "{what}: IEND last");
    assert!(names.contains(&&b"IDAT"[..]), "{what}: no IDAT");
    let (_, start, len) = chunks[0];
    assert_eq!(len, 13, "{what}: IHDR length");
    let w = u32::from_be_bytes(b[start..start + 4].try_into().expect("4 bytes"));
    let h = u32::from_be_bytes(b[start + 4..start + 8].try_into().expect("4 bytes"));
    assert!(w > 0 && h > 0, "{what}: size {w}x{h}");
    (w, h)
}

// ---------------------------------------------------------------------------------------------
// subcommands
// ---------------------------------------------------------------------------------------------

#[test]
fn info_describes_a_capture() {
    let t = TempDir::new("cli", "info");
    let out = ok(
        &t.0,
        &["info", npz_fixture("two_patches").to_str().expect("utf-8")],
    );
    print!("{out}");
    for want in [
        "non-confocal",
        "lasers       64 = 8x8",
        "SPADs        64 = 8x8",
        "175 bins x 0.02 m from t0 = 1 m",
        "non-finite 0",
    ] {
        assert!(out.contains(want), "`vltm info` lacks `{want}`:\n{out}");
    }
}

/// The `--volume` SPEC on `info`'s `volume` line.
fn suggested_volume(info: &str) -> &str {
    let line = info
        .lines()
        .find(|l| l.starts_with("volume       suggested --volume "))
        .unwrap_or_else(|| panic!("`vltm info` suggests no volume:\n{info}"));
    line["volume       suggested --volume ".len()..]
        .split_whitespace()
        .next()
        .expect("a SPEC")
}

/// Checks a suggested volume against a capture's time window: every slice of the volume holds
/// a voxel whose shortest 3-bounce path (over the capture's pairs) lies in the window, the
/// nearest slice's shortest path is not before the window opens, and the z range covers at
/// least 80 % of the depths the window reaches (`(t_max − t0)/2` in front of a spot).
fn check_suggestion(g: &io::Geometry, v: &Volume) -> Result<(), String> {
    let axes = v.axes.ok_or("a point list, not a grid")?;
    let (t0, t1) = (g.t0, g.t0 + (g.nt - 1) as f64 * g.dt);
    let d = |a: [f32; 3], b: [f32; 3]| {
        (0..3)
            .map(|i| f64::from(a[i] - b[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let shortest = |p: [f32; 3]| {
        let mut m = f64::INFINITY;
        for (l, x_l) in g.lasers.iter().enumerate() {
            for x_s in g.row_spads(l) {
                m = m.min(d(*x_l, p) + d(p, *x_s));
            }
        }
        m
    };
    let nz = v.shape[2];
    let tol = 1e-3;
    for iz in 0..nz {
        let slice: Vec<f64> = (0..v.shape[0] * v.shape[1])
            .map(|k| shortest(v.points[k * nz + iz]))
            .collect();
        let lo = slice.iter().copied().fold(f64::INFINITY, f64::min);
        let z = v.points[iz][2];
        if lo > t1 + tol {
            return Err(format!(
                "slice z = {z}: the shortest path {lo:.4} m is past the window's end {t1:.4} m"
            ));
        }
        if iz == 0 && lo < t0 - tol {
            return Err(format!(
                "nearest slice z = {z}: the shortest path {lo:.4} m is before the window opens at {t0:.4} m"
            ));
        }
    }
    let reach = 0.5 * (t1 - t0.max(0.0));
    let span = f64::from(axes[2][1] - axes[2][0]);
    if span < 0.8 * reach {
        return Err(format!(
            "z spans {span:.4} m of the {reach:.4} m the window reaches"
        ));
    }
    if axes[2][0] <= 0.0 {
        return Err(format!(
            "z starts at {} m, not in front of the wall",
            axes[2][0]
        ));
    }
    Ok(())
}

/// `info` suggests a whole volume, z included: the SPEC parses, `direct` runs on it, and its
/// z range is the depths the capture's time window reaches (on two fixtures with different
/// windows). Teeth: the check refuses a z range past the window, one before it, and one that
/// covers a small part of it.
#[test]
fn info_suggests_a_whole_volume() {
    let t = TempDir::new("cli", "suggest");
    for stem in ["two_patches", "three_points"] {
        let cap = npz_fixture(stem);
        let out = ok(&t.0, &["info", cap.to_str().expect("utf-8")]);
        let spec = suggested_volume(&out);
        let v = Volume::parse(spec).unwrap_or_else(|e| panic!("{spec}: {e}"));
        let g = io::open(&cap).expect("open").geometry;
        check_suggestion(&g, &v).unwrap_or_else(|e| panic!("{stem}: --volume {spec}: {e}"));
        ok(
            &t.0,
            &[
                "direct",
                cap.to_str().expect("utf-8"),
                "--volume",
                spec,
                "--out",
                "d.npy",
            ],
        );
    }
    // The Stanford chart's window opens at the wall: z starts one pitch in front of it.
    let chart = support::fixture("real/data_resolution_chart_40cm.mat");
    let out = ok(&t.0, &["info", chart.to_str().expect("utf-8")]);
    let v = Volume::parse(suggested_volume(&out)).expect("parse");
    let z = v.axes.expect("grid")[2];
    assert!(z[0] > 0.0 && z[0] < 0.01 && z[1] <= 2.4547 / 2.0, "{z:?}");
    assert!(z[1] > 1.2, "{z:?}");
    // Teeth.
    let g = io::open(&npz_fixture("two_patches"))
        .expect("open")
        .geometry;
    for (bad, why) in [
        ("-0.5:0.5:8,-0.5:0.5:8,0.5:2.6:13", "past the window's end"),
        (
            "-0.5:0.5:8,-0.5:0.5:8,0.3:2.2:13",
            "before the window opens",
        ),
        ("-0.5:0.5:8,-0.5:0.5:8,0.5:1.2:13", "the window reaches"),
    ] {
        let e = check_suggestion(&g, &Volume::parse(bad).expect("parse"))
            .expect_err(&format!("{bad} passed the check"));
        assert!(e.contains(why), "{bad}: {e}");
    }
}

/// `info --volume` says which path a grid takes and the aligned grid; `direct` on that
/// off-lattice grid with the planar path forced runs it resampled and names the support grid.
#[test]
fn off_lattice_volume_is_named_and_resampled() {
    let t = TempDir::new("cli", "offgrid");
    let cap = npz_fixture("two_patches");
    let cap = cap.to_str().expect("utf-8");
    let vol = "-0.7:0.7:15,-0.7:0.7:15,0.4:1.3:4";
    let out = ok(&t.0, &["info", cap, "--volume", vol]);
    for want in [
        "fast paths   FFT path for wall-parallel grids of x-y pitch 0.1428571 x 0.1428571 m",
        "the volume   off the wall's lattice",
        "the nearest aligned grid is --volume -0.7:0.7285714:11,-0.7:0.7285714:11,0.4:1.3:4",
    ] {
        assert!(
            out.contains(want),
            "`vltm info --volume` lacks `{want}`:\n{out}"
        );
    }
    let out = ok(
        &t.0,
        &[
            "direct",
            cap,
            "--volume",
            vol,
            "--wavelength",
            "0.8",
            "--sigma",
            "0.4",
            "--path",
            "planar",
            "--out",
            "d.npy",
        ],
    );
    assert!(
        out.contains("path planar, resampled") && out.contains("computed on --volume"),
        "{out}"
    );
    let err = fails(
        &t.0,
        &[
            "direct",
            cap,
            "--volume",
            vol,
            "--wavelength",
            "0.2",
            "--path",
            "planar",
            "--out",
            "e.npy",
        ],
        2,
    );
    assert!(err.contains("nor on a resampled grid"), "{err}");
    assert!(
        !t.0.join("e.npy").exists(),
        "nothing written on a refused path"
    );
}

/// `simulate` renders a scene file to the same capture as the committed fixture.
#[test]
fn simulate_writes_the_committed_capture() {
    let t = TempDir::new("cli", "simulate");
    let out_npz = t.path("s.npz");
    let scene = support::fixture("scenes/two_patches_line.json");
    let out = ok(
        &t.0,
        &[
            "simulate",
            scene.to_str().expect("utf-8"),
            "--out",
            out_npz.to_str().expect("utf-8"),
        ],
    );
    print!("{out}");
    assert!(out.contains("64 lasers x 8 SPADs x 175 bins"), "{out}");
    let fresh = io::open(&out_npz).expect("read the simulated capture");
    let committed = io::open(&npz_fixture("two_patches_line")).expect("fixture");
    assert_eq!(fresh.geometry, committed.geometry);
    assert!(
        fresh.data == committed.data,
        "simulated H differs from the fixture"
    );
}

/// `direct` writes the `.npy` and `.png` it is asked for, and its volume equals the library's
/// `probe::direct` on the same capture; without `--out`/`--png` it writes `direct.npy` and
/// `direct.png` in the current directory. `--threads 1` and `--swap-roles` run too.
#[test]
fn direct_writes_volume_and_figure() {
    let t = TempDir::new("cli", "direct");
    let cap = npz_fixture("two_patches");
    let cap = cap.to_str().expect("utf-8");
    let (f_npy, f_png) = (t.path("d.npy"), t.path("d.png"));
    let out = ok(
        &t.0,
        &[
            "direct",
            cap,
            "--volume",
            SPEC,
            "--out",
            f_npy.to_str().expect("utf-8"),
            "--png",
            f_png.to_str().expect("utf-8"),
        ],
    );
    print!("{out}");
    let v = npy(&f_npy, SHAPE);
    let (w, h) = png(&f_png);
    println!("d.png: {w}x{h}");
    let vol = Volume::parse(SPEC).expect("spec");
    let lib = probe::direct(
        &mut io::open(Path::new(cap)).expect("fixture"),
        &vol,
        &Wave::default(),
        Exec::default(),
    )
    .expect("direct");
    let max = lib.values.iter().copied().fold(0.0f32, f32::max);
    let diff = v
        .iter()
        .zip(&lib.values)
        .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    assert!(
        max > 0.0 && diff <= 1e-6 * max,
        "CLI and library direct images differ by {diff:e} (peak {max:e})"
    );

    // Default output names, in the current directory; one thread.
    ok(&t.0, &["direct", cap, "--volume", SPEC, "--threads", "1"]);
    let v1 = npy(&t.path("direct.npy"), SHAPE);
    png(&t.path("direct.png"));
    assert!(v1 == v, "--threads 1 changed the direct image");

    // --swap-roles on the 1-D SPAD array: SPADs as projector, lasers as camera.
    let line = npz_fixture("two_patches_line");
    let sw = t.path("swap.npy");
    ok(
        &t.0,
        &[
            "direct",
            line.to_str().expect("utf-8"),
            "--volume",
            SPEC,
            "--swap-roles",
            "--weights",
            "one",
            "--compensate-laser",
            "--out",
            sw.to_str().expect("utf-8"),
        ],
    );
    let v = npy(&sw, SHAPE);
    assert!(v.iter().any(|&x| x > 0.0), "--swap-roles: empty image");
}

/// `--out F.h5` writes the same volume as HDF5 (`intensity`, `volume_xyz`, the parameters as
/// attributes), read back with the pure-Rust reader.
#[test]
fn direct_and_column_write_hdf5_volumes() {
    let t = TempDir::new("cli", "h5out");
    let cap = npz_fixture("two_patches");
    let cap = cap.to_str().expect("utf-8");
    let s = |p: &Path| p.to_str().expect("utf-8").to_string();
    for (probe, extra) in [("direct", vec![]), ("column", vec!["--focus", FOCUS])] {
        let (f_npy, f_h5) = (
            t.path(&format!("{probe}.npy")),
            t.path(&format!("{probe}.h5")),
        );
        for f in [&f_npy, &f_h5] {
            let mut args = vec![probe, cap, "--volume", SPEC];
            args.extend(&extra);
            let f = s(f);
            args.extend(["--out", f.as_str()]);
            ok(&t.0, &args);
        }
        let v = npy(&f_npy, SHAPE);
        let (h, shape) = vltm::export::h5::read_volume(&f_h5).expect("read the HDF5 volume");
        assert_eq!(shape, SHAPE.to_vec(), "{probe}: HDF5 shape");
        assert!(h == v, "{probe}: the HDF5 and .npy volumes differ");
    }
}

/// The path-traced y-tal capture of `fixtures/ytal` through the command line as a user runs it: `info` names its
/// format and geometry, `direct` streams it row by row and writes a volume whose peak is on
/// patch A (x_a = (−0.25, 0.15, 0.7): the volume's voxel (−0.25, 0.15, 0.65), as y-tal's).
#[test]
fn ytal_capture_through_the_command_line() {
    let t = TempDir::new("cli", "ytalcli");
    let h5 = support::fixture("ytal/two_patches/two_patches.hdf5");
    let h5 = h5.to_str().expect("utf-8");
    let out = ok(&t.0, &["info", h5]);
    print!("{out}");
    for want in [
        "H_format T_Lx_Ly_Sx_Sy",
        "exhaustive",
        "lasers       64 = 8x8",
        "SPADs        64 = 8x8",
        "400 bins x 0.01 m from t0 = 1 m",
    ] {
        assert!(out.contains(want), "`vltm info` lacks `{want}`:\n{out}");
    }
    let single = support::fixture("ytal/single/single.hdf5");
    let out = ok(&t.0, &["info", single.to_str().expect("utf-8")]);
    assert!(
        out.contains("H_format T_Sx_Sy") && out.contains("reciprocity"),
        "{out}"
    );
    let f = t.path("d.npy");
    let spec = "-0.75:0.75:16,-0.75:0.75:16,0.4:1.35:20";
    let out = ok(
        &t.0,
        &[
            "direct",
            h5,
            "--volume",
            spec,
            "--wavelength",
            "0.4",
            "--sigma",
            "0.4",
            "--weights",
            "one",
            "--compensate-laser",
            "--out",
            f.to_str().expect("utf-8"),
        ],
    );
    print!("{out}");
    let v = npy(&f, [16, 16, 20]);
    let peak = (0..v.len())
        .max_by(|&i, &j| v[i].total_cmp(&v[j]))
        .expect("voxels");
    assert_eq!(peak, (5 * 16 + 9) * 20 + 5, "peak voxel {peak}");
}

/// `column` with each gate writes readable outputs; `--shell R0:R1` zeroes every voxel outside
/// the shell around the focus.
#[test]
fn column_runs_every_gate_and_shell() {
    let t = TempDir::new("cli", "column");
    let cap = npz_fixture("two_patches");
    let cap = cap.to_str().expect("utf-8");
    for gate in ["two-bounce", "higher-order", "none"] {
        let (f_npy, f_png) = (
            t.path(&format!("{gate}.npy")),
            t.path(&format!("{gate}.png")),
        );
        let out = ok(
            &t.0,
            &[
                "column",
                cap,
                "--focus",
                FOCUS,
                "--volume",
                SPEC,
                "--gate",
                gate,
                "--out",
                f_npy.to_str().expect("utf-8"),
                "--png",
                f_png.to_str().expect("utf-8"),
            ],
        );
        print!("{out}");
        let v = npy(&f_npy, SHAPE);
        assert!(v.iter().any(|&x| x > 0.0), "--gate {gate}: empty column");
        png(&f_png);
    }
    let f = t.path("shell.npy");
    ok(
        &t.0,
        &[
            "column",
            cap,
            "--focus",
            FOCUS,
            "--volume",
            SPEC,
            "--shell",
            "0.3:0.8",
            "--out",
            f.to_str().expect("utf-8"),
        ],
    );
    let v = npy(&f, SHAPE);
    let vol = Volume::parse(SPEC).expect("spec");
    let a = [-0.45f32, 0.0, 0.8];
    let (mut inside, mut outside_nonzero) = (0usize, 0usize);
    for (x, p) in v.iter().zip(&vol.points) {
        let d = ((0..3).map(|i| (p[i] - a[i]).powi(2)).sum::<f32>()).sqrt();
        if (0.3..0.8).contains(&d) {
            inside += usize::from(*x > 0.0);
        } else if *x != 0.0 {
            outside_nonzero += 1;
        }
    }
    println!("--shell 0.3:0.8: {inside} non-zero voxels inside, {outside_nonzero} outside");
    assert!(
        inside > 0 && outside_nonzero == 0,
        "--shell 0.3:0.8: {inside} non-zero voxels inside, {outside_nonzero} outside"
    );
}

/// `indirect` writes a volume that is zero outside Γ (voxels whose direct light exceeds
/// ε·max) and reports Γ.
#[test]
fn indirect_writes_a_gamma_masked_volume() {
    let t = TempDir::new("cli", "indirect");
    let cap = npz_fixture("two_patches");
    let cap = cap.to_str().expect("utf-8");
    let (f_npy, f_png, f_dir) = (t.path("i.npy"), t.path("i.png"), t.path("d.npy"));
    let out = ok(
        &t.0,
        &[
            "indirect",
            cap,
            "--volume",
            SPEC,
            "--epsilon",
            "0.2",
            "--min-separation",
            "0.3",
            "--out",
            f_npy.to_str().expect("utf-8"),
            "--png",
            f_png.to_str().expect("utf-8"),
        ],
    );
    print!("{out}");
    assert!(
        out.contains("Γ: ") && out.contains("pairs with 0.300 <= |x_a - x_b|"),
        "{out}"
    );
    let v = npy(&f_npy, SHAPE);
    png(&f_png);
    ok(
        &t.0,
        &[
            "direct",
            cap,
            "--volume",
            SPEC,
            "--out",
            f_dir.to_str().expect("utf-8"),
        ],
    );
    let d = npy(&f_dir, SHAPE);
    let gamma = probe::gamma_mask(&d, 0.2);
    let n = gamma.iter().filter(|&&g| g).count();
    assert!(
        out.contains(&format!("Γ: {n} of {} voxels", d.len())),
        "Γ count differs from the direct image's ({n}):\n{out}"
    );
    assert!(
        v.iter().zip(&gamma).all(|(&x, &g)| g || x == 0.0) && v.iter().any(|&x| x > 0.0),
        "indirect volume must be non-zero and zero outside Γ"
    );
    // --shell overrides --min-separation.
    ok(
        &t.0,
        &[
            "indirect",
            cap,
            "--volume",
            SPEC,
            "--shell",
            "0.5:inf",
            "--out",
            f_npy.to_str().expect("utf-8"),
        ],
    );
    npy(&f_npy, SHAPE);
}

/// `demo --out DIR`: the table names the figure and its indirect-light ratios (docs/concepts.md's,
/// asserted within bands), and the 10 PNG figures, 10 `.npy` volumes and `summary.txt` (= the table) are written. (~15 s.)
#[test]
fn demo_writes_figures_volumes_and_summary() {
    let t = TempDir::new("cli", "demo");
    let dir = t.path("out");
    let out = ok(&t.0, &["demo", "--out", dir.to_str().expect("utf-8")]);
    print!("{out}");
    for want in [
        "figure at [0.35, 0.0, 0.8]",
        "indirect light on the figure: means over its",
        "direct (diagonal)",
        "column far 0.45-1.20 m, Γ",
    ] {
        assert!(out.contains(want), "demo table lacks `{want}`:\n{out}");
    }
    // Means over the figure's voxels beside the control (docs/indirect-light.md): the last
    // column of each row is the ratio.
    let ratio = |row: &str| -> f32 {
        out.lines()
            .find(|l| l.starts_with(row))
            .and_then(|l| l.split_whitespace().last())
            .and_then(|r| r.trim_end_matches('x').parse().ok())
            .unwrap_or_else(|| panic!("no ratio for `{row}` in the table:\n{out}"))
    };
    let (gated, ungated, eq17, corrected) = (
        ratio("column T(x_a, ·), 4-vertex gate"),
        ratio("column T(x_a, ·), no gate"),
        ratio("in-focus I_i (Eq. 17)"),
        ratio("in-focus I_i, leak-corrected"),
    );
    // The documented numbers (docs/concepts.md), each within a band that a change of the probes would leave.
    let within = |x: f32, want: f32, tol: f32| (x - want).abs() <= tol * want;
    assert!(
        within(gated, 1.26, 0.05) && within(ungated, 1.40, 0.05),
        "demo: gated column {gated}x (documented 1.26x), no gate {ungated}x (documented 1.40x)"
    );
    assert!(
        within(eq17, 0.99, 0.05),
        "demo: Eq. 17 {eq17}x the control (documented 0.99x)"
    );
    assert!(
        within(corrected, 862.0, 0.2),
        "demo: leak-corrected I_i is {corrected}x the control (documented 862x)"
    );
    let kept: f32 = out
        .split("the leak-corrected I_i keeps ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no kept fraction in the table:\n{out}"));
    assert!(
        within(kept, 0.59, 0.1),
        "demo: the leak-corrected I_i keeps {kept} of the indirect-only truth (documented 0.59)"
    );
    // The panel is lit back by the figure: its voxels' leak-corrected I_i against the control.
    let panel: f32 = out
        .lines()
        .find(|l| l.starts_with("in-focus I_i, leak-corr., panel"))
        .and_then(|l| {
            l.split_whitespace()
                .find(|w| w.ends_with('x') && w.len() > 1)
        })
        .and_then(|r| r.trim_end_matches('x').parse().ok())
        .unwrap_or_else(|| panic!("no panel ratio in the table:\n{out}"));
    assert!(
        within(panel, 1212.0, 0.2),
        "demo: leak-corrected I_i on the panel is {panel}x the control (documented 1212x)"
    );
    // In-focus indirect light peaks on a surface the other lights: Eq. 17 as is on the figure
    // (the panel's light on it, and the figure's own leak), the leak-corrected I_i (the
    // default) on the panel, which the figure lights back; never on the box.
    for (row, on) in [
        ("in-focus indirect (leak-corr.)", "panel"),
        ("in-focus indirect (Eq. 17)", "figure"),
    ] {
        let line = out
            .lines()
            .find(|l| l.starts_with(row))
            .unwrap_or_else(|| panic!("no `{row}` row:\n{out}"));
        assert!(
            line.contains(on),
            "`{row}` does not peak on the {on}: {line}"
        );
    }
    // Ground truth: the direct image peaks on each object (within about one voxel, 6 cm pitch).
    for obj in ["panel", "figure", "box"] {
        let line = out
            .lines()
            .find(|l| l.trim_start().starts_with(obj) && l.contains("from its surface"))
            .unwrap_or_else(|| panic!("no direct-light line for {obj}:\n{out}"));
        let d: f32 = line
            .split(" m, ")
            .nth(1)
            .and_then(|s| s.split(" m from").next())
            .and_then(|s| s.trim().parse().ok())
            .unwrap_or_else(|| panic!("no distance in `{line}`"));
        assert!(
            d <= 0.1,
            "demo: the direct peak near {obj} is {d} m from it: {line}"
        );
    }
    let summary = std::fs::read_to_string(dir.join("summary.txt")).expect("summary.txt");
    assert_eq!(summary, out, "summary.txt differs from the printed table");
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .expect("demo dir")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .collect();
    files.sort();
    let count = |ext: &str| files.iter().filter(|f| f.ends_with(ext)).count();
    assert_eq!(
        (count(".png"), count(".npy")),
        (10, 10),
        "demo files: {files:?}"
    );
    for f in &files {
        let p = dir.join(f);
        if f.ends_with(".png") {
            png(&p);
        } else if f.ends_with(".npy") {
            let v = npy(&p, [21, 11, 13]);
            assert!(v.iter().any(|&x| x > 0.0), "{f}: empty");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// errors
// ---------------------------------------------------------------------------------------------

/// `vltm --help` explains the physics terms; each subcommand's help explains its own.
#[test]
fn help_explains_the_terms() {
    let t = TempDir::new("cli", "help");
    let top = ok(&t.0, &["--help"]);
    for term in [
        "relay wall",
        "z = 0",
        "metres of optical path",
        "x_a",
        "x_b",
        "T(x_a, x_b)",
    ] {
        assert!(
            top.contains(term),
            "vltm --help should explain `{term}`:\n{top}"
        );
    }
    let column = ok(&t.0, &["column", "--help"]);
    for term in [
        "--gate",
        "two-bounce",
        "higher-order",
        "--shell",
        "--wavelength",
        "--sigma",
    ] {
        assert!(
            column.contains(term),
            "vltm column --help should explain `{term}`:\n{column}"
        );
    }
    let indirect = ok(&t.0, &["indirect", "--help"]);
    for term in ["--epsilon", "--min-separation", "Γ"] {
        assert!(
            indirect.contains(term),
            "vltm indirect --help should explain `{term}`:\n{indirect}"
        );
    }
}

/// Bad arguments: exit code 2 and one line naming the argument.
#[test]
fn bad_arguments_exit_2_with_one_line() {
    let t = TempDir::new("cli", "badargs");
    let cap = npz_fixture("two_patches");
    let cap = cap.to_str().expect("utf-8");
    let col = |extra: &[&'static str]| {
        let mut a = vec!["column", cap, "--volume", SPEC, "--focus", FOCUS];
        a.extend_from_slice(extra);
        a
    };
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["direct", cap, "--volume", "1:2:3,4"], "--volume"),
        (
            vec!["direct", cap, "--volume", "-1:1:3,0:0:x,0.5:1:3"],
            "--volume",
        ),
        (
            vec!["direct", cap, "--volume", "-1:1:3,0:0:1,0:1:5"],
            "--volume",
        ),
        (
            vec!["column", cap, "--volume", SPEC, "--focus", "0,0,0"],
            "--focus",
        ),
        (
            vec!["column", cap, "--volume", SPEC, "--focus", "0,0,-0.5"],
            "--focus",
        ),
        (
            vec!["column", cap, "--volume", SPEC, "--focus", "0,0"],
            "--focus",
        ),
        (col(&["--gate", "three-bounce"]), "--gate"),
        (col(&["--weights", "two"]), "--weights"),
        (col(&["--shell", "0.8:0.3"]), "--shell"),
        (col(&["--shell", "near"]), "--shell"),
        (
            vec!["indirect", cap, "--volume", SPEC, "--epsilon", "1.5"],
            "--epsilon",
        ),
        (
            vec!["indirect", cap, "--volume", SPEC, "--epsilon=-0.1"],
            "--epsilon",
        ),
        (
            vec!["--threads", "0", "direct", cap, "--volume", SPEC],
            "--threads",
        ),
        (
            vec!["direct", cap, "--volume", SPEC, "--threads", "0"],
            "--threads",
        ),
        (vec!["frobnicate"], "frobnicate"),
        // clap's own errors keep what they name on the one line: the missing argument,
        // the values a choice accepts.
        (vec!["direct", cap], "--volume <SPEC>"),
        (col(&["--gate", "late"]), "two-bounce, higher-order, none"),
    ];
    for (args, names) in &cases {
        let line = fails(&t.0, args, 2);
        assert!(
            line.contains(names),
            "vltm {args:?}: the error should name `{names}`: {line}"
        );
    }
}

/// Unreadable or corrupt captures: exit code 1 and one line naming the file.
#[test]
fn bad_captures_exit_1_naming_the_file() {
    let t = TempDir::new("cli", "baddata");
    let good = std::fs::read(npz_fixture("two_patches_single")).expect("fixture");
    let truncated = t.path("truncated.npz");
    std::fs::write(&truncated, &good[..good.len() / 2]).expect("write");
    let text_file = t.path("notes.npz");
    std::fs::write(&text_file, "this is not a capture\n").expect("write");
    let empty = t.path("empty.npz");
    std::fs::write(&empty, b"").expect("write");
    // A valid archive whose `H` stream is damaged: flip bytes in the middle of the file.
    let damaged = t.path("damaged.npz");
    let mut d = good.clone();
    let mid = d.len() / 2;
    d[mid..mid + 64].iter_mut().for_each(|b| *b ^= 0x5A);
    std::fs::write(&damaged, &d).expect("write");
    let missing = t.path("missing.npz");
    for p in [&truncated, &text_file, &empty, &damaged, &missing] {
        let s = p.to_str().expect("utf-8");
        for args in [
            vec!["info", s],
            vec!["direct", s, "--volume", SPEC],
            vec!["column", s, "--volume", SPEC, "--focus", FOCUS],
        ] {
            let line = fails(&t.0, &args, 1);
            assert!(
                line.contains(s),
                "vltm {args:?}: the error should name the file: {line}"
            );
        }
    }
    // A corrupt scene file for `simulate` is bad data too.
    let scene = t.path("scene.json");
    std::fs::write(&scene, "{\"setup\": 1}").expect("write");
    let s = scene.to_str().expect("utf-8");
    let out = t.path("x.npz");
    let line = fails(
        &t.0,
        &["simulate", s, "--out", out.to_str().expect("utf-8")],
        1,
    );
    assert!(
        line.contains(s),
        "simulate: the error should name the file: {line}"
    );
}

/// `simulate --ptu` writes a PicoQuant T3 stream and its sidecar; reading the `.ptu` back
/// gives the same capture as the `.npz` (Poisson counts are whole photons), so `direct` on
/// both writes the same volume, bit for bit.
#[test]
fn simulate_ptu_round_trip() {
    let t = TempDir::new("cli", "ptu");
    let mut scene: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(support::fixture("scenes/two_patches.json")).expect("scene"),
    )
    .expect("json");
    scene["noise"] = serde_json::json!({"peak_counts": 50.0, "background": 0.2, "seed": 7});
    let scene_path = t.path("noisy.json");
    std::fs::write(&scene_path, scene.to_string()).expect("write scene");
    let s = |p: &PathBuf| p.to_str().expect("utf-8").to_string();
    let (npz, ptu) = (t.path("c.npz"), t.path("c.ptu"));
    let out = ok(
        &t.0,
        &[
            "simulate",
            &s(&scene_path),
            "--out",
            &s(&npz),
            "--ptu",
            &s(&ptu),
        ],
    );
    assert!(
        out.contains("sidecar") && t.path("c.json").exists(),
        "{out}"
    );
    let info = ok(&t.0, &["info", &s(&ptu)]);
    assert!(
        info.contains("64 = 8x8") && info.contains("non-finite 0"),
        "{info}"
    );
    let mut images = Vec::new();
    for (cap, name) in [(&npz, "a.npy"), (&ptu, "b.npy")] {
        let f = t.path(name);
        ok(
            &t.0,
            &["direct", &s(cap), "--volume", SPEC, "--out", &s(&f)],
        );
        images.push(npy(&f, SHAPE));
    }
    assert!(images[0].iter().any(|&v| v > 0.0));
    assert_eq!(images[0], images[1]);
    // A sidecar that does not match the file is a data error (exit 1) naming the sidecar field.
    let side = std::fs::read_to_string(t.path("c.json")).expect("sidecar");
    let mut v: serde_json::Value = serde_json::from_str(&side).expect("json");
    v["rows"] = serde_json::json!(63);
    std::fs::write(t.path("c.json"), v.to_string()).expect("write sidecar");
    let err = fails(&t.0, &["info", &s(&ptu)], 1);
    assert!(err.contains("c.json") || err.contains("rows"), "{err}");
    // `direct` streams the photons (no whole-file read): the same error, and a truncated
    // record stream is a data error naming the file.
    let err = fails(&t.0, &["direct", &s(&ptu), "--volume", SPEC], 1);
    assert!(err.contains("c.json") || err.contains("rows"), "{err}");
    std::fs::write(t.path("c.json"), side).expect("restore sidecar");
    let bytes = std::fs::read(&ptu).expect("ptu");
    let cut = t.path("cut.ptu");
    std::fs::write(&cut, &bytes[..bytes.len() - 6]).expect("write");
    std::fs::copy(t.path("c.json"), t.path("cut.json")).expect("sidecar");
    let err = fails(&t.0, &["direct", &s(&cut), "--volume", SPEC], 1);
    assert!(err.contains("cut.ptu"), "{err}");
}

// ----- reliability: no file lost, hygiene (issue 14) -----------------------------------------

/// A path as a command-line argument.
fn s(p: &Path) -> String {
    p.to_str().expect("utf-8 path").to_string()
}

/// The files of a directory, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .expect("read dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// `--out` naming the input capture is refused before anything is read or written; the
/// capture is left as it was.
#[test]
fn an_output_naming_the_input_is_refused() {
    let t = TempDir::new("cli", "out-is-input");
    let cap = t.path("c.npz");
    std::fs::copy(npz_fixture("two_patches"), &cap).expect("copy");
    let before = std::fs::read(&cap).expect("read");
    let err = fails(
        &t.0,
        &["direct", "c.npz", "--volume", SPEC, "--out", "./c.npz"],
        2,
    );
    assert!(err.contains("is an input"), "{err}");
    let err = fails(
        &t.0,
        &["direct", "c.npz", "--volume", SPEC, "--png", &s(&cap)],
        2,
    );
    assert!(err.contains("--out"), "{err}");
    assert_eq!(std::fs::read(&cap).expect("read"), before);
    let scene = support::fixture("scenes/three_points.json");
    let copy = t.path("scene.json");
    std::fs::copy(&scene, &copy).expect("copy scene");
    fails(&t.0, &["simulate", "scene.json", "--out", "scene.json"], 2);
    assert_eq!(
        std::fs::read(&copy).expect("read"),
        std::fs::read(&scene).expect("read")
    );
}

/// A volume and its figure are written all or nothing: when the figure cannot be written, the
/// previous volume file is intact and no partial or temporary file is left.
#[test]
fn a_failed_output_keeps_the_previous_file() {
    let t = TempDir::new("cli", "keep-previous");
    let out = t.path("v.npy");
    std::fs::write(&out, b"previous").expect("write");
    // A figure path that names a directory: refused when it is staged, after the volume's
    // (a missing folder would be created before the work).
    let missing = t.path("dir.png");
    std::fs::create_dir(&missing).expect("mkdir");
    let err = fails(
        &t.0,
        &[
            "direct",
            &s(&npz_fixture("two_patches")),
            "--volume",
            SPEC,
            "--out",
            &s(&out),
            "--png",
            &s(&missing),
        ],
        2,
    );
    assert!(err.contains("dir.png"), "{err}");
    assert_eq!(std::fs::read(&out).expect("read"), b"previous");
    assert_eq!(listing(&t.0), ["dir.png", "v.npy"]);
    std::fs::remove_dir(&missing).expect("rmdir");
    // The same command with a writable figure replaces both.
    let png = t.path("v.png");
    ok(
        &t.0,
        &[
            "direct",
            &s(&npz_fixture("two_patches")),
            "--volume",
            SPEC,
            "--out",
            &s(&out),
            "--png",
            &s(&png),
        ],
    );
    npy(&out, SHAPE);
    assert_eq!(listing(&t.0), ["v.npy", "v.png"]);
}

/// A capture, its PTU stream and its sidecar are written all or nothing; a full device gives
/// one clean line (no message of the zip writer glued on).
#[test]
fn simulate_outputs_are_all_or_nothing() {
    let t = TempDir::new("cli", "sim-atomic");
    let scene = support::fixture("scenes/three_points.json");
    // A PTU path that names a directory: it cannot be written.
    let missing = t.path("dir.ptu");
    std::fs::create_dir(&missing).expect("mkdir");
    fails(
        &t.0,
        &[
            "simulate",
            &s(&scene),
            "--out",
            "c.npz",
            "--ptu",
            &s(&missing),
        ],
        2,
    );
    assert_eq!(listing(&t.0), ["dir.ptu"]);
    if Path::new("/dev/full").exists() {
        let err = fails(&t.0, &["simulate", &s(&scene), "--out", "/dev/full"], 1);
        assert!(err.contains("/dev/full") && !err.contains("drop"), "{err}");
    }
}

/// Thread counts beyond 4 per core are refused at parse time, before any thread starts.
#[test]
fn absurd_thread_counts_are_refused() {
    let t = TempDir::new("cli", "threads");
    let err = fails(
        &t.0,
        &[
            "--threads",
            "100000",
            "info",
            &s(&npz_fixture("two_patches")),
        ],
        2,
    );
    // Refused by the argument parser (exit 2, the bound in the message), before any thread
    // pool exists; no timing is asserted (the machine may be busy).
    assert!(
        err.contains("--threads") && err.contains("per core"),
        "{err}"
    );
    ok(
        &t.0,
        &["--threads", "1", "info", &s(&npz_fixture("two_patches"))],
    );
}

/// Strings from a file (here a JSON key with a terminal escape and a newline) are escaped
/// before they reach the terminal.
#[test]
fn control_bytes_from_files_are_escaped() {
    let t = TempDir::new("cli", "escape");
    let scene = t.path("bad.json");
    std::fs::write(&scene, "{\"\\u001b[31mred\\nline\": 1}").expect("write");
    let o = vltm_in(&t.0, &["simulate", &s(&scene), "--out", "c.npz"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stderr));
    assert!(
        !o.stderr.contains(&0x1b),
        "raw escape byte on stderr: {:?}",
        text(&o.stderr)
    );
    assert_eq!(text(&o.stderr).lines().count(), 1, "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("\\u{1b}"), "{}", text(&o.stderr));
}

/// A MAT v5 file of uncompressed numeric `double` arrays (name, dims, column-major values),
/// written to the published format.
fn mat_v5(vars: &[(&str, &[usize], &[f64])]) -> Vec<u8> {
    fn elem(ty: u32, data: &[u8]) -> Vec<u8> {
        let mut v = ty.to_le_bytes().to_vec();
        v.extend_from_slice(&(data.len() as u32).to_le_bytes());
        v.extend_from_slice(data);
        v.resize(v.len().div_ceil(8) * 8, 0);
        v
    }
    let mut f = b"MATLAB 5.0 MAT-file, written by tests/cli.rs".to_vec();
    f.resize(116, b' ');
    f.extend_from_slice(&[0; 8]);
    f.extend_from_slice(&0x0100u16.to_le_bytes());
    f.extend_from_slice(b"IM");
    for (name, dims, values) in vars {
        let mut body = elem(6, &[6, 0, 0, 0, 0, 0, 0, 0]);
        let d: Vec<u8> = dims
            .iter()
            .flat_map(|&x| (x as i32).to_le_bytes())
            .collect();
        body.extend(elem(5, &d));
        body.extend(elem(1, name.as_bytes()));
        let raw: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        body.extend(elem(9, &raw));
        f.extend(elem(14, &body));
    }
    f
}

/// A Stanford-layout `.mat` (`rect_data` 8×8×200 + `width`): a floor of 2 counts, a wall
/// return in the first 20 bins, and a hidden point 0.4 m in front of the wall centre
/// (confocal path 2·|x − p|, bins of 4 ps, t = 0 at the wall); `info`, `direct` with the
/// preprocessing, and the errors of bad windows, backgrounds and files.
#[test]
fn mat_captures_through_the_command_line() {
    let t = TempDir::new("cli", "mat");
    let (n, nt, w) = (8usize, 1000usize, 0.1f64);
    let dt = 4e-12 * 299_792_458.0;
    let mut v = vec![2.0f64; n * n * nt];
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (-w + 2.0 * w * i as f64 / 7.0, -w + 2.0 * w * j as f64 / 7.0);
            let path = 2.0 * (x * x + y * y + 0.16f64).sqrt();
            let b = (path / dt).round() as usize;
            for k in 0..20 {
                v[i + n * (j + n * k)] += 1000.0;
            }
            if b < nt {
                v[i + n * (j + n * b)] += 50.0;
            }
        }
    }
    let f = t.path("s.mat");
    std::fs::write(
        &f,
        mat_v5(&[("rect_data", &[n, n, nt], &v), ("width", &[1, 1], &[w])]),
    )
    .expect("write");
    let fs = f.to_str().expect("utf-8");
    let out = ok(&t.0, &["info", fs]);
    for want in [
        "MAT v5",
        "rect_data 8x8x1000 double",
        "assumed: 4 ps bins",
        "t = 0 at the wall",
        "over [-0.1, 0.1]^2",
    ] {
        assert!(out.contains(want), "info should say `{want}`: {out}");
    }
    let vol = "-0.1:0.1:5,-0.1:0.1:5,0.3:0.5:11";
    let out = ok(
        &t.0,
        &[
            "direct",
            fs,
            "--volume",
            vol,
            "--t-min",
            "30b",
            "--rebin",
            "2",
            "--background",
            "auto",
            "--wavelength",
            "0.04",
            "--weights",
            "one",
            "--out",
            "d.npy",
        ],
    );
    assert!(
        out.contains("background auto") && out.contains("where no return from the volume"),
        "{out}"
    );
    let d = npy(&t.path("d.npy"), [5, 5, 11]);
    assert!(d.iter().all(|x| x.is_finite()));
    let best = (0..d.len())
        .max_by(|&a, &b| d[a].total_cmp(&d[b]))
        .expect("voxels");
    // The point at (0, 0, 0.4): centre column, slice 5 of 0.3..0.5.
    assert_eq!(
        (best / 11 / 5, best / 11 % 5, best % 11),
        (2, 2, 5),
        "{d:?}"
    );
    // A window that leaves nothing, a background above every count: errors, exit 2.
    let line = fails(
        &t.0,
        &["direct", fs, "--volume", vol, "--t-min", "1000b"],
        2,
    );
    assert!(line.contains("no bins left"), "{line}");
    let line = fails(
        &t.0,
        &["direct", fs, "--volume", vol, "--background", "1e6"],
        2,
    );
    assert!(line.contains("nothing left to image"), "{line}");
    // Unknown layout: exit 1, one line listing the variables.
    let u = t.path("u.mat");
    std::fs::write(&u, mat_v5(&[("foo", &[2, 3], &[0.0; 6])])).expect("write");
    let us = u.to_str().expect("utf-8");
    let line = fails(&t.0, &["info", us], 1);
    assert!(
        line.contains(us) && line.contains("foo 2x3 double"),
        "{line}"
    );
    // Truncated: exit 1 naming the file and the variable.
    let good = std::fs::read(&f).expect("read");
    let tr = t.path("t.mat");
    std::fs::write(&tr, &good[..good.len() / 2]).expect("write");
    let trs = tr.to_str().expect("utf-8");
    for args in [vec!["info", trs], vec!["direct", trs, "--volume", vol]] {
        let line = fails(&t.0, &args, 1);
        assert!(line.contains(trs) && line.contains("rect_data"), "{line}");
    }
}

/// The largest |x − y| / max|y| over two volumes of the same length.
fn rel_of_max(x: &[f32], y: &[f32]) -> f64 {
    assert_eq!(x.len(), y.len());
    let m = y.iter().fold(0.0f64, |m, &v| m.max(f64::from(v).abs()));
    assert!(m > 0.0, "reference volume is zero");
    x.iter()
        .zip(y)
        .map(|(&a, &b)| (f64::from(a) - f64::from(b)).abs() / m)
        .fold(0.0, f64::max)
}

/// `direct --gate none|higher-order` are the kernel's un-gated and Eq. 18 diagonals (each
/// checked against the float64 reference in `tests/proptest_kernel.rs`) as the library
/// computes them; `--gate gaussian` is `direct` itself.
#[test]
fn direct_runs_every_gate() {
    let t = TempDir::new("cli", "directgates");
    let cap = s(&npz_fixture("two_patches"));
    let vol = Volume::parse(SPEC).expect("spec");
    let plain = t.path("d.npy");
    ok(
        &t.0,
        &["direct", &cap, "--volume", SPEC, "--out", &s(&plain)],
    );
    let d = npy(&plain, SHAPE);
    for (arg, gate) in [
        ("gaussian", probe::ColumnGate::TwoBounce),
        ("none", probe::ColumnGate::None),
        ("higher-order", probe::ColumnGate::HigherOrder),
    ] {
        let f = t.path(&format!("{arg}.npy"));
        ok(
            &t.0,
            &[
                "direct",
                &cap,
                "--volume",
                SPEC,
                "--gate",
                arg,
                "--out",
                &s(&f),
            ],
        );
        let v = npy(&f, SHAPE);
        let mut src = io::open_source(&npz_fixture("two_patches")).expect("fixture");
        let lib = probe::diagonal(&mut *src, &vol, gate, &Wave::default(), Exec::default())
            .expect("diagonal");
        let diff = rel_of_max(&v, &lib.values);
        let from_gauss = rel_of_max(&v, &d);
        println!(
            "direct --gate {arg}: {diff:.1e} from the library, {from_gauss:.2} from the Gaussian diagonal"
        );
        assert!(diff <= 1e-6, "--gate {arg}: {diff:.3e}");
        if arg == "gaussian" {
            assert_eq!(v, d, "--gate gaussian is plain direct");
        } else {
            assert!(
                from_gauss > 0.05,
                "--gate {arg} equals the Gaussian diagonal"
            );
        }
    }
}

/// `column --mask-epsilon E` is the column times Γ (from the direct light, as `indirect`);
/// `column --shells R1,R2` writes near, middle and far parts that partition the column; an
/// empty Γ is an error naming `--mask-epsilon`.
#[test]
fn column_masks_and_shells_partition() {
    let t = TempDir::new("cli", "maskshells");
    let cap = s(&npz_fixture("two_patches"));
    let vol = Volume::parse(SPEC).expect("spec");
    let (fc, fm, fd, fs) = (
        t.path("c.npy"),
        t.path("m.npy"),
        t.path("d.npy"),
        t.path("s.npy"),
    );
    let col = ["column", &cap, "--focus", FOCUS, "--volume", SPEC];
    ok(&t.0, &[&col[..], &["--out", &s(&fc)]].concat());
    ok(
        &t.0,
        &[&col[..], &["--mask-epsilon", "0.2", "--out", &s(&fm)]].concat(),
    );
    ok(&t.0, &["direct", &cap, "--volume", SPEC, "--out", &s(&fd)]);
    let (c, m, d) = (npy(&fc, SHAPE), npy(&fm, SHAPE), npy(&fd, SHAPE));
    let gamma = probe::gamma_mask(&d, 0.2);
    let n_gamma = gamma.iter().filter(|&&g| g).count();
    let masked: Vec<f32> = c
        .iter()
        .zip(&gamma)
        .map(|(&x, &g)| if g { x } else { 0.0 })
        .collect();
    println!("--mask-epsilon 0.2: Γ has {n_gamma} of {} voxels", c.len());
    assert!(n_gamma > 0 && n_gamma < c.len());
    assert_eq!(m, masked, "masked column = column × Γ");
    // Shells: three outputs, disjoint, summing to the column.
    ok(
        &t.0,
        &[&col[..], &["--shells", "0.3,0.6", "--out", &s(&fs)]].concat(),
    );
    let parts: Vec<Vec<f32>> = ["near", "middle", "far"]
        .iter()
        .map(|p| npy(&t.path(&format!("s.{p}.npy")), SHAPE))
        .collect();
    let a = [-0.45f32, 0.0, 0.8];
    let bounds = [(0.0, 0.3), (0.3, 0.6), (0.6, f32::INFINITY)];
    let mut counts = [0usize; 3];
    for (i, p) in vol.points.iter().enumerate() {
        let r = ((0..3).map(|k| (p[k] - a[k]).powi(2)).sum::<f32>()).sqrt();
        let sum: f32 = parts.iter().map(|v| v[i]).sum();
        assert_eq!(
            sum, c[i],
            "voxel {i}: the shells do not add up to the column"
        );
        for (k, ((lo, hi), v)) in bounds.iter().zip(&parts).enumerate() {
            if (*lo..*hi).contains(&r) {
                assert_eq!(v[i], c[i], "voxel {i} at {r} m belongs to shell {k}");
                counts[k] += usize::from(v[i] > 0.0);
            } else {
                assert_eq!(v[i], 0.0, "voxel {i} at {r} m outside shell {k}");
            }
        }
    }
    println!("--shells 0.3,0.6: non-zero voxels near/middle/far {counts:?}");
    assert!(counts.iter().all(|&n| n > 0), "{counts:?}");
    // Γ empty: a volume far beyond the capture's time window has no direct light.
    let err = fails(
        &t.0,
        &[
            "column",
            &cap,
            "--focus",
            FOCUS,
            "--volume",
            "0:0.1:2,0:0:1,6:7:3",
            "--mask-epsilon",
            "0.2",
            "--out",
            &s(&t.path("x.npy")),
        ],
        2,
    );
    // Voxels the capture never saw: the window check (the same error for every probe)
    // refuses them before Γ is formed.
    assert!(
        err.contains("volume")
            && err.contains("no path through the probed points")
            && err.lines().count() == 1,
        "{err}"
    );
    assert!(!t.path("x.npy").exists());
}

/// `indirect` writes Γ and I_d beside I_i; `--shells` writes near, middle and far sums that
/// add up to the sum over every pair; `--gate higher-order` is the Γ-masked sum of Eq. 18
/// columns (Eq. 17 with Eq. 18) as the column probe computes them; an empty Γ is an error
/// naming `--epsilon`.
#[test]
fn indirect_writes_gamma_direct_shells_and_higher_order() {
    let t = TempDir::new("cli", "indirectplus");
    let cap = s(&npz_fixture("two_patches"));
    let vol = Volume::parse(SPEC).expect("spec");
    let base = ["indirect", &cap, "--volume", SPEC, "--epsilon", "0.3"];
    let (fi, fs, fh, fd) = (
        t.path("i.npy"),
        t.path("s.npy"),
        t.path("h.npy"),
        t.path("d.npy"),
    );
    ok(
        &t.0,
        &[&base[..], &["--shell", "0:inf", "--out", &s(&fi)]].concat(),
    );
    ok(&t.0, &["direct", &cap, "--volume", SPEC, "--out", &s(&fd)]);
    let (all, d) = (npy(&fi, SHAPE), npy(&fd, SHAPE));
    let g = npy(&t.path("i.gamma.npy"), SHAPE);
    let id = npy(&t.path("i.direct.npy"), SHAPE);
    assert_eq!(id, d, "i.direct.npy is the direct light");
    let gamma = probe::gamma_mask(&d, 0.3);
    let want: Vec<f32> = gamma.iter().map(|&k| f32::from(u8::from(k))).collect();
    assert_eq!(g, want, "i.gamma.npy is Γ");
    let idx: Vec<usize> = (0..gamma.len()).filter(|&i| gamma[i]).collect();
    println!("Γ: {} voxels", idx.len());
    ok(
        &t.0,
        &[&base[..], &["--shells", "0.15,0.3", "--out", &s(&fs)]].concat(),
    );
    let parts: Vec<Vec<f32>> = ["near", "middle", "far"]
        .iter()
        .map(|p| npy(&t.path(&format!("s.{p}.npy")), SHAPE))
        .collect();
    let sum: Vec<f32> = (0..all.len())
        .map(|i| parts.iter().map(|v| v[i]).sum())
        .collect();
    let diff = rel_of_max(&sum, &all);
    let shares: Vec<f32> = parts.iter().map(|v| v.iter().sum()).collect();
    println!("--shells 0.15,0.3: near + middle + far vs all pairs {diff:.1e}; totals {shares:?}");
    assert!(
        diff <= 1e-6 && shares.iter().all(|&x| x > 0.0),
        "{diff:.3e} {shares:?}"
    );
    // Higher order: against the Γ-masked sum of the Eq. 18 column probes over Γ.
    ok(
        &t.0,
        &[
            &base[..],
            &[
                "--gate",
                "higher-order",
                "--min-separation",
                "0.3",
                "--out",
                &s(&fh),
            ],
        ]
        .concat(),
    );
    let h = npy(&fh, SHAPE);
    let pts: Vec<_> = idx.iter().map(|&i| vol.points[i]).collect();
    let g_vol = Volume::points(pts.clone()).expect("Γ");
    let mut want = vec![0.0f64; vol.len()];
    for a in &pts {
        let mut src = io::open_source(&npz_fixture("two_patches")).expect("fixture");
        let col = probe::column(
            &mut *src,
            *a,
            &g_vol,
            probe::ColumnGate::HigherOrder,
            probe::Shell {
                r0: 0.3,
                r1: f32::INFINITY,
            },
            &Wave::default(),
            Exec::default(),
        )
        .expect("higher-order column");
        for (k, v) in col.values.iter().enumerate() {
            if pts[k] != *a {
                want[idx[k]] += f64::from(*v);
            }
        }
    }
    let want: Vec<f32> = want.iter().map(|&x| x as f32).collect();
    let diff = rel_of_max(&h, &want);
    let ratio = h.iter().sum::<f32>() / all.iter().sum::<f32>();
    println!(
        "--gate higher-order: {diff:.1e} from the sum of Eq. 18 columns; total {ratio:.2e} of the two-bounce sum"
    );
    assert!(diff <= 1e-6, "higher-order indirect: {diff:.3e}");
    let err = fails(
        &t.0,
        &["indirect", &cap, "--volume", "0:0.1:2,0:0:1,6:7:3"],
        2,
    );
    // Voxels the capture never saw: the window check (the same error for every probe)
    // refuses them before Γ is formed.
    assert!(
        err.contains("volume")
            && err.contains("no path through the probed points")
            && err.lines().count() == 1,
        "{err}"
    );
}

/// `matrix --from gamma --to SPEC` writes re, im, intensity, from_xyz and to_xyz: Γ's
/// voxels, |A|² = re² + im², each row the column probe at its focus; an output over the
/// memory budget is an error naming the options; `relight` with a one-hot voxel image is the
/// column at that voxel and with no non-zero weight an error naming `--pattern`; `row`
/// equals `column --swap-roles`.
#[test]
fn matrix_relight_and_row_through_the_command_line() {
    let t = TempDir::new("cli", "matrix");
    let cap = s(&npz_fixture("two_patches"));
    let vol = Volume::parse(SPEC).expect("spec");
    let fm = t.path("m.h5");
    let out = ok(
        &t.0,
        &[
            "matrix",
            &cap,
            "--from",
            "gamma",
            "--to",
            SPEC,
            "--volume",
            SPEC,
            "--epsilon",
            "0.3",
            "--out",
            &s(&fm),
        ],
    );
    print!("{out}");
    let read = |name: &str| vltm::export::h5::read_f32_dataset(&fm, name).expect("dataset");
    let (re, shape) = read("re");
    let (im, _) = read("im");
    let (int, _) = read("intensity");
    let (from, fshape) = read("from_xyz");
    let (to, tshape) = read("to_xyz");
    let fd = t.path("d.npy");
    ok(&t.0, &["direct", &cap, "--volume", SPEC, "--out", &s(&fd)]);
    let gamma = probe::gamma_mask(&npy(&fd, SHAPE), 0.3);
    let g_pts: Vec<f32> = vol
        .points
        .iter()
        .zip(&gamma)
        .filter(|&(_, &k)| k)
        .flat_map(|(p, _)| *p)
        .collect();
    let nf = g_pts.len() / 3;
    assert_eq!(shape, vec![nf, vol.len()]);
    assert_eq!((fshape, tshape), (vec![nf, 3], vec![vol.len(), 3]));
    assert_eq!(from, g_pts, "from_xyz is Γ");
    assert_eq!(to, vol.points.iter().flatten().copied().collect::<Vec<_>>());
    for k in 0..int.len() {
        let i2 = f64::from(re[k]).powi(2) + f64::from(im[k]).powi(2);
        assert!(
            (i2 - f64::from(int[k])).abs() <= 1e-6 * i2.max(1e-30),
            "element {k}"
        );
    }
    let mut worst = 0.0f64;
    for i in [0, nf / 2, nf - 1] {
        let a = format!("{},{},{}", from[3 * i], from[3 * i + 1], from[3 * i + 2]);
        let fc = t.path("c.npy");
        ok(
            &t.0,
            &[
                "column",
                &cap,
                "--focus",
                &a,
                "--volume",
                SPEC,
                "--path",
                "band",
                "--out",
                &s(&fc),
            ],
        );
        let c = npy(&fc, SHAPE);
        worst = worst.max(rel_of_max(&int[i * vol.len()..(i + 1) * vol.len()], &c));
    }
    println!(
        "matrix rows vs column probes (both leak-corrected over SPEC): {worst:.1e} of the column's maximum"
    );
    assert!(worst <= 1e-6, "{worst:.3e}");
    // --no-leak-correct: the capture as it is, row for row the uncorrected column; the
    // correction changed the matrix.
    let fr = t.path("raw.h5");
    let said = ok(
        &t.0,
        &[
            "matrix",
            &cap,
            "--from",
            "gamma",
            "--to",
            SPEC,
            "--volume",
            SPEC,
            "--epsilon",
            "0.3",
            "--no-leak-correct",
            "--out",
            &s(&fr),
        ],
    );
    assert!(out.contains("leak correction") && !said.contains("leak correction"));
    let (raw, _) = vltm::export::h5::read_f32_dataset(&fr, "intensity").expect("dataset");
    let a = format!("{},{},{}", from[0], from[1], from[2]);
    let fc = t.path("c.npy");
    ok(
        &t.0,
        &[
            "column",
            &cap,
            "--focus",
            &a,
            "--volume",
            SPEC,
            "--path",
            "band",
            "--no-leak-correct",
            "--out",
            &s(&fc),
        ],
    );
    let c = npy(&fc, SHAPE);
    assert!(rel_of_max(&raw[..vol.len()], &c) <= 1e-6);
    assert!(
        rel_of_max(&int[..vol.len()], &c) > 1e-3,
        "the correction changed nothing"
    );
    // Over the memory budget: named, nothing written.
    let big = t.path("big.h5");
    let err = fails(
        &t.0,
        &[
            "matrix",
            &cap,
            "--from",
            "-3:3:300,-3:3:300,1:2:30",
            "--to",
            "-3:3:300,-3:3:300,1:2:3",
            "--out",
            &s(&big),
        ],
        1,
    );
    assert!(
        err.contains("--from") && err.contains("--to") && err.contains("budget"),
        "{err}"
    );
    assert!(!big.exists());
    let err = fails(
        &t.0,
        &[
            "matrix",
            &cap,
            "--from",
            FOCUS,
            "--to",
            FOCUS,
            "--out",
            &s(&t.path("m.npy")),
        ],
        2,
    );
    assert!(err.contains("--out"), "{err}");
    // Relight with a one-hot voxel image = the column at that voxel.
    let k = vol.nearest([-0.4, 0.0, 0.8]);
    let mut img = vec![0.0f32; vol.len()];
    img[k] = 1.0;
    let (fp, fr, fc) = (t.path("p.npy"), t.path("r.npy"), t.path("c.npy"));
    vltm::export::npy::write_f32(&fp, &img, &SHAPE).expect("pattern");
    ok(
        &t.0,
        &[
            "relight",
            &cap,
            "--pattern",
            &s(&fp),
            "--volume",
            SPEC,
            "--out",
            &s(&fr),
        ],
    );
    let p = vol.points[k];
    let a = format!("{},{},{}", p[0], p[1], p[2]);
    ok(
        &t.0,
        &[
            "column",
            &cap,
            "--focus",
            &a,
            "--volume",
            SPEC,
            "--path",
            "band",
            "--out",
            &s(&fc),
        ],
    );
    let diff = rel_of_max(&npy(&fr, SHAPE), &npy(&fc, SHAPE));
    println!("relight, one-hot image vs column: {diff:.1e}");
    assert!(diff <= 1e-6, "{diff:.3e}");
    vltm::export::npy::write_f32(&fp, &vec![0.0f32; vol.len()], &SHAPE).expect("pattern");
    for pat in [s(&fp), "-0.4,0,0.8,0".to_string()] {
        let err = fails(
            &t.0,
            &["relight", &cap, "--pattern", &pat, "--volume", SPEC],
            2,
        );
        assert!(
            err.contains("--pattern") && err.contains("non-zero"),
            "{err}"
        );
    }
    // A row = the column of the transposed capture.
    let (fr, fc) = (t.path("row.npy"), t.path("swapped.npy"));
    ok(
        &t.0,
        &[
            "row",
            &cap,
            "--focus",
            FOCUS,
            "--volume",
            SPEC,
            "--no-leak-correct",
            "--out",
            &s(&fr),
        ],
    );
    ok(
        &t.0,
        &[
            "column",
            &cap,
            "--focus",
            FOCUS,
            "--volume",
            SPEC,
            "--swap-roles",
            "--no-leak-correct",
            "--path",
            "band",
            "--out",
            &s(&fc),
        ],
    );
    let diff = rel_of_max(&npy(&fr, SHAPE), &npy(&fc, SHAPE));
    println!("row vs column --swap-roles: {diff:.1e}");
    assert!(diff <= 1e-6, "{diff:.3e}");
}

/// The leak correction (docs/indirect-light.md): `indirect`, `column`, `row` and `relight`
/// correct by default; a volume whose direct returns all fall beyond the capture's window is
/// refused with the window error; `column` reports the energy it removed, `--leak-correct`
/// (kept for scripts) changes nothing and `--no-leak-correct` gives the column as it is.
#[test]
fn leak_correct_on_the_command_line() {
    let t = TempDir::new("cli", "leak");
    let cap = npz_fixture("two_patches");
    let cap = cap.to_str().expect("utf-8");
    // 3-vertex paths of voxels 4.5–5 m deep exceed the 4.48 m window.
    let far = "-0.2:0.2:3,-0.2:0.2:3,4.5:5:2";
    // The window check (the same error for every probe) refuses them before Γ is formed;
    // an empty Γ inside the window is refused naming --leak-epsilon (tests/leak.rs).
    let err = fails(&t.0, &["indirect", cap, "--volume", far], 2);
    assert!(
        err.contains("volume")
            && err.contains("no path through the probed points")
            && err.lines().count() == 1,
        "{err}"
    );
    let column = |name: &str, extra: &[&str]| {
        let f = t.path(name);
        let mut a = vec!["column", cap, "--focus", "-0.45,0,0.8", "--volume", SPEC];
        a.extend_from_slice(extra);
        a.extend_from_slice(&["--out", f.to_str().expect("utf-8")]);
        (ok(&t.0, &a), npy(&f, SHAPE))
    };
    let (out, v) = column("c.npy", &[]);
    assert!(
        out.contains("leak correction (--no-leak-correct to skip): "),
        "{out}"
    );
    assert!(
        v.iter().any(|&x| x > 0.0),
        "leak-corrected column is all zero"
    );
    let (_, same) = column("c2.npy", &["--leak-correct"]);
    assert_eq!(v, same, "--leak-correct is the default");
    let (out, raw) = column("raw.npy", &["--no-leak-correct"]);
    assert!(!out.contains("leak correction"), "{out}");
    assert!(
        raw.iter().sum::<f32>() > 2.0 * v.iter().sum::<f32>(),
        "the correction removes direct light from the column"
    );
    for (probe, extra) in [("row", "--focus"), ("relight", "--pattern")] {
        let f = t.path(&format!("{probe}.npy"));
        let out = ok(
            &t.0,
            &[
                probe,
                cap,
                extra,
                "-0.45,0,0.8",
                "--volume",
                SPEC,
                "--out",
                f.to_str().expect("utf-8"),
            ],
        );
        assert!(out.contains("leak correction (--no-leak-correct"), "{out}");
    }
    let out = ok(
        &t.0,
        &[
            "indirect",
            cap,
            "--volume",
            SPEC,
            "--out",
            t.path("i.npy").to_str().expect("utf-8"),
        ],
    );
    assert!(
        out.contains("leak correction (--no-leak-correct to skip)"),
        "{out}"
    );
}

/// `--leak-correct model` (docs/indirect-light.md): the surface model fitted to the two-patch
/// capture and subtracted before the pair sums; the run says which correction it used and the
/// energy the model explains. When the model cannot be used (here: its buffers over a small
/// `--max-memory`, checked before any pass) the run falls back to the time windows with
/// exactly one warning line saying why, and writes what `--leak-correct gate` writes. A bad
/// method is refused naming the flag, as is `model` with `--no-leak-correct`.
#[test]
fn leak_correct_model_on_the_command_line() {
    let t = TempDir::new("cli", "leak-model");
    let cap = npz_fixture("two_patches");
    let cap = cap.to_str().expect("utf-8");
    let run = |name: &str, extra: &[&str]| {
        let f = t.path(name);
        let mut a = vec!["indirect", cap, "--volume", SPEC, "--progress", "none"];
        a.extend_from_slice(extra);
        a.extend_from_slice(&["--out", f.to_str().expect("utf-8")]);
        let o = vltm_in(&t.0, &a);
        assert!(o.status.success(), "{a:?}: {}", text(&o.stderr));
        (text(&o.stdout), text(&o.stderr), npy(&f, SHAPE))
    };
    // The model explains ≥ 99 % of this noise-free render (measured 0.9926).
    let (out, err, model) = run("m.npy", &["--leak-correct", "model"]);
    assert!(
        out.contains("leak correction (--leak-correct model): the surface model (")
            && out.contains("of the capture's energy and is subtracted"),
        "{out}"
    );
    let explained: f64 = out
        .split("explains ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|x| x.parse().ok())
        .expect("the energy explained");
    assert!((0.99..=1.0).contains(&explained), "{out}");
    assert!(!out.contains("3-vertex windows"), "{out}");
    assert!(err.is_empty(), "{err}");
    assert!(model.iter().any(|&x| x > 0.0), "all zero");
    let (_, _, gate) = run("g.npy", &["--leak-correct", "gate"]);
    assert_ne!(
        model, gate,
        "the model and the windows remove different light"
    );
    // The fallback: one warning line naming why, then the windows, as `--leak-correct gate`.
    let small = ["--max-memory", "4M"];
    let (out, err, fell) = run(
        "f.npy",
        &[&small[..], &["--leak-correct", "model"]].concat(),
    );
    let (gate_out, gate_err, gate) = run("g8.npy", &[&small[..], &["--leak-correct"]].concat());
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with("vltm: warning: leak correction: ")
            && err.contains("memory budget (set it with --max-memory)")
            && err
                .trim_end()
                .ends_with("; using the time windows (--leak-correct gate)"),
        "{err}"
    );
    assert!(gate_err.is_empty(), "{gate_err}");
    assert!(
        out.contains("leak correction (--no-leak-correct to skip): "),
        "{out}"
    );
    assert_eq!(out.lines().count(), gate_out.lines().count(), "{out}");
    assert_eq!(fell, gate, "the fallback is the windows");
    // Refused before anything runs, naming the flag.
    let o = t.s("x.npy");
    for bad in [
        vec![
            "indirect",
            cap,
            "--volume",
            SPEC,
            "--leak-correct",
            "fit",
            "--out",
            &o,
        ],
        vec![
            "column",
            cap,
            "--focus",
            FOCUS,
            "--volume",
            SPEC,
            "--leak-correct",
            "models",
            "--out",
            &o,
        ],
        vec![
            "indirect",
            cap,
            "--volume",
            SPEC,
            "--leak-correct",
            "model",
            "--no-leak-correct",
            "--out",
            &o,
        ],
    ] {
        let err = fails(&t.0, &bad, 2);
        assert!(err.contains("--leak-correct"), "{bad:?}: {err}");
    }
    assert!(!t.path("x.npy").exists());
}

/// `--leak-correct auto` (docs/indirect-light.md): the windows' pass first, then the surface
/// model only where the energy the windows leave lies next to them. On the two patches
/// (compact: their inter-reflection arrives apart from their direct light) it says so with
/// the adjacency and writes exactly what `--leak-correct gate` writes, for `indirect` and for
/// a column; `live` (which chooses before the scan) and a partial in-focus sum (the model
/// needs the whole capture) refuse it naming the flag. The path-traced case, where it picks
/// the model, is in `tests/leak.rs`.
#[test]
fn leak_correct_auto_on_the_command_line() {
    let t = TempDir::new("cli", "leak-auto");
    let cap = npz_fixture("two_patches");
    let cap = cap.to_str().expect("utf-8");
    // The README's volume (windows of 5 cm voxels; on coarser voxels the windows widen and
    // the adjacency grows: docs/indirect-light.md).
    let (spec, shape) = ("-0.6:0.6:25,-0.2:0.2:5,0.5:1.2:15", [25, 5, 15]);
    let run = |name: &str, cmd: &[&str], extra: &[&str]| {
        let f = t.path(name);
        let mut a = cmd.to_vec();
        a.extend_from_slice(&["--volume", spec, "--progress", "none"]);
        a.extend_from_slice(extra);
        a.extend_from_slice(&["--out", f.to_str().expect("utf-8")]);
        let o = vltm_in(&t.0, &a);
        assert!(o.status.success(), "{a:?}: {}", text(&o.stderr));
        (text(&o.stdout), npy(&f, shape))
    };
    for cmd in [vec!["indirect", cap], vec!["column", cap, "--focus", FOCUS]] {
        let (out, auto) = run("a.npy", &cmd, &["--leak-correct", "auto"]);
        let (_, gate) = run("g.npy", &cmd, &["--leak-correct", "gate"]);
        // Measured 0.07.
        let a = support::cmd::auto_adjacency(&out);
        assert!(a < 0.15, "{out}");
        assert!(
            out.contains("the windows (what they leave stands apart"),
            "{out}"
        );
        assert!(!out.contains("surface model"), "{out}");
        assert_eq!(auto, gate, "{cmd:?}: auto is the windows here");
    }
    let o = t.s("x.npy");
    let d = t.s("d.npy");
    ok(&t.0, &["direct", cap, "--volume", SPEC, "--out", &d]);
    for bad in [
        vec![
            "live",
            cap,
            "--replay-rate",
            "1000",
            "--volume",
            SPEC,
            "--focus",
            FOCUS,
            "--leak-correct",
            "auto",
            "--out",
            &o,
        ],
        vec![
            "indirect",
            cap,
            "--volume",
            SPEC,
            "--direct",
            &d,
            "--rows",
            ":40",
            "--partial",
            &o,
            "--leak-correct",
            "auto",
        ],
    ] {
        let err = fails(&t.0, &bad, 2);
        assert!(
            err.contains("--leak-correct") && err.lines().count() == 1,
            "{bad:?}: {err}"
        );
    }
    assert!(!t.path("x.npy").exists());
}

/// A capture with no light at all (the two-patch fixture zeroed): every probe that forms Γ
/// refuses it with an error naming its option — `indirect` and `matrix ... gamma`
/// `--epsilon`, `column --mask-epsilon` that option, `column --leak-correct` that one —
/// never an all-zero result, and writes nothing.
#[test]
fn empty_gamma_is_an_error_naming_the_option() {
    let t = TempDir::new("cli", "dark");
    let mut c = vltm::io::open(&npz_fixture("two_patches")).expect("fixture");
    c.data.iter_mut().for_each(|x| *x = 0.0);
    let dark = t.path("dark.npz");
    vltm::io::npz::write(&c, &dark).expect("write");
    let (cap, out) = (s(&dark), s(&t.path("o.npy")));
    let h5 = s(&t.path("m.h5"));
    let cases: [(Vec<&str>, &str); 4] = [
        (
            vec!["indirect", &cap, "--volume", SPEC, "--out", &out],
            "--epsilon",
        ),
        (
            vec![
                "matrix", &cap, "--from", "gamma", "--to", "gamma", "--volume", SPEC, "--out", &h5,
            ],
            "--epsilon",
        ),
        (
            vec![
                "column",
                &cap,
                "--focus",
                FOCUS,
                "--volume",
                SPEC,
                "--mask-epsilon",
                "0.1",
                "--out",
                &out,
            ],
            "--mask-epsilon",
        ),
        (
            vec![
                "column",
                &cap,
                "--focus",
                FOCUS,
                "--volume",
                SPEC,
                "--leak-correct",
                "--out",
                &out,
            ],
            "--leak-correct",
        ),
    ];
    for (args, option) in cases {
        let err = fails(&t.0, &args, 2);
        assert!(
            err.contains(option) && err.lines().count() == 1,
            "{args:?}: {err}"
        );
    }
    assert!(!t.path("o.npy").exists() && !t.path("m.h5").exists());
}

/// Partial states of the matrix and of leak-corrected indirect light on the command line:
/// `matrix --rows --partial` parts merged by `vltm merge --out F.h5` give the file of one
/// `vltm matrix` run; `indirect --direct D --rows --partial` (leak correction by default)
/// parts merged give `vltm indirect --direct D`; `gamma` with `--partial`, `--rows` without
/// it and a merged matrix without `--out F.h5` are refused naming the option.
#[test]
fn matrix_and_leak_corrected_parts_through_the_command_line() {
    let t = TempDir::new("cli", "matrix-parts");
    let cap = s(&npz_fixture("two_patches"));
    let from = "-0.3:0.3:2,-0.1:0.1:2,0.6:0.8:2";
    let one = t.path("one.h5");
    let base = ["matrix", cap.as_str(), "--from", from, "--to", SPEC];
    ok(&t.0, &[&base[..], &["--out", &s(&one)]].concat());
    let (pa, pb) = (t.path("a.part"), t.path("b.part"));
    ok(
        &t.0,
        &[&base[..], &["--rows", "0:25", "--partial", &s(&pa)]].concat(),
    );
    ok(
        &t.0,
        &[&base[..], &["--rows", "25:", "--partial", &s(&pb)]].concat(),
    );
    let merged = t.path("merged.h5");
    ok(&t.0, &["merge", &s(&pb), &s(&pa), "--out", &s(&merged)]);
    for name in ["re", "im", "intensity", "from_xyz", "to_xyz"] {
        let (x, sx) = vltm::export::h5::read_f32_dataset(&one, name).expect("one");
        let (y, sy) = vltm::export::h5::read_f32_dataset(&merged, name).expect("merged");
        assert_eq!(sx, sy, "{name}");
        let max = x.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let worst = x
            .iter()
            .zip(&y)
            .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
        assert!(
            max > 0.0 && worst <= 1e-6 * max,
            "{name}: {worst:e} of {max:e}"
        );
    }
    let err = fails(&t.0, &["merge", &s(&pa), &s(&pb)], 2);
    assert!(err.contains("--out"), "{err}");
    let err = fails(
        &t.0,
        &["merge", &s(&pa), &s(&pb), "--out", &s(&t.path("m.npy"))],
        2,
    );
    assert!(err.contains("--out") && err.contains("HDF5"), "{err}");
    let err = fails(
        &t.0,
        &[
            "matrix",
            &cap,
            "--from",
            "gamma",
            "--to",
            SPEC,
            "--volume",
            SPEC,
            "--partial",
            &s(&t.path("g.part")),
        ],
        2,
    );
    assert!(err.contains("--partial") && err.contains("gamma"), "{err}");
    let err = fails(
        &t.0,
        &[&base[..], &["--rows", "0:8", "--out", &s(&one)]].concat(),
        2,
    );
    assert!(err.contains("--rows") && err.contains("--partial"), "{err}");
    // Leak-corrected indirect light in two parts = one pass with the same Γ.
    let d = t.path("d.npy");
    ok(&t.0, &["direct", &cap, "--volume", SPEC, "--out", &s(&d)]);
    let ind = [
        "indirect",
        cap.as_str(),
        "--volume",
        SPEC,
        "--direct",
        &s(&d),
    ];
    let whole = t.path("i.npy");
    let out = ok(&t.0, &[&ind[..], &["--out", &s(&whole)]].concat());
    assert!(out.contains("leak correction"), "{out}");
    let (ia, ib) = (t.path("ia.part"), t.path("ib.part"));
    ok(
        &t.0,
        &[&ind[..], &["--rows", ":40", "--partial", &s(&ia)]].concat(),
    );
    ok(
        &t.0,
        &[&ind[..], &["--rows", "40:", "--partial", &s(&ib)]].concat(),
    );
    let fm = t.path("im.npy");
    let out = ok(&t.0, &["merge", &s(&ia), &s(&ib), "--out", &s(&fm)]);
    assert!(out.contains("leak correction"), "{out}");
    let worst = rel_of_max(&npy(&whole, SHAPE), &npy(&fm, SHAPE));
    assert!(worst <= 1e-6, "{worst:e}");
}

/// `indirect`'s summary line (and the provenance of its outputs) gives the configuration pass
/// 2 ran on: the column configuration over Γ, whose DFT the automatic margin widens when Γ's
/// 4-vertex paths reach past the window. (It gave pass 1's, the diagonal's.) The window is cut
/// at `T_MAX` metres, after the direct returns and before the patches' pair paths.
#[test]
fn indirect_summary_gives_pass_two_configuration() {
    use vltm::io::RowSource;
    use vltm::io::prep::{Bound, Prep, Prepared};
    use vltm::probe::Wave;
    const T_MAX: f64 = 2.4;
    let t = TempDir::new("cli", "indirect-pass-two");
    let cap = npz_fixture("two_patches");
    let out = ok(
        &t.0,
        &[
            "indirect",
            cap.to_str().expect("utf-8"),
            "--volume",
            SPEC,
            "--t-max",
            &T_MAX.to_string(),
            "--no-leak-correct",
            "--out",
            "i.npy",
        ],
    );
    print!("{out}");
    let j = |prefix: &str| -> usize {
        let line = out
            .lines()
            .find(|l| l.starts_with(prefix))
            .unwrap_or_else(|| panic!("no `{prefix}` line:\n{out}"));
        let at = line.find("J = ").expect("J") + 4;
        line[at..]
            .split(|c: char| !c.is_ascii_digit())
            .next()
            .and_then(|s| s.parse().ok())
            .expect("J's value")
    };
    // Pass 2's configuration, from the library: the column configuration over Γ (the CLI's
    // own Γ output) on the cut capture.
    let gamma = npy(&t.path("i.gamma.npy"), SHAPE);
    let volume = vltm::volume::Volume::parse(SPEC).expect("volume");
    let pts: Vec<_> = volume
        .points
        .iter()
        .zip(&gamma)
        .filter_map(|(p, &g)| (g > 0.5).then_some(*p))
        .collect();
    assert!(!pts.is_empty(), "Γ is empty");
    let mut c = vltm::io::open(&cap).expect("capture");
    let prep = Prep {
        t_max: Some(Bound::Metres(T_MAX)),
        rebin: 1,
        ..Prep::default()
    };
    let cut = Prepared::new(&mut c, prep, None).expect("window");
    let g = cut.geometry();
    let wave = Wave::default();
    let pass2 = wave.column_config(g, &pts, &pts).expect("column config");
    let pass1 = wave.config(g).expect("config");
    assert_ne!(
        pass2.bins(),
        pass1.bins(),
        "the test needs a window that widens pass 2's DFT"
    );
    assert_eq!(j("indirect:"), pass2.bins(), "J of the summary line");
}

/// `relight` and `row` preprocess the counts as every probe does (`--t-min`, `--t-max`,
/// `--rebin`, `--background`): the same result as on a capture windowed, rebinned and
/// floored by hand; a floor above every count is refused; a part of a scan (`--rows`,
/// `--partial`) is refused in one line naming the option, nothing written.
#[test]
fn relight_and_row_preprocess_and_refuse_parts() {
    let t = TempDir::new("cli", "rowprep");
    let cap = npz_fixture("two_patches");
    let c = io::open(&cap).expect("fixture");
    let g = c.geometry.clone();
    // Bins 10..174, pairs summed, 1e-4 counts per source bin subtracted, clamped at 0.
    let (n0, n1, k, floor) = (10usize, 174usize, 2usize, 1e-4f32);
    let nt = (n1 - n0) / k;
    let mut data = Vec::with_capacity(g.lasers.len() * g.spads_per_row() * nt);
    for h in c.data.chunks_exact(g.nt) {
        for b in 0..nt {
            let sum: f32 = h[n0 + k * b..n0 + k * (b + 1)].iter().sum();
            data.push((sum - k as f32 * floor).max(0.0));
        }
    }
    let g2 = io::Geometry {
        nt,
        dt: g.dt * k as f64,
        t0: g.t0 + n0 as f64 * g.dt + (k - 1) as f64 * g.dt / 2.0,
        ..g
    };
    let pre = t.path("pre.npz");
    io::npz::write(&io::Capture::new(g2, data, &pre).expect("capture"), &pre).expect("write");
    let flags = [
        "--t-min",
        "10b",
        "--t-max",
        "174b",
        "--rebin",
        "2",
        "--background",
        "1e-4",
    ];
    let (cap, pre) = (s(&cap), s(&pre));
    let (a, b) = (t.path("a.npy"), t.path("b.npy"));
    let (a_s, b_s) = (s(&a), s(&b));
    let part = t.path("p.part");
    let part_s = s(&part);
    for probe in ["relight", "row"] {
        let point = if probe == "row" {
            "--focus"
        } else {
            "--pattern"
        };
        // The preprocessing on the capture as it is (the test's subject is the flags).
        let base = [
            probe,
            &cap,
            point,
            FOCUS,
            "--volume",
            SPEC,
            "--no-leak-correct",
            "--out",
        ];
        let mut args = base.to_vec();
        args.push(&a_s);
        let mut with = args.clone();
        with.extend(flags);
        let out = ok(&t.0, &with);
        assert!(out.contains("preprocessing: window bins 10..174"), "{out}");
        let mut by_hand = base.to_vec();
        by_hand[1] = &pre;
        by_hand.push(&b_s);
        ok(&t.0, &by_hand);
        let plain = npy(&b, SHAPE);
        let diff = rel_of_max(&npy(&a, SHAPE), &plain);
        println!("{probe} with the preprocessing flags vs a preprocessed capture: {diff:.1e}");
        assert!(diff <= 1e-5, "{probe}: {diff:.3e}");
        // The flags change the result (they are not ignored): the unprocessed capture differs.
        ok(&t.0, &args);
        let raw = rel_of_max(&npy(&a, SHAPE), &plain);
        assert!(
            raw > 1e-3,
            "{probe}: the preprocessing changed nothing ({raw:.1e})"
        );
        // A floor above every count: refused, naming --background.
        std::fs::remove_file(&a).expect("rm");
        let mut dark = args.clone();
        dark.extend(["--background", "1"]);
        let err = fails(&t.0, &dark, 2);
        assert!(err.contains("--background"), "{err}");
        assert!(!a.exists(), "{probe}: an output was written");
        // A part of the scan: one line naming the option, nothing written.
        for (extra, named) in [
            (vec!["--rows", "0:4"], "--rows"),
            (vec!["--rows", "0:4", "--partial", &part_s], "--rows"),
            (vec!["--partial", &part_s], "--partial"),
        ] {
            let mut v = args.clone();
            v.extend(extra.iter().copied());
            let err = fails(&t.0, &v, 2);
            assert!(
                err.contains(named)
                    && err.contains("vltm matrix")
                    && err.trim().lines().count() == 1,
                "{probe}: {err}"
            );
            assert!(
                !a.exists() && !part.exists(),
                "{probe}: an output was written"
            );
        }
    }
}

/// `VLTM_TIMINGS=1` names the serial and parallel parts of a column on the planar path
/// (opening, the planar tables, reading rows, imaging, writing) and the serial fraction; and
/// the column is byte-identical on 1, 2 and 3 threads (the planar tables, the planning and
/// the reads split over the pool compute every value the same way).
#[test]
fn timings_name_the_sections_and_threads_change_no_byte() {
    let t = TempDir::new("cli", "timings");
    let cap = s(&npz_fixture("two_patches"));
    let mut outputs = Vec::new();
    for threads in ["1", "2", "3"] {
        let out = t.path(&format!("column{threads}.npy"));
        let o = Command::new(support::vltm_bin())
            .current_dir(&t.0)
            .env("VLTM_TIMINGS", "1")
            .args([
                "--threads",
                threads,
                "column",
                &cap,
                "--focus",
                FOCUS,
                "--volume",
                "-0.5:0.5:8,-0.5:0.5:8,0.5:1.2:8",
                "--out",
                &s(&out),
            ])
            .output()
            .expect("run vltm");
        let err = text(&o.stderr);
        assert!(o.status.success(), "{err}");
        assert!(
            text(&o.stdout).contains("path planar"),
            "{}",
            text(&o.stdout)
        );
        for line in [
            &format!("timings ({threads} threads)"),
            "serial   opening the capture",
            "parallel planar tables",
            "parallel read rows",
            "parallel imaging the column",
            "serial   writing outputs (and fsync)",
            "outside any section",
        ] {
            assert!(err.contains(line), "no `{line}` in:\n{err}");
        }
        outputs.push(std::fs::read(&out).expect("read the column"));
    }
    assert!(outputs[0].len() > 128 && outputs.iter().all(|o| *o == outputs[0]));
}
