//! The commands that run a probe over a capture or write one: `demo`, `info`, `simulate`,
//! `direct`, `column`, `indirect`, `merge`; the matrix commands are in `ltm`, `surface` in
//! `surface`.

use vltm::atomic::Transaction;
use vltm::exec::Exec;
use vltm::io;
use vltm::probe::{self, ColumnGate, Gamma, IndirectOptions, LeakOptions, Shell};
use vltm::volume::{Volume, parse_point};

use crate::args::{Command, DiagGateArg, LeakArg};
use crate::console::{Failure, say};
use crate::outputs::{Out, prepare_output, refuse_overwriting_inputs};
use crate::summary::{Label, finish};
use crate::{info, input, leak, ltm, open, partial, progress, split, surface, title};

/// Runs one command.
pub(crate) fn run(cmd: Command) -> Result<(), Failure> {
    match cmd {
        Command::Matrix(a) => ltm::matrix(a),
        Command::Relight(a) => ltm::relight(a),
        Command::Row(a) => ltm::row(a),
        Command::Live(a) => crate::live::run(a),
        Command::Demo { out } => {
            let table = vltm::demo::run(&out, Some(&progress::BARS))?;
            let _ = std::io::Write::write_all(&mut std::io::stdout(), table.as_bytes());
            Ok(())
        }
        Command::Info {
            capture,
            sidecar: Some(sidecar),
            ..
        } => info::sidecar_template(&capture, &sidecar),
        Command::Info {
            capture,
            png,
            volume,
            input,
            sidecar: None,
        } => info::info(&capture, &input, png.as_deref(), volume.as_deref()),
        Command::Simulate {
            scene,
            out,
            ptu,
            uncompressed,
        } => {
            let mut outputs = vec![out.as_path()];
            let sidecar = ptu.as_ref().map(|p| p.with_extension("json"));
            outputs.extend(ptu.as_deref());
            outputs.extend(sidecar.as_deref());
            refuse_overwriting_inputs(std::slice::from_ref(&scene), &outputs)?;
            prepare_output(&out, Out::Capture)?;
            if let Some(p) = &ptu {
                prepare_output(p, Out::Ptu)?;
            }
            let s = vltm::sim::Scene::load(&scene)?;
            let c = s.render_with(Exec {
                progress: Some(&progress::BARS),
                ..Exec::default()
            })?;
            // The capture, the PTU stream and its sidecar: all or nothing.
            let mut t = Transaction::new();
            io::npz::stage(&mut t, &c, &out, !uncompressed)?;
            let side = match &ptu {
                Some(p) => {
                    let w = io::ptu::stage_t3(&mut t, &c, p, &io::ptu::T3WriteOptions::default())?;
                    w.sidecar_path
                }
                None => None,
            };
            t.commit()?;
            if let (Some(p), Some(side)) = (&ptu, side) {
                say!("wrote {} and its sidecar {}", p.display(), side.display());
            }
            let g = &c.geometry;
            let scan = if g.paired_apart() {
                format!("{} pairs (laser spot, SPAD spot)", g.lasers.len())
            } else if g.coincident() {
                format!("{} confocal spots", g.lasers.len())
            } else {
                format!("{} lasers x {} SPADs", g.lasers.len(), g.spads.len())
            };
            say!(
                "wrote {}: {scan} x {} bins (dt {} m, t0 {} m)",
                out.display(),
                g.nt,
                g.dt,
                g.t0
            );
            Ok(())
        }
        Command::Direct {
            capture,
            gate,
            common,
        } if partial::wanted(&common)? => {
            if gate != DiagGateArg::Gaussian {
                return Err(vltm::Error::arg(
                    "partial",
                    "partial states hold the Gaussian-gated diagonal (direct light) only",
                )
                .into());
            }
            partial::run(&common, &capture, probe::Task::Direct)
        }
        Command::Direct {
            capture,
            gate,
            common,
        } => {
            let volume = Volume::parse(&common.volume)?;
            let mut c = open::capture(&common, &capture)?;
            let g = match gate {
                DiagGateArg::Gaussian => ColumnGate::TwoBounce,
                DiagGateArg::None => ColumnGate::None,
                DiagGateArg::HigherOrder => ColumnGate::HigherOrder,
            };
            let sigma = common.wave().config(c.geometry())?.sigma();
            let o = input::with_prep(&common.input, &mut *c, &volume.points, sigma, |rows| {
                probe::diagonal(rows, &volume, g, &common.wave(), common.exec())
            })?;
            let label = Label {
                probe: "direct",
                title: title::direct(&title::arg(&gate), &o.config),
                focus: None,
                marks: Vec::new(),
            };
            finish(&common, &capture, &o, &volume, label)
        }
        Command::Surface {
            capture,
            floor,
            thickness,
            layers,
            contrast,
            depth,
            common,
        } => {
            let opts = probe::SurfaceOptions {
                floor,
                thickness,
                layers,
                contrast,
            };
            surface::run(&capture, &opts, depth.as_deref(), &common)
        }
        Command::Column {
            capture,
            focus,
            gate,
            shell,
            shells,
            mask_epsilon,
            leak,
            common,
        } => {
            let a = parse_point("focus", &focus)?;
            probe::check_focus(a)?;
            let volume = Volume::parse(&common.volume)?;
            let shell_arg = shell.clone();
            let shell = shell
                .as_deref()
                .map(Shell::parse)
                .transpose()?
                .unwrap_or(Shell::ALL);
            let cuts = shells.as_deref().map(Shell::parse_cuts).transpose()?;
            let leak = leak::Leak::of(&leak, &capture)?;
            if partial::wanted(&common)? {
                if cuts.is_some() || mask_epsilon.is_some() {
                    return Err(vltm::Error::arg(
                        "partial",
                        "a partial column takes $shell, not $shells or $mask_epsilon (apply them to the merged volume)",
                    )
                    .into());
                }
                if leak.method.is_some() {
                    return Err(vltm::Error::arg(
                        "partial",
                        "a partial column cannot be leak-corrected (its Γ needs the direct light of the whole capture): add $no_leak_correct, or run the column over the whole scan",
                    )
                    .into());
                }
                let task = probe::Task::Column {
                    focus: a,
                    gate: gate.gate(),
                    shell,
                };
                return partial::run(&common, &capture, task);
            }
            let mut c = open::capture(&common, &capture)?;
            let sigma = common.wave().config(c.geometry())?.sigma();
            let o = input::with_prep(&common.input, &mut *c, &volume.points, sigma, |rows| {
                // Bad input is refused before the extra passes (Γ of the mask, the leak fit).
                let (g, w) = (gate.gate(), common.wave());
                probe::check_column(rows.geometry(), a, &volume, g, &w, common.exec())?;
                let mask = match mask_epsilon {
                    Some(e) => Some(
                        split::gamma(rows, &volume, e, "mask_epsilon", &common)?
                            .0
                            .mask,
                    ),
                    None => None,
                };
                let (mut o, used) =
                    leak::corrected(rows, &volume, &leak, (&w, common.exec()), |src| {
                        probe::column(src, a, &volume, g, shell, &w, common.exec())
                    })?;
                if let Some(m) = &mask {
                    o.values
                        .iter_mut()
                        .zip(m)
                        .for_each(|(x, &k)| *x *= f32::from(u8::from(k)));
                }
                Ok::<_, Failure>((o, used))
            })?;
            let (o, used) = o;
            let words = title::ColumnWords {
                gate: title::arg(&gate),
                shell: shell_arg.as_deref(),
                mask_epsilon,
                leak: used,
            };
            let title = title::column(a, &words, &o.config);
            match cuts {
                Some(cuts) => {
                    split::column_shells(&common, &capture, &o, &volume, a, &cuts, &title)
                }
                None => {
                    let label = Label {
                        probe: "column",
                        title,
                        focus: Some(a),
                        marks: Vec::new(),
                    };
                    finish(&common, &capture, &o, &volume, label)
                }
            }
        }
        Command::Indirect {
            capture,
            epsilon,
            min_separation,
            shell,
            direct,
            shells,
            gate,
            leak,
            common,
        } => {
            let method = leak.method();
            let volume = Volume::parse(&common.volume)?;
            let shell = match (shell, min_separation) {
                (Some(s), _) => Some(Shell::parse(&s)?),
                (None, Some(r)) if r >= 0.0 => Some(Shell {
                    r0: r,
                    r1: f32::INFINITY,
                }),
                (None, Some(r)) => {
                    return Err(vltm::Error::arg(
                        "min_separation",
                        format!("expected R >= 0, found {r}"),
                    )
                    .into());
                }
                (None, None) => None,
            };
            Gamma::check_epsilon(epsilon, "epsilon")?;
            let cuts = shells.as_deref().map(Shell::parse_cuts).transpose()?;
            let opts = IndirectOptions {
                epsilon,
                shell,
                gate: gate.gate(),
                leak: method.map(|_| LeakOptions::default()),
                ..Default::default()
            };
            let direct = match &direct {
                Some(d) => Some(partial::read_direct(d, &volume)?),
                None => None,
            };
            if partial::wanted(&common)? {
                let Some(d) = &direct else {
                    return Err(vltm::Error::arg(
                        "partial",
                        "in-focus indirect light over a part of the rows needs Γ: pass $direct D.npy, the merged direct light over the same volume and options",
                    )
                    .into());
                };
                if cuts.is_some() || opts.gate != ColumnGate::TwoBounce {
                    return Err(vltm::Error::arg(
                        "partial",
                        "a partial in-focus sum takes the two-bounce gate and one $shell",
                    )
                    .into());
                }
                if matches!(method, Some(LeakArg::Model | LeakArg::Auto)) {
                    return Err(vltm::Error::arg(
                        "partial",
                        "the surface model (which $leak_correct auto may choose) is fitted to the whole capture: a partial in-focus sum takes $leak_correct gate (or $no_leak_correct)",
                    )
                    .into());
                }
                let gamma = Gamma::of(d, epsilon, "epsilon")?.mask;
                // The leak gate corrects each row on its own (Γ's return times only): a part
                // is corrected exactly as one pass corrects those rows.
                let leak = opts.leak.is_some();
                let task = probe::Task::Indirect { gamma, shell, leak };
                return partial::run(&common, &capture, task);
            }
            let leak = leak::Leak::new(method, epsilon, &capture)?;
            let mut c = open::capture(&common, &capture)?;
            let sigma = common.wave().config(c.geometry())?.sigma();
            let run = input::with_prep(&common.input, &mut *c, &volume.points, sigma, |rows| {
                split::indirect_run(&common, rows, &volume, (&opts, &leak), cuts, direct)
            })?;
            split::indirect_write(&common, &capture, &volume, &opts, &run)?;
            if !common.wave.compensate_laser && io::laser_falloff_in_data(&capture)?.0 {
                say!(
                    "note: {} holds the laser's cos θ / d² falloff (a tal render): --compensate-laser divides it out (`vltm info` says why; docs/indirect-light.md)",
                    capture.display()
                );
            }
            Ok(())
        }
        Command::Merge {
            parts,
            out,
            png,
            partial,
        } => partial::merge(&parts, out, png, partial),
    }
}
