//! `vltm live`: following a scan while it is acquired.
//!
//! * a replayed capture gives, at the end, the offline commands' volumes (direct light,
//!   column, in-focus indirect light) within 1e-6 of the peak, and snapshots on the way;
//! * a PTU file written row by row by a **separate process** at the paper's dwell (87 ms per
//!   row, records split at odd byte boundaries, the record count patched into the header at
//!   the end as acquisition software does) is followed, the served status advances while the
//!   file grows, and the result equals `vltm direct` / `vltm column` on the finished file;
//! * bad input: a stream that stops mid-record, a header that is not T3, a marker that never
//!   comes (the states of the rows before it kept, then resumed to the offline result), a
//!   state of another configuration, a port in use, a state that would be overwritten;
//! * the [`Follower`] on a stream equals [`PtuSource`] row by row, and every truncation of a
//!   stream is a clean error.
//!
//! The browser test is `tests/live_browser.rs`.

mod support;

use std::io::{Read, Seek, SeekFrom, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use support::cmd::{TempDir, npz_fixture, read_npy, text, vltm};
use vltm::io::RowSource;
use vltm::io::ptu::{self, FollowOptions, Follower, PtuSource, Sidecar, T3WriteOptions};

const SPEC: &str = "-0.6:0.6:13,-0.1:0.1:3,0.5:1.2:8";
const FOCUS: &str = "-0.45,0,0.8";
/// The paper's dwell per laser row.
const DWELL_MS: u64 = 87;

fn ok(o: &Output) {
    assert!(
        o.status.success(),
        "vltm failed: {}\n{}",
        text(&o.stderr),
        text(&o.stdout)
    );
}

/// A failure with exit code 1 and one line on stderr, which contains every `needle`.
fn fails_with(o: &Output, needles: &[&str]) -> String {
    let err = text(&o.stderr);
    assert!(!o.status.success(), "expected a failure, got: {err}");
    let last = err
        .lines()
        .rfind(|l| l.starts_with("vltm: ") && !l.starts_with("vltm: note"));
    let line = last.unwrap_or_else(|| panic!("no error line in: {err}"));
    for n in needles {
        assert!(line.contains(n), "`{n}` not in `{line}`");
    }
    line.to_string()
}

/// The values of a `.npy` volume.
fn npy(p: &Path) -> Vec<f32> {
    read_npy(p).0
}

/// `a` equals `b` within `1e-6·max|b|`; returns how many values are bit-identical.
fn close(a: &[f32], b: &[f32], what: &str) -> usize {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    let peak = b.iter().fold(0f32, |m, x| m.max(x.abs()));
    assert!(peak > 0.0, "{what}: an empty volume proves nothing");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= 1e-6 * peak,
            "{what}: voxel {i}: live {x} vs offline {y} (peak {peak})"
        );
    }
    a.iter()
        .zip(b)
        .filter(|(x, y)| x.to_bits() == y.to_bits())
        .count()
}

/// A small PTU capture: `two_patches_single` (64 rows, one SPAD) scaled to whole photons,
/// its rows [`DWELL_MS`] apart on the sync clock, as the paper's scan.
fn make_ptu(dir: &TempDir) -> (PathBuf, PathBuf) {
    let mut c = vltm::io::open(&npz_fixture("two_patches_single")).expect("fixture");
    let max = c.data.iter().fold(0f32, |m, &x| m.max(x));
    for x in &mut c.data {
        *x = (*x / max * 400.0).round();
    }
    let p = dir.path("scan.ptu");
    let o = T3WriteOptions::default();
    // 87 ms per row on the sync clock: the gap after a row's photons (one sync each).
    let per_row = (DWELL_MS as f64 * 1e-3 / o.sync_period).round() as u64;
    let photons = (0..c.geometry.lasers.len())
        .map(|l| c.row(l).iter().map(|&x| x as u64).sum::<u64>())
        .max()
        .unwrap_or(0);
    let o = T3WriteOptions {
        syncs_between_rows: per_row - photons * u64::from(o.syncs_per_photon),
        ..o
    };
    ptu::write_t3(&c, &p, &o).expect("write ptu");
    (p.clone(), p.with_extension("json"))
}

/// The byte offsets in a PTU file where each row marker record starts, and the header's
/// length.
fn row_offsets(ptu_bytes: &[u8], side: &Path) -> (usize, Vec<usize>) {
    let sidecar = Sidecar::load(side).expect("sidecar");
    let h = ptu::Header::read(&mut &ptu_bytes[..], Path::new("scan.ptu")).expect("header");
    let start = h.data_offset as usize;
    let mut dec = ptu::Decoder::new(h.record_type);
    let bit = 1u8 << (sidecar.row_marker - 1);
    let mut rows = Vec::new();
    for (i, r) in ptu_bytes[start..].chunks_exact(4).enumerate() {
        let rec = u32::from_le_bytes([r[0], r[1], r[2], r[3]]);
        if let ptu::Decoded::Event(ptu::Event::Marker { bits, .. }) = dec.decode(rec)
            && bits & bit != 0
        {
            rows.push(start + 4 * i);
        }
    }
    (start, rows)
}

/// Where `TTResult_NumberOfRecords`'s 8-byte value sits in the header.
fn count_offset(bytes: &[u8]) -> usize {
    let name = b"TTResult_NumberOfRecords";
    let i = bytes
        .windows(name.len())
        .position(|w| w == name)
        .expect("record count tag");
    i + 32 + 4 + 4
}

/// Run by [`follows_a_ptu_file_written_by_another_process`] in a child process: writes the
/// PTU file `$VLTM_WRITER_SRC` to `$VLTM_WRITER_DST` as an acquisition does — the header with
/// a record count of 0, then each row's records `$VLTM_WRITER_DWELL_MS` after the previous
/// ones (in two writes split inside a record), the count patched in at the end — stopping
/// after `$VLTM_WRITER_ROWS` rows if set (a marker that never comes).
#[test]
#[ignore = "a helper process of follows_a_ptu_file_written_by_another_process"]
fn ptu_writer_process() {
    let Some(src) = std::env::var_os("VLTM_WRITER_SRC") else {
        return;
    };
    let dst = PathBuf::from(std::env::var_os("VLTM_WRITER_DST").expect("dst"));
    let dwell: u64 = std::env::var("VLTM_WRITER_DWELL_MS")
        .expect("dwell")
        .parse()
        .expect("dwell ms");
    let stop: Option<usize> = std::env::var("VLTM_WRITER_ROWS")
        .ok()
        .map(|s| s.parse().expect("rows"));
    let bytes = std::fs::read(&src).expect("read src");
    let side = PathBuf::from(&src).with_extension("json");
    let (start, rows) = row_offsets(&bytes, &side);
    let at = count_offset(&bytes);
    let mut header = bytes[..start].to_vec();
    header[at..at + 8].copy_from_slice(&0i64.to_le_bytes());
    let mut f = std::fs::File::create(&dst).expect("create dst");
    // The header in two pieces: the reader waits inside it too.
    f.write_all(&header[..start / 2]).expect("write");
    f.flush().expect("flush");
    std::thread::sleep(Duration::from_millis(dwell));
    f.write_all(&header[start / 2..]).expect("write");
    let mut cuts = rows.clone();
    cuts.push(bytes.len());
    let n = stop.unwrap_or(rows.len());
    for w in cuts.windows(2).take(n) {
        let (a, b) = (w[0], w[1]);
        // Split inside a record: the reader sees an incomplete record and waits.
        let mid = (a + (b - a) / 2) | 1;
        let mid = mid.min(b);
        std::thread::sleep(Duration::from_millis(dwell));
        f.write_all(&bytes[a..mid]).expect("write");
        f.flush().expect("flush");
        f.write_all(&bytes[mid..b]).expect("write");
        f.flush().expect("flush");
    }
    if stop.is_none() {
        f.seek(SeekFrom::Start(at as u64)).expect("seek");
        f.write_all(&bytes[at..at + 8]).expect("patch count");
        f.flush().expect("flush");
    }
}

/// Starts [`ptu_writer_process`] in a child process.
fn spawn_writer(src: &Path, dst: &Path, dwell_ms: u64, rows: Option<usize>) -> std::process::Child {
    let mut c = Command::new(std::env::current_exe().expect("test exe"));
    c.args(["--ignored", "--exact", "ptu_writer_process", "--nocapture"])
        .env("VLTM_WRITER_SRC", src)
        .env("VLTM_WRITER_DST", dst)
        .env("VLTM_WRITER_DWELL_MS", dwell_ms.to_string())
        .stdout(Stdio::null());
    if let Some(r) = rows {
        c.env("VLTM_WRITER_ROWS", r.to_string());
    }
    c.spawn().expect("spawn writer")
}

/// GET `path` from a server on loopback: the body, or `None` if it does not answer.
fn http_get(port: u16, path: &str) -> Option<Vec<u8>> {
    let mut s = TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    write!(s, "GET {path} HTTP/1.1\r\nHost: localhost\r\n\r\n").ok()?;
    let mut buf = Vec::new();
    s.read_to_end(&mut buf).ok()?;
    let i = buf.windows(4).position(|w| w == b"\r\n\r\n")?;
    buf[..i]
        .starts_with(b"HTTP/1.1 200")
        .then(|| buf[i + 4..].to_vec())
}

/// A free loopback port.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .expect("bind")
        .local_addr()
        .expect("addr")
        .port()
}

/// `vltm live CAP --replay-rate RATE --volume SPEC --focus FOCUS ARGS --out OUT`.
fn replay(cap: &str, rate: u32, args: &[&str], out: &Path) -> Output {
    let rate = rate.to_string();
    let mut a = vec![
        "live",
        cap,
        "--replay-rate",
        &rate,
        "--volume",
        SPEC,
        "--focus",
        FOCUS,
    ];
    a.extend(args);
    a.extend(["--out", out.to_str().expect("utf-8")]);
    vltm(&a)
}

#[test]
fn replay_matches_the_offline_commands() {
    let d = TempDir::new("live", "replay");
    let cap = npz_fixture("two_patches");
    let cap = cap.to_str().expect("utf-8");
    let out = d.path("live.npy");
    let o = replay(cap, 400, &["--every", "16"], &out);
    ok(&o);
    let err = text(&o.stderr);
    // The progress line: rows, photons/s, time per row against the dwell, ETA.
    let progress: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("live: rows"))
        .collect();
    assert!(!progress.is_empty(), "no progress line in {err}");
    assert!(
        progress.iter().all(|l| l.contains("photons/s")
            && l.contains("ms/row folded vs")
            && l.contains("ms dwell")
            && l.contains("ETA")),
        "{progress:?}"
    );
    assert!(progress.last().is_some_and(|l| l.contains("rows 64/64")));
    let offline = |args: &[&str], name: &str| {
        let p = d.path(name);
        let mut a = args.to_vec();
        a.extend(["--volume", SPEC, "--out", p.to_str().expect("utf-8")]);
        ok(&vltm(&a));
        npy(&p)
    };
    let direct = offline(&["direct", cap], "direct.npy");
    let column = offline(
        &["column", cap, "--focus", FOCUS, "--no-leak-correct"],
        "column.npy",
    );
    let indirect = offline(&["indirect", cap], "indirect.npy");
    let same = close(&npy(&out), &direct, "direct light");
    eprintln!(
        "direct light: {same} of {} voxels bit-identical",
        direct.len()
    );
    close(&npy(&d.path("live.column0.npy")), &column, "column");
    close(
        &npy(&d.path("live.indirect.npy")),
        &indirect,
        "indirect light",
    );
    // At the end the column once more, leak-corrected over the stored rows: `vltm column` at
    // its defaults; the running column (the capture as it is) differs.
    let corrected = offline(&["column", cap, "--focus", FOCUS], "corrected.npy");
    let live_corrected = npy(&d.path("live.column0.corrected.npy"));
    close(&live_corrected, &corrected, "leak-corrected column");
    assert!(
        column.iter().sum::<f32>() > 2.0 * live_corrected.iter().sum::<f32>(),
        "the running column is not corrected"
    );
    assert!(
        text(&o.stdout).contains("column0: peak") && text(&o.stdout).contains("not leak-corrected"),
        "{}",
        text(&o.stdout)
    );
    for f in [
        "live.png",
        "live.column0.png",
        "live.column0.corrected.png",
        "live.indirect.png",
        "live.transient.png",
        "live.direct.part",
        "live.column0.part",
    ] {
        assert!(d.path(f).is_file(), "{f} missing");
    }
    // The final states are complete: `vltm merge` finishes them into the same volume.
    let merged = d.path("merged.npy");
    ok(&vltm(&[
        "merge",
        d.path("live.direct.part").to_str().expect("utf-8"),
        "--out",
        merged.to_str().expect("utf-8"),
    ]));
    assert_eq!(npy(&merged), npy(&out));
    // A second run onto the same states is refused (they would be replaced by fewer rows).
    let again = vltm(&[
        "live",
        cap,
        "--replay-rate",
        "400",
        "--volume",
        SPEC,
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    fails_with(&again, &["live.direct.part exists", "--resume"]);
}

/// `--leak-correct model`: at the end, the in-focus indirect light and the corrected column
/// run on the stored rows minus the surface model, as `vltm indirect` and `vltm column` with
/// `--leak-correct model` compute them on the finished file, and the run says so; a capture
/// the model cannot explain (three point scatterers) falls back to the windows with the
/// offline commands' warning and their results.
#[test]
fn replay_with_the_surface_model_matches_the_offline_commands() {
    for (name, used) in [("two_patches", true), ("three_points", false)] {
        let d = TempDir::new("live", &format!("model_{name}"));
        let cap = npz_fixture(name);
        let cap = cap.to_str().expect("utf-8");
        let o = replay(cap, 2000, &["--leak-correct", "model"], &d.path("live.npy"));
        ok(&o);
        let (stdout, stderr) = (text(&o.stdout), text(&o.stderr));
        let offline = |args: &[&str], file: &str| {
            let p = d.path(file);
            let mut a = args.to_vec();
            a.extend(["--volume", SPEC, "--leak-correct", "model"]);
            a.extend(["--out", p.to_str().expect("utf-8")]);
            ok(&vltm(&a));
            npy(&p)
        };
        let indirect = offline(&["indirect", cap], "indirect.npy");
        let column = offline(&["column", cap, "--focus", FOCUS], "column.npy");
        let live_indirect = npy(&d.path("live.indirect.npy"));
        if indirect.iter().any(|x| *x != 0.0) {
            close(
                &live_indirect,
                &indirect,
                &format!("{name}: indirect light"),
            );
        } else {
            // Three points leave no pair of Γ outside the windows: both are empty.
            assert_eq!(live_indirect, indirect, "{name}: indirect light");
        }
        close(
            &npy(&d.path("live.column0.corrected.npy")),
            &column,
            &format!("{name}: corrected column"),
        );
        if used {
            assert!(
                stdout.contains("leak correction (--leak-correct model): the surface model"),
                "{name}: {stdout}"
            );
            // The model's result is not the windows' (the comparison above has teeth).
            let gate = d.path("gate.npy");
            ok(&vltm(&[
                "indirect",
                cap,
                "--volume",
                SPEC,
                "--out",
                gate.to_str().expect("utf-8"),
            ]));
            let (g, m) = (npy(&gate), indirect);
            let peak = m.iter().fold(0f32, |a, x| a.max(x.abs()));
            assert!(
                g.iter().zip(&m).any(|(a, b)| (a - b).abs() > 1e-3 * peak),
                "{name}: the model's indirect light equals the windows'"
            );
        } else {
            assert!(
                stderr.contains("leak correction: the surface model explains")
                    && stderr.contains("using the time windows (--leak-correct gate)"),
                "{name}: {stderr}"
            );
        }
    }
}

#[test]
fn follows_a_ptu_file_written_by_another_process() {
    let d = TempDir::new("live", "follow");
    let (src, side) = make_ptu(&d);
    let live_ptu = d.path("acq.ptu");
    std::fs::copy(&side, live_ptu.with_extension("json")).expect("sidecar");
    let mut writer = spawn_writer(&src, &live_ptu, DWELL_MS, None);
    // The file appears when the writer starts.
    let t = Instant::now();
    while !live_ptu.exists() && t.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(5));
    }
    let port = free_port();
    let out = d.path("live.npy");
    let child = Command::new(support::vltm_bin())
        .args([
            "live",
            live_ptu.to_str().expect("utf-8"),
            "--volume",
            SPEC,
            "--focus",
            FOCUS,
            "--every",
            "8",
            "--no-indirect",
            "--serve",
            &port.to_string(),
            "--linger",
            "1",
            "--out",
            out.to_str().expect("utf-8"),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn vltm live");
    // The served status advances while the file grows.
    let mut seen = Vec::new();
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(60) {
        if let Some(b) = http_get(port, "/status.json") {
            let v: serde_json::Value = serde_json::from_slice(&b).expect("status json");
            let rows = v["rows"].as_u64().unwrap_or(0);
            if seen.last() != Some(&rows) {
                seen.push(rows);
            }
            if v["done"].as_bool() == Some(true) {
                break;
            }
            if rows > 0 {
                assert!(
                    http_get(port, "/png/direct.png").is_some_and(|p| p.starts_with(b"\x89PNG")),
                    "no figure served"
                );
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let o = child.wait_with_output().expect("vltm live");
    assert!(writer.wait().expect("writer").success());
    ok(&o);
    let partway: Vec<_> = seen.iter().filter(|&&r| r > 0 && r < 64).collect();
    assert!(
        partway.len() >= 3,
        "the rows should appear while the file is written: {seen:?}"
    );
    assert_eq!(seen.last(), Some(&64), "{seen:?}");
    // The progress line shows the dwell read from the sync clock: 87 ms per row.
    let err = text(&o.stderr);
    let last = err.lines().rfind(|l| l.starts_with("live: rows"));
    let dwell: f64 = last
        .and_then(|l| l.split(" vs ").nth(1))
        .and_then(|l| l.split(" ms dwell").next())
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no dwell in {last:?}"));
    assert!(
        (dwell - DWELL_MS as f64).abs() < 2.0,
        "dwell {dwell} ms: {last:?}"
    );
    eprintln!("followed at {DWELL_MS} ms per row: {last:?}; rows seen by the server: {seen:?}");
    // The finished file, offline.
    let p = |n: &str| d.path(n).to_str().expect("utf-8").to_string();
    let f = live_ptu.to_str().expect("utf-8");
    ok(&vltm(&[
        "direct",
        f,
        "--volume",
        SPEC,
        "--out",
        &p("d.npy"),
    ]));
    ok(&vltm(&[
        "column",
        f,
        "--focus",
        FOCUS,
        "--volume",
        SPEC,
        "--no-leak-correct",
        "--out",
        &p("c.npy"),
    ]));
    close(&npy(&out), &npy(&d.path("d.npy")), "direct light");
    close(
        &npy(&d.path("live.column0.npy")),
        &npy(&d.path("c.npy")),
        "column",
    );
    assert_eq!(
        std::fs::read(&live_ptu).expect("read"),
        std::fs::read(&src).expect("read"),
        "the writer wrote the file"
    );
}

#[test]
fn a_marker_that_never_comes_keeps_the_rows_before_it_and_resumes() {
    let d = TempDir::new("live", "never");
    let (src, side) = make_ptu(&d);
    let live_ptu = d.path("acq.ptu");
    std::fs::copy(&side, live_ptu.with_extension("json")).expect("sidecar");
    // The writer stops after 40 rows: the 41st row marker never comes.
    let mut writer = spawn_writer(&src, &live_ptu, 5, Some(40));
    let t = Instant::now();
    while !live_ptu.exists() && t.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(5));
    }
    let out = d.path("live.npy");
    let o = vltm(&[
        "live",
        live_ptu.to_str().expect("utf-8"),
        "--volume",
        SPEC,
        "--every",
        "16",
        "--idle-timeout",
        "1.5",
        "--no-indirect",
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    assert!(writer.wait().expect("writer").success());
    let line = fails_with(
        &o,
        &[
            "acq.ptu",
            "markers",
            "64 row markers",
            "stopped growing",
            "byte",
        ],
    );
    assert!(line.contains("40 before"), "{line}");
    let state = d.path("live.direct.part");
    let part = vltm::probe::Partial::read(&state).expect("the last good state is kept");
    assert_eq!(part.rows(), vec![0..39], "rows whose end marker came");
    // The acquisition goes on (the whole file now): resume from the state.
    std::fs::copy(&src, &live_ptu).expect("finish the file");
    let o = vltm(&[
        "live",
        live_ptu.to_str().expect("utf-8"),
        "--volume",
        SPEC,
        "--every",
        "16",
        "--no-indirect",
        "--resume",
        state.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    ok(&o);
    assert!(text(&o.stdout).contains("resuming with 39 of 64 rows"));
    let off = d.path("d.npy");
    ok(&vltm(&[
        "direct",
        live_ptu.to_str().expect("utf-8"),
        "--volume",
        SPEC,
        "--out",
        off.to_str().expect("utf-8"),
    ]));
    close(&npy(&out), &npy(&off), "resumed direct light");
    // A state of another configuration is refused, naming it.
    let o = vltm(&[
        "live",
        live_ptu.to_str().expect("utf-8"),
        "--volume",
        "-0.6:0.6:7,-0.1:0.1:3,0.5:1.2:8",
        "--no-indirect",
        "--resume",
        state.to_str().expect("utf-8"),
        "--out",
        d.path("other.npy").to_str().expect("utf-8"),
    ]);
    fails_with(
        &o,
        &[
            "--resume",
            "live.direct.part",
            "not a state of this capture",
        ],
    );
}

#[test]
fn bad_streams_fail_with_one_line_naming_the_position() {
    let d = TempDir::new("live", "bad");
    let (src, side) = make_ptu(&d);
    let bytes = std::fs::read(&src).expect("read");
    let (_, rows) = row_offsets(&bytes, &side);
    let side_s = side.to_str().expect("utf-8");
    let out = d.path("o.npy");
    let out_s = out.to_str().expect("utf-8");
    // A pipe that stops mid-record, after 10 rows.
    let cut = rows[10] + 2;
    let mut child = Command::new(support::vltm_bin())
        .args([
            "live",
            "-",
            "--sidecar",
            side_s,
            "--volume",
            SPEC,
            "--every",
            "4",
            "--no-indirect",
            "--out",
            out_s,
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(&bytes[..cut])
        .expect("pipe");
    let o = child.wait_with_output().expect("wait");
    fails_with(
        &o,
        &[
            "<stdin>",
            "records",
            "partial record of 2 bytes",
            &format!("byte {}", cut - 2),
        ],
    );
    // The 9 rows closed by a row marker are kept as a state.
    let part = vltm::probe::Partial::read(&d.path("o.direct.part")).expect("state kept");
    assert_eq!(part.rows(), vec![0..9]);
    // A header that is not T3 (a T2 record type).
    let mut t2 = bytes.clone();
    let name = b"TTResultFormat_TTTRRecType";
    let i = t2
        .windows(name.len())
        .position(|w| w == name)
        .expect("record type tag")
        + 40;
    t2[i..i + 8].copy_from_slice(&0x0101_0204i64.to_le_bytes());
    let bad = d.path("t2.ptu");
    std::fs::write(&bad, &t2).expect("write");
    std::fs::copy(&side, bad.with_extension("json")).expect("sidecar");
    let o = vltm(&[
        "live",
        bad.to_str().expect("utf-8"),
        "--volume",
        SPEC,
        "--out",
        d.path("t2.npy").to_str().expect("utf-8"),
    ]);
    fails_with(&o, &["t2.ptu", "TTResultFormat_TTTRRecType"]);
    assert!(!d.path("t2.npy").exists() && !d.path("t2.direct.part").exists());
    // A port in use.
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = l.local_addr().expect("addr").port();
    let o = vltm(&[
        "live",
        src.to_str().expect("utf-8"),
        "--volume",
        SPEC,
        "--serve",
        &port.to_string(),
        "--out",
        d.path("p.npy").to_str().expect("utf-8"),
    ]);
    fails_with(&o, &["--serve", &format!("127.0.0.1:{port}")]);
    drop(l);
}

/// The follower over a finished stream gives [`PtuSource`]'s rows; every truncation of the
/// stream is an error naming the position, never a panic or a wrong row.
#[test]
fn follower_equals_ptu_source_and_truncations_fail_cleanly() {
    let d = TempDir::new("live", "follower");
    let (src, side) = make_ptu(&d);
    let bytes = std::fs::read(&src).expect("read");
    let sc = Sidecar::load(&side).expect("sidecar");
    let mut a = PtuSource::open(&src, &side).expect("open");
    let mut f = Follower::stream(
        Box::new(std::io::Cursor::new(bytes.clone())),
        Path::new("s"),
        sc.clone(),
        &side,
        FollowOptions::default(),
    )
    .expect("follower");
    let mut row = Vec::new();
    for l in 0..a.geometry().lasers.len() {
        a.read_row(l, &mut row).expect("row");
        let r = f.next_row().expect("row").expect("a row");
        assert_eq!((r.index, &r.data), (l, &row));
        assert!(r.seconds.is_some_and(|s| s > 0.0));
    }
    assert!(f.next_row().expect("end").is_none());
    assert_eq!(f.counts().binned, a.counts().binned);
    // Truncations at 97 positions across the file.
    let (start, _) = row_offsets(&bytes, &side);
    let mut cut = 1;
    while cut < bytes.len() {
        let mut b = bytes[..cut].to_vec();
        // The count says 0 (a stream): the end of the pipe ends it.
        if cut > start {
            let at = count_offset(&b);
            b[at..at + 8].copy_from_slice(&0i64.to_le_bytes());
        }
        let r = Follower::stream(
            Box::new(std::io::Cursor::new(b)),
            Path::new("s"),
            sc.clone(),
            &side,
            FollowOptions::default(),
        );
        if let Ok(mut f) = r {
            let mut n = 0;
            let e = loop {
                match f.next_row() {
                    Ok(Some(_)) => n += 1,
                    Ok(None) => break None,
                    Err(e) => break Some(e),
                }
            };
            if let Some(e) = e {
                let m = e.to_string();
                assert!(m.contains("byte"), "cut {cut}: {m}");
            } else {
                assert_eq!(n, 64, "cut {cut} ended cleanly with {n} rows");
            }
        }
        cut += bytes.len() / 97 + 1;
    }
}

/// Follows `bytes` as a pipe, passing over rows `0..skip`: the rows it hands out.
fn follow_bytes(bytes: &[u8], side: &Path, skip: usize) -> (Vec<ptu::FollowedRow>, ptu::Counts) {
    let sc = Sidecar::load(side).expect("sidecar");
    let mut f = Follower::stream(
        Box::new(std::io::Cursor::new(bytes.to_vec())),
        Path::new("s"),
        sc,
        side,
        FollowOptions::default(),
    )
    .expect("follower");
    f.skip_rows(skip);
    let mut rows = Vec::new();
    while let Some(r) = f.next_row().expect("row") {
        rows.push(r);
    }
    (rows, f.counts())
}

/// A resumed run passes over the rows its states hold: the follower hands out the same rows
/// after them as without skipping, and counts the photons it passed over; `vltm live` on a
/// file resumed from `--partial` states of rows 0:20 (made from the finished file: its size
/// in their identity, where the followed file's states say 0) passes over those rows, reads
/// them again for the in-focus indirect light at the end, and equals the offline commands.
#[test]
fn resume_passes_over_the_rows_the_states_hold() {
    let d = TempDir::new("live", "skip");
    let (src, side) = make_ptu(&d);
    let bytes = std::fs::read(&src).expect("read");
    let (all, c0) = follow_bytes(&bytes, &side, 0);
    let (rest, c) = follow_bytes(&bytes, &side, 20);
    assert_eq!(all.len(), 64);
    assert_eq!(rest.len(), 44);
    assert_eq!(rest[0].index, 20);
    for (a, b) in all[20..].iter().zip(&rest) {
        assert_eq!((a.index, &a.data, a.photons), (b.index, &b.data, b.photons));
    }
    let before: u64 = all[..20].iter().map(|r| r.photons).sum();
    assert!(before > 0);
    assert_eq!(c.skipped_rows, before, "the photons passed over");
    assert_eq!(c.binned + c.skipped_rows, c0.binned);
    // The CLI: states of rows 0:20 from the finished file, then live on it.
    let f = src.to_str().expect("utf-8");
    let p = |n: &str| d.path(n).to_str().expect("utf-8").to_string();
    ok(&vltm(&[
        "direct",
        f,
        "--volume",
        SPEC,
        "--rows",
        "0:20",
        "--partial",
        &p("d.part"),
    ]));
    ok(&vltm(&[
        "column",
        f,
        "--focus",
        FOCUS,
        "--volume",
        SPEC,
        "--no-leak-correct",
        "--rows",
        "0:20",
        "--partial",
        &p("c.part"),
    ]));
    let out = d.path("live.npy");
    let o = vltm(&[
        "live",
        f,
        "--volume",
        SPEC,
        "--focus",
        FOCUS,
        "--every",
        "0",
        "--resume",
        &p("d.part"),
        "--resume",
        &p("c.part"),
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    ok(&o);
    assert!(
        text(&o.stdout).contains("resuming with 20 of 64 rows"),
        "{}",
        text(&o.stdout)
    );
    // The first progress line comes after 44 rows at most: rows 0:20 were not folded again.
    let offline = |args: &[&str], name: &str| {
        let mut a = args.to_vec();
        let q = p(name);
        a.extend(["--volume", SPEC, "--out", &q]);
        ok(&vltm(&a));
        npy(&d.path(name))
    };
    close(
        &npy(&out),
        &offline(&["direct", f], "od.npy"),
        "resumed direct light",
    );
    close(
        &npy(&d.path("live.column0.npy")),
        &offline(
            &["column", f, "--focus", FOCUS, "--no-leak-correct"],
            "oc.npy",
        ),
        "resumed column",
    );
    close(
        &npy(&d.path("live.indirect.npy")),
        &offline(&["indirect", f], "oi.npy"),
        "in-focus indirect light of a resumed run (rows 0:20 read again)",
    );
    let merged = vltm::probe::Partial::read(&d.path("live.direct.part")).expect("state");
    assert_eq!(merged.rows(), vec![0..64]);
}

/// Standard input that stops sending without closing: `--idle-timeout` ends it, with one
/// line naming `<stdin>` and the byte position, and the rows before it kept as states; the
/// whole stream then resumes from them (the rows the states hold passed over unbinned).
#[test]
fn stdin_that_stops_sending_times_out_and_resumes() {
    let d = TempDir::new("live", "stdin-idle");
    let (src, side) = make_ptu(&d);
    let bytes = std::fs::read(&src).expect("read");
    let (_, rows) = row_offsets(&bytes, &side);
    let at = count_offset(&bytes);
    let mut head = bytes.clone();
    head[at..at + 8].copy_from_slice(&0i64.to_le_bytes());
    let out = d.path("live.npy");
    let args = |extra: &[&str]| {
        let mut a = vec![
            "live".to_string(),
            "-".into(),
            "--sidecar".into(),
            side.to_str().expect("utf-8").into(),
            "--volume".into(),
            SPEC.into(),
            "--no-indirect".into(),
            "--every".into(),
            "8".into(),
            "--out".into(),
            out.to_str().expect("utf-8").into(),
        ];
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let mut child = Command::new(support::vltm_bin())
        .args(args(&["--idle-timeout", "1"]))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let mut stdin = child.stdin.take().expect("stdin");
    // The header and 30 rows (up to the 31st row marker, which closes row 29), then silence.
    stdin.write_all(&head[..rows[30] + 4]).expect("write");
    stdin.flush().expect("flush");
    let t = Instant::now();
    let o = loop {
        if let Some(_s) = child.try_wait().expect("wait") {
            break child.wait_with_output().expect("output");
        }
        assert!(
            t.elapsed() < Duration::from_secs(60),
            "vltm live did not give up on a silent pipe"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    drop(stdin);
    let line = fails_with(
        &o,
        &[
            "<stdin>",
            "stream sent nothing for 1.0 s",
            "byte",
            "markers",
        ],
    );
    assert!(line.contains("31 before"), "{line}");
    assert!(
        line.contains(&format!("at byte {}", rows[30] + 4)),
        "{line}"
    );
    let state = d.path("live.direct.part");
    let part = vltm::probe::Partial::read(&state).expect("the last good state is kept");
    assert_eq!(part.rows(), vec![0..30]);
    // The relay sends the whole stream again: resume.
    let mut child = Command::new(support::vltm_bin())
        .args(args(&["--resume", state.to_str().expect("utf-8")]))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let mut stdin = child.stdin.take().expect("stdin");
    stdin.write_all(&head).expect("write");
    drop(stdin);
    let o = child.wait_with_output().expect("output");
    ok(&o);
    assert!(text(&o.stdout).contains("resuming with 30 of 64 rows"));
    let off = d.path("d.npy");
    ok(&vltm(&[
        "direct",
        src.to_str().expect("utf-8"),
        "--volume",
        SPEC,
        "--out",
        off.to_str().expect("utf-8"),
    ]));
    close(
        &npy(&out),
        &npy(&off),
        "direct light resumed from standard input",
    );
}

/// The probes' window rule: a volume with no path in the capture's window is the same one
/// line as `vltm direct`'s; one with few paths in it warns as `direct` does.
#[test]
fn live_applies_the_window_rule_of_every_probe() {
    let d = TempDir::new("live", "window");
    let cap = npz_fixture("two_patches");
    let cap = cap.to_str().expect("utf-8");
    let far = "-0.2:0.2:3,-0.2:0.2:3,30:31:2";
    let o = vltm(&[
        "direct",
        cap,
        "--volume",
        far,
        "--out",
        d.path("d.npy").to_str().expect("utf-8"),
    ]);
    let want = fails_with(&o, &["volume", "no path through the probed points"]);
    let o = vltm(&[
        "live",
        cap,
        "--replay-rate",
        "1000",
        "--volume",
        far,
        "--out",
        d.path("l.npy").to_str().expect("utf-8"),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert_eq!(fails_with(&o, &[]), want, "live and direct say the same");
    assert!(!d.path("l.npy").exists() && !d.path("l.direct.part").exists());
    // One voxel of six in the window: live runs and warns as direct does.
    let pts = "-0.45,0,0.8;0,0,30;0,0,31;0,0,32;0,0,33;0,0,34";
    let o = vltm(&[
        "direct",
        cap,
        "--volume",
        pts,
        "--out",
        d.path("d.npy").to_str().expect("utf-8"),
    ]);
    ok(&o);
    let warn = |o: &Output| {
        text(&o.stderr)
            .lines()
            .find(|l| l.starts_with("vltm: warning: only"))
            .map(str::to_string)
    };
    let want = warn(&o).expect("direct warns");
    let o = vltm(&[
        "live",
        cap,
        "--replay-rate",
        "1000",
        "--no-indirect",
        "--volume",
        pts,
        "--out",
        d.path("l.npy").to_str().expect("utf-8"),
    ]);
    ok(&o);
    assert_eq!(warn(&o), Some(want), "{}", text(&o.stderr));
}

/// The firmware's voxels (`vltm-firmware-gen volume`), focus and wavelength.
const FW_VOLUME: &str = "-0.225,-0.225,0.5;-0.075,-0.225,0.5;0.075,-0.225,0.5;0.225,-0.225,0.5;\
-0.225,-0.075,0.5;-0.075,-0.075,0.5;0.075,-0.075,0.5;0.225,-0.075,0.5;-0.225,0.075,0.5;\
-0.075,0.075,0.5;0.075,0.075,0.5;0.225,0.075,0.5;-0.225,0.225,0.5;-0.075,0.225,0.5;\
0.075,0.225,0.5;0.225,0.225,0.5;-0.075,-0.075,0.35;-0.075,-0.075,0.65";
const FW_FOCUS: &str = "-0.075,-0.075,0.5";

/// The states the QEMU firmware wrote after folding the scan's last rows (8..16) of
/// `kernel/firmware/fixture/scene.json`'s capture (`fixtures/firmware/`): `vltm live` on that
/// capture resumes from them, folds rows 0..8 itself, and equals the offline commands within
/// the kernel's f32 tolerance (10⁻⁶ of the peak); a state of another capture or other
/// parameters is refused with one line naming the field.
#[test]
fn resumes_from_the_firmwares_state() {
    let d = TempDir::new("live", "firmware");
    let scene = support::repo_root().join("kernel/firmware/fixture/scene.json");
    let cap = d.path("scene.npz");
    let c = cap.to_str().expect("utf-8");
    ok(&vltm(&[
        "simulate",
        scene.to_str().expect("utf-8"),
        "--out",
        c,
        "--uncompressed",
    ]));
    let fw = |n: &str| support::fixture(&format!("firmware/{n}"));
    let (fd, fc) = (fw("fw_direct.vltmpart"), fw("fw_column.vltmpart"));
    let held = vltm::probe::Partial::read(&fd).expect("firmware state");
    assert_eq!(
        held.rows(),
        vec![8..16],
        "the firmware folds the scan's last rows"
    );
    let p = |n: &str| d.path(n).to_str().expect("utf-8").to_string();
    let live = |cap: &str, extra: &[&str], out: &str| {
        let mut a = vec![
            "live",
            cap,
            "--replay-rate",
            "1000",
            "--volume",
            FW_VOLUME,
            "--wavelength",
            "0.1",
            "--focus",
            FW_FOCUS,
            "--resume",
            fd.to_str().expect("utf-8"),
            "--resume",
            fc.to_str().expect("utf-8"),
        ];
        a.extend(extra);
        let out = p(out);
        a.extend(["--out", &out]);
        vltm(&a)
    };
    let o = live(c, &[], "live.npy");
    ok(&o);
    assert!(
        text(&o.stdout).contains("resuming with 8 of 16 rows"),
        "{}",
        text(&o.stdout)
    );
    let offline = |args: &[&str], name: &str| {
        let mut a = args.to_vec();
        let q = p(name);
        a.extend(["--volume", FW_VOLUME, "--wavelength", "0.1", "--out", &q]);
        ok(&vltm(&a));
        npy(&d.path(name))
    };
    close(
        &npy(&d.path("live.npy")),
        &offline(&["direct", c], "d.npy"),
        "direct light",
    );
    close(
        &npy(&d.path("live.column0.npy")),
        &offline(
            &["column", c, "--focus", FW_FOCUS, "--no-leak-correct"],
            "c.npy",
        ),
        "column",
    );
    close(
        &npy(&d.path("live.indirect.npy")),
        &offline(&["indirect", c], "i.npy"),
        "in-focus indirect light",
    );
    // The final states hold every row: the firmware's and the host's.
    let s = vltm::probe::Partial::read(&d.path("live.direct.part")).expect("state");
    assert_eq!(s.rows(), vec![0..16]);
    // Another capture, other parameters: one line naming the field.
    let other = npz_fixture("two_patches");
    let o = live(other.to_str().expect("utf-8"), &[], "x.npy");
    fails_with(
        &o,
        &[
            "--resume",
            "fw_direct.vltmpart",
            "different captures",
            "capture.",
        ],
    );
    let o = live(c, &["--sigma", "0.08"], "y.npy");
    fails_with(
        &o,
        &["--resume", "fw_direct.vltmpart", "sigma: 0.08 vs null"],
    );
    assert!(!d.path("y.npy").exists() && !d.path("y.direct.part").exists());
}
