//! Probes with several outputs from one run: Γ masks (`column --mask-epsilon`), the near,
//! middle and far shells (`--shells R1,R2`), and `indirect`'s Γ and `I_d` beside `I_i`.
//!
//! Output names: after `--out F.npy` (and `--png F.png`), `F.near.npy`, `F.middle.npy`,
//! `F.far.npy` for the shells, and for `indirect` also `F.gamma.npy` (Γ as float32 1/0) and
//! `F.direct.npy` (`I_d`, the diagonal of pass 1); without `--out`/`--png`, the probe's name
//! stands for `F` (`indirect.gamma.npy`, …).

use std::path::Path;

use vltm::io::RowSource;
use vltm::out::h5::Provenance;
use vltm::probe::{self, IndirectOptions, Shell};
use vltm::volume::Volume;
use vltm_kernel::Point;
use vltm_kernel::geometry::dist;

use crate::outputs::{Part, write_parts};
use crate::{Common, Failure, summarize};

/// Parses `--shells R1,R2` (metres, 0 < R1 < R2) into near `[0, R1)`, middle `[R1, R2)` and
/// far `[R2, ∞)`.
pub(crate) fn parse_shells(s: &str) -> vltm::Result<[Shell; 3]> {
    let bad = || {
        vltm::Error::arg(
            "--shells",
            format!("expected R1,R2 with 0 < R1 < R2 in metres, found `{s}`"),
        )
    };
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    let r1: f32 = a.trim().parse().map_err(|_| bad())?;
    let r2: f32 = b.trim().parse().map_err(|_| bad())?;
    if !(r1 > 0.0 && r2 > r1 && r2.is_finite()) {
        return Err(bad());
    }
    Ok([
        Shell { r0: 0.0, r1 },
        Shell { r0: r1, r1: r2 },
        Shell {
            r0: r2,
            r1: f32::INFINITY,
        },
    ])
}

/// The names of the three shells.
const SHELL_TAGS: [&str; 3] = ["near", "middle", "far"];

/// Γ = {v : I_d(v) > ε·max} over `volume` (a diagonal pass over `src`); an error naming
/// `arg` when ε is out of range or Γ is empty.
pub(crate) fn gamma(
    src: &mut dyn RowSource,
    volume: &Volume,
    epsilon: f32,
    arg: &str,
    c: &Common,
) -> Result<Vec<bool>, Failure> {
    Ok(gamma_and_direct(src, volume, epsilon, arg, c)?.0)
}

/// [`gamma`] and the direct light it was taken from.
fn gamma_and_direct(
    src: &mut dyn RowSource,
    volume: &Volume,
    epsilon: f32,
    arg: &str,
    c: &Common,
) -> Result<(Vec<bool>, Vec<f32>), Failure> {
    if !(0.0..1.0).contains(&epsilon) {
        return Err(vltm::Error::arg(arg, format!("expected 0 <= E < 1, found {epsilon}")).into());
    }
    let d = probe::direct(src, volume, &c.wave(), c.exec())?;
    Ok((gamma_of(&d.values, volume, epsilon, arg)?, d.values))
}

/// Γ of a direct-light volume at `epsilon` (of its maximum); an empty Γ is an error naming
/// `arg`.
fn gamma_of(
    direct: &[f32],
    volume: &Volume,
    epsilon: f32,
    arg: &str,
) -> Result<Vec<bool>, Failure> {
    if !(0.0..1.0).contains(&epsilon) {
        return Err(vltm::Error::arg(arg, format!("expected 0 <= E < 1, found {epsilon}")).into());
    }
    let g = probe::gamma_mask(direct, epsilon);
    let n = g.iter().filter(|&&k| k).count();
    if n == 0 {
        return Err(vltm::Error::arg(
            arg,
            "Γ is empty: the direct light is zero on every voxel of --volume",
        )
        .into());
    }
    say!(
        "Γ: {n} of {} voxels above ε = {epsilon} of the direct maximum",
        volume.len()
    );
    Ok(g)
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
        .map(|sh| {
            o.values
                .iter()
                .zip(&volume.points)
                .map(|(&x, p)| if sh.contains(dist(&a, p)) { x } else { 0.0 })
                .collect()
        })
        .collect();
    let parts: Vec<Part<'_>> = cut
        .iter()
        .zip(SHELL_TAGS)
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
    opts: &IndirectOptions,
    cuts: Option<[Shell; 3]>,
    direct: Option<Vec<f32>>,
) -> Result<IndirectRun, Failure> {
    let t = std::time::Instant::now();
    let (gamma, direct) = match direct {
        Some(d) => (gamma_of(&d, volume, opts.epsilon, "--epsilon")?, d),
        None => gamma_and_direct(src, volume, opts.epsilon, "--epsilon", c)?,
    };
    let wave = c.wave();
    let (sums, report, shells): (Vec<Vec<f32>>, _, Vec<Shell>) = match &cuts {
        None => {
            let o = probe::indirect_over(src, volume, &gamma, opts, &wave, c.exec())?;
            if let Some(e) = o.explained {
                say!(
                    "leak correction (--no-leak-correct to skip): {e:.4} of the capture's energy was in the 3-vertex windows of Γ and removed"
                );
            }
            (vec![o.values], o.report, vec![o.shell])
        }
        Some(cuts) => {
            let (s, r) = probe::indirect_shells(src, volume, &gamma, opts, cuts, &wave, c.exec())?;
            (s, r, cuts.to_vec())
        }
    };
    let cfg = wave.config(src.geometry())?;
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
            .zip(SHELL_TAGS)
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
