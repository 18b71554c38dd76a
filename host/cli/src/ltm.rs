//! The matrix commands: `vltm matrix` (the LTM between two voxel sets, or a part's state),
//! `vltm relight` (the image under a weighted pattern of foci) and `vltm row` (`T(·, x_b)`).

use std::path::{Path, PathBuf};

use vltm::probe::{self, Gamma, Pattern};
use vltm::volume::{Volume, parse_point};
use vltm_kernel::Point;

use crate::args::{Common, MatrixArgs, RelightArgs, RowArgs};
use crate::console::{Failure, say};
use crate::outputs::{
    Out, check_matrix_out, prepare_output, refuse_overwriting_inputs, write_matrix,
};
use crate::summary::{Label, finish};
use crate::{input, leak, open, partial, progress, title};

fn exec() -> probe::Exec<'static> {
    probe::Exec {
        progress: Some(&progress::BARS),
        ..probe::Exec::default()
    }
}

/// `vltm matrix`: Γ if asked for, the matrix (or a part's state), the HDF5 file.
pub(crate) fn matrix(a: MatrixArgs) -> Result<(), Failure> {
    let outputs: Vec<&Path> = a
        .out
        .iter()
        .chain(&a.partial)
        .map(PathBuf::as_path)
        .collect();
    refuse_overwriting_inputs(std::slice::from_ref(&a.capture), &outputs)?;
    if let Some(out) = &a.out {
        check_matrix_out(out)?;
    }
    if let Some(p) = &a.partial {
        prepare_output(p, Out::State)?;
    }
    if a.rows.is_some() && a.partial.is_none() {
        return Err(vltm::Error::arg(
            "rows",
            "a part of a scan is written as a partial state: add $partial F (then `vltm merge` the parts)",
        )
        .into());
    }
    Gamma::check_epsilon(a.epsilon, "epsilon")?;
    let wave = a.wave.wave();
    let wants_gamma = [&a.from, &a.to].iter().any(|s| s.trim() == "gamma");
    if wants_gamma && a.partial.is_some() {
        return Err(vltm::Error::arg(
            "partial",
            "`gamma` needs the direct light of the whole capture: give $from/$to as SPECs or point lists (Γ's points of a merged direct run)",
        )
        .into());
    }
    let mut src = open::streamed(&a.capture)?;
    let gamma: Option<Vec<Point>> = if wants_gamma {
        let spec = a.volume.as_deref().ok_or_else(|| {
            vltm::Error::arg("volume", "`gamma` in $from/$to needs the volume of Γ")
        })?;
        let volume = Volume::parse(spec)?;
        let (g, _) = Gamma::measure(&mut *src, &volume, a.epsilon, "epsilon", &wave, exec())?;
        let g = g.non_empty("epsilon")?;
        say!(
            "Γ: {} of {} voxels above ε = {} of the direct maximum",
            g.count(),
            volume.len(),
            a.epsilon
        );
        let pts = g.points(&volume);
        Some(pts)
    } else {
        None
    };
    let set = |arg: &str, s: &str| -> vltm::Result<Vec<Point>> {
        match (s.trim(), &gamma) {
            ("gamma", Some(g)) => Ok(g.clone()),
            _ => Volume::parse(s).map(|v| v.points).map_err(|e| match e {
                vltm::Error::Argument { msg, .. } => vltm::Error::arg(arg, msg),
                e => e,
            }),
        }
    };
    let from = set("from", &a.from)?;
    let to = set("to", &a.to)?;
    if let Some(part) = &a.partial {
        let volume = Volume::points(to)?;
        let task = probe::Task::Matrix { from };
        return partial::run_task(
            &a.capture,
            &mut *src,
            &volume,
            &task,
            (&wave, exec()),
            a.rows.as_deref(),
            part,
        );
    }
    // The capture's direct light is removed over --volume (Γ's volume) by default, as in
    // `column` and `row`; without a volume there is nothing to fit it to.
    let leak = leak::Leak::of(&a.leak, &a.capture)?;
    let volume = match (&a.volume, leak.method) {
        (Some(spec), Some(_)) => Some(Volume::parse(spec)?),
        (None, Some(_)) => {
            say!(
                "matrix: not leak-corrected: give --volume (the volume whose direct light is removed, as column's) or --no-leak-correct"
            );
            None
        }
        (_, None) => None,
    };
    let (m, used) = match &volume {
        Some(volume) => leak::corrected(&mut *src, volume, &leak, (&wave, exec()), |s| {
            probe::matrix(s, &from, &to, &wave, exec())
        })?,
        None => (probe::matrix(&mut *src, &from, &to, &wave, exec())?, None),
    };
    let texts = [
        ("from", a.from.trim().to_string()),
        ("to", a.to.trim().to_string()),
        ("volume", a.volume.clone().unwrap_or_default()),
    ];
    let numbers = [
        ("epsilon", f64::from(a.epsilon)),
        (
            "leak_correct",
            match used {
                None => 0.0,
                Some(leak::Used::Gate) => 1.0,
                Some(leak::Used::Model) => 2.0,
            },
        ),
        ("leak_epsilon", f64::from(a.leak.leak_epsilon)),
        (
            "compensate_laser",
            f64::from(u8::from(wave.compensate_laser)),
        ),
    ];
    let out = a.out.as_deref().unwrap_or(Path::new("matrix.h5"));
    write_matrix(&m, &from, &to, &a.capture, out, &numbers, texts)
}

/// `vltm relight`: the pattern, one factorised pass, the outputs.
pub(crate) fn relight(a: RelightArgs) -> Result<(), Failure> {
    let c = &a.common;
    let volume = Volume::parse(&c.volume)?;
    let pattern = if a.pattern.trim().ends_with(".npy") {
        let p = Path::new(a.pattern.trim());
        let (img, shape) = vltm::export::npy::read_f32(p)?;
        if shape.iter().product::<usize>() != volume.len() || shape.len() != 3 {
            return Err(vltm::Error::arg(
                "pattern",
                format!(
                    "{}: shape {shape:?}, expected the volume's {:?}",
                    p.display(),
                    volume.shape
                ),
            )
            .into());
        }
        Pattern::from_image(&volume, &img)?
    } else {
        Pattern::parse(&a.pattern)?
    };
    refuse_parts(
        c,
        "relight",
        "split the scan with `vltm matrix $from FOCI $to SPEC $rows A:B $partial F` (with $no_leak_correct, relighting is a weighted sum of the matrix's rows)",
    )?;
    let leak = leak::Leak::of(&a.leak, &a.capture)?;
    let mut src = open::capture(c, &a.capture)?;
    let sigma = c.wave().config(src.geometry())?.sigma();
    let reach: Vec<Point> = volume.points.iter().chain(&pattern.foci).copied().collect();
    let r = input::with_prep(&c.input, &mut *src, &reach, sigma, |rows| {
        probe::check_relight(rows.geometry(), &pattern, &volume, &c.wave())?;
        leak::corrected(rows, &volume, &leak, (&c.wave(), c.exec()), |src| {
            probe::relight(src, &pattern, &volume, &c.wave(), c.exec())
        })
    })?;
    let (r, used) = r;
    say!(
        "pattern: {} foci with non-zero weight, {} pass(es) over the capture",
        pattern.foci.len(),
        r.passes
    );
    let title = title::relight(pattern.foci.len(), used, &r.output.config);
    let marks: Vec<(Point, String)> = pattern
        .foci
        .iter()
        .take(8)
        .map(|p| (*p, "p".to_string()))
        .collect();
    let label = Label {
        probe: "relight",
        title,
        focus: None,
        marks,
    };
    finish(c, &a.capture, &r.output, &volume, label)
}

/// `vltm row`: `T(x_a, x_b)` over the volume's `x_a`, streamed by laser rows.
pub(crate) fn row(a: RowArgs) -> Result<(), Failure> {
    let b = parse_point("focus", &a.focus)?;
    probe::check_focus(b)?;
    let c = &a.common;
    if c.swap_roles {
        return Err(vltm::Error::arg(
            "swap_roles",
            "`row` is the transposed column already (use `column $swap_roles` for the in-memory transpose)",
        )
        .into());
    }
    let volume = Volume::parse(&c.volume)?;
    refuse_parts(
        c,
        "row",
        "split the scan with `vltm matrix $from SPEC $to X,Y,Z $rows A:B $partial F` (with $no_leak_correct, the row is the matrix's column at x_b)",
    )?;
    let leak = leak::Leak::of(&a.leak, &a.capture)?;
    let mut src = open::capture(c, &a.capture)?;
    let sigma = c.wave().config(src.geometry())?.sigma();
    let mut reach = volume.points.clone();
    reach.push(b);
    let o = input::with_prep(&c.input, &mut *src, &reach, sigma, |rows| {
        probe::check_row(rows.geometry(), b, &volume, &c.wave())?;
        leak::corrected(rows, &volume, &leak, (&c.wave(), c.exec()), |src| {
            probe::row(src, b, &volume, &c.wave(), c.exec())
        })
    })?;
    let (o, used) = o;
    let label = Label {
        probe: "row",
        title: title::row(b, used, &o.config),
        focus: None,
        marks: vec![(b, "x_b".to_string())],
    };
    finish(c, &a.capture, &o, &volume, label)
}

/// `relight` and `row` run over the whole scan: a part of one (`--rows`, `--partial`) is
/// refused, naming the option given and the command that splits the same sums.
fn refuse_parts(c: &Common, probe: &str, hint: &str) -> Result<(), Failure> {
    let arg = match (&c.rows, &c.partial) {
        (Some(_), _) => "rows",
        (None, Some(_)) => "partial",
        (None, None) => return Ok(()),
    };
    Err(vltm::Error::arg(
        arg,
        format!("`{probe}` runs over the whole scan and writes no partial state: {hint}"),
    )
    .into())
}
