//! `vltm demo`: a built-in scene like the paper's Fig. 5, simulated, probed and drawn.
//!
//! A diffuse **panel** faces the relay wall and turns toward a **figure** (a tall board)
//! standing beside it; a **box** elsewhere is a distractor. The virtual projector focuses on
//! the panel's centre `x_a`: light reflected by the panel onto the figure is first-order
//! indirect light of the LTM column `T(x_a, ·)`. The scene is rendered twice, with all light
//! paths and with direct light only (the control), and every probe runs on both.
//!
//! Front ends: `vltm demo` (the command line) and `vltm.demo()` (Python) call [`run`]; it
//! needs no input file. Cost: two renders of 144 × 144 × 300 bins and eleven probes over
//! 3003 voxels (about a minute on two cores); memory: two captures of 25 MB.

use crate::error::{Error, Result};
use crate::exec::{Exec, Progress};
use crate::export::figure::Figure;
use crate::io::{Capture, RowSource};
use crate::probe::{self, ColumnGate, IndirectOptions, LeakOptions, Shell, Wave};
use crate::sim::{Aperture, Bounces, Cuboid, Object, Patch, Scene, Setup};
use crate::volume::Volume;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;
use vltm_kernel::Point;
use vltm_kernel::geometry::dist;

/// Focus of the virtual projector: the panel's centre.
pub const PANEL: [f64; 3] = [-0.35, 0.0, 0.8];
/// Centre of the figure standing beside the panel.
pub const FIGURE: [f64; 3] = [0.35, 0.0, 0.8];
/// Centre of the distractor box.
pub const BOX: [f64; 3] = [0.0, -0.3, 1.1];

/// The demo scene with the given light paths: 12×12 lasers × 12×12 SPADs over a 1 m wall,
/// 300 bins of 1 cm from t0 = 1 m.
pub fn scene(bounces: Bounces) -> Scene {
    let grid = || Aperture::grid([12, 12], [1.0, 1.0], [0.0, 0.0]);
    let mut setup = Setup::new(grid(), grid(), 300, 0.01);
    setup.t0 = 1.0;
    let mut panel = Patch::new("panel", PANEL, [1.0, 0.0, -1.0], [0.3, 0.3]);
    panel.samples = 6;
    let mut figure = Patch::new("figure", FIGURE, [-1.0, 0.0, -1.0], [0.14, 0.34]);
    figure.samples = 5;
    let mut distractor = Cuboid::new("box", BOX, [0.15, 0.15, 0.15]);
    distractor.samples = 2;
    let mut s = Scene::new(setup).with(panel).with(figure).with(distractor);
    s.bounces = bounces;
    s.pulse_sigma = Some(0.01);
    s
}

/// The imaged volume: 21 × 11 × 13 voxels, 6 cm pitch.
pub fn volume() -> Result<Volume> {
    Volume::grid([-0.6, -0.3, 0.5], [0.6, 0.3, 1.22], [21, 11, 13])
}

/// The voxels of the demo scene's object `name` (`"panel"`, `"figure"`) in `vol`: the voxels
/// its surface passes through (nearest voxel of a 40 × 40 sampling of the board), grown by
/// one voxel in every grid direction.
pub fn object_voxels(vol: &Volume, name: &str) -> Result<Vec<usize>> {
    let mut s = scene(Bounces::All);
    s.objects.retain(|o| o.name() == name);
    for o in &mut s.objects {
        if let Object::Patch(p) = o {
            p.samples = 40;
        }
    }
    let surface: Vec<Point> = s.sample_points().iter().map(|p| p32(p.position)).collect();
    let v = vol.surface_voxels(&surface);
    if v.is_empty() {
        return Err(Error::arg(
            "demo",
            format!("the {name} has no voxel in the volume"),
        ));
    }
    Ok(v)
}

fn p32(p: [f64; 3]) -> Point {
    p.map(|c| c as f32)
}

fn argmax(v: &[f32]) -> usize {
    (0..v.len())
        .max_by(|&a, &b| v[a].total_cmp(&v[b]))
        .unwrap_or(0)
}

/// Name of the object whose surface (sample points) is nearest to `p`, and that distance.
fn nearest(scene: &Scene, p: Point) -> (String, f32) {
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name()).collect();
    scene
        .sample_points()
        .iter()
        .map(|sp| {
            (
                names.get(sp.group).copied().unwrap_or("?").to_string(),
                dist(&p, &p32(sp.position)),
            )
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or(("?".into(), f32::NAN))
}

/// One result row of the table.
struct Line {
    name: &'static str,
    /// The output files' name: `<stem>.png`, `<stem>.npy`.
    stem: &'static str,
    /// What the figure shows, after the name in its title.
    shows: &'static str,
    /// Whether the figure marks the focus x_a (a column).
    marked: bool,
    values: Vec<f32>,
    /// Time of the probe run; `None` for a row derived from the row above it (a mask or a
    /// shell applied to the same column).
    seconds: Option<f64>,
}

/// Runs the demo into `out` (created if needed): the figures (`<result>.png`), volumes
/// (`<result>.npy`) and `summary.txt`; returns the table text. `progress` draws the probes'
/// progress (the command line's bars; `None` for none).
///
/// # Errors
/// I/O errors writing the outputs (and, in principle, kernel errors).
pub fn run(out: &Path, progress: Option<&'static dyn Progress>) -> Result<String> {
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let t_all = Instant::now();
    let t = Instant::now();
    let truth = scene(Bounces::All);
    let mut full: Capture = truth.render()?;
    let mut control: Capture = scene(Bounces::Direct).render()?;
    let t_render = t.elapsed().as_secs_f64();
    let vol = volume()?;
    let wave = Wave {
        wavelength: Some(0.2),
        ..Wave::default()
    };
    // Progress bars go to stderr and are hidden when it is not a terminal.
    let exec = Exec {
        progress,
        ..Exec::default()
    };
    let a = p32(PANEL);
    let mut lines = Vec::new();

    let d = probe::direct(&mut full, &vol, &wave, exec)?;
    let gamma = probe::gamma_mask(&d.values, 0.1);
    lines.push(Line {
        name: "direct (diagonal)",
        stem: "direct",
        shows: "T(x_v, x_v)",
        marked: false,
        values: d.values.clone(),
        seconds: Some(d.seconds),
    });
    let col =
        |src: &mut Capture, gate, shell| probe::column(src, a, &vol, gate, shell, &wave, exec);
    let gated = col(&mut full, ColumnGate::TwoBounce, Shell::ALL)?;
    let ungated = col(&mut full, ColumnGate::None, Shell::ALL)?;
    let higher = col(&mut full, ColumnGate::HigherOrder, Shell::ALL)?;
    let gated_ctrl = col(&mut control, ColumnGate::TwoBounce, Shell::ALL)?;
    let mask = |v: &[f32]| {
        v.iter()
            .zip(&gamma)
            .map(|(&x, &g)| if g { x } else { 0.0 })
            .collect::<Vec<f32>>()
    };
    let (near, far) = (Shell { r0: 0.15, r1: 0.45 }, Shell { r0: 0.45, r1: 1.2 });
    let shelled = |s: Shell| {
        let m = mask(&gated.values);
        m.iter()
            .zip(&vol.points)
            .map(|(&x, p)| if s.contains(dist(&a, p)) { x } else { 0.0 })
            .collect::<Vec<f32>>()
    };
    lines.push(Line {
        name: "column, gated",
        stem: "column_gated",
        shows: "T(x_a, x_b)",
        marked: true,
        values: gated.values.clone(),
        seconds: Some(gated.seconds),
    });
    lines.push(Line {
        name: "column, gated, Γ-masked",
        stem: "column_gated_masked",
        shows: "T(x_a, x_b)",
        marked: true,
        values: mask(&gated.values),
        seconds: None,
    });
    lines.push(Line {
        name: "column, no gate",
        stem: "column_ungated",
        shows: "T(x_a, x_b)",
        marked: true,
        values: ungated.values.clone(),
        seconds: Some(ungated.seconds),
    });
    lines.push(Line {
        name: "column, no gate, Γ-masked",
        stem: "column_ungated_masked",
        shows: "T(x_a, x_b)",
        marked: true,
        values: mask(&ungated.values),
        seconds: None,
    });
    lines.push(Line {
        name: "column, higher-order, Γ-masked",
        stem: "column_higher_order_masked",
        shows: "T(x_a, x_b)",
        marked: true,
        values: mask(&higher.values),
        seconds: Some(higher.seconds),
    });
    lines.push(Line {
        name: "column near 0.15-0.45 m, Γ",
        stem: "column_near",
        shows: "T(x_a, x_b)",
        marked: true,
        values: shelled(near),
        seconds: None,
    });
    lines.push(Line {
        name: "column far 0.45-1.20 m, Γ",
        stem: "column_far",
        shows: "T(x_a, x_b)",
        marked: true,
        values: shelled(far),
        seconds: None,
    });
    // In-focus indirect light (Eqs. 15–17): every a ∈ Γ as a projector focus, summed over
    // pairs at least r0 = 1.5σ apart; the same Γ for the direct-only control.
    let opts = IndirectOptions::default();
    let eq17 = probe::indirect_over(&mut full, &vol, &gamma, &opts, &wave, exec)?;
    let eq17_ctrl = probe::indirect_over(&mut control, &vol, &gamma, &opts, &wave, exec)?;
    // The same with the capture's direct light removed first (what `vltm indirect` does by
    // default; `--no-leak-correct` gives the plain Eq. 17 above); the control gets the same
    // correction (its own windows over the same Γ).
    let leak_opts = IndirectOptions {
        leak: Some(LeakOptions::default()),
        ..opts
    };
    let lc = probe::indirect_over(&mut full, &vol, &gamma, &leak_opts, &wave, exec)?;
    let lc_ctrl = probe::indirect_over(&mut control, &vol, &gamma, &leak_opts, &wave, exec)?;
    lines.push(Line {
        name: "in-focus indirect (leak-corr.)",
        stem: "indirect",
        shows: "I_i(x_b) after removing the direct returns of Γ (default)",
        marked: false,
        values: lc.values.clone(),
        seconds: Some(lc.seconds),
    });
    lines.push(Line {
        name: "in-focus indirect (Eq. 17)",
        stem: "indirect_eq17",
        shows: "I_i(x_b) = sum over x_a in Γ of T(x_a, x_b)",
        marked: false,
        values: eq17.values.clone(),
        seconds: Some(eq17.seconds),
    });

    // Indirect light on the figure against the direct-only control, same Γ: means over the
    // figure's voxels (its surface ± one voxel), never one chosen voxel.
    let fig = object_voxels(&vol, "figure")?;
    let panel = object_voxels(&vol, "panel")?;
    let mean_on = |idx: &[usize], v: &[f32]| {
        idx.iter().map(|&i| f64::from(v[i])).sum::<f64>() / idx.len() as f64
    };
    let on_figure = |v: &[f32]| mean_on(&fig, v);
    let ungated_ctrl = col(&mut control, ColumnGate::None, Shell::ALL)?;
    // The indirect-only truth: Eq. 17 on H − H_control (known here, not on a real capture).
    let mut diff = full.clone();
    diff.data
        .iter_mut()
        .zip(&control.data)
        .for_each(|(x, c)| *x -= c);
    let only = probe::indirect_over(&mut diff, &vol, &gamma, &opts, &wave, exec)?;
    let rows = [
        (
            "column T(x_a, ·), 4-vertex gate",
            &gated.values,
            &gated_ctrl.values,
        ),
        (
            "column T(x_a, ·), no gate",
            &ungated.values,
            &ungated_ctrl.values,
        ),
        ("in-focus I_i (Eq. 17)", &eq17.values, &eq17_ctrl.values),
        ("in-focus I_i, leak-corrected", &lc.values, &lc_ctrl.values),
    ];

    let mut table = String::new();
    let g = full.geometry();
    let _ = writeln!(
        table,
        "vltm demo: panel at {PANEL:?}, figure at {FIGURE:?}, box at {BOX:?} (m)\n\
         capture: {} lasers x {} SPADs x {} bins of {} m from t0 = {} m, rendered twice (all paths / direct only) in {t_render:.1} s\n\
         probes: λ = {:.3} m, σ = {:.3} m, J = {} band bins; volume {}x{}x{} voxels; focus x_a = panel centre; Γ: {} voxels (ε = 0.1)\n",
        g.lasers.len(),
        g.spads.len(),
        g.nt,
        g.dt,
        g.t0,
        d.config.wavelength(),
        d.config.sigma(),
        d.config.bins(),
        vol.shape[0],
        vol.shape[1],
        vol.shape[2],
        gamma.iter().filter(|&&x| x).count()
    );
    let _ = writeln!(
        table,
        "{:<32} {:>8}  {:<22} {:>14}",
        "probe", "time [s]", "peak (x, y, z) [m]", "nearest surface"
    );
    for l in &lines {
        let p = vol.points[argmax(&l.values)];
        let (obj, e) = nearest(&truth, p);
        let time = l
            .seconds
            .map_or("(same)".to_string(), |s| format!("{s:.2}"));
        let _ = writeln!(
            table,
            "{:<32} {time:>8}  ({:+.2}, {:+.2}, {:+.2})    {obj} ({e:.2} m)",
            l.name, p[0], p[1], p[2]
        );
    }
    let _ = writeln!(
        table,
        "(same): the column of the row above, masked by Γ or cut to a shell (no run of its own)\n\
         leak-corr.: the capture's direct light removed first, what `vltm indirect` does by default; Eq. 17: as in the paper (--no-leak-correct)"
    );
    // Ground truth: the direct image's brightest voxel within 0.15 m of each object's surface,
    // against that surface.
    let _ = writeln!(
        table,
        "\ndirect light near each object (brightest voxel within 0.15 m of its surface):"
    );
    let surf: Vec<(String, f32)> = vol.points.iter().map(|&p| nearest(&truth, p)).collect();
    let d_max = d.values.iter().copied().fold(0.0f32, f32::max);
    for o in &truth.objects {
        let best = (0..vol.len())
            .filter(|&i| surf[i].0 == o.name() && surf[i].1 <= 0.15)
            .max_by(|&i, &j| d.values[i].total_cmp(&d.values[j]));
        if let Some(i) = best {
            let p = vol.points[i];
            let _ = writeln!(
                table,
                "  {:<8} peak ({:+.2}, {:+.2}, {:+.2}) m, {:.2} m from its surface, {:.2} of the image maximum",
                o.name(),
                p[0],
                p[1],
                p[2],
                surf[i].1,
                d.values[i] / d_max
            );
        }
    }
    let _ = writeln!(
        table,
        "\nindirect light on the figure: means over its {} voxels (its surface ± one voxel), beside the direct-only \
         control\n(same Γ and settings: λ = {:.3} m, σ = {:.3} m, ε = {}, r0 = {:.2} m; leak correction: the 3-vertex windows of Γ zeroed)\n\
         these ratios come from vltm's built-in simulator (Lambertian patches, no occlusion, no thickness); on path-traced \
         captures they are far lower (docs/indirect-light.md)\n\
         {:<34} {:>12} {:>12} {:>10}",
        fig.len(),
        d.config.wavelength(),
        d.config.sigma(),
        opts.epsilon,
        eq17.shell.r0,
        "probe",
        "figure",
        "control",
        "ratio"
    );
    for (name, f, c) in rows {
        let (f, c) = (on_figure(f), on_figure(c));
        let _ = writeln!(table, "{name:<34} {f:>12.4e} {c:>12.4e} {:>9.2}x", f / c);
    }
    // The panel is lit back by the figure: the leak-corrected I_i peaks there.
    let (p_lc, p_ctrl) = (
        mean_on(&panel, &lc.values),
        mean_on(&panel, &lc_ctrl.values),
    );
    let _ = writeln!(
        table,
        "{:<34} {p_lc:>12.4e} {p_ctrl:>12.4e} {:>9.2}x   (the panel's {} voxels, lit back by the figure)",
        "in-focus I_i, leak-corr., panel",
        p_lc / p_ctrl,
        panel.len()
    );
    let _ = writeln!(
        table,
        "indirect-only truth on the figure (Eq. 17 on H − H_control): {:.4e}; the leak-corrected I_i keeps {:.2} of it \
         ({:.4} of the capture's energy was in the removed windows)\ntotal {:.1} s; figures and .npy volumes in {}",
        on_figure(&only.values),
        on_figure(&lc.values) / on_figure(&only.values),
        lc.explained.unwrap_or(0.0),
        t_all.elapsed().as_secs_f64(),
        out.display()
    );

    write_lines(out, &lines, &vol, a)?;
    crate::atomic::write_bytes(&out.join("summary.txt"), table.as_bytes())?;
    Ok(table)
}

/// Each result's figure and `.npy` volume in `out`, named by its own [`Line::stem`].
fn write_lines(out: &Path, lines: &[Line], vol: &Volume, a: Point) -> Result<()> {
    let [x, y, z] = vol.axes.unwrap_or([[0.0; 2]; 3]);
    for l in lines {
        let marks = if l.marked {
            vec![(a, "x_a".to_string())]
        } else {
            Vec::new()
        };
        Figure {
            data: &l.values,
            shape: vol.shape,
            x,
            y,
            z,
            title: format!("{}: {}", l.name, l.shows),
            marks,
        }
        .write_png(&out.join(format!("{}.png", l.stem)))?;
        crate::export::npy::write_f32(out.join(format!("{}.npy", l.stem)), &l.values, &vol.shape)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every result is written under its own name, however many there are and in whatever
    /// order (the files were once paired with a fixed list of ten names by position, which
    /// dropped or mislabelled any result added or moved).
    #[test]
    fn every_line_is_written_under_its_own_name() {
        let vol = Volume::parse("-0.1:0.1:3,-0.1:0.1:3,0.5:0.7:3").unwrap();
        let line = |stem: &'static str, v: f32| Line {
            name: stem,
            stem,
            shows: "test",
            marked: stem.starts_with('c'),
            values: vec![v; vol.len()],
            seconds: None,
        };
        // Eleven results, in an order no fixed list knows.
        let stems = [
            "indirect_eq17",
            "direct",
            "c1",
            "c2",
            "c3",
            "c4",
            "c5",
            "c6",
            "c7",
            "c8",
            "extra",
        ];
        let lines: Vec<Line> = stems
            .iter()
            .enumerate()
            .map(|(i, s)| line(s, i as f32 + 1.0))
            .collect();
        let dir = std::env::temp_dir().join(format!("vltm-demo-lines-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        write_lines(&dir, &lines, &vol, [0.0, 0.0, 0.6]).unwrap();
        for (i, s) in stems.iter().enumerate() {
            let (v, shape) = crate::export::npy::read_f32(dir.join(format!("{s}.npy"))).unwrap();
            assert_eq!(shape, vol.shape.to_vec(), "{s}");
            assert!(
                v.iter().all(|&x| x == i as f32 + 1.0),
                "{s}.npy holds another result"
            );
            assert!(dir.join(format!("{s}.png")).is_file(), "{s}.png");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
