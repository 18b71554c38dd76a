//! `vltm surface`: direct light on a plane fitted to it (`vltm::probe::surface`), its summary
//! lines, the image on the plane (`--out`, `--png`) and the depth map (`--depth`).

use std::path::Path;
use vltm::probe::{self, SurfaceOptions};
use vltm::volume::Volume;

use crate::args::Common;
use crate::console::{Failure, say};
use crate::input;
use crate::open;
use crate::outputs::{Out, prepare_output, refuse_overwriting_inputs};
use crate::summary::{Label, finish};

/// Runs `vltm surface` on `capture`.
pub(crate) fn run(
    capture: &Path,
    opts: &SurfaceOptions,
    depth: Option<&Path>,
    common: &Common,
) -> Result<(), Failure> {
    opts.check()?;
    if common.rows.is_some() || common.partial.is_some() {
        return Err(vltm::Error::arg(
            "rows",
            "a surface is fitted to the whole slab: partial runs are for direct, column and indirect",
        )
        .into());
    }
    if let Some(d) = depth {
        refuse_overwriting_inputs(&[capture.to_path_buf()], &[d])?;
        prepare_output(d, Out::Depth)?;
    }
    let slab = Volume::parse(&common.volume)?;
    let mut c = open::capture(common, capture)?;
    let sigma = common.wave().config(c.geometry())?.sigma();
    let s = input::with_prep(&common.input, &mut *c, &slab.points, sigma, |rows| {
        probe::surface(rows, &slab, &common.wave(), opts, common.exec())
    })?;
    let [a, b, cz] = s.fit.plane;
    let [nx, ny, nz] = slab.shape;
    say!(
        "surface: plane z = {a:.4} {b:+.4}·x {cz:+.4}·y m through {} of {} columns (weighted rms {:.1} mm), from a {nx}x{ny}x{nz} slab in {:.2} s (path {})",
        s.fit.fitted,
        nx * ny,
        s.fit.rms * 1e3,
        s.slab.seconds,
        s.slab.path.name()
    );
    if s.outside > 0 {
        say!(
            "surface: {} of {} samples lie outside the slab's depth range and were clamped to it (widen the volume in z)",
            s.outside,
            s.image.len()
        );
    }
    let contrast = match opts.contrast {
        Some(c) => format!("; divided by the front view blurred over {c} m"),
        None => String::new(),
    };
    let cfg = &s.slab.config;
    let title = format!(
        "surface: direct light (lambda {:.3} m, sigma {:.3} m) on the plane z = {a:.3} {b:+.3}x {cz:+.3}y m, +-{} cm{contrast}",
        cfg.wavelength(),
        cfg.sigma(),
        0.5 * opts.thickness * 100.0
    );
    let o = probe::Output {
        values: s.image.clone(),
        ..s.slab.clone()
    };
    finish(
        common,
        capture,
        &o,
        &s.volume,
        Label {
            probe: "surface",
            title,
            focus: None,
            marks: Vec::new(),
        },
    )?;
    if let Some(d) = depth {
        vltm::export::npy::write_f32(d, &s.depth, &[nx, ny])?;
        say!("wrote {}", d.display());
    }
    Ok(())
}
