//! What a user meets at the door: output names whose extension disagrees with what is
//! written, output folders, misspelled flags, missing files, named pipes, oversized sidecars
//! and scenes, parameters out of range, and the `$name` markers of library messages. Each case
//! runs the `vltm` binary (found as in `tests/cli.rs`) in a temporary directory.

mod support;

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::PathBuf;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};
use support::cmd::TempDir;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn run(dir: &TempDir, args: &[&str]) -> Output {
    Command::new(support::vltm_bin())
        .current_dir(&dir.0)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("run vltm")
}

/// Every error line seen by [`fails`], for the marker check.
static SEEN: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());

/// Asserts that no library parameter marker (`$name`, `$NAME`) reached the user.
fn no_marker(line: &str) {
    let b = line.as_bytes();
    for (i, &c) in b.iter().enumerate() {
        if c == b'$' {
            let next = b.get(i + 1).copied().unwrap_or(b' ');
            assert!(
                !(next.is_ascii_alphabetic() || next == b'_' || next == b'{'),
                "a `$` marker reached the user: {line}"
            );
        }
    }
}

/// Runs `vltm args…` in `dir` and asserts: exit code `code`, nothing on stdout, one stderr
/// line starting with `vltm: ` containing every string of `says`, no `$` marker, and no file
/// added to the directory. Returns the line.
fn fails(dir: &TempDir, args: &[&str], code: i32, says: &[&str]) -> String {
    let before = dir.files();
    let o = run(dir, args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(code), "vltm {args:?}: {err}");
    assert!(
        o.stdout.is_empty(),
        "vltm {args:?}: stdout before a failure: {}",
        String::from_utf8_lossy(&o.stdout)
    );
    let lines: Vec<&str> = err.lines().collect();
    assert!(
        lines.len() == 1 && lines[0].starts_with("vltm: "),
        "vltm {args:?}: expected one error line, found:\n{err}"
    );
    for s in says {
        assert!(
            lines[0].contains(s),
            "vltm {args:?}: `{s}` not in: {}",
            lines[0]
        );
    }
    no_marker(lines[0]);
    assert_eq!(before, dir.files(), "vltm {args:?}: files added or removed");
    SEEN.lock().unwrap().push(lines[0].to_string());
    lines[0].to_string()
}

fn ok(dir: &TempDir, args: &[&str]) -> String {
    let o = run(dir, args);
    assert!(
        o.status.success(),
        "vltm {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A small simulated capture `c.npz` (stored, streamed) and its PTU `c.ptu` + `c.json`.
fn capture(dir: &TempDir) {
    let scene = root().join("kernel/firmware/fixture/scene.json");
    ok(
        dir,
        &[
            "simulate",
            scene.to_str().unwrap(),
            "--out",
            "c.npz",
            "--ptu",
            "c.ptu",
            "--uncompressed",
        ],
    );
}

const VOLUME: &str = "-0.2:0.2:4,-0.2:0.2:4,0.3:0.6:4";

// ---------------------------------------------------------------------------------------
// Outputs.

/// The format follows the extension: a mismatched or unknown one is refused before any work
/// (nothing written, nothing on stdout), naming the flag and what it expects.
#[test]
fn output_extension_must_match_its_format() {
    let t = TempDir::new("user", "ext");
    capture(&t);
    let probe = |extra: &[&str]| {
        let mut a = vec!["direct", "c.npz", "--volume", VOLUME];
        a.extend_from_slice(extra);
        a.into_iter().map(str::to_string).collect::<Vec<_>>()
    };
    for (extra, says) in [
        (
            vec!["--out", "result.png"],
            vec!["--out", "result.png", ".npy", "found .png"],
        ),
        (vec!["--out", "result"], vec!["--out", "found no extension"]),
        (
            vec!["--out", "r.npy", "--png", "r.npy"],
            vec!["--png", "found .npy"],
        ),
        (vec!["--png", "r.jpg"], vec!["--png", ".png"]),
    ] {
        let a = probe(&extra);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        fails(&t, &a, 2, &says);
    }
    let scene = root().join("kernel/firmware/fixture/scene.json");
    let s = scene.to_str().unwrap();
    fails(
        &t,
        &["simulate", s, "--out", "x.npy"],
        2,
        &["--out", ".npz"],
    );
    fails(
        &t,
        &["simulate", s, "--out", "x.npz", "--ptu", "x.bin"],
        2,
        &["--ptu", ".ptu"],
    );
    fails(
        &t,
        &[
            "matrix", "c.npz", "--from", "0,0,0.4", "--to", "0,0,0.5", "--out", "m.npy",
        ],
        2,
        &["--out", "HDF5"],
    );
    fails(
        &t,
        &["info", "c.npz", "--png", "s.npy"],
        2,
        &["--png", ".png"],
    );
    // The accepted spellings still write what they name.
    for out in ["v.npy", "v.h5", "v.HDF5"] {
        ok(&t, &["direct", "c.npz", "--volume", VOLUME, "--out", out]);
        let head = std::fs::read(t.path(out)).unwrap();
        let npy = head.starts_with(b"\x93NUMPY");
        assert_eq!(npy, out.ends_with(".npy"), "{out}");
    }
}

/// A missing output folder is created before the work (and its output written there); one
/// that cannot be created is refused in one line before any work.
#[test]
fn output_folders_are_made_before_the_work() {
    let t = TempDir::new("user", "folders");
    capture(&t);
    let out = ok(
        &t,
        &[
            "direct",
            "c.npz",
            "--volume",
            VOLUME,
            "--out",
            "new/deeper/x.npy",
            "--png",
            "figs/x.png",
        ],
    );
    assert!(t.path("new/deeper/x.npy").is_file(), "{out}");
    assert!(t.path("figs/x.png").is_file(), "{out}");
    // A folder under a file cannot be made: refused, nothing written.
    std::fs::write(t.path("afile"), b"x").unwrap();
    fails(
        &t,
        &[
            "direct",
            "c.npz",
            "--volume",
            VOLUME,
            "--out",
            "afile/x.npy",
        ],
        2,
        &["--out", "afile/x.npy", "cannot create its folder"],
    );
    // `live` into a folder that does not exist: made first; the run completes there.
    let o = run(
        &t,
        &[
            "live",
            "c.npz",
            "--volume",
            VOLUME,
            "--out",
            "live/scan.npy",
            "--replay-rate",
            "1000",
            "--no-indirect",
        ],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(t.path("live/scan.npy").is_file(), "{err}");
    assert!(!err.contains("continue with --resume"), "{err}");
}

/// A `live` run that fails names no state file it did not write.
#[test]
fn live_names_no_unwritten_state() {
    let t = TempDir::new("user", "live-state");
    capture(&t);
    std::fs::write(t.path("afile"), b"x").unwrap();
    let o = run(
        &t,
        &[
            "live",
            "c.npz",
            "--volume",
            VOLUME,
            "--out",
            "afile/scan.npy",
            "--replay-rate",
            "1000",
        ],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        !err.contains(".part"),
        "names a state it did not write: {err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
}

// ---------------------------------------------------------------------------------------
// Errors.

/// A misspelled flag keeps clap's suggestion, on the one error line.
#[test]
fn misspelled_flag_is_suggested() {
    let t = TempDir::new("user", "typo");
    let line = fails(
        &t,
        &["direct", "c.npz", "--volumne", VOLUME],
        2,
        &["'--volumne'"],
    );
    assert!(line.contains("'--volume'"), "{line}");
    let line = fails(&t, &["dierct"], 2, &["dierct"]);
    assert!(line.contains("direct"), "{line}");
}

/// A missing capture is "no such file" whatever its extension; a missing `.ptu` names the
/// `.ptu`, a missing sidecar names the sidecar and says what it is.
#[test]
fn missing_files_are_named() {
    let t = TempDir::new("user", "missing");
    for name in [
        "nothere.nzp",
        "nothere.npz",
        "nothere",
        "nothere.ptu",
        "nothere.mat",
    ] {
        let line = fails(&t, &["info", name], 1, &[name, "No such file"]);
        assert!(!line.contains("unknown capture format"), "{line}");
        assert!(!line.contains(".json"), "{line}");
    }
    capture(&t);
    std::fs::remove_file(t.path("c.json")).unwrap();
    for args in [
        vec!["info", "c.ptu"],
        vec!["direct", "c.ptu", "--volume", VOLUME],
    ] {
        fails(
            &t,
            &args,
            1,
            &[
                "c.json",
                "No such file",
                "c.ptu needs a JSON sidecar",
                "docs/formats.md",
                "vltm info c.ptu --sidecar c.json",
            ],
        );
    }
    // An existing file with an unknown extension is an unknown format, naming CAPTURE.
    std::fs::write(t.path("c.nzp"), b"x").unwrap();
    fails(
        &t,
        &["info", "c.nzp"],
        2,
        &["CAPTURE", "unknown capture format"],
    );
}

/// `info` prints nothing on stdout before a failure (here: the capture opens, its
/// preprocessing is refused).
#[test]
fn info_prints_nothing_before_failing() {
    let t = TempDir::new("user", "info-stdout");
    capture(&t);
    std::fs::write(t.path("bad.npz"), b"not a zip").unwrap();
    fails(&t, &["info", "bad.npz"], 1, &["bad.npz"]);
    fails(&t, &["info", "c.npz", "--rebin", "0"], 2, &["--rebin"]);
}

/// Wave parameters that make no sense are refused with their flag and valid range.
#[test]
fn wave_parameters_out_of_range() {
    let t = TempDir::new("user", "wave");
    capture(&t);
    for (flag, value, says) in [
        ("--band", "1e-300", "1 to 20"),
        ("--band", "0.5", "1 to 20"),
        ("--band", "1e300", "1 to 20"),
        ("--band", "NaN", "1 to 20"),
        ("--wavelength", "1e-300", "Nyquist"),
        ("--wavelength", "0.015", "0.02 to 1000000 m"),
        ("--wavelength", "1e300", "0.02 to 1000000 m"),
        ("--sigma", "1e-300", "one time bin"),
        ("--sigma", "-1", "0.01 to 1000000 m"),
        ("--sigma", "1e9", "0.01 to 1000000 m"),
    ] {
        let value_arg = format!("{flag}={value}");
        for probe in [
            vec!["direct", "c.npz"],
            vec!["column", "c.npz", "--focus", "0,0,0.4"],
            vec!["indirect", "c.npz"],
        ] {
            let mut a = probe.clone();
            a.extend(["--volume", VOLUME, value_arg.as_str(), "--out", "o.npy"]);
            let line = fails(&t, &a, 2, &[flag, says]);
            assert!(line.contains(&format!("argument `{flag}`")), "{line}");
        }
    }
    // The range's ends are accepted.
    for (flag, value) in [("--band", "1"), ("--band", "20")] {
        ok(
            &t,
            &[
                "direct", "c.npz", "--volume", VOLUME, flag, value, "--out", "o.npy",
            ],
        );
    }
}

/// A broad set of bad invocations: every error is one line, and no `$name` marker of a
/// library message reaches the user.
#[test]
fn no_template_marker_reaches_the_user() {
    let t = TempDir::new("user", "markers");
    capture(&t);
    let cases: &[(&[&str], i32)] = &[
        (&["info", "nothere.nzp"], 1),
        (&["direct", "c.npz", "--volume", "1:2"], 2),
        (&["direct", "c.npz", "--volume", VOLUME, "--rows", "0:2"], 2),
        (
            &[
                "direct",
                "c.npz",
                "--volume",
                VOLUME,
                "--rows",
                "9:2",
                "--partial",
                "p",
            ],
            2,
        ),
        (
            &[
                "direct", "c.npz", "--volume", VOLUME, "--path", "lookup", "--gate", "none",
            ],
            2,
        ),
        (
            &["column", "c.npz", "--volume", VOLUME, "--focus", "0,0"],
            2,
        ),
        (
            &[
                "column", "c.npz", "--volume", VOLUME, "--focus", "0,0,0.4", "--shell", "2:1",
            ],
            2,
        ),
        (
            &["indirect", "c.npz", "--volume", VOLUME, "--epsilon", "2"],
            2,
        ),
        (
            &[
                "indirect", "c.npz", "--volume", VOLUME, "--shells", "0.5,0.1",
            ],
            2,
        ),
        (
            &[
                "matrix", "c.npz", "--from", "gamma", "--to", "0,0,0.5", "--out", "m.h5",
            ],
            2,
        ),
        (
            &[
                "matrix", "c.npz", "--from", "0,0,0.4", "--to", "0,0,0.5", "--rows", "0:2",
                "--out", "m.h5",
            ],
            2,
        ),
        (
            &["relight", "c.npz", "--volume", VOLUME, "--pattern", "x"],
            2,
        ),
        (&["merge", "nothere.part"], 1),
        (
            &[
                "live", "c.npz", "--volume", VOLUME, "--out", "l.npy", "--resume", "l.npy",
            ],
            2,
        ),
        (
            &[
                "live",
                "c.npz",
                "--volume",
                VOLUME,
                "--out",
                "l.npy",
                "--idle-timeout=-1",
            ],
            2,
        ),
        (&["--max-memory", "12Q", "info", "c.npz"], 2),
        (&["--threads", "0", "info", "c.npz"], 2),
        (&["info", "c.npz", "--delta-t", "1"], 2),
        (&["simulate", "nothere.json", "--out", "s.npz"], 1),
    ];
    for (args, code) in cases {
        let o = run(&t, args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(*code), "vltm {args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "vltm {args:?}: {err}");
        no_marker(&err);
    }
    // And every line the other tests of this file saw (those run before this one).
    for line in SEEN.lock().unwrap().iter() {
        no_marker(line);
    }
    // The check has teeth.
    assert!(std::panic::catch_unwind(|| no_marker("argument `$CAPTURE`: x")).is_err());
    assert!(std::panic::catch_unwind(|| no_marker("raise $epsilon")).is_err());
    no_marker("costs $5");
}

// ---------------------------------------------------------------------------------------
// Bad input.

/// A named pipe is refused before it is opened, in one line, by every offline command (it
/// blocked forever).
#[test]
fn named_pipe_is_refused_at_once() {
    let t = TempDir::new("user", "fifo");
    let fifo = t.path("f.npz");
    let st = Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .expect("mkfifo (coreutils)");
    assert!(st.success());
    let ptu = t.path("g.ptu");
    assert!(Command::new("mkfifo").arg(&ptu).status().unwrap().success());
    std::fs::write(t.path("g.json"), b"{}").unwrap();
    for args in [
        vec!["info", "f.npz"],
        vec!["direct", "f.npz", "--volume", VOLUME],
        vec!["column", "f.npz", "--volume", VOLUME, "--focus", "0,0,0.4"],
        vec!["indirect", "f.npz", "--volume", VOLUME],
        vec!["info", "g.ptu"],
        vec!["simulate", "f.npz", "--out", "s.npz"],
    ] {
        let start = Instant::now();
        let mut child = Command::new(support::vltm_bin())
            .current_dir(&t.0)
            .args(&args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // A generous bound: the run must not block (it blocked forever).
        while child.try_wait().unwrap().is_none() {
            if start.elapsed() > Duration::from_secs(20) {
                let _ = child.kill();
                panic!("vltm {args:?} blocked on a named pipe");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "vltm {args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            (err.contains("f.npz") || err.contains("g.ptu")) && err.contains("a named pipe"),
            "{err}"
        );
        assert!(err.contains("regular file"), "{err}");
    }
}

/// A sidecar or a scene that is not a small regular file (a link to `/dev/zero`, a file
/// over 16 MiB) is refused before it is read.
#[test]
fn oversized_sidecar_and_scene_are_refused() {
    let t = TempDir::new("user", "big-json");
    capture(&t);
    std::fs::remove_file(t.path("c.json")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", t.path("c.json")).unwrap();
    fails(
        &t,
        &["info", "c.ptu"],
        1,
        &["c.json", "regular file", "a device"],
    );
    std::os::unix::fs::symlink("/dev/urandom", t.path("s.json")).unwrap();
    fails(
        &t,
        &["simulate", "s.json", "--out", "s.npz"],
        1,
        &["s.json", "a device"],
    );
    // A sparse 17 MiB scene: refused by its size, not read.
    let f = std::fs::File::create(t.path("big.json")).unwrap();
    f.set_len(17 << 20).unwrap();
    fails(
        &t,
        &["simulate", "big.json", "--out", "s.npz"],
        1,
        &["big.json", "at most 17 MB", "18 MB"],
    );
}

/// A stored `.npz` whose `H` entry has bytes after its data: refused alike by `info` and
/// every probe (the streamed probes accepted it).
#[test]
fn npz_with_extra_bytes_is_refused_by_every_command() {
    use std::io::Read as _;
    let t = TempDir::new("user", "npz-extra");
    capture(&t);
    let mut z = zip::ZipArchive::new(std::fs::File::open(t.path("c.npz")).unwrap()).unwrap();
    let mut members = BTreeMap::new();
    for i in 0..z.len() {
        let mut e = z.by_index(i).unwrap();
        let mut v = Vec::new();
        e.read_to_end(&mut v).unwrap();
        if e.name() == "H.npy" {
            v.extend(std::iter::repeat_n(0u8, 4000));
        }
        members.insert(e.name().to_string(), v);
    }
    let mut w = zip::ZipWriter::new(std::fs::File::create(t.path("x.npz")).unwrap());
    let opts =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for (name, bytes) in &members {
        w.start_file(name.as_str(), opts).unwrap();
        w.write_all(bytes).unwrap();
    }
    w.finish().unwrap();
    for args in [
        vec!["info", "x.npz"],
        vec!["direct", "x.npz", "--volume", VOLUME, "--out", "o.npy"],
        vec![
            "column", "x.npz", "--volume", VOLUME, "--focus", "0,0,0.4", "--out", "o.npy",
        ],
        vec!["indirect", "x.npz", "--volume", VOLUME, "--out", "o.npy"],
    ] {
        fails(&t, &args, 1, &["x.npz", "H"]);
    }
    // The clean file passes the same commands.
    ok(
        &t,
        &["direct", "c.npz", "--volume", VOLUME, "--out", "o.npy"],
    );
}

/// `vltm info F.ptu --sidecar F.json` writes a template pre-filled from the file (rows and
/// their marker, channels, bins, bin width); filled in with the geometry as a user would,
/// `direct` reads the `.ptu` with it and finds the volume the original sidecar gives.
#[test]
fn sidecar_template_round_trips() {
    let t = TempDir::new("user", "template");
    capture(&t);
    ok(
        &t,
        &["direct", "c.ptu", "--volume", VOLUME, "--out", "a.npy"],
    );
    let original: serde_json::Value =
        serde_json::from_slice(&std::fs::read(t.path("c.json")).unwrap()).unwrap();
    std::fs::remove_file(t.path("c.json")).unwrap();
    let said = ok(&t, &["info", "c.ptu", "--sidecar", "t.json"]);
    assert!(
        said.contains("wrote t.json") && said.contains("c.json"),
        "{said}"
    );
    // Not over an existing file, and only for a .ptu.
    fails(
        &t,
        &["info", "c.ptu", "--sidecar", "t.json"],
        2,
        &["--sidecar", "t.json exists"],
    );
    fails(
        &t,
        &["info", "c.npz", "--sidecar", "u.json"],
        2,
        &["--sidecar", ".ptu"],
    );
    let text = std::fs::read_to_string(t.path("t.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    // Pre-filled from the file.
    assert_eq!(v["rows"], 16, "{text}");
    assert_eq!(v["row_marker"], 1, "{text}");
    assert_eq!(v["channels"], serde_json::json!([0, 1, 2, 3]), "{text}");
    assert_eq!(v["nt"], 128, "{text}");
    assert!(
        (v["bin_width"].as_f64().unwrap() - 0.01).abs() < 1e-9,
        "{text}"
    );
    assert!(v["_lasers"].as_str().unwrap().contains("FILL IN"), "{text}");
    assert!(
        v["_help"].as_str().unwrap().contains("docs/formats.md"),
        "{text}"
    );
    // As it is, the geometry is missing: refused naming the sidecar's field.
    std::fs::copy(t.path("t.json"), t.path("c.json")).unwrap();
    fails(
        &t,
        &["direct", "c.ptu", "--volume", VOLUME, "--out", "b.npy"],
        1,
        &["c.json", "lasers"],
    );
    // Filled in: the spots, t0 and the devices' positions (the notes stay).
    for key in ["lasers", "spads", "t0", "laser_origin", "sensor_origin"] {
        v[key] = original[key].clone();
    }
    std::fs::write(t.path("c.json"), serde_json::to_string_pretty(&v).unwrap()).unwrap();
    ok(
        &t,
        &["direct", "c.ptu", "--volume", VOLUME, "--out", "b.npy"],
    );
    assert_eq!(
        std::fs::read(t.path("a.npy")).unwrap(),
        std::fs::read(t.path("b.npy")).unwrap(),
        "the template's volume differs from the original sidecar's"
    );
}
