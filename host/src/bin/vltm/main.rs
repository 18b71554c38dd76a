//! `vltm`: virtual light transport matrices of hidden scenes from NLOS captures.
//!
//! Exit codes: 0 success, 2 bad arguments, 1 bad or unreadable input data.

use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use vltm::atomic::Transaction;
use vltm::exec::{Exec, Path as EvalPath};
use vltm::io::{self, RowSource};
use vltm::out::h5::Provenance;
use vltm::probe::{self, ColumnGate, IndirectOptions, LeakOptions, Shell, Wave};
use vltm::volume::{Volume, parse_point};

mod demo;
mod input;
mod progress;
use input::Input;
use vltm_kernel::Point;

/// `println!` that ignores a closed stdout (`vltm info CAPTURE | head` must not panic).
#[macro_export]
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}

/// `eprintln!` that ignores a closed stderr (`vltm … 2>&1 | head -1` must not panic; the
/// exit code stays the one the run would have had).
#[macro_export]
macro_rules! tell {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}

mod ltm;
mod outputs;
mod partial;
mod split;
use outputs::write_outputs;

/// Virtual light transport matrices (LTM) of hidden scenes from non-line-of-sight captures
/// (Marco et al., ICCV 2021).
///
/// Terms: the relay wall is the plane z = 0, the hidden scene is at z > 0, all lengths are
/// metres of optical path. The virtual projector focuses light at x_a, the virtual camera
/// images x_b; T(x_a, x_b) is the light that goes from x_a to x_b.
#[derive(Parser, Debug)]
#[command(name = "vltm", version, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Worker threads (default: all cores).
    #[arg(long, global = true)]
    threads: Option<usize>,
    /// Memory budget, e.g. 12G or 500M (default: the least of half the physical memory and
    /// 3/4 of the address-space, data-segment and cgroup limits; `vltm info` shows it; never
    /// above those limits). Every buffer sized from a file, a scene or an argument is checked
    /// against it before it is made.
    #[arg(long, global = true, value_name = "SIZE")]
    max_memory: Option<String>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Built-in scene → figures and a summary table (no input files needed).
    Demo {
        /// Output directory.
        #[arg(long, default_value = "vltm-demo")]
        out: PathBuf,
    },
    /// Print a capture's dimensions, geometry, time axis and counts.
    Info {
        /// Capture file (.npz, .hdf5/.h5, .ptu, .mat).
        capture: PathBuf,
        /// Plot the summed transient (counts against path length, log scale) to this PNG.
        #[arg(long, value_name = "F.png")]
        png: Option<PathBuf>,
        #[command(flatten)]
        input: Input,
    },
    /// Render a synthetic capture from a scene file (JSON).
    Simulate {
        /// Scene file.
        scene: PathBuf,
        /// Output capture (.npz).
        #[arg(long)]
        out: PathBuf,
        /// Also write the capture as a synthetic PicoQuant T3 photon stream (HydraHarp V2)
        /// with its sidecar F.json (counts rounded to whole photons).
        #[arg(long, value_name = "F.ptu")]
        ptu: Option<PathBuf>,
        /// Store H uncompressed in the .npz (larger file, much faster to read).
        #[arg(long)]
        uncompressed: bool,
    },
    /// Direct light: the LTM diagonal T(x_v, x_v) over a volume (3-vertex gate).
    Direct {
        /// Capture file.
        capture: PathBuf,
        /// Time gate on the 3-vertex time |x_l-x_v|+|x_v-x_s|: gaussian = direct light
        /// (Eqs. 11-12); none = monochromatic, no gate (paper Fig. 6); higher-order = light
        /// arriving after it (Eq. 18 on the diagonal: x_v lit, returning to x_v later).
        #[arg(long, value_enum, default_value_t = DiagGateArg::Gaussian)]
        gate: DiagGateArg,
        #[command(flatten)]
        common: Common,
    },
    /// First-order (or higher-order) indirect light from a focus point: the LTM column T(x_a, ·).
    Column {
        /// Capture file.
        capture: PathBuf,
        /// Focus x_a of the virtual projector, "X,Y,Z" in metres (z > 0).
        #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
        focus: String,
        /// Time gate: two-bounce = 4-vertex gate at |x_l-x_a|+|x_a-x_b|+|x_b-x_s| (Eq. 14);
        /// higher-order = light arriving after that (Eq. 18); none = monochromatic, no gate.
        #[arg(long, value_enum, default_value_t = GateArg::TwoBounce)]
        gate: GateArg,
        /// Keep only voxels with R0 <= |x_a - x_b| < R1 metres (near/middle/far light).
        #[arg(long, value_name = "R0:R1")]
        shell: Option<String>,
        /// Near, middle and far light in one pass: three outputs F.near/F.middle/F.far
        /// (.npy/.png) for |x_a - x_b| in [0, R1), [R1, R2), [R2, inf).
        #[arg(long, value_name = "R1,R2", conflicts_with = "shell")]
        shells: Option<String>,
        /// Γ-mask the column: zero every voxel whose direct light is not above E·max
        /// (an extra diagonal pass, as `indirect`).
        #[arg(long, value_name = "E")]
        mask_epsilon: Option<f32>,
        /// Remove the capture's direct light before the column: zero, per laser/SPAD pair,
        /// the bins where a 3-vertex return of a voxel of Γ (direct light above
        /// --leak-epsilon of the maximum) can arrive (see README, "Leak-corrected indirect
        /// light").
        #[arg(long)]
        leak_correct: bool,
        /// Relative threshold of the voxels the --leak-correct fit places scatterers at.
        #[arg(long, default_value_t = 0.1, value_name = "E")]
        leak_epsilon: f32,
        #[command(flatten)]
        common: Common,
    },
    /// In-focus indirect light: Γ = voxels whose direct light exceeds ε·max, then the sum of
    /// T(x_a, x_b) over pairs in Γ at least --min-separation apart (Eqs. 15-17).
    Indirect {
        /// Capture file.
        capture: PathBuf,
        /// Relative threshold ε of the Γ mask (0 <= ε < 1).
        #[arg(long, default_value_t = 0.1)]
        epsilon: f32,
        /// Minimum |x_a - x_b| of a pair in metres (default 1.5 σ).
        #[arg(long, value_name = "R")]
        min_separation: Option<f32>,
        /// Keep only pairs with R0 <= |x_a - x_b| < R1 metres (overrides --min-separation).
        #[arg(long, value_name = "R0:R1")]
        shell: Option<String>,
        /// Γ from this direct-light volume (float32 .npy over the same --volume, e.g. from
        /// `vltm merge` of direct parts) instead of pass 1; needed with --rows/--partial.
        #[arg(long, value_name = "D.npy")]
        direct: Option<PathBuf>,
        /// Near, middle and far pairs in one pass: three outputs F.near/F.middle/F.far for
        /// |x_a - x_b| in (0, R1), [R1, R2), [R2, inf) (instead of --shell/--min-separation).
        #[arg(long, value_name = "R1,R2", conflicts_with_all = ["shell", "min_separation"])]
        shells: Option<String>,
        /// Gate of the summed columns: two-bounce (Eq. 14, first-order indirect light),
        /// higher-order (Eq. 18 with Eq. 17: the paper's ">= 3rd bounce"), none.
        #[arg(long, value_enum, default_value_t = GateArg::TwoBounce)]
        gate: GateArg,
        /// Remove the capture's direct light before the columns (the default): zero, per
        /// laser/SPAD pair, the bins where a 3-vertex return of a Γ voxel can arrive (see
        /// README, "Leak-corrected indirect light").
        #[arg(long, conflicts_with = "no_leak_correct")]
        leak_correct: bool,
        /// The paper's Eq. 17 on the capture as it is (no leak correction).
        #[arg(long)]
        no_leak_correct: bool,
        #[command(flatten)]
        common: Common,
    },
    /// Merge partial states (--partial of direct, column, indirect, matrix over row ranges) by
    /// addition and finish them: the same volume as one pass over all rows.
    Merge {
        /// Partial state files; together they must hold every laser row exactly once.
        #[arg(required = true)]
        parts: Vec<PathBuf>,
        /// Output volume: float32 .npy, or HDF5 for a .h5/.hdf5 name.
        #[arg(long, value_name = "F.npy|F.h5")]
        out: Option<PathBuf>,
        /// Output figure (maximum-intensity projections).
        #[arg(long, value_name = "F.png")]
        png: Option<PathBuf>,
        /// Write the merged state (still partial, or complete) instead of finishing it.
        #[arg(long, value_name = "F")]
        partial: Option<PathBuf>,
    },
    /// The LTM between two voxel sets as a matrix: complex amplitudes and intensities of
    /// T(x_a, x_b) (two-bounce gate) for x_a in --from, x_b in --to, written to HDF5.
    Matrix(ltm::MatrixArgs),
    /// Relighting: the virtual camera's image i = T·p under an illumination that weights
    /// several projector foci (one factorised pass; amplitudes add).
    Relight(ltm::RelightArgs),
    /// A row T(., x_b) of the LTM (virtual camera focused at x_b, projector over the volume),
    /// streamed by laser rows without transposing the capture.
    Row(ltm::RowArgs),
}

#[derive(ValueEnum, Clone, Copy, Debug)]
enum GateArg {
    TwoBounce,
    HigherOrder,
    None,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum DiagGateArg {
    Gaussian,
    None,
    HigherOrder,
}

impl GateArg {
    fn gate(self) -> ColumnGate {
        match self {
            Self::TwoBounce => ColumnGate::TwoBounce,
            Self::HigherOrder => ColumnGate::HigherOrder,
            Self::None => ColumnGate::None,
        }
    }
}

#[derive(ValueEnum, Clone, Copy, Debug)]
enum WeightsArg {
    /// The paper's 1/d per leg of the virtual lenses.
    Inv,
    /// No weights (y-tal's default).
    One,
}

/// Options shared by every probe.
#[derive(Args, Debug)]
struct Common {
    /// Voxels: "x0:x1:nx,y0:y1:ny,z0:z1:nz" (metres, inclusive end points) or "x,y,z;x,y,z".
    #[arg(long, value_name = "SPEC", allow_hyphen_values = true)]
    volume: String,
    #[command(flatten)]
    wave: ltm::WaveArgs,
    /// Use the SPADs as the virtual projector and the lasers as the camera (reciprocity;
    /// 1-D SPAD arrays focus illumination along their axis).
    #[arg(long)]
    swap_roles: bool,
    /// Evaluation path: auto (the cheapest that applies), band (the kernel's band sum, any
    /// geometry), planar (FFT convolution over a SPAD grid or a confocal wall grid; diagonal and two-bounce columns),
    /// lookup (baseband + cubic interpolation; diagonal only). For indirect it applies to
    /// pass 1 (the diagonal); pass 2 images its Γ columns with the band sum.
    #[arg(long, value_enum, default_value_t = PathArg::Auto)]
    path: PathArg,
    /// Output volume: float32 .npy of shape (nx, ny, nz), or HDF5 for a .h5/.hdf5 name
    /// (datasets `intensity` and `volume_xyz`, the parameters as attributes).
    #[arg(long, value_name = "F.npy|F.h5")]
    out: Option<PathBuf>,
    /// Output figure: front (x-y) and top (x-z) maximum-intensity projections.
    #[arg(long, value_name = "F.png")]
    png: Option<PathBuf>,
    /// Only the laser rows A..B (B exclusive, 0-based) of the scan: one part of a scan split
    /// over processes. Needs --partial.
    #[arg(long, value_name = "A:B")]
    rows: Option<String>,
    /// Write the accumulator state to F (binary, see `vltm::probe::partial`) instead of the
    /// volume; `vltm merge` adds the parts and finishes them.
    #[arg(long, value_name = "F")]
    partial: Option<PathBuf>,
    #[command(flatten)]
    input: Input,
}

/// `--path` values.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum PathArg {
    Auto,
    Band,
    Planar,
    Lookup,
}

impl Common {
    fn exec(&self) -> Exec<'static> {
        Exec {
            progress: Some(&progress::BARS),
            path: match self.path {
                PathArg::Auto => EvalPath::Auto,
                PathArg::Band => EvalPath::Band,
                PathArg::Planar => EvalPath::Planar,
                PathArg::Lookup => EvalPath::Lookup,
            },
        }
    }

    fn wave(&self) -> Wave {
        self.wave.wave()
    }

    /// The capture as a row source: y-tal HDF5 files, PicoQuant PTU photon streams and
    /// uncompressed `.npz` captures are streamed row by row (memory O(Ks·Nt)); compressed
    /// `.npz`, and `--swap-roles` (a transpose), are read into memory.
    fn load(&self, path: &Path) -> vltm::Result<Box<dyn RowSource>> {
        let mut inputs = vec![path.to_path_buf()];
        if io::extension(path).as_deref() == Some("ptu") {
            inputs.push(path.with_extension("json"));
        }
        let outputs: Vec<&Path> = self
            .out
            .iter()
            .chain(&self.png)
            .chain(&self.partial)
            .map(PathBuf::as_path)
            .collect();
        refuse_overwriting_inputs(&inputs, &outputs)?;
        if self.swap_roles {
            let mut src = self.input.open(path)?;
            let g = src.geometry().clone();
            let mut data = Vec::new();
            let mut row = Vec::new();
            for l in 0..g.lasers.len() {
                src.read_row(l, &mut row)?;
                data.extend_from_slice(&row);
            }
            let c = io::Capture::new(g, data, path)?;
            Ok(Box::new(io::swap_roles(&c)?))
        } else {
            self.input.open(path)
        }
    }
}

/// Refuses an output path that names one of the command's input files (the capture, its PTU
/// sidecar, a scene): writing it would destroy the input.
pub(crate) fn refuse_overwriting_inputs(inputs: &[PathBuf], outputs: &[&Path]) -> vltm::Result<()> {
    for o in outputs {
        if let Some(i) = inputs.iter().find(|i| same_file(i, o)) {
            return Err(vltm::Error::arg(
                "--out",
                format!(
                    "{} is an input of this command ({}): choose another output path",
                    o.display(),
                    i.display()
                ),
            ));
        }
    }
    Ok(())
}

/// Whether two paths name the same file (after resolving links; for a path that does not
/// exist yet, its directory is resolved).
fn same_file(a: &Path, b: &Path) -> bool {
    let resolve = |p: &Path| {
        p.canonicalize().ok().or_else(|| {
            let dir = match p.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            Some(dir.canonicalize().ok()?.join(p.file_name()?))
        })
    };
    match (resolve(a), resolve(b)) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}

/// Escapes control characters (terminal escapes, newlines from a file's strings) so that an
/// error stays one printable line.
fn printable(msg: &str) -> String {
    msg.chars()
        .map(|c| {
            if c.is_control() {
                c.escape_default().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// An error with its exit code.
struct Failure {
    code: u8,
    err: anyhow::Error,
}

impl From<vltm::Error> for Failure {
    fn from(e: vltm::Error) -> Self {
        Self {
            code: if e.is_usage() { 2 } else { 1 },
            err: e.into(),
        }
    }
}

impl From<anyhow::Error> for Failure {
    fn from(err: anyhow::Error) -> Self {
        let code = match err.downcast_ref::<vltm::Error>() {
            Some(e) if e.is_usage() => 2,
            _ => 1,
        };
        Self { code, err }
    }
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) if !e.use_stderr() => {
            // --help and --version.
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            // One line, like every other error: clap's message up to its first blank line
            // (the argument it names, the values it expects), without "error: " and the
            // usage block.
            let text = e.render().to_string();
            let msg = text
                .lines()
                .take_while(|l| !l.trim().is_empty())
                .map(str::trim)
                .collect::<Vec<_>>()
                .join(" ");
            let msg = msg.trim_start_matches("error: ");
            let msg = if msg.is_empty() { "bad arguments" } else { msg };
            tell!("vltm: {msg} (see --help)");
            return ExitCode::from(2);
        }
    };
    if let Some(n) = cli.threads {
        // More threads than 4 per core only add start-up time and memory.
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        let most = 4 * cores;
        if n == 0 || n > most {
            tell!(
                "vltm: argument `--threads`: expected 1 to {most} threads (4 per core, {cores} cores), found {n}"
            );
            return ExitCode::from(2);
        }
        if rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .is_err()
        {
            tell!("vltm: argument `--threads`: the thread pool could not be started");
            return ExitCode::from(1);
        }
    }
    if let Some(m) = &cli.max_memory {
        match vltm::budget::parse_size(m) {
            Ok(b) => vltm::budget::set(b),
            Err(e) => {
                tell!("vltm: {}", printable(&e.to_string()));
                return ExitCode::from(2);
            }
        }
    }
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            // vltm errors already name their cause; context chains print as "context: cause".
            let msg = match f.err.downcast_ref::<vltm::Error>() {
                Some(e) => e.to_string(),
                None => format!("{:#}", f.err),
            };
            tell!("vltm: {}", printable(&msg.replace('\n', " ")));
            ExitCode::from(f.code)
        }
    }
}

fn run(cmd: Command) -> Result<(), Failure> {
    match cmd {
        Command::Matrix(a) => ltm::matrix(a),
        Command::Relight(a) => ltm::relight(a),
        Command::Row(a) => ltm::row(a),
        Command::Demo { out } => {
            let table = demo::run(&out)?;
            let _ = std::io::Write::write_all(&mut std::io::stdout(), table.as_bytes());
            Ok(())
        }
        Command::Info {
            capture,
            png,
            input,
        } => input::info(&capture, &input, png.as_deref()),
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
            say!(
                "wrote {}: {} lasers x {} SPADs x {} bins (dt {} m, t0 {} m)",
                out.display(),
                g.lasers.len(),
                g.spads_per_row(),
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
                    "--partial",
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
            let mut c = common.load(&capture)?;
            let g = match gate {
                DiagGateArg::Gaussian => ColumnGate::TwoBounce,
                DiagGateArg::None => ColumnGate::None,
                DiagGateArg::HigherOrder => ColumnGate::HigherOrder,
            };
            let sigma = common.wave().config(c.geometry())?.sigma();
            let o = input::with_prep(&common.input, &mut *c, &volume.points, sigma, |rows| {
                probe::diagonal(rows, &volume, g, &common.wave(), common.exec())
            })?;
            finish_probe(
                &common,
                &capture,
                "direct",
                &o,
                &volume,
                None,
                "direct light",
            )
        }
        Command::Column {
            capture,
            focus,
            gate,
            shell,
            shells,
            mask_epsilon,
            leak_correct,
            leak_epsilon,
            common,
        } => {
            let a = parse_point("--focus", &focus)?;
            probe::check_focus(a)?;
            let volume = Volume::parse(&common.volume)?;
            let shell = shell
                .as_deref()
                .map(Shell::parse)
                .transpose()?
                .unwrap_or(Shell::ALL);
            let cuts = shells.as_deref().map(split::parse_shells).transpose()?;
            if partial::wanted(&common)? {
                if cuts.is_some() || mask_epsilon.is_some() {
                    return Err(vltm::Error::arg(
                        "--partial",
                        "a partial column takes --shell, not --shells or --mask-epsilon (apply them to the merged volume)",
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
            let mut c = common.load(&capture)?;
            let sigma = common.wave().config(c.geometry())?.sigma();
            let o = input::with_prep(&common.input, &mut *c, &volume.points, sigma, |rows| {
                let mask = match mask_epsilon {
                    Some(e) => Some(split::gamma(rows, &volume, e, "--mask-epsilon", &common)?),
                    None => None,
                };
                let mut o = if leak_correct {
                    let model = probe::fit_over_volume(
                        rows,
                        &volume,
                        leak_epsilon,
                        &common.wave(),
                        &LeakOptions::default(),
                        common.exec(),
                    )?;
                    say!(
                        "leak correction: {:.4} of the capture's energy was in the 3-vertex windows of Γ's {} voxels and removed ({:.2} s)",
                        model.explained,
                        model.points().len(),
                        model.seconds
                    );
                    let mut lc = probe::LeakCorrected::new(rows, &model);
                    let g = gate.gate();
                    probe::column(&mut lc, a, &volume, g, shell, &common.wave(), common.exec())?
                } else {
                    let g = gate.gate();
                    probe::column(rows, a, &volume, g, shell, &common.wave(), common.exec())?
                };
                if let Some(m) = &mask {
                    o.values
                        .iter_mut()
                        .zip(m)
                        .for_each(|(x, &k)| *x *= f32::from(u8::from(k)));
                }
                Ok::<_, Failure>(o)
            })?;
            let title = format!("column T(x_a, .), gate {gate:?}");
            match cuts {
                Some(cuts) => {
                    split::column_shells(&common, &capture, &o, &volume, a, &cuts, &title)
                }
                None => finish_probe(&common, &capture, "column", &o, &volume, Some(a), &title),
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
            leak_correct: _,
            no_leak_correct,
            common,
        } => {
            let volume = Volume::parse(&common.volume)?;
            let shell = match (shell, min_separation) {
                (Some(s), _) => Some(Shell::parse(&s)?),
                (None, Some(r)) if r >= 0.0 => Some(Shell {
                    r0: r,
                    r1: f32::INFINITY,
                }),
                (None, Some(r)) => {
                    return Err(vltm::Error::arg(
                        "--min-separation",
                        format!("expected R >= 0, found {r}"),
                    )
                    .into());
                }
                (None, None) => None,
            };
            if !(0.0..1.0).contains(&epsilon) {
                return Err(vltm::Error::arg(
                    "--epsilon",
                    format!("expected 0 <= E < 1, found {epsilon}"),
                )
                .into());
            }
            let cuts = shells.as_deref().map(split::parse_shells).transpose()?;
            let opts = IndirectOptions {
                epsilon,
                shell,
                gate: gate.gate(),
                leak: (!no_leak_correct).then(LeakOptions::default),
                ..Default::default()
            };
            let direct = match &direct {
                Some(d) => Some(partial::read_direct(d, &volume)?),
                None => None,
            };
            if partial::wanted(&common)? {
                let Some(d) = &direct else {
                    return Err(vltm::Error::arg(
                        "--partial",
                        "in-focus indirect light over a part of the rows needs Γ: pass --direct D.npy, the merged direct light over the same volume and options",
                    )
                    .into());
                };
                if cuts.is_some() || opts.gate != ColumnGate::TwoBounce {
                    return Err(vltm::Error::arg(
                        "--partial",
                        "a partial in-focus sum takes the two-bounce gate and one --shell",
                    )
                    .into());
                }
                let gamma = probe::gamma_mask(d, epsilon);
                // The leak gate corrects each row on its own (Γ's return times only): a part
                // is corrected exactly as one pass corrects those rows.
                let leak = opts.leak.is_some();
                let task = probe::Task::Indirect { gamma, shell, leak };
                return partial::run(&common, &capture, task);
            }
            let mut c = common.load(&capture)?;
            let sigma = common.wave().config(c.geometry())?.sigma();
            let run = input::with_prep(&common.input, &mut *c, &volume.points, sigma, |rows| {
                split::indirect_run(&common, rows, &volume, &opts, cuts, direct)
            })?;
            split::indirect_write(&common, &capture, &volume, &opts, &run)
        }
        Command::Merge {
            parts,
            out,
            png,
            partial,
        } => partial::merge(&parts, out, png, partial),
    }
}

/// The capture's format (HDF5), geometry, time axis and counts, for `vltm info`.
fn describe(path: &Path, c: &io::Capture) -> Result<(), Failure> {
    let g = &c.geometry;
    let (kl, ks) = (g.lasers.len(), g.spads_per_row());
    let span = |p: &[Point]| {
        let lo: Vec<f32> = (0..3)
            .map(|i| p.iter().map(|q| q[i]).fold(f32::INFINITY, f32::min))
            .collect();
        let hi: Vec<f32> = (0..3)
            .map(|i| p.iter().map(|q| q[i]).fold(f32::NEG_INFINITY, f32::max))
            .collect();
        format!(
            "x {:.3}..{:.3}, y {:.3}..{:.3}, z {:.3}..{:.3} m",
            lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]
        )
    };
    if io::is_hdf5(path) {
        input::describe_hdf5(path)?;
    }
    say!(
        "scan         {}",
        if g.confocal {
            "confocal"
        } else {
            "non-confocal"
        }
    );
    say!(
        "lasers       {} = {}x{} ({})",
        kl,
        g.laser_shape[0],
        g.laser_shape[1],
        span(&g.lasers)
    );
    say!(
        "SPADs        {} = {}x{} ({})",
        g.spads.len(),
        g.spad_shape[0],
        g.spad_shape[1],
        span(&g.spads)
    );
    say!(
        "laser_xyz    {:?} m, sensor_xyz {:?} m",
        g.laser_origin,
        g.sensor_origin
    );
    say!(
        "time axis    {} bins x {} m from t0 = {} m to {:.4} m; device legs {}",
        g.nt,
        g.dt,
        g.t0,
        g.t0 + (g.nt as f64 - 1.0) * g.dt,
        if g.legs_in_time {
            "included"
        } else {
            "not included (wall to wall)"
        }
    );
    let (mut sum, mut max, mut nonzero, mut bad) = (0.0f64, f32::NEG_INFINITY, 0usize, 0usize);
    for &h in &c.data {
        if h.is_finite() {
            sum += h as f64;
            max = max.max(h);
            nonzero += usize::from(h != 0.0);
        } else {
            bad += 1;
        }
    }
    say!(
        "histograms   {} = {kl} x {ks} x {} values; sum {sum:.4e}, max {max:.4e}, non-zero {nonzero}, non-finite {bad}",
        c.data.len(),
        g.nt
    );
    say!(
        "default λ    {:.4} m (twice the aperture pitch)",
        probe::default_wavelength(g)
    );
    Ok(())
}

fn summarize(
    what: &str,
    v: &[f32],
    volume: &Volume,
    seconds: f64,
    report: &vltm_kernel::Report,
    cfg: &vltm_kernel::Config,
    path: Option<EvalPath>,
) {
    let (i, m) =
        v.iter().enumerate().fold(
            (0, f32::NEG_INFINITY),
            |a, (i, &x)| if x > a.1 { (i, x) } else { a },
        );
    let p = volume.points.get(i).copied().unwrap_or_default();
    let path = path.map_or(String::new(), |p| format!(", path {}", p.name()));
    say!(
        "{what}: {} voxels, {} rows in {seconds:.2} s (λ = {:.4} m, σ = {:.4} m, J = {}{path}); peak {m:.4e} at ({:.3}, {:.3}, {:.3}) m",
        v.len(),
        report.rows,
        cfg.wavelength(),
        cfg.sigma(),
        cfg.bins(),
        p[0],
        p[1],
        p[2]
    );
    if report.non_finite > 0 {
        tell!(
            "vltm: warning: {} non-finite histogram samples were read as 0",
            report.non_finite
        );
    }
    if report.aliased > 0 {
        tell!(
            "vltm: warning: {} voxels have path lengths outside the capture's alias-free window",
            report.aliased
        );
    }
}

/// The summary line and the outputs of a `direct` or `column` run; a column's focus is marked
/// in the figure and recorded in an HDF5 volume.
fn finish_probe(
    common: &Common,
    capture: &Path,
    probe: &str,
    o: &probe::Output,
    volume: &Volume,
    focus: Option<Point>,
    title: &str,
) -> Result<(), Failure> {
    summarize(
        probe,
        &o.values,
        volume,
        o.seconds,
        &o.report,
        &o.config,
        Some(o.path),
    );
    let meta = Provenance {
        probe,
        config: &o.config,
        focus,
        capture,
    };
    let marks: Vec<(Point, String)> = focus.map(|a| (a, "x_a".to_string())).into_iter().collect();
    write_outputs(
        (&common.out, &common.png),
        &meta,
        &o.values,
        volume,
        title,
        &marks,
    )
}
