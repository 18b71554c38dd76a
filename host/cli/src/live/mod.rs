//! `vltm live`: follow a scan while it is acquired (a PTU file still being written, a T3
//! stream on standard input, or any capture replayed at a fixed rate), fold its rows into
//! the direct light and the `--focus` columns as they arrive, write snapshots every
//! `--every` rows, the in-focus indirect light at the end, and optionally serve a live page
//! (`--serve`, module `serve`). The domain logic is `vltm::live`.

mod serve;

use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use vltm::exec::EvalPath;
use vltm::io::{self, ptu};
use vltm::live::{self, LiveOptions, LiveRun, LiveSource, Outputs, Update};
use vltm::probe::{self, IndirectOptions, LeakOptions, ModelOptions, Partial};
use vltm::volume::{Volume, parse_point};

use crate::args::LiveArgs;
use crate::args::{LeakArg, PathArg};
use crate::console::{Failure, say};
use crate::open;
use crate::outputs::{Out, prepare_output, refuse_overwriting_inputs, same_file};

/// Where the rows come from.
enum Kind {
    Follow(PathBuf),
    Stdin(PathBuf),
    Replay(f64),
}

/// The progress line: rows done, photons per second, time per row against the dwell, ETA.
struct Progress {
    start: Instant,
    tty: bool,
}

impl Progress {
    fn line(&self, run: &LiveRun, fold: (f64, usize)) -> String {
        let el = self.start.elapsed().as_secs_f64().max(1e-9);
        let (done, total) = (run.folded(), run.total_rows());
        let per_row = if fold.1 > 0 {
            fold.0 / fold.1 as f64
        } else {
            0.0
        };
        // The dwell from the source (sync clock, replay rate), else the arrival interval of
        // the rows that arrived in this run (not those a resumed run passed over).
        let arrived = run.received().saturating_sub(run.stored_from());
        let arrival = el / arrived.max(1) as f64;
        let dwell = run.dwell().unwrap_or(arrival);
        // Rows come no faster than they are acquired, nor than they arrive.
        let pace = dwell.max(arrival);
        let left = total.saturating_sub(run.received()) as f64;
        let eta = left * pace.max(per_row) + run.pending() as f64 * per_row;
        format!(
            "live: rows {done}/{total}, {:.3e} photons/s, {:.1} ms/row folded vs {:.1} ms dwell{}, ETA {:.1} s",
            run.photons() / el,
            per_row * 1e3,
            dwell * 1e3,
            if per_row > pace {
                " (falling behind)"
            } else {
                ""
            },
            eta
        )
    }

    fn show(&self, s: &str) {
        if self.tty {
            eprint!("\r\x1b[2K{s}");
        } else {
            eprintln!("{s}");
        }
    }
}

fn status_json(run: &LiveRun, line: &str, views: &[live::View], done: bool) -> serde_json::Value {
    let probes: Vec<serde_json::Value> = views
        .iter()
        .map(|v| {
            serde_json::json!({
                "tag": v.tag,
                "title": v.title,
                "peak": v.peak.0,
                "peak_at": v.peak.1,
            })
        })
        .collect();
    serde_json::json!({
        "rows": run.folded(),
        "received": run.received(),
        "total": run.total_rows(),
        "photons": run.photons(),
        "transient": run.transient().iter().any(|&x| x > 0.0),
        "line": line,
        "done": done,
        "probes": probes,
    })
}

/// Runs `vltm live`.
pub(crate) fn run(a: LiveArgs) -> Result<(), Failure> {
    let volume = Volume::parse(&a.volume)?;
    let mut focus = Vec::new();
    for f in &a.focus {
        let p = parse_point("--focus", f)?;
        probe::check_focus(p)?;
        focus.push(p);
    }
    if !(a.idle_timeout.is_finite() && a.idle_timeout > 0.0) {
        return Err(vltm::Error::arg(
            "--idle-timeout",
            format!("expected seconds > 0, found {}", a.idle_timeout),
        )
        .into());
    }
    if !(a.linger.is_finite() && a.linger >= 0.0) {
        return Err(vltm::Error::arg(
            "--linger",
            format!("expected seconds >= 0, found {}", a.linger),
        )
        .into());
    }
    if !(0.0..1.0).contains(&a.epsilon) {
        return Err(vltm::Error::arg(
            "--epsilon",
            format!("expected 0 <= E < 1, found {}", a.epsilon),
        )
        .into());
    }
    let is_ptu = io::extension(&a.source).as_deref() == Some("ptu");
    let stdin = a.source.as_os_str() == "-";
    let kind = match (a.replay_rate, stdin, is_ptu) {
        (Some(r), false, _) => Kind::Replay(r),
        (Some(_), true, _) => {
            return Err(vltm::Error::arg(
                "--replay-rate",
                "standard input is followed as it comes: replay a capture file",
            )
            .into());
        }
        (None, true, _) => Kind::Stdin(a.sidecar.clone().ok_or_else(|| {
            vltm::Error::arg(
                "--sidecar",
                "a T3 stream on standard input needs its sidecar: --sidecar F.json",
            )
        })?),
        (None, false, true) => Kind::Follow(
            a.sidecar
                .clone()
                .unwrap_or_else(|| a.source.with_extension("json")),
        ),
        (None, false, false) => {
            return Err(vltm::Error::arg(
                "--replay-rate",
                format!(
                    "{} is not a PTU stream: replay it with --replay-rate ROWS/s",
                    a.source.display()
                ),
            )
            .into());
        }
    };
    let outputs = Outputs { out: a.out.clone() };
    let mut tags = vec!["direct".to_string()];
    tags.extend((0..focus.len()).map(|i| format!("column{i}")));
    if !a.no_indirect {
        tags.push("indirect".into());
        if a.leak.method().is_some() {
            // The columns once more at the end, leak-corrected over the stored rows.
            tags.extend((0..focus.len()).map(|i| format!("column{i}.corrected")));
        }
    }
    let tag_refs: Vec<&str> = tags.iter().map(String::as_str).collect();
    let all = outputs.all(&tag_refs);
    // Inputs are never outputs (a resumed state is replaced by the run that continues it,
    // but it may not be one of the other outputs).
    let mut inputs: Vec<PathBuf> = Vec::new();
    for r in &a.resume {
        if let Some(o) = all.iter().find(|o| same_file(r, o))
            && !tag_refs.iter().any(|t| same_file(&outputs.state(t), o))
        {
            return Err(vltm::Error::arg(
                "--resume",
                format!(
                    "{} is an output of this run, not a partial state",
                    o.display()
                ),
            )
            .into());
        }
    }
    if !stdin {
        inputs.push(a.source.clone());
    }
    if let Kind::Follow(s) | Kind::Stdin(s) = &kind {
        inputs.push(s.clone());
    }
    let outs: Vec<&Path> = all.iter().map(PathBuf::as_path).collect();
    refuse_overwriting_inputs(&inputs, &outs)?;
    prepare_output(&a.out, Out::Volume)?;
    // A state on disk is only replaced by this run's when this run continues it.
    for t in &tag_refs {
        let p = outputs.state(t);
        if p.exists() && !a.resume.iter().any(|r| same_file(r, &p)) {
            let held = Partial::read(&p).map_or_else(
                |_| "unreadable".to_string(),
                |s| format!("rows {:?} of {}", s.rows(), s.total_rows()),
            );
            return Err(vltm::Error::arg(
                "--out",
                format!(
                    "{} exists ({held}): continue that run with --resume, or remove it or choose another --out",
                    p.display()
                ),
            )
            .into());
        }
    }
    let mut resume = Vec::new();
    for r in &a.resume {
        resume.push((r.clone(), Partial::read(r)?));
    }
    // The port first: a port in use fails before anything is read.
    let server = match &a.serve {
        Some(addr) => Some(serve::Server::bind(addr)?),
        None => None,
    };
    let opts_follow = ptu::FollowOptions {
        idle_timeout: Duration::from_secs_f64(a.idle_timeout),
        ..Default::default()
    };
    let name = if stdin {
        PathBuf::from("<stdin>")
    } else {
        a.source.clone()
    };
    let source: Box<dyn LiveSource> = match &kind {
        Kind::Follow(side) => Box::new(ptu::Follower::file(&a.source, side, opts_follow)?),
        Kind::Stdin(side) => {
            let sc = ptu::Sidecar::load(side)?;
            Box::new(ptu::Follower::stream(
                Box::new(std::io::stdin()),
                &name,
                sc,
                side,
                opts_follow,
            )?)
        }
        Kind::Replay(rate) => {
            let mut src = open::source(&a.source, &io::mat::MatOptions::default())?;
            Box::new(live::Replay::from_source(&mut *src, *rate, &a.source)?)
        }
    };
    let g = source.geometry().clone();
    let wave = a.wave.wave();
    let indirect = (!a.no_indirect).then(|| IndirectOptions {
        epsilon: a.epsilon,
        leak: a.leak.method().map(|_| LeakOptions::default()),
        ..Default::default()
    });
    // `--leak-correct model`: the laser's falloff rendered when a replayed file holds it (a
    // PTU stream of a real scan does not).
    let model = match (a.leak.method(), &kind) {
        (Some(LeakArg::Model), _) if a.no_indirect => None,
        (Some(LeakArg::Model), Kind::Replay(_)) => Some(ModelOptions::with_laser_falloff(
            io::laser_falloff_in_data(&a.source)?.0,
        )),
        (Some(LeakArg::Model), _) => Some(ModelOptions::with_laser_falloff(false)),
        (Some(LeakArg::Gate) | None, _) => None,
        (Some(LeakArg::Auto), _) => {
            return Err(vltm::Error::arg(
                "leak_correct",
                "live corrects the rows as they arrive and chooses before the scan: pass $leak_correct gate or model",
            )
            .into());
        }
    };
    let opts = LiveOptions {
        volume,
        focus,
        wave,
        path: match a.path {
            PathArg::Auto => EvalPath::Auto,
            PathArg::Band => EvalPath::Band,
            PathArg::Planar => EvalPath::Planar,
            PathArg::Lookup => EvalPath::Lookup,
            PathArg::Phasor => EvalPath::Phasor,
        },
        indirect,
        model,
        capture_name: name
            .file_name()
            .map_or_else(String::new, |f| f.to_string_lossy().into_owned()),
        // A replayed capture is a finished file: its size is part of the states' identity
        // (they then merge with `--partial` states of the same file); a followed stream has
        // no final size yet (0, which matches any).
        file_bytes: match &kind {
            Kind::Replay(_) => std::fs::metadata(&a.source).map_or(0, |m| m.len()),
            Kind::Follow(_) | Kind::Stdin(_) => 0,
        },
    };
    let mut run = LiveRun::new(&g, opts, resume)?;
    for w in run.warnings() {
        crate::console::tell!("vltm: warning: {w}");
    }
    if run.folded() > 0 {
        say!(
            "live: resuming with {} of {} rows in the states",
            run.folded(),
            run.total_rows()
        );
    }
    if let Some(s) = &server {
        say!("live: serving http://{}/", s.addr());
    }
    let progress = Progress {
        start: Instant::now(),
        tty: std::io::stderr().is_terminal(),
    };
    let mut observe = |u: Update<'_>| match u {
        Update::Folded {
            run, views, fold, ..
        } => {
            let line = progress.line(run, fold);
            progress.show(&line);
            if let Some(s) = &server {
                s.publish(status_json(run, &line, views, false), views, run);
            }
        }
        Update::Finished { run, views } => {
            if progress.tty {
                eprintln!();
            }
            let line = format!(
                "live: {} rows in {:.1} s, {:.3e} photons/s",
                run.total_rows(),
                progress.start.elapsed().as_secs_f64(),
                run.photons() / progress.start.elapsed().as_secs_f64().max(1e-9)
            );
            if let Some(s) = &server {
                s.publish(status_json(run, &line, views, true), views, run);
            }
            say!("{line}");
            match run.end_model() {
                Some(live::EndModel::Used {
                    facets,
                    surfels,
                    explained,
                    photon_noise,
                    seconds,
                }) => {
                    crate::leak::say_model(
                        *facets,
                        *surfels,
                        (*explained, *photon_noise),
                        *seconds,
                    );
                }
                Some(live::EndModel::Unused(reason)) => crate::leak::warn_unused(reason),
                None => {}
            }
            for v in views {
                let p = v.peak.1;
                // Live columns are folded row by row, before Γ exists: no leak correction.
                let note = if v.tag.starts_with("column") && !v.tag.ends_with(".corrected") {
                    " (not leak-corrected: see the .corrected column, or `vltm column` on the finished capture)"
                } else {
                    ""
                };
                say!(
                    "{}: peak {:.4e} at ({:.3}, {:.3}, {:.3}) m{note}",
                    v.tag,
                    v.peak.0,
                    p[0],
                    p[1],
                    p[2]
                );
            }
        }
    };
    let r = live::drive(source, &mut run, &outputs, a.every, &name, &mut observe);
    if let Some(s) = &server {
        if let Err(e) = &r {
            s.fail(&e.to_string());
        }
        s.linger(Duration::from_secs_f64(a.linger.clamp(0.0, 86_400.0)));
    }
    if let Err(e) = r {
        if progress.tty {
            eprintln!();
        }
        // Only a state that was written is named, with the rows it holds.
        let state = outputs.state("direct");
        if run.folded() > 0
            && let Ok(held) = Partial::read(&state)
        {
            let rows: usize = held.rows().iter().map(ExactSizeIterator::len).sum();
            eprintln!(
                "vltm: note: the states of {rows} rows are in {} (continue with --resume)",
                state.display()
            );
        }
        return Err(e.into());
    }
    for p in &all {
        if p.exists() {
            say!("wrote {}", p.display());
        }
    }
    Ok(())
}
