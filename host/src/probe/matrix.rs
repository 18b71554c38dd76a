//! The LTM as a matrix: complex amplitudes `A(x_a, x_b)` of the two-bounce (Gaussian-gated,
//! Eq. 14) transport between two voxel sets ([`matrix`]), and relighting ([`relight`]): the
//! virtual camera's image `A_p(b) = Σ_a p_a·A(a, b)` under a virtual illumination that is a
//! weighted sum of projector foci.
//!
//! **Method.** Both use the factorised column of the kernel: per laser row
//! and per focus `a`, `U_a[s][j] += w(|x_l − x_a|)·e^{iν_j|x_l − x_a|}·HG_ls[j]`, then at the end
//! `A(a, b) = Σ_s w(|x_b − x_s|) Σ_j e^{iν_j(|x_a − x_b| + |x_b − x_s|)}·U_a[s][j]`. The
//! amplitudes are imaged on the host ([`column_amplitudes`]) with exactly the arithmetic of
//! the kernel's `Probe::image` (the same `f32` phase recurrences, `f64` sums), so
//! `|A(a, b)|²` is the kernel's column intensity bit for bit when the configuration is the
//! same. Intensities are `T = |A|²`. One [`Wave::column_config`] (automatic margin over all
//! pairs) serves every element, so no element wraps around the DFT period.
//!
//! **Relighting and linearity.** The projector side of `A` is linear in the illumination:
//! a pattern `p` (weights on foci) gives `A_p(b) = Σ_a p_a A(a, b)` in the same single pass
//! over the capture, one factorised accumulator per focus with a non-zero weight. The foci
//! cannot share one accumulator: the 4-vertex gate is centred on `|x_l − x_a| + |x_a − x_b| +
//! |x_b − x_s|`, whose middle leg couples each focus to each imaged voxel, so the per-focus
//! spectra are combined at imaging time, per voxel.
//!
//! **Cost.** Per laser row `K_a·Ks·8J` flops (one factorised push per focus, in parallel);
//! at the end `K_a·K_b·Ks·14J` (imaging). The capture is read once per pass.
//!
//! **Memory** (checked with [`crate::budget::check`] before anything is allocated):
//! accumulators of `16·J·(Ks + 1)` bytes per focus of a pass ([`Probe::state_bytes`]),
//! and for [`matrix`] the result: [`MATRIX_BYTES_PER_ELEMENT`] bytes per element
//! (`Complex32` amplitudes, 8 B, plus what the HDF5 writer holds while it encodes the file:
//! `re`, `im`, `intensity` as `f32` and their encoded copy, 36 B), and while imaging,
//! `16·n_to` bytes per column of a group of `4·threads` foci (measured, 2026-11-25, 2 cores:
//! 10 × 10⁶ elements peak at 437 MB resident, 43.7 B per element, against 7.8 MB for a
//! 10 × 10 matrix). If the accumulators of all
//! foci do not fit beside the result, the foci are split into passes (each reads the capture
//! once more); if not even one focus fits, the error names `--from`/`--to` (matrix) or
//! `--pattern` (relight). Per-thread row buffers: `4·threads` rows of histograms (two batches), as every probe.

use super::column::{Columns, column_aliased, column_amplitudes, factorised_columns};
use super::crop::{Crop, Reach, with_crop};
use super::drive::*;
use super::output::Output;
use super::wave::*;
use crate::budget;
use crate::error::{Error, Result};
use crate::exec::{Exec, chunk_len};
use crate::io::capture::{Geometry, RowSource};
use crate::volume::Volume;
use num_complex::{Complex32, Complex64};
use rayon::prelude::*;
use std::time::Instant;
use vltm_kernel::{Config, Gate, Point, Probe, Report, Scan, Target};

/// Bytes per element of a [`matrix`] held at its peak (amplitudes, and the HDF5 writer's
/// `re`, `im`, `intensity` and their encoded copy): `8 + 3·4 + 3·4 + 3·4`.
pub const MATRIX_BYTES_PER_ELEMENT: u128 = 44;

/// Bytes of the amplitudes of one group of foci being imaged (`4·threads` columns of
/// `16·n` bytes).
fn imaging_bytes(n: usize) -> u128 {
    budget::bytes(
        4 * rayon::current_num_threads().max(1),
        budget::bytes(n, 16),
    )
}

/// The two-bounce LTM restricted to `from × to` (see the module docs).
#[derive(Clone, Debug)]
pub struct Matrix {
    /// Amplitudes `A(from[i], to[k])` at `i·to.len() + k` (row-major: one row per focus).
    pub amplitudes: Vec<Complex32>,
    /// Number of focus points (rows).
    pub n_from: usize,
    /// Number of imaged voxels (columns).
    pub n_to: usize,
    /// Counters (rows of the last pass; `aliased`: elements outside the alias-free window).
    pub report: Report,
    /// Passes over the capture.
    pub passes: usize,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// The kernel configuration (λ, σ, J, margin), of the cropped time axis.
    pub config: Config,
    /// The part of the time axis kept ([`Wave::crop`]: the paths between the two sets);
    /// `None`: all of it.
    pub crop: Option<Crop>,
}

impl Matrix {
    /// Intensities `T = |A|²`, in the order of [`Matrix::amplitudes`].
    pub fn intensities(&self) -> Vec<f32> {
        self.amplitudes
            .iter()
            .map(|z| {
                let (re, im) = (f64::from(z.re), f64::from(z.im));
                (re * re + im * im) as f32
            })
            .collect()
    }
}

/// Result of [`relight`].
#[derive(Clone, Debug)]
pub struct Relit {
    /// Amplitudes `A_p(b)` per voxel (volume order).
    pub amplitudes: Vec<Complex64>,
    /// The probe's output: intensities `|A_p(b)|²`, counters, configuration.
    pub output: Output,
    /// Passes over the capture.
    pub passes: usize,
}

/// Checks a set of foci (non-empty, in front of the wall).
fn check_set(arg: &str, pts: &[Point]) -> Result<()> {
    if pts.is_empty() {
        return Err(Error::arg(arg, "the voxel set is empty"));
    }
    if let Some(p) = pts
        .iter()
        .find(|p| !(p.iter().all(|c| c.is_finite()) && p[2] > 0.0))
    {
        return Err(Error::arg(
            arg,
            format!("{p:?} is on or behind the wall (need z > 0)"),
        ));
    }
    Ok(())
}

/// How many foci one pass can hold beside `fixed` bytes of results; an error naming `arg`
/// when not even one fits.
fn foci_per_pass(
    cfg: &Config,
    ks: usize,
    n_foci: usize,
    fixed: u128,
    arg: &str,
    what: &str,
) -> Result<usize> {
    let per =
        Probe::state_bytes(cfg, Target::Column([0.0, 0.0, 1.0]), Gate::Gaussian, 0, ks) as u128;
    let all = fixed.saturating_add(per.saturating_mul(n_foci as u128));
    if budget::check(String::new, all).is_ok() {
        return Ok(n_foci.max(1));
    }
    budget::check(
        || format!("argument `{arg}`: {what} and one focus's accumulator"),
        fixed.saturating_add(per),
    )?;
    let room = u128::from(budget::get()) - fixed;
    Ok(((room / per.max(1)) as usize).clamp(1, n_foci.max(1)))
}

/// Images the factorised columns `probes` (one per focus of `foci`) over `voxels`, in
/// parallel over groups of foci and chunks of voxels, handing `sink(i, amplitudes)` every
/// focus `i` in order (deterministic sums). Returns the aliased elements.
fn image_foci(
    probes: &[Probe<'_>],
    scan: &Scan<'_>,
    foci: &[Point],
    voxels: &[Point],
    mut sink: impl FnMut(usize, Vec<Complex64>),
) -> usize {
    let cl = chunk_len(voxels.len());
    let group = 4 * rayon::current_num_threads().max(1);
    let mut aliased = 0;
    for (k, (ps, fs)) in probes.chunks(group).zip(foci.chunks(group)).enumerate() {
        let imaged: Vec<(Vec<Complex64>, usize)> = ps
            .par_iter()
            .zip(fs)
            .map(|(p, a)| {
                let mut amp = vec![Complex64::new(0.0, 0.0); voxels.len()];
                voxels
                    .par_chunks(cl)
                    .zip(amp.par_chunks_mut(cl))
                    .for_each(|(v, o)| column_amplitudes(p, scan, *a, v, o));
                let legs = p.column_spectra().map_or((0.0, -1.0), |(_, l)| l);
                (amp, column_aliased(scan, *a, voxels, legs))
            })
            .collect();
        for (i, (amp, al)) in imaged.into_iter().enumerate() {
            aliased += al;
            sink(k * group + i, amp);
        }
    }
    aliased
}

/// One pass: a factorised Gaussian column per focus of `foci`, then `sink(i, amplitudes)`
/// for every focus `i` in order (imaged in parallel over groups of foci and chunks of
/// `voxels`). Returns the counters.
fn amplitude_pass(
    src: &mut dyn RowSource,
    job: Job<'_>,
    foci: &[Point],
    voxels: &[Point],
    label: &str,
    sink: impl FnMut(usize, Vec<Complex64>),
) -> Result<Report> {
    let cfg = job.cfg;
    let g = src.geometry().clone();
    g.need_spad_grid(label, "the matrix needs")?;
    let ks = g.spads_per_row();
    let n_state = Probe::state_len(cfg, Target::Column(foci[0]), Gate::Gaussian, 0, ks);
    let mut states: Vec<Vec<f64>> = foci.iter().map(|_| vec![0.0; n_state]).collect();
    let probes = drive_probes(
        src,
        job,
        label,
        states.iter_mut().map(Vec::as_mut_slice),
        |scan, k, s| Probe::new(scan, Target::Column(foci[k]), Gate::Gaussian, &[], s),
    )?;
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, &g.spads, &mut tables)?;
    let aliased = image_foci(&probes, &scan, foci, voxels, sink);
    let rows = probes.first().map(Probe::report).unwrap_or_default();
    Ok(Report { aliased, ..rows })
}

/// The budget check of a `n_from × n_to` result (shared by [`matrix`] and [`matrix_acc`]).
fn check_result(nf: usize, nt: usize) -> Result<u128> {
    let out_bytes = budget::bytes(nf, budget::bytes(nt, MATRIX_BYTES_PER_ELEMENT));
    budget::check(
        || {
            format!(
                "argument `$from`/`$to`: a {nf} x {nt} matrix ({MATRIX_BYTES_PER_ELEMENT} B per element)"
            )
        },
        out_bytes,
    )?;
    Ok(out_bytes)
}

/// The accumulators of [`matrix`] over the source's rows ([`RowSource::rows`]: a part of a
/// scan split by rows, `vltm matrix --rows A:B --partial F`): one factorised column per focus
/// of `from`, all in one pass (a partial state holds them all), with the configuration
/// [`matrix`] derives (from the whole capture's geometry and both sets).
///
/// # Errors
/// As [`matrix`]; [`Error::Memory`] naming `--from` when the accumulators of all foci do not
/// fit beside the result.
pub(super) fn matrix_acc(
    src: &mut dyn RowSource,
    from: &[Point],
    to: &[Point],
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<(Columns, Config)> {
    check_set("from", from)?;
    check_set("to", to)?;
    let (nf, nt) = (from.len(), to.len());
    let out_bytes = check_result(nf, nt)?;
    src.geometry()
        .need_spad_grid("matrix", "the matrix needs")?;
    let base = wave.config(src.geometry())?;
    super::window::window_rule(
        src.geometry(),
        &base,
        Some(from),
        to,
        super::gate::ColumnGate::TwoBounce,
        exec,
    )?;
    let reach = Reach {
        foci: Some(from),
        voxels: to,
        late: false,
    };
    with_crop(src, wave, exec, reach, |src, exec, _| {
        let cfg = wave.column_config(src.geometry(), from, to)?;
        let ks = src.geometry().spads_per_row();
        let per = Probe::state_bytes(&cfg, Target::Column([0.0, 0.0, 1.0]), Gate::Gaussian, 0, ks)
            as u128;
        budget::check(
            || {
                format!(
                    "argument `$from`: the accumulators of all {nf} foci (a partial state holds them all) and the matrix"
                )
            },
            out_bytes
                .saturating_add(imaging_bytes(nt))
                .saturating_add(per.saturating_mul(nf as u128)),
        )?;
        let job = Job {
            cfg: &cfg,
            wave,
            exec,
        };
        let cols = factorised_columns(src, job, from, Gate::Gaussian, "matrix")?;
        Ok((cols, cfg))
    })
}

/// The matrix from the accumulated columns of [`matrix_acc`] (a merged, complete partial
/// state), imaged exactly as [`matrix`] images its pass; `spads` are the capture's SPAD spots.
///
/// # Errors
/// Kernel errors (sizes).
pub(super) fn matrix_of_columns(
    cols: &mut Columns,
    cfg: &Config,
    spads: &[Point],
    from: &[Point],
    to: &[Point],
) -> Result<Matrix> {
    let t = Instant::now();
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, spads.len())];
    let scan = Scan::new(cfg, spads, &mut tables)?;
    let n_state = Probe::state_len(
        cfg,
        Target::Column([0.0, 0.0, 1.0]),
        Gate::Gaussian,
        0,
        spads.len(),
    );
    let report = cols.report;
    let probes = cols
        .state
        .chunks_mut(n_state.max(1))
        .zip(from)
        .zip(&cols.legs)
        .map(|((st, a), legs)| {
            Probe::resume(
                &scan,
                Target::Column(*a),
                Gate::Gaussian,
                &[],
                st,
                report,
                *legs,
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let nt = to.len();
    let mut amplitudes = vec![Complex32::new(0.0, 0.0); from.len() * nt];
    let aliased = image_foci(&probes, &scan, from, to, |i, amp| {
        for (o, z) in amplitudes[i * nt..(i + 1) * nt].iter_mut().zip(amp) {
            *o = Complex32::new(z.re as f32, z.im as f32);
        }
    });
    Ok(Matrix {
        amplitudes,
        n_from: from.len(),
        n_to: nt,
        report: Report { aliased, ..report },
        passes: 1,
        seconds: t.elapsed().as_secs_f64(),
        config: *cfg,
        crop: None,
    })
}

/// The two-bounce LTM restricted to `from × to` (amplitudes; see the module docs for the
/// method, cost and memory). Reads the capture once per pass (one pass unless the
/// accumulators of all `from` foci do not fit the memory budget).
///
/// # Errors
/// [`Error::Argument`] (`from`/`to`) for an empty set or a point on or behind the wall;
/// [`Error::Memory`] naming `--from`/`--to` when the result does not fit the budget;
/// configuration, read and kernel errors.
pub fn matrix(
    src: &mut dyn RowSource,
    from: &[Point],
    to: &[Point],
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<Matrix> {
    wave.refuse_cosine("`matrix`")?;
    check_set("from", from)?;
    check_set("to", to)?;
    let t = Instant::now();
    let (nf, nt) = (from.len(), to.len());
    let out_bytes = check_result(nf, nt)?;
    let base = wave.config(src.geometry())?;
    super::window::window_rule(
        src.geometry(),
        &base,
        Some(from),
        to,
        super::gate::ColumnGate::TwoBounce,
        exec,
    )?;
    let reach = Reach {
        foci: Some(from),
        voxels: to,
        late: false,
    };
    let (amplitudes, report, passes, cfg, crop) =
        with_crop(src, wave, exec, reach, |src, exec, crop| {
            let cfg = wave.column_config(src.geometry(), from, to)?;
            let ks = src.geometry().spads_per_row();
            let fixed = out_bytes.saturating_add(imaging_bytes(nt));
            let per_pass = foci_per_pass(&cfg, ks, nf, fixed, "from", "the matrix")?;
            let mut amplitudes = vec![Complex32::new(0.0, 0.0); nf * nt];
            let mut report = Report::default();
            let mut passes = 0;
            for (c, foci) in from.chunks(per_pass).enumerate() {
                let rows = &mut amplitudes[c * per_pass * nt..];
                let r = amplitude_pass(
                    src,
                    Job {
                        cfg: &cfg,
                        wave,
                        exec,
                    },
                    foci,
                    to,
                    "matrix",
                    |i, amp| {
                        for (o, z) in rows[i * nt..(i + 1) * nt].iter_mut().zip(amp) {
                            *o = Complex32::new(z.re as f32, z.im as f32);
                        }
                    },
                )?;
                report = Report {
                    aliased: report.aliased + r.aliased,
                    ..r
                };
                passes += 1;
            }
            Ok((amplitudes, report, passes, cfg, crop))
        })?;
    Ok(Matrix {
        amplitudes,
        n_from: nf,
        n_to: nt,
        report,
        passes,
        seconds: t.elapsed().as_secs_f64(),
        config: cfg,
        crop,
    })
}

/// A relighting pattern: focus points with weights (zero weights are dropped).
#[derive(Clone, Debug, PartialEq)]
pub struct Pattern {
    /// Focus points `x_a` (m, z > 0).
    pub foci: Vec<Point>,
    /// Their weights `p_a` (non-zero).
    pub weights: Vec<f64>,
}

impl Pattern {
    /// A pattern from points and weights; points with weight 0 are dropped.
    ///
    /// # Errors
    /// [`Error::Argument`] (`pattern`) when no weight is non-zero, a weight is not finite,
    /// or a point is on or behind the wall.
    pub fn new(points: &[(Point, f64)]) -> Result<Self> {
        if let Some((p, w)) = points.iter().find(|(_, w)| !w.is_finite()) {
            return Err(Error::arg(
                "pattern",
                format!("the weight of {p:?} is {w}, not a finite number"),
            ));
        }
        let kept: Vec<&(Point, f64)> = points.iter().filter(|(_, w)| *w != 0.0).collect();
        if kept.is_empty() {
            return Err(Error::arg(
                "pattern",
                "no focus has a non-zero weight: the illumination would be dark",
            ));
        }
        let foci: Vec<Point> = kept.iter().map(|(p, _)| *p).collect();
        check_set("pattern", &foci)?;
        Ok(Self {
            foci,
            weights: kept.iter().map(|(_, w)| *w).collect(),
        })
    }

    /// Parses `x,y,z,w;x,y,z,w;…` (metres, weights) — a weight may be left out (1).
    ///
    /// # Errors
    /// [`Error::Argument`] (`pattern`) for malformed entries and as [`Pattern::new`].
    pub fn parse(s: &str) -> Result<Self> {
        let mut pts = Vec::new();
        for item in s.split(';').map(str::trim).filter(|i| !i.is_empty()) {
            let nums: Vec<f64> = item
                .split(',')
                .map(|x| x.trim().parse::<f64>())
                .collect::<std::result::Result<_, _>>()
                .map_err(|_| {
                    Error::arg(
                        "pattern",
                        format!("expected x,y,z,w numbers separated by `;`, found `{item}`"),
                    )
                })?;
            let (p, w) = match nums[..] {
                [x, y, z] => ([x as f32, y as f32, z as f32], 1.0),
                [x, y, z, w] => ([x as f32, y as f32, z as f32], w),
                _ => {
                    return Err(Error::arg(
                        "pattern",
                        format!("expected x,y,z or x,y,z,w, found `{item}`"),
                    ));
                }
            };
            pts.push((p, w));
        }
        Self::new(&pts)
    }

    /// A voxel image over `volume` (one weight per voxel, volume order) as a pattern.
    ///
    /// # Errors
    /// [`Error::Argument`] (`pattern`) when the image does not have one value per voxel,
    /// and as [`Pattern::new`].
    pub fn from_image(volume: &Volume, image: &[f32]) -> Result<Self> {
        if image.len() != volume.len() {
            return Err(Error::arg(
                "pattern",
                format!(
                    "the image has {} values, the volume {} voxels (shape {:?})",
                    image.len(),
                    volume.len(),
                    volume.shape
                ),
            ));
        }
        let pts: Vec<(Point, f64)> = volume
            .points
            .iter()
            .zip(image)
            .map(|(p, w)| (*p, f64::from(*w)))
            .collect();
        Self::new(&pts)
    }
}

/// The checks [`relight`] makes before it reads a row: the lens weights, a SPAD grid and the
/// capture's window; for a front end that runs another pass first (the leak correction's Γ).
///
/// # Errors
/// As [`relight`]'s argument errors.
pub fn check_relight(g: &Geometry, pattern: &Pattern, volume: &Volume, wave: &Wave) -> Result<()> {
    wave.refuse_cosine("`relight`")?;
    g.need_spad_grid("relight", "the matrix needs")?;
    let base = wave.config(g)?;
    super::window::window_rule(
        g,
        &base,
        Some(&pattern.foci),
        &volume.points,
        super::gate::ColumnGate::TwoBounce,
        Exec::default(),
    )
    .map(|_| ())
}

/// Relighting: `A_p(b) = Σ_a p_a A(a, b)` over `volume`, intensities `|A_p|²` (see the
/// module docs). One pass over the capture unless the accumulators of all foci exceed the
/// memory budget.
///
/// # Errors
/// [`Error::Memory`] naming `--pattern` when not even one focus's accumulator fits;
/// configuration, read and kernel errors.
pub fn relight(
    src: &mut dyn RowSource,
    pattern: &Pattern,
    volume: &Volume,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<Relit> {
    wave.refuse_cosine("`relight`")?;
    let t = Instant::now();
    let nb = volume.len();
    let fixed = budget::bytes(nb, 16).saturating_add(imaging_bytes(nb));
    let base = wave.config(src.geometry())?;
    super::window::window_rule(
        src.geometry(),
        &base,
        Some(&pattern.foci),
        &volume.points,
        super::gate::ColumnGate::TwoBounce,
        exec,
    )?;
    let reach = Reach {
        foci: Some(&pattern.foci),
        voxels: &volume.points,
        late: false,
    };
    let (acc, report, passes, cfg, crop) = with_crop(src, wave, exec, reach, |src, exec, crop| {
        let cfg = wave.column_config(src.geometry(), &pattern.foci, &volume.points)?;
        let ks = src.geometry().spads_per_row();
        let per_pass = foci_per_pass(
            &cfg,
            ks,
            pattern.foci.len(),
            fixed,
            "pattern",
            "the relit image",
        )?;
        let mut acc = vec![Complex64::new(0.0, 0.0); nb];
        let mut report = Report::default();
        let mut passes = 0;
        for (foci, weights) in pattern
            .foci
            .chunks(per_pass)
            .zip(pattern.weights.chunks(per_pass))
        {
            let r = amplitude_pass(
                src,
                Job {
                    cfg: &cfg,
                    wave,
                    exec,
                },
                foci,
                &volume.points,
                "relight",
                |i, amp| {
                    for (o, z) in acc.iter_mut().zip(amp) {
                        *o += z * weights[i];
                    }
                },
            )?;
            report = Report {
                aliased: report.aliased + r.aliased,
                ..r
            };
            passes += 1;
        }
        Ok((acc, report, passes, cfg, crop))
    })?;
    let amplitudes = acc;
    let values = amplitudes.iter().map(|z| z.norm_sqr() as f32).collect();
    Ok(Relit {
        amplitudes,
        output: Output {
            values,
            report,
            seconds: t.elapsed().as_secs_f64(),
            config: cfg,
            path: crate::exec::EvalPath::Band,
            crop,
            aligned: None,
        },
        passes,
    })
}
