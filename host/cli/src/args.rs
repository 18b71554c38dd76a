//! The command line's arguments (clap): the commands, the options every probe shares
//! ([`Common`]), the wave options and the matrix commands' arguments. Parsing only: the
//! commands run in `commands` and `ltm`, and open their capture through `open`.

use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
use vltm::exec::{EvalPath, Exec};
use vltm::probe::{ColumnGate, Wave};
use vltm_kernel::Weights;

use crate::input::Input;
use crate::progress;

/// Virtual light transport matrices (LTM) of hidden scenes from non-line-of-sight captures
/// (Marco et al., ICCV 2021).
///
/// Terms: the relay wall is the plane z = 0, the hidden scene is at z > 0, all lengths are
/// metres of optical path. The virtual projector focuses light at x_a, the virtual camera
/// images x_b; T(x_a, x_b) is the light that goes from x_a to x_b.
#[derive(Parser, Debug)]
#[command(name = "vltm", version, propagate_version = true)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
    /// Worker threads (default: all cores).
    #[arg(long, global = true)]
    pub(crate) threads: Option<usize>,
    /// Memory budget, e.g. 12G or 500M (default: the least of half the physical memory and
    /// 3/4 of the address-space, data-segment and cgroup limits; `vltm info` shows it; never
    /// above those limits). Every buffer sized from a file, a scene or an argument is checked
    /// against it before it is made.
    #[arg(long, global = true, value_name = "SIZE")]
    pub(crate) max_memory: Option<String>,
    /// Progress of the long stages on stderr: `auto` (a bar on a terminal, otherwise a plain
    /// line every few seconds once the command has run a few seconds), `bar`, `plain` or
    /// `none`.
    #[arg(long, global = true, value_enum, default_value_t = progress::Mode::Auto)]
    pub(crate) progress: progress::Mode,
}

#[derive(Subcommand, Debug)]
pub(crate) enum Command {
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
        /// Also say which evaluation path direct light over this volume takes (the FFT path,
        /// resampled or not, or the lookup) and the aligned grid the FFT path would take.
        #[arg(long, value_name = "SPEC", allow_hyphen_values = true)]
        volume: Option<String>,
        /// For a .ptu capture without its sidecar: write a template sidecar F.json (each field
        /// with a `_help` note, pre-filled from the file's header and records) to fill in.
        #[arg(long, value_name = "F.json", conflicts_with_all = ["png", "volume"])]
        sidecar: Option<PathBuf>,
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
    /// Direct light on a plane fitted to it: the depth of the brightest voxel of each (x, y)
    /// column of a slab volume, a plane through the bright ones, and the image on that plane
    /// (a tilted sign or chart, legible; see docs/real-data.md).
    Surface {
        /// Capture file.
        capture: PathBuf,
        /// Columns dimmer than FLOOR × the slab's maximum stay out of the plane fit.
        #[arg(long, default_value_t = 0.25, value_name = "FLOOR")]
        floor: f32,
        /// Metres along z that the image spans around the plane.
        #[arg(long, default_value_t = 0.02, value_name = "M")]
        thickness: f32,
        /// Samples along z over --thickness (the figure's top view).
        #[arg(long, default_value_t = 5, value_name = "K")]
        layers: usize,
        /// Local contrast: divide by the front view blurred by a Gaussian of S metres (the
        /// values become ratios; brings out strokes where the brightness falls off).
        #[arg(long, value_name = "S")]
        contrast: Option<f32>,
        /// Also write the depth of each column's brightest voxel (metres, nx x ny) to F.npy.
        #[arg(long, value_name = "F.npy")]
        depth: Option<PathBuf>,
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
        #[command(flatten)]
        leak: LeakArgs,
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
        #[command(flatten)]
        leak: LeakMethodArgs,
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
    Matrix(MatrixArgs),
    /// Relighting: the virtual camera's image i = T·p under an illumination that weights
    /// several projector foci (one factorised pass; amplitudes add).
    Relight(RelightArgs),
    /// A row T(., x_b) of the LTM (virtual camera focused at x_b, projector over the volume),
    /// streamed by laser rows without transposing the capture.
    Row(RowArgs),
    /// Follow a scan while it is acquired (a .ptu file being written, `-` for a T3 stream on
    /// stdin, or a capture replayed at --replay-rate): direct light and columns row by row,
    /// snapshots every K rows, in-focus indirect light at the end, a live page with --serve.
    Live(LiveArgs),
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub(crate) enum GateArg {
    TwoBounce,
    HigherOrder,
    None,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum DiagGateArg {
    Gaussian,
    None,
    HigherOrder,
}

impl GateArg {
    pub(crate) fn gate(self) -> ColumnGate {
        match self {
            Self::TwoBounce => ColumnGate::TwoBounce,
            Self::HigherOrder => ColumnGate::HigherOrder,
            Self::None => ColumnGate::None,
        }
    }
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub(crate) enum WeightsArg {
    /// The paper's 1/d per leg of the virtual lenses.
    Inv,
    /// No weights (y-tal's default).
    One,
    /// The paper's 1/d per leg times the cosine at the leg's wall point, |n·(x_v − x)|/d with
    /// the relay surface's normal n there (+z where the capture has none): `direct` on paired
    /// and confocal scans.
    Cos,
}

/// Options shared by every probe.
#[derive(Args, Debug)]
pub(crate) struct Common {
    /// Voxels: "x0:x1:nx,y0:y1:ny,z0:z1:nz" (metres, inclusive end points) or "x,y,z;x,y,z".
    #[arg(long, value_name = "SPEC", allow_hyphen_values = true)]
    pub(crate) volume: String,
    #[command(flatten)]
    pub(crate) wave: WaveArgs,
    /// Use the SPADs as the virtual projector and the lasers as the camera (reciprocity;
    /// 1-D SPAD arrays focus illumination along their axis; a paired scan exchanges its
    /// laser and SPAD spots).
    #[arg(long)]
    pub(crate) swap_roles: bool,
    /// Evaluation path: auto (the cheapest that applies), band (the kernel's band sum, any
    /// geometry), planar (FFT convolution over a SPAD grid or a confocal wall grid; diagonal and two-bounce columns),
    /// lookup (baseband + cubic interpolation; diagonal only), phasor (a full-phasor table per
    /// histogram, 8 voxels per vector; diagonal only, any scan). For indirect it applies to
    /// pass 1 (the diagonal); pass 2 images its Γ columns with the band sum.
    #[arg(long, value_enum, default_value_t = PathArg::Auto)]
    pub(crate) path: PathArg,
    /// Output volume: float32 .npy of shape (nx, ny, nz), or HDF5 for a .h5/.hdf5 name
    /// (datasets `intensity` and `volume_xyz`, the parameters as attributes).
    #[arg(long, value_name = "F.npy|F.h5")]
    pub(crate) out: Option<PathBuf>,
    /// Output figure: front (x-y) and top (x-z) maximum-intensity projections, drawn as seen
    /// from the relay wall (x increasing to the left).
    #[arg(long, value_name = "F.png")]
    pub(crate) png: Option<PathBuf>,
    /// Only the laser rows A..B (B exclusive, 0-based) of the scan: one part of a scan split
    /// over processes. Needs --partial.
    #[arg(long, value_name = "A:B")]
    pub(crate) rows: Option<String>,
    /// Write the accumulator state to F (binary, see `vltm::probe::partial`) instead of the
    /// volume; `vltm merge` adds the parts and finishes them.
    #[arg(long, value_name = "F")]
    pub(crate) partial: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) input: Input,
}

/// `--path` values.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub(crate) enum PathArg {
    Auto,
    Band,
    Planar,
    Lookup,
    Phasor,
}

impl Common {
    pub(crate) fn exec(&self) -> Exec<'static> {
        Exec {
            progress: Some(&progress::BARS),
            path: match self.path {
                PathArg::Auto => EvalPath::Auto,
                PathArg::Band => EvalPath::Band,
                PathArg::Planar => EvalPath::Planar,
                PathArg::Lookup => EvalPath::Lookup,
                PathArg::Phasor => EvalPath::Phasor,
            },
        }
    }

    pub(crate) fn wave(&self) -> Wave {
        self.wave.wave()
    }
}

/// `vltm matrix`.
#[derive(Args, Debug)]
pub(crate) struct MatrixArgs {
    /// Capture file.
    pub(crate) capture: PathBuf,
    /// Projector foci x_a (the matrix's rows): a SPEC ("x0:x1:nx,y0:y1:ny,z0:z1:nz" or
    /// "x,y,z;x,y,z") or `gamma` (Γ of --volume).
    #[arg(long, value_name = "SPEC|gamma", allow_hyphen_values = true)]
    pub(crate) from: String,
    /// Imaged voxels x_b (the matrix's columns): a SPEC or `gamma`.
    #[arg(long, value_name = "SPEC|gamma", allow_hyphen_values = true)]
    pub(crate) to: String,
    /// The volume whose Γ = {x : direct(x) > ε·max} `gamma` stands for (as `vltm indirect`),
    /// and over which the capture's direct light is removed first (leak correction, on by
    /// default when a volume is given; --no-leak-correct skips it).
    #[arg(long, value_name = "SPEC", allow_hyphen_values = true)]
    pub(crate) volume: Option<String>,
    /// Relative threshold ε of Γ (0 <= ε < 1).
    #[arg(long, default_value_t = 0.1)]
    pub(crate) epsilon: f32,
    /// Output: HDF5 file (datasets re, im, intensity of shape (n_from, n_to), from_xyz,
    /// to_xyz; the parameters as attributes).
    #[arg(long, value_name = "F.h5", required_unless_present = "partial")]
    pub(crate) out: Option<PathBuf>,
    /// Only the laser rows A..B (B exclusive, 0-based) of the scan: one part of a scan split
    /// over processes. Needs --partial.
    #[arg(long, value_name = "A:B")]
    pub(crate) rows: Option<String>,
    /// Write the accumulator state (one factorised column per --from focus) to F instead of
    /// the matrix; `vltm merge --out F.h5` adds the parts and images the matrix.
    #[arg(long, value_name = "F", conflicts_with = "out")]
    pub(crate) partial: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) leak: LeakArgs,
    #[command(flatten)]
    pub(crate) wave: WaveArgs,
}

/// The virtual wave options (as for every probe).
#[derive(Args, Debug)]
pub(crate) struct WaveArgs {
    /// Virtual wavelength λ in metres (default: twice the aperture pitch).
    #[arg(long, value_name = "M")]
    pub(crate) wavelength: Option<f64>,
    /// Std of the Gaussian time gate in metres of path (default 2λ/3).
    #[arg(long, value_name = "M")]
    pub(crate) sigma: Option<f64>,
    /// Lens weights per leg: inv = the paper's 1/d, one = none (y-tal), cos = 1/d times the
    /// wall's cosine at the leg's spot (per-point normals; `direct` on paired and confocal scans).
    #[arg(long, value_enum, default_value_t = WeightsArg::Inv)]
    pub(crate) weights: WeightsArg,
    /// Frequency band half-width in units of 1/σ (truncation error ≈ erfc(m/√2)).
    #[arg(long, default_value_t = 5.0, value_name = "M")]
    pub(crate) band: f64,
    /// Divide each laser row by the physical laser's cos θ / d² falloff to its spot.
    #[arg(long)]
    pub(crate) compensate_laser: bool,
    /// Keep the whole time axis and the default DFT period (by default the axis is cropped to
    /// the bins the probed voxels can reach, with the gate's support, before the band
    /// transform, and `direct`'s period shrunk to its paths' span).
    #[arg(long)]
    pub(crate) no_crop: bool,
}

impl WaveArgs {
    /// The probes' wave options.
    pub(crate) fn wave(&self) -> Wave {
        Wave {
            wavelength: self.wavelength,
            sigma: self.sigma,
            weights: match self.weights {
                WeightsArg::Inv | WeightsArg::Cos => Weights::Inv,
                WeightsArg::One => Weights::One,
            },
            cosine: matches!(self.weights, WeightsArg::Cos),
            band_half_width: self.band,
            compensate_laser: self.compensate_laser,
            auto_margin: true,
            crop: !self.no_crop,
        }
    }
}

/// `--leak-correct [METHOD]` and `--no-leak-correct`, the same in every command that removes
/// the capture's direct light first (`indirect`, `column`, `row`, `relight`, `matrix`,
/// `live`).
#[derive(Args, Debug)]
pub(crate) struct LeakMethodArgs {
    /// How the capture's direct light is removed first: gate (the default; alone,
    /// `--leak-correct` means it) zeroes, per laser/SPAD pair, the bins where a 3-vertex return
    /// of a voxel of Γ (the voxels whose direct light is above the command's threshold) can
    /// arrive; model subtracts a surface model fitted to the capture (by `live`, to the whole
    /// scan once it is in), falling back to gate (with a warning saying why) when it explains
    /// less than 99 % of the energy; auto runs gate's pass and tries model only where the
    /// energy the windows leave lies mostly next to them (extended surfaces; not for `live`
    /// or a partial scan). See docs/indirect-light.md.
    #[arg(
        long,
        value_enum,
        value_name = "METHOD",
        num_args = 0..=1,
        default_value_t = LeakArg::Gate,
        default_missing_value = "gate",
        conflicts_with = "no_leak_correct"
    )]
    pub(crate) leak_correct: LeakArg,
    /// The capture as it is, no leak correction (for `indirect`, the paper's Eq. 17): the
    /// capture's direct light passes the gate near the projector's own surface.
    #[arg(long)]
    pub(crate) no_leak_correct: bool,
}

impl LeakMethodArgs {
    /// The method asked for, `None` with `--no-leak-correct`.
    pub(crate) fn method(&self) -> Option<LeakArg> {
        (!self.no_leak_correct).then_some(self.leak_correct)
    }
}

/// The leak correction of `column`, `row`, `relight` and `matrix`: on by default, as
/// `indirect`'s.
#[derive(Args, Debug)]
pub(crate) struct LeakArgs {
    #[command(flatten)]
    pub(crate) how: LeakMethodArgs,
    /// Relative threshold of the Γ voxels whose direct returns the leak correction removes.
    #[arg(long, default_value_t = 0.1, value_name = "E")]
    pub(crate) leak_epsilon: f32,
}

impl LeakArgs {
    /// The method asked for, `None` with `--no-leak-correct`.
    pub(crate) fn method(&self) -> Option<LeakArg> {
        self.how.method()
    }
}

/// `--leak-correct`'s methods.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LeakArg {
    /// Zero the time windows of Γ's direct returns.
    Gate,
    /// Subtract a surface model fitted to the capture (the windows when it explains too
    /// little).
    Model,
    /// The windows, or the surface model where most of the energy the windows leave lies
    /// within one window half-width of them (an adjacency of at least 0.4).
    Auto,
}

/// `vltm relight`.
#[derive(Args, Debug)]
pub(crate) struct RelightArgs {
    /// Capture file.
    pub(crate) capture: PathBuf,
    /// The illumination: weighted foci "x,y,z,w;x,y,z,w" (metres; w = 1 if left out), or a
    /// float32 .npy voxel image of the volume's shape (its voxels are the foci).
    #[arg(long, value_name = "x,y,z,w;...|F.npy", allow_hyphen_values = true)]
    pub(crate) pattern: String,
    #[command(flatten)]
    pub(crate) leak: LeakArgs,
    #[command(flatten)]
    pub(crate) common: Common,
}

/// `vltm row`.
#[derive(Args, Debug)]
pub(crate) struct RowArgs {
    /// Capture file.
    pub(crate) capture: PathBuf,
    /// Focus x_b of the virtual camera, "X,Y,Z" in metres (z > 0).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub(crate) focus: String,
    #[command(flatten)]
    pub(crate) leak: LeakArgs,
    #[command(flatten)]
    pub(crate) common: Common,
}

/// `vltm live` arguments.
#[derive(Args, Debug)]
pub(crate) struct LiveArgs {
    /// What to follow: a PicoQuant .ptu (T3) file still being written (followed like
    /// `tail -f`), `-` (a T3 record stream on standard input, header first), or any capture
    /// vltm reads, replayed at --replay-rate.
    pub(crate) source: PathBuf,
    /// Voxels: "x0:x1:nx,y0:y1:ny,z0:z1:nz" (metres, inclusive end points) or "x,y,z;x,y,z".
    #[arg(long, value_name = "SPEC", allow_hyphen_values = true)]
    pub(crate) volume: String,
    /// Focus x_a of a two-bounce column run row by row beside the direct light, "X,Y,Z" in
    /// metres (repeatable).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub(crate) focus: Vec<String>,
    /// Output volume F.npy (or F.h5): the direct light; columns `F.column<i>.npy`, the in-focus
    /// indirect light F.indirect.npy, figures beside them (.png), partial states
    /// `F.<probe>.part`, the summed transient F.transient.png.
    #[arg(long, value_name = "F.npy|F.h5")]
    pub(crate) out: PathBuf,
    /// Write the volumes, figures and partial states every K rows (0: only at the end).
    #[arg(long, value_name = "K", default_value_t = 8)]
    pub(crate) every: usize,
    /// Continue an interrupted run from its partial states (F.direct.part and every
    /// `F.column<i>.part`; repeat the option).
    #[arg(long, value_name = "STATE")]
    pub(crate) resume: Vec<PathBuf>,
    /// End the stream when a followed file has not grown for S seconds.
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    pub(crate) idle_timeout: f64,
    /// Replay the capture at this many rows per second (any capture; a .ptu file is then read
    /// as finished instead of followed).
    #[arg(long, value_name = "ROWS/s")]
    pub(crate) replay_rate: Option<f64>,
    /// The PTU sidecar (default: the .ptu file with extension .json; needed for `-`).
    #[arg(long, value_name = "F.json")]
    pub(crate) sidecar: Option<PathBuf>,
    /// Serve a live page at this address: PORT or ADDR:PORT (loopback unless an address is
    /// given).
    #[arg(long, value_name = "127.0.0.1:PORT")]
    pub(crate) serve: Option<String>,
    /// Keep serving the page this many seconds after the run ends.
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    pub(crate) linger: f64,
    /// Γ threshold of the in-focus indirect light at the end (relative to the direct
    /// light's maximum).
    #[arg(long, value_name = "E", default_value_t = 0.1)]
    pub(crate) epsilon: f32,
    /// Skip the in-focus indirect light at the end.
    #[arg(long)]
    pub(crate) no_indirect: bool,
    #[command(flatten)]
    pub(crate) leak: LeakMethodArgs,
    #[command(flatten)]
    pub(crate) wave: WaveArgs,
    /// Evaluation path of the direct light and the columns (as the probes' --path).
    #[arg(long, value_enum, default_value_t = PathArg::Auto)]
    pub(crate) path: PathArg,
}
