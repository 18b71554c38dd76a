//! Probes with several outputs from one run: Γ masks (`column --mask-epsilon`), the near,
//! middle and far shells (`--shells R1,R2`), and `indirect`'s Γ and `I_d` beside `I_i`.
//!
//! Output names: after `--out F.npy` (and `--png F.png`), `F.near.npy`, `F.middle.npy`,
//! `F.far.npy` for the shells, and for `indirect` also `F.gamma.npy` (Γ as float32 1/0) and
//! `F.direct.npy` (`I_d`, the diagonal of pass 1); without `--out`/`--png`, the probe's name
//! stands for `F` (`indirect.gamma.npy`, …).

use std::path::Path;

use vltm::export::h5::Provenance;
use vltm::io::RowSource;
use vltm::probe::{self, Gamma, IndirectOptions, Shell};
use vltm::volume::Volume;
use vltm_kernel::Point;

use crate::args::{Common, LeakArg};
use crate::console::{Failure, say};
use crate::leak::{Leak, auto_tries_model, fit_model, say_gate};
use crate::outputs::{Part, write_parts};
use crate::summary::summarize;

/// Γ over `volume` from a diagonal pass over `src` at `epsilon` (`param` names it); an
/// empty Γ is an error.
pub(crate) fn gamma(
    src: &mut dyn RowSource,
    volume: &Volume,
    epsilon: f32,
    param: &str,
    c: &Common,
) -> Result<(Gamma, Vec<f32>), Failure> {
    let (g, d) = Gamma::measure(src, volume, epsilon, param, &c.wave(), c.exec())?;
    Ok((announce(g.non_empty(param)?, volume), d.values))
}

/// Prints Γ's size.
fn announce(g: Gamma, volume: &Volume) -> Gamma {
    say!(
        "Γ: {} of {} voxels above ε = {} of the direct maximum",
        g.count(),
        volume.len(),
        g.epsilon
    );
    g
}

/// A column cut into its near, middle and far shells around the focus `a`, written as three
/// outputs.
pub(crate) fn column_shells(
    c: &Common,
    capture: &Path,
    o: &probe::Output,
    volume: &Volume,
    a: Point,
    cuts: &[Shell; 3],
    title: &str,
) -> Result<(), Failure> {
    summarize(
        "column",
        &o.values,
        volume,
        o.seconds,
        &o.report,
        &o.config,
        Some(o.path),
    );
    let cut: Vec<Vec<f32>> = cuts
        .iter()
        .map(|sh| sh.cut(a, &o.values, &volume.points))
        .collect();
    let parts: Vec<Part<'_>> = cut
        .iter()
        .zip(Shell::CUT_NAMES)
        .zip(cuts)
        .map(|((v, tag), sh)| Part {
            tag: Some(tag),
            values: v,
            title: format!("{title}, {tag} {:.2}-{:.2} m", sh.r0, sh.r1),
        })
        .collect();
    let meta = Provenance {
        probe: "column",
        config: &o.config,
        focus: Some(a),
        capture,
    };
    write_parts(
        (&c.out, &c.png),
        &meta,
        &parts,
        volume,
        &[(a, "x_a".to_string())],
    )
}

/// What one `indirect` run computed, before it is written.
pub(crate) struct IndirectRun {
    gamma: Vec<bool>,
    direct: Vec<f32>,
    sums: Vec<Vec<f32>>,
    report: vltm_kernel::Report,
    shells: Vec<Shell>,
    cfg: vltm_kernel::Config,
    seconds: f64,
}

/// `indirect` on `src` (already preprocessed): Γ from pass 1, or from `direct` (a direct-light
/// volume given with `--direct`), then the pair sums of pass 2, one per shell of `cuts` (or
/// the single shell of `opts`).
pub(crate) fn indirect_run(
    c: &Common,
    src: &mut dyn RowSource,
    volume: &Volume,
    (opts, leak): (&IndirectOptions, &Leak),
    cuts: Option<[Shell; 3]>,
    direct: Option<Vec<f32>>,
) -> Result<IndirectRun, Failure> {
    let t = std::time::Instant::now();
    let (gamma, direct) = match direct {
        Some(d) => {
            let g = Gamma::of(&d, opts.epsilon, "epsilon")?.non_empty("epsilon")?;
            (announce(g, volume).mask, d)
        }
        None => {
            let (g, d) = gamma(src, volume, opts.epsilon, "epsilon", c)?;
            (g.mask, d)
        }
    };
    let wave = c.wave();
    // `--leak-correct model`: pass 2 on the capture minus the model, or the windows when the
    // model is not used (fit_model has said why). `auto`: the windows' pass over Γ first (the
    // pass the windows make inside `indirect`), and the model where what they leave lies
    // next to them.
    let model = match leak.method {
        Some(LeakArg::Model) => fit_model(src, &wave, leak.falloff, c.exec())?,
        Some(LeakArg::Auto) => {
            let lo = opts.leak.unwrap_or_default();
            let gate = probe::fit_over_gamma(src, volume, &gamma, &wave, &lo, c.exec())?;
            if auto_tries_model(&gate) {
                fit_model(src, &wave, leak.falloff, c.exec())?
            } else {
                None
            }
        }
        _ => None,
    };
    let opts = &IndirectOptions {
        leak: if model.is_some() { None } else { opts.leak },
        ..*opts
    };
    let mut subtracted;
    let src: &mut dyn RowSource = match &model {
        Some(m) => {
            subtracted = m.subtracted(src);
            &mut subtracted
        }
        None => src,
    };
    // The summary and the provenance record the configuration pass 2 ran on.
    let (sums, report, shells, cfg): (Vec<Vec<f32>>, _, Vec<Shell>, _) = match &cuts {
        None => {
            let o = probe::indirect_over(src, volume, &gamma, opts, &wave, c.exec())?;
            if let Some(e) = o.explained {
                say_gate(e, None, None);
            }
            (vec![o.values], o.report, vec![o.shell], o.config)
        }
        Some(cuts) => {
            let p = probe::indirect_shells(src, volume, &gamma, opts, cuts, &wave, c.exec())?;
            (p.sums, p.report, cuts.to_vec(), p.config)
        }
    };
    Ok(IndirectRun {
        gamma,
        direct,
        sums,
        report,
        shells,
        cfg,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// The summary and the outputs of an [`indirect_run`]: `I_i` (or its three shells), Γ and
/// `I_d`, all or nothing.
pub(crate) fn indirect_write(
    c: &Common,
    capture: &Path,
    volume: &Volume,
    opts: &IndirectOptions,
    run: &IndirectRun,
) -> Result<(), Failure> {
    let IndirectRun {
        gamma,
        direct,
        sums,
        report,
        shells,
        cfg,
        seconds,
    } = run;
    for sh in shells {
        say!(
            "pairs with {:.3} <= |x_a - x_b| < {:.3} m ({} gate)",
            sh.r0,
            sh.r1,
            match opts.gate {
                probe::ColumnGate::TwoBounce => "two-bounce",
                probe::ColumnGate::HigherOrder => "higher-order",
                probe::ColumnGate::None => "no",
            }
        );
    }
    let total: Vec<f32> = (0..volume.len())
        .map(|i| sums.iter().map(|s| s[i]).sum())
        .collect();
    summarize("indirect", &total, volume, *seconds, report, cfg, None);
    let meta = Provenance {
        probe: "indirect",
        config: cfg,
        focus: None,
        capture,
    };
    let g: Vec<f32> = gamma.iter().map(|&k| f32::from(u8::from(k))).collect();
    let mut parts: Vec<Part<'_>> = if sums.len() == 1 {
        vec![Part {
            tag: None,
            values: &sums[0],
            title: "in-focus indirect light".to_string(),
        }]
    } else {
        sums.iter()
            .zip(Shell::CUT_NAMES)
            .zip(shells)
            .map(|((v, tag), sh)| Part {
                tag: Some(tag),
                values: v,
                title: format!("in-focus indirect light, {tag} {:.2}-{:.2} m", sh.r0, sh.r1),
            })
            .collect()
    };
    parts.push(Part {
        tag: Some("gamma"),
        values: &g,
        title: format!("Γ (direct light above {} of its maximum)", opts.epsilon),
    });
    parts.push(Part {
        tag: Some("direct"),
        values: direct,
        title: "direct light I_d (pass 1)".to_string(),
    });
    write_parts((&c.out, &c.png), &meta, &parts, volume, &[])
}
