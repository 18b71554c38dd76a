//! Progress of the long stages on stderr (`--progress`, `VLTM_PROGRESS_INTERVAL_MS`): off a
//! terminal `indirect` prints plain lines for its rows and its column stage, never on stdout;
//! `--progress none` prints none. The plain printer's throttle and the stage bookkeeping have
//! unit tests in `host/cli/src/progress.rs`.

mod support;

use std::process::{Command, Output};

/// A 15 × 15 × 9 volume in front of the panels of `panel_figure_all`.
const SPEC: &str = "-0.7:0.7:15,-0.5:0.5:15,0.6:1.2:9";

/// `vltm indirect` on the path-traced panels, stderr piped, with `--progress mode` and
/// a plain line at every step (interval 0, from the start: a stage shorter than any interval
/// still shows).
fn indirect(mode: &str, test: &str) -> Output {
    let dir = std::env::temp_dir().join(format!("vltm-progress-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let capture = support::fixture("pathtraced/panel_figure_all/panel_figure_all.hdf5");
    let o = Command::new(support::vltm_bin())
        .env("VLTM_PROGRESS_INTERVAL_MS", "0")
        .arg("indirect")
        .arg(&capture)
        .args(["--volume", SPEC, "--progress", mode, "--out"])
        .arg(dir.join("ind.npy"))
        .output()
        .expect("run vltm");
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        o.status.success(),
        "vltm indirect failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// The progress lines of `stage` in `text`: `vltm: <stage> N/M (P %)…`, with N ≤ M.
fn lines<'t>(text: &'t str, stage: &str) -> Vec<&'t str> {
    let head = format!("vltm: {stage} ");
    text.lines()
        .filter(|l| {
            l.strip_prefix(&head)
                .and_then(|rest| rest.split_whitespace().next())
                .and_then(|frac| frac.split_once('/'))
                .and_then(|(n, m)| Some((n.parse::<u64>().ok()?, m.parse::<u64>().ok()?)))
                .is_some_and(|(n, m)| n <= m && m > 0)
        })
        .collect()
}

#[test]
fn indirect_off_a_terminal_prints_plain_lines_for_its_stages_on_stderr() {
    for mode in ["auto", "plain"] {
        let o = indirect(mode, mode);
        let err = String::from_utf8_lossy(&o.stderr);
        let out = String::from_utf8_lossy(&o.stdout);
        for stage in ["indirect", "indirect: columns", "indirect: pair sums"] {
            assert!(
                !lines(&err, stage).is_empty(),
                "--progress {mode}: no progress line for `{stage}` on stderr:\n{err}"
            );
            assert!(
                lines(&out, stage).is_empty(),
                "--progress {mode}: progress on stdout:\n{out}"
            );
        }
        // The summary stays on stdout.
        assert!(out.contains("indirect: "), "summary missing:\n{out}");
    }
}

#[test]
fn progress_none_prints_no_progress() {
    let o = indirect("none", "none");
    let err = String::from_utf8_lossy(&o.stderr);
    for stage in [
        "indirect",
        "indirect: columns",
        "indirect: pair sums",
        "leak fit",
    ] {
        assert!(
            lines(&err, stage).is_empty(),
            "--progress none printed progress for `{stage}`:\n{err}"
        );
    }
}

#[test]
fn a_bad_progress_mode_is_one_error_line() {
    let o = Command::new(support::vltm_bin())
        .args(["info", "--progress", "loud"])
        .output()
        .expect("run vltm");
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("--progress"), "{err}");
}
