//! The surface model of a capture (analysis by synthesis, Stage 2 of issue 34): the whole
//! pipeline from the capture alone to a fitted model of its direct light, which
//! [`Synthesized`] subtracts row by row (`--leak-correct model` in the command line).
//!
//! # Pipeline ([`model_of_capture`])
//!
//! 1. **Direct-light image** at the wavelength [`geometry_wavelength`] (half the wall's pitch),
//!    or the shortest whose band the bins resolve, `2.2·Δt·(1 + 3m/4π)` (`m` the band's
//!    half-width, σ = 2λ/3), when that is longer (the user's other wave options kept), on a
//!    fine grid ([`ModelOptions::volume`], or by default: x–y the laser and SPAD spots'
//!    extent widened by one step, at a step of about half that wavelength that divides the
//!    wall's pitch, so that the FFT path takes it; z the depths the time window reaches
//!    ([`window_depths`]) at a step of two bins `2·Δt`, at most 512 depths: the brightest
//!    depth of a column is refined by a parabola, and the refinement corrects centimetres).
//!    A capture of more than [`IMAGE_HISTOGRAMS`] (1,024) histograms is imaged from every
//!    second laser row and column, all SPADs kept.
//! 2. **Surfels** of the columns brighter than [`ModelOptions::epsilon`] of the maximum
//!    ([`Surfels::from_direct`]), split into planar **facets** ([`facets_from_surfels`], split
//!    tolerance [`ModelOptions::split_tol`] × the grid's lateral step).
//! 3. The facets' poses and edges **refined** and missing faces grown against the capture
//!    ([`refine_facets`], [`ModelOptions::facets`]: at most `sweeps` sweeps per round and
//!    `grow` rounds, every corner inside the image's grid widened by [`BOUNDS_MARGIN`] of its
//!    size on each side unless `facets.bounds` says otherwise, at most `facets.work` surfel
//!    returns laid out, [`crate::probe::synth::REFINE_WORK`] by default), then sampled every
//!    `facets.pitch` metres as surfels. Non-finite samples read as 0 in every pass, as the
//!    probes read them.
//! 4. The surfels' render **fitted** to the capture ([`SynthModel::fit`],
//!    [`ModelOptions::fit`]); the energy it explains is [`SurfaceModel::explained`].
//!
//! # When the model is not used ([`ModelOutcome::Unexplained`])
//!
//! A paired or confocal scan (the model needs a SPAD grid seen from every laser row), a wall
//! of a single spot, no surface in the image, an image that splits into more than
//! [`ModelOptions::max_facets`] planar facets (default [`MAX_FACETS`]: a capture of noise
//! splits into many), a refinement that does not settle within `facets.work` surfel returns,
//! a fit that fails or is not finite, a surface at or behind the relay
//! wall, buffers over the memory budget, or a model that explains less than
//! [`ModelOptions::min_explained`] of the capture's energy (default 0.99; for a capture of
//! photon counts, every sample a non-negative integer, less the share `Σ H / Σ H²` of their
//! Poisson noise, which no model explains: [`SurfaceModel::photon_noise`]): the caller
//! falls back to the time windows ([`super::LeakMethod::Gate`]) and says why
//! ([`ModelOutcome::Unexplained`] holds the reason, one line). Options out of range and read
//! errors are errors.
//!
//! # Cost and memory
//!
//! Passes over the capture: one for the direct-light image (its planner's path), one over at
//! most [`FacetOptions::subset`]² laser rows × SPADs (16 × 16 by default) for the refinement,
//! two for the fit; then the probes read the capture minus the model (each row rendered once
//! more). Memory, checked against the budget before the first pass: the image (`4·V` bytes,
//! plus its pass's own plan), the column surfels (`≤ 64·nx·ny·sub²` bytes), the refinement's
//! residual and its renders of a facet and 14 moves (`128·pairs·Nt` bytes); and before the
//! fit, its SPAD tables (`8·K·S` bytes).

use crate::budget;
use crate::error::{Error, Result};
use crate::exec::Exec;
use crate::io::capture::{Geometry, RowSource};
use crate::probe::direct::direct;
use crate::probe::fast::aligned::window_depths;
use crate::probe::synth::{
    Facet, FacetFit, FacetOptions, Surfels, SynthModel, SynthOptions, Synthesized,
    facet_legs_bytes, facets_from_surfels, geometry_wavelength, refine_facets,
};
use crate::probe::wave::Wave;
use crate::timings::{self, Kind};
use crate::volume::Volume;
use std::time::Instant;

/// How [`model_of_capture`] builds the surface model (each checked by [`ModelOptions::check`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ModelOptions {
    /// The grid of the direct-light image the surfaces are read from (`None`: derived from the
    /// capture, see the module docs).
    pub volume: Option<Volume>,
    /// The image's wavelength (m; `None`: [`geometry_wavelength`]).
    pub wavelength: Option<f64>,
    /// Columns brighter than this fraction of the image's maximum get surfels (default 0.1).
    pub epsilon: f32,
    /// Surfels per column side (default 5).
    pub sub: usize,
    /// A cluster whose RMS distance to its plane exceeds this many lateral steps of the grid
    /// is split (default 0.25).
    pub split_tol: f64,
    /// The refinement of the facets (sweeps, surfel pitch, growth).
    pub facets: FacetOptions,
    /// One cluster (reflectance, gains) per facet (default) or per cluster of the image.
    pub per_facet: bool,
    /// The fit of the render to the capture.
    pub fit: SynthOptions,
    /// The model is used when it explains at least this fraction of the capture's energy
    /// (default 0.99), less the share of its photon noise when the capture holds photon
    /// counts ([`SurfaceModel::photon_noise`]).
    pub min_explained: f64,
    /// An image that splits into more planar facets than this is not read as surfaces
    /// (default [`MAX_FACETS`]): the refinement's time grows with the facets, and a capture
    /// of noise splits into many.
    pub max_facets: usize,
}

/// The default of [`ModelOptions::max_facets`].
pub const MAX_FACETS: usize = 12;

/// How far beyond the direct-light image's grid a facet may reach, as a fraction of the
/// grid's size on each axis ([`FacetOptions::bounds`] when none is given; not toward the
/// wall, which bounds it).
pub const BOUNDS_MARGIN: f64 = 0.25;

impl Default for ModelOptions {
    fn default() -> Self {
        Self {
            volume: None,
            wavelength: None,
            epsilon: 0.1,
            sub: 5,
            split_tol: 0.25,
            facets: FacetOptions::default(),
            per_facet: true,
            fit: SynthOptions::default(),
            min_explained: 0.99,
            max_facets: MAX_FACETS,
        }
    }
}

impl ModelOptions {
    /// The defaults, the physical laser's `cos θ / d²` falloff rendered when `falloff` (a
    /// capture that holds it: `crate::io::laser_falloff_in_data`), as the command line's and
    /// Python's `leak_correct` model uses them.
    pub fn with_laser_falloff(falloff: bool) -> Self {
        Self {
            fit: SynthOptions {
                laser_falloff: falloff,
                ..SynthOptions::default()
            },
            ..Self::default()
        }
    }
}

/// The most sweeps per round of the refinement.
pub const MAX_SWEEPS: usize = 100;
/// The most facets grown.
pub const MAX_GROWN: usize = 32;

impl ModelOptions {
    /// Checks every option once.
    ///
    /// # Errors
    /// [`Error::Argument`] naming the option out of range: `surfel_volume` (not a grid with at
    /// least 3 depths), `surfel_wavelength` (not positive and finite), `surfel_epsilon`
    /// (outside (0, 1)), `surfel_sub` (outside 1..=16), `split_tol` (not positive and finite),
    /// `sweeps` (outside 1..=[`MAX_SWEEPS`]), `grow` (over [`MAX_GROWN`]), `pitch` (outside
    /// (0, 0.5] m), `grow_gain` (outside (0, 1)), `subset` (outside 1..=256), `bounds` (not a box of finite corners),
    /// `min_explained` (outside [0, 1]), `max_facets` (outside 1..=64), `work` (not positive
    /// and finite), `max_surfels` (outside 1..=2²⁰), and the fit's options
    /// ([`SynthOptions::check`]).
    pub fn check(&self) -> Result<()> {
        if let Some(v) = &self.volume
            && (v.axes.is_none() || v.shape[2] < 3)
        {
            return Err(Error::arg(
                "surfel_volume",
                "must be a grid (x, y and z ranges) with at least 3 depths",
            ));
        }
        if let Some(w) = self.wavelength
            && !(w.is_finite() && w > 0.0)
        {
            return Err(Error::arg(
                "surfel_wavelength",
                "must be positive and finite (m)",
            ));
        }
        if !(self.epsilon > 0.0 && self.epsilon < 1.0) {
            return Err(Error::arg("surfel_epsilon", "must lie in (0, 1)"));
        }
        if !(1..=16).contains(&self.sub) {
            return Err(Error::arg("surfel_sub", "must lie in 1..=16"));
        }
        if !(self.split_tol.is_finite() && self.split_tol > 0.0) {
            return Err(Error::arg(
                "split_tol",
                "must be positive and finite (lateral steps)",
            ));
        }
        let f = &self.facets;
        if !(1..=MAX_SWEEPS).contains(&f.sweeps) {
            return Err(Error::arg(
                "sweeps",
                format!("must lie in 1..={MAX_SWEEPS}"),
            ));
        }
        if f.grow > MAX_GROWN {
            return Err(Error::arg("grow", format!("must be at most {MAX_GROWN}")));
        }
        if !(f.pitch.is_finite() && f.pitch > 0.0 && f.pitch <= 0.5) {
            return Err(Error::arg("pitch", "must lie in (0, 0.5] m"));
        }
        if !(f.grow_gain.is_finite() && f.grow_gain > 0.0 && f.grow_gain < 1.0) {
            return Err(Error::arg("grow_gain", "must lie in (0, 1)"));
        }
        if !(1..=256).contains(&f.subset) {
            return Err(Error::arg(
                "subset",
                "must lie in 1..=256 laser rows and SPADs",
            ));
        }
        if !(self.min_explained.is_finite() && (0.0..=1.0).contains(&self.min_explained)) {
            return Err(Error::arg("min_explained", "must lie in [0, 1]"));
        }
        if !(1..=64).contains(&self.max_facets) {
            return Err(Error::arg("max_facets", "must lie in 1..=64"));
        }
        f.check_bounds()?;
        f.check_work()?;
        self.fit.check()
    }
}

/// A fitted surface model of a capture's direct light.
#[derive(Clone, Debug)]
pub struct SurfaceModel {
    /// The fitted render ([`Synthesized`] subtracts it).
    pub model: SynthModel,
    /// The facets read from the direct-light image, before their refinement.
    pub initial: Vec<Facet>,
    /// The refined facets (diagnostics: poses, edges, amplitudes, sweeps).
    pub facets: FacetFit,
    /// The grid of the direct-light image.
    pub volume: Volume,
    /// Fraction of the capture's energy `Σ H²` the model explains ([`SynthModel::explained`]).
    pub explained: f64,
    /// The fraction of the energy a capture of photon counts holds as Poisson noise
    /// ([`SynthModel::photon_noise`]); the model must explain
    /// [`ModelOptions::min_explained`] less this.
    pub photon_noise: Option<f64>,
    /// Wall-clock seconds of the whole pipeline.
    pub seconds: f64,
}

impl SurfaceModel {
    /// The capture `src` minus the model, row by row.
    pub fn subtracted<'a>(&'a self, src: &'a mut dyn RowSource) -> Synthesized<'a> {
        Synthesized::new(src, &self.model)
    }
}

/// What [`model_of_capture`] found.
#[derive(Clone, Debug)]
pub enum ModelOutcome {
    /// The model explains enough of the capture: subtract it.
    Fitted(Box<SurfaceModel>),
    /// The model cannot be used; the reason, one line (other parameters written `$name`), and
    /// the model when one was fitted (it explains too little).
    Unexplained {
        /// Why, e.g. `the surface model explains 95.2 % of the energy (< 99 %)`.
        reason: String,
        /// The model that explains too little, if one was fitted.
        model: Option<Box<SurfaceModel>>,
    },
}

/// The default grid of the direct-light image (module docs), or why there is none.
fn default_volume(g: &Geometry, lam: f64) -> std::result::Result<Volume, String> {
    // Half the wavelength, rounded to divide the wall's pitch (the FFT path's lattice).
    let pitch = f64::from(
        vltm_kernel::geometry::pitch(&g.lasers, g.laser_shape)
            .max(vltm_kernel::geometry::pitch(&g.spads, g.spad_shape)),
    );
    let step = if pitch > 0.0 {
        pitch / (pitch / (0.5 * lam)).round().max(1.0)
    } else {
        0.5 * lam
    };
    let (lo, hi) = g.lasers.iter().chain(&g.spads).fold(
        ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
        |(lo, hi), p| {
            (
                [lo[0].min(f64::from(p[0])), lo[1].min(f64::from(p[1]))],
                [hi[0].max(f64::from(p[0])), hi[1].max(f64::from(p[1]))],
            )
        },
    );
    let dz = (2.0 * g.dt).max(1e-4);
    let Some((near, far)) = window_depths(g, dz) else {
        return Err("the capture's time window reaches no depth in front of the wall".into());
    };
    let nz = (((far - near) / dz).floor() as usize + 1).clamp(3, 512);
    let n = |i: usize| ((hi[i] - lo[i]) / step).round() as usize + 3;
    let (a, b) = ([lo[0] - step, lo[1] - step], [hi[0] + step, hi[1] + step]);
    Volume::grid(
        [a[0] as f32, a[1] as f32, near as f32],
        [b[0] as f32, b[1] as f32, far as f32],
        [n(0), n(1), nz],
    )
    .map_err(|e| format!("no grid for the direct-light image: {e}"))
}

/// A capture of more than this many histograms has its direct-light image of
/// [`model_of_capture`] taken from every second laser row and column (every SPAD kept): the
/// image only starts the facets, which are refined against every histogram. On the 8 × 8 ×
/// 8 × 8 captures (4,096 histograms) it took the image from 0.16–0.20 s to 0.04–0.05 s with
/// Stage 2 as good (panel/figure seed 0: 83.6× / 89.4× the control against 78.1× / 88.6×
/// from all of them); on the 16 × 16 × 16 × 16 render the image from all 65,536 took 22 s of
/// the model's 27 s. A coarser lattice loses the parallax the facets start from: every 8th
/// row and column there (1,024 histograms) left the figure at 19.9× against 25.2×.
pub const IMAGE_HISTOGRAMS: usize = 1_024;

/// The capture seen through every second row and column of its laser grid (all SPADs
/// kept), when it has more than [`IMAGE_HISTOGRAMS`] histograms.
struct LaserLattice<'a> {
    src: &'a mut dyn RowSource,
    keep: Vec<usize>,
    g: Geometry,
}

impl<'a> LaserLattice<'a> {
    /// `None` when the capture has at most [`IMAGE_HISTOGRAMS`] histograms, its laser spots
    /// are not the grid their shape states (or a single spot), or the scan is paired.
    fn of(src: &'a mut dyn RowSource) -> Option<Self> {
        let g = src.geometry();
        let [nx, ny] = g.laser_shape;
        let total = g.lasers.len().saturating_mul(g.spads.len());
        if g.confocal || total <= IMAGE_HISTOGRAMS || nx * ny != g.lasers.len() || nx * ny < 2 {
            return None;
        }
        let (xs, ys): (Vec<usize>, Vec<usize>) =
            ((0..nx).step_by(2).collect(), (0..ny).step_by(2).collect());
        let keep: Vec<usize> = xs
            .iter()
            .flat_map(|i| ys.iter().map(move |j| i * ny + j))
            .collect();
        let mut sub = g.clone();
        sub.lasers = keep.iter().map(|&l| g.lasers[l]).collect();
        sub.laser_shape = [xs.len(), ys.len()];
        if !g.normals.lasers.is_empty() {
            sub.normals.lasers = keep.iter().map(|&l| g.normals.lasers[l]).collect();
        }
        Some(Self { src, keep, g: sub })
    }
}

impl RowSource for LaserLattice<'_> {
    fn geometry(&self) -> &Geometry {
        &self.g
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<vltm_kernel::Point> {
        match self.keep.get(l) {
            Some(&k) => self.src.read_row(k, out),
            None => Err(Error::arg(
                "row",
                format!(
                    "row {l} of a sub-lattice of {} laser spots",
                    self.keep.len()
                ),
            )),
        }
    }
}

/// The default [`FacetOptions::bounds`]: the image's grid widened by [`BOUNDS_MARGIN`] of its
/// size on each side, but not behind `wall_z`.
fn bounds_of(v: &Volume, wall_z: f64) -> Option<[[f64; 3]; 2]> {
    let a = v.axes?;
    let (mut lo, mut hi) = ([0.0; 3], [0.0; 3]);
    for i in 0..3 {
        let (x0, x1) = (
            f64::from(a[i][0].min(a[i][1])),
            f64::from(a[i][0].max(a[i][1])),
        );
        let m = BOUNDS_MARGIN * (x1 - x0);
        lo[i] = x0 - m;
        hi[i] = x1 + m;
    }
    lo[2] = lo[2].max(wall_z);
    (0..3).all(|i| lo[i] < hi[i]).then_some([lo, hi])
}

/// Lateral step of a grid (the coarser of x and y).
fn lateral_step(v: &Volume) -> f64 {
    let step = |i: usize| match v.axes {
        Some(a) if v.shape[i] > 1 => f64::from(a[i][1] - a[i][0]).abs() / (v.shape[i] - 1) as f64,
        _ => 0.0,
    };
    step(0).max(step(1))
}

/// An error of a step of the pipeline: a read error is returned, anything else becomes the
/// reason the model is not used (an argument error's message without the internal parameter
/// it names; other parameters written `$name`).
fn reason(e: Error) -> Result<String> {
    match e {
        Error::Io { .. } | Error::Format { .. } => Err(e),
        Error::Argument { msg, .. } => Ok(msg),
        e => Ok(e.render(|p: &str| format!("${p}"))),
    }
}

/// Builds and fits the surface model of `src`'s direct light from the capture alone (module
/// docs): `wave` the probes' wave options (the image takes their weights, band and laser
/// compensation at its own wavelength), `opts` checked first.
///
/// # Errors
/// Options out of range ([`ModelOptions::check`]) and read errors. Everything else that
/// keeps the model from being used is a [`ModelOutcome::Unexplained`], never a panic.
pub fn model_of_capture(
    src: &mut dyn RowSource,
    wave: &Wave,
    opts: &ModelOptions,
    exec: Exec<'_>,
) -> Result<ModelOutcome> {
    opts.check()?;
    let t = Instant::now();
    let unexplained = |reason: String| ModelOutcome::Unexplained {
        reason,
        model: None,
    };
    let g = src.geometry().clone();
    if g.confocal {
        return Ok(unexplained(
            "the surface model needs a SPAD grid seen from every laser row, not a paired or confocal scan".into(),
        ));
    }
    // The shortest wavelength whose band (at σ = 2λ/3) stays below the bins' Nyquist
    // frequency, with a margin of 10 %.
    let shortest = 2.2 * g.dt * (1.0 + 3.0 * wave.band_half_width / (4.0 * std::f64::consts::PI));
    let by_geometry = geometry_wavelength(&g).map(|l| l.max(shortest));
    let Some(lam) = opts.wavelength.or(by_geometry) else {
        return Ok(unexplained(
            "a single laser or SPAD spot gives no image to read surfaces from".into(),
        ));
    };
    let volume = match &opts.volume {
        Some(v) => v.clone(),
        None => match default_volume(&g, lam) {
            Ok(v) => v,
            Err(r) => return Ok(unexplained(r)),
        },
    };
    // The buffers known before the first pass, checked together.
    let pairs = g.lasers.len().min(opts.facets.subset) * g.spads.len().min(opts.facets.subset);
    let mut plan = budget::Plan::new();
    plan.add(
        "the direct-light image",
        budget::bytes(volume.len(), 4 + 12),
    )
    .add(
        "the column surfels",
        budget::bytes(
            volume.shape[0] * volume.shape[1],
            64 * (opts.sub * opts.sub) as u128,
        ),
    )
    .add(
        "the refinement's residual and its renders of a facet and 14 moves",
        budget::bytes(pairs.saturating_mul(g.nt), 8 * 16),
    )
    .add(
        "the refinement's surfel legs",
        facet_legs_bytes(
            opts.facets.max_surfels,
            g.lasers.len().min(opts.facets.subset),
            g.spads.len().min(opts.facets.subset),
            rayon::current_num_threads(),
        ),
    );
    if let Err(e) = plan.check(|| "the surface model".into()) {
        return Ok(unexplained(reason(e)?));
    }
    let image_wave = Wave {
        wavelength: Some(lam),
        sigma: None,
        ..*wave
    };
    let image = {
        let mut lattice = LaserLattice::of(src);
        match lattice.as_mut() {
            Some(l) => direct(l, &volume, &image_wave, exec),
            None => direct(src, &volume, &image_wave, exec),
        }
    };
    let d = match image {
        Ok(d) => d,
        Err(e) => return Ok(unexplained(reason(e)?)),
    };
    let wall_z = g
        .lasers
        .iter()
        .chain(&g.spads)
        .map(|p| f64::from(p[2]))
        .fold(f64::NEG_INFINITY, f64::max);
    let step = lateral_step(&volume);
    let mut steps = || -> Result<(Vec<Facet>, FacetFit, Surfels)> {
        let raw = Surfels::from_direct(&volume, &d.values, opts.epsilon, opts.sub, wall_z)?;
        let initial = facets_from_surfels(&raw, opts.split_tol * step, step)?;
        if initial.len() > opts.max_facets {
            return Err(Error::arg(
                "max_facets",
                format!(
                    "the direct-light image splits into {} planar facets, more than {} (not a scene of a few surfaces)",
                    initial.len(),
                    opts.max_facets
                ),
            ));
        }
        let facet_opts = FacetOptions {
            bounds: opts.facets.bounds.or_else(|| bounds_of(&volume, wall_z)),
            ..opts.facets
        };
        let scale: Vec<f64> = (0..g.lasers.len())
            .map(|l| {
                if opts.fit.laser_falloff {
                    g.laser_falloff_at(l)
                } else {
                    1.0
                }
            })
            .collect();
        let fit = {
            let _t = timings::section("direct-light model: facets", Kind::Parallel);
            refine_facets(src, &initial, &scale, &facet_opts, exec)?
        };
        let surfels = fit.surfels(opts.facets.pitch, opts.per_facet)?;
        Ok((initial, fit, surfels))
    };
    let (initial, facets, surfels) = match steps() {
        Ok(x) => x,
        Err(e) => return Ok(unexplained(reason(e)?)),
    };
    if let Some(p) = surfels
        .points
        .iter()
        .find(|p| p[2].is_nan() || p[2] <= wall_z)
    {
        return Ok(unexplained(format!(
            "a refined surface at z = {:.3} m lies at or behind the relay wall (z = {wall_z:.3} m)",
            p[2]
        )));
    }
    let tables = budget::bytes(surfels.len().saturating_mul(g.spads.len()), 8);
    if let Err(e) = budget::check(|| "the surface model's SPAD tables".into(), tables) {
        return Ok(unexplained(reason(e)?));
    }
    let fit_opts = SynthOptions {
        max_bytes: opts
            .fit
            .max_bytes
            .min(usize::try_from(budget::get()).unwrap_or(usize::MAX)),
        ..opts.fit
    };
    let model = match SynthModel::fit(src, surfels, &fit_opts, exec) {
        Ok(m) => m,
        Err(e) => return Ok(unexplained(reason(e)?)),
    };
    let (explained, photon_noise) = (model.explained, model.photon_noise);
    let out = Box::new(SurfaceModel {
        model,
        initial,
        facets,
        volume,
        explained,
        photon_noise,
        seconds: t.elapsed().as_secs_f64(),
    });
    if !(explained.is_finite() && explained >= 0.0) {
        return Ok(unexplained(format!(
            "the surface model's fit diverged (energy explained {explained})"
        )));
    }
    // Photon counts: their Poisson noise is energy no model explains.
    let noise = photon_noise.unwrap_or(0.0);
    if explained < opts.min_explained - noise {
        let pct = |x: f64| (1000.0 * x).round() / 10.0;
        let less = match photon_noise {
            Some(n) => format!(" less its photon noise's {} %", pct(n)),
            None => String::new(),
        };
        return Ok(ModelOutcome::Unexplained {
            reason: format!(
                "the surface model explains {:.1} % of the energy (< {} %{less})",
                (1000.0 * explained).floor() / 10.0,
                pct(opts.min_explained)
            ),
            model: Some(out),
        });
    }
    Ok(ModelOutcome::Fitted(out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::capture::Capture;
    use crate::sim::{Aperture, Scene, Setup};

    const EXEC: Exec<'static> = Exec {
        progress: None,
        path: crate::exec::EvalPath::Auto,
    };

    /// Grids of `lasers` and `spads` spots over a wall of 1 m, `nt` bins of `dt` from 1 m; the
    /// samples from `value(i)`.
    fn wall(
        lasers: [usize; 2],
        spads: [usize; 2],
        (nt, dt): (usize, f64),
        value: impl FnMut(usize) -> f32,
    ) -> Capture {
        let mut g = Scene::new(Setup::new(
            Aperture::grid(lasers, [1.0, 1.0], [0.0, 0.0]),
            Aperture::grid(spads, [1.0, 1.0], [0.0, 0.0]),
            nt,
            dt,
        ))
        .geometry();
        g.t0 = 1.0;
        let len = g.lasers.len() * g.spads.len() * g.nt;
        Capture {
            geometry: g,
            data: (0..len).map(value).collect(),
        }
    }

    /// A dark capture: 4×4 lasers × 4×4 SPADs, 300 bins of 1 cm from 1 m.
    fn dark() -> Capture {
        wall([4, 4], [4, 4], (300, 0.01), |_| 0.0)
    }

    /// A capture of more than [`IMAGE_HISTOGRAMS`] histograms is imaged from every second
    /// laser row and column (its geometry and rows those of the kept spots); a smaller one,
    /// a laser list and a paired scan are imaged whole.
    #[test]
    fn large_captures_are_imaged_from_a_laser_sub_lattice() {
        let make = |lasers, spads| wall(lasers, spads, (2, 0.01), |i| i as f32);
        // 16 × 16 lasers × 128 SPADs = 32,768 histograms: every second row and column.
        let mut c = make([16, 16], [16, 8]);
        let full = c.geometry.clone();
        let mut l = LaserLattice::of(&mut c).expect("a sub-lattice");
        let g = l.geometry().clone();
        assert_eq!(g.laser_shape, [8, 8]);
        assert_eq!(g.lasers.len() * g.spads.len(), 8192);
        assert!(g.validate(std::path::Path::new("sub-lattice")).is_ok());
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for (i, j) in [(0, 0), (1, 2), (63, 16 * 14 + 14)] {
            let x = l.read_row(i, &mut a).unwrap();
            assert_eq!(x, full.lasers[j]);
            assert_eq!(g.lasers[i], full.lasers[j]);
            b.clear();
            b.extend_from_slice(&c_row(&full, j));
            assert_eq!(a, b, "row {i} = laser {j}");
        }
        assert!(l.read_row(64, &mut a).is_err());
        // Small enough: imaged whole; a line of lasers is thinned along it; a paired scan is
        // imaged whole.
        assert!(LaserLattice::of(&mut make([4, 8], [4, 8])).is_none());
        let mut big = make([32, 32], [32, 32]);
        assert!(LaserLattice::of(&mut big).is_some_and(|l| l.g.laser_shape == [16, 16]));
        let mut line = make([16, 16], [16, 8]);
        line.geometry.laser_shape = [256, 1];
        assert!(LaserLattice::of(&mut line).is_some_and(|l| l.g.laser_shape == [128, 1]));
        let mut paired = make([16, 16], [16, 8]);
        paired.geometry.confocal = true;
        assert!(LaserLattice::of(&mut paired).is_none());
    }

    /// Row `l` of the capture `make` builds: its values are their own indices.
    fn c_row(g: &Geometry, l: usize) -> Vec<f32> {
        let n = g.spads.len() * g.nt;
        (l * n..(l + 1) * n).map(|i| i as f32).collect()
    }

    #[test]
    fn bad_options_are_refused_naming_them() {
        let d = ModelOptions::default;
        let facets = |f: FacetOptions| ModelOptions { facets: f, ..d() };
        let fd = FacetOptions::default;
        let cases: Vec<(ModelOptions, &str)> = vec![
            (
                ModelOptions {
                    volume: Some(Volume::parse("0,0,1;0,0,1.1").expect("points")),
                    ..d()
                },
                "surfel_volume",
            ),
            (
                ModelOptions {
                    volume: Some(Volume::parse("-0.5:0.5:5,-0.5:0.5:5,1:1.1:2").expect("grid")),
                    ..d()
                },
                "surfel_volume",
            ),
            (
                ModelOptions {
                    wavelength: Some(-0.1),
                    ..d()
                },
                "surfel_wavelength",
            ),
            (
                ModelOptions {
                    epsilon: 1.0,
                    ..d()
                },
                "surfel_epsilon",
            ),
            (ModelOptions { sub: 0, ..d() }, "surfel_sub"),
            (
                ModelOptions {
                    split_tol: f64::NAN,
                    ..d()
                },
                "split_tol",
            ),
            (facets(FacetOptions { sweeps: 0, ..fd() }), "sweeps"),
            (
                facets(FacetOptions {
                    sweeps: MAX_SWEEPS + 1,
                    ..fd()
                }),
                "sweeps",
            ),
            (
                facets(FacetOptions {
                    grow: MAX_GROWN + 1,
                    ..fd()
                }),
                "grow",
            ),
            (facets(FacetOptions { pitch: 0.0, ..fd() }), "pitch"),
            (facets(FacetOptions { subset: 0, ..fd() }), "subset"),
            (facets(FacetOptions { work: 0.0, ..fd() }), "work"),
            (
                facets(FacetOptions {
                    work: f64::INFINITY,
                    ..fd()
                }),
                "work",
            ),
            (
                facets(FacetOptions {
                    grow_gain: 1.0,
                    ..fd()
                }),
                "grow_gain",
            ),
            (
                facets(FacetOptions {
                    bounds: Some([[0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]),
                    ..fd()
                }),
                "bounds",
            ),
            (
                facets(FacetOptions {
                    bounds: Some([[f64::NAN, 0.0, 0.0], [1.0, 1.0, 1.0]]),
                    ..fd()
                }),
                "bounds",
            ),
            (
                facets(FacetOptions {
                    max_surfels: 0,
                    ..fd()
                }),
                "max_surfels",
            ),
            (
                ModelOptions {
                    min_explained: 1.5,
                    ..d()
                },
                "min_explained",
            ),
            (
                ModelOptions {
                    max_facets: 0,
                    ..d()
                },
                "max_facets",
            ),
            (
                ModelOptions {
                    fit: SynthOptions {
                        max_shift: -1.0,
                        ..SynthOptions::default()
                    },
                    ..d()
                },
                "max_shift",
            ),
        ];
        let mut cap = dark();
        for (o, name) in cases {
            match model_of_capture(&mut cap, &Wave::default(), &o, EXEC) {
                Err(Error::Argument { arg, msg }) => assert_eq!(arg, name, "{msg}"),
                other => panic!("{name}: {other:?}"),
            }
        }
        assert!(ModelOptions::default().check().is_ok());
    }

    /// A capture of uniform noise on an 8 × 8 × 8 × 8 wall of 1 m, 175 bins of 2 cm from 1 m
    /// (the geometry of `fixtures/two_patches.npz`).
    fn noise() -> Capture {
        let mut x = 0x2545_f491_4f6c_dd1d_u64;
        wall([8, 8], [8, 8], (175, 0.02), |_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 40) as f32 / (1u64 << 24) as f32
        })
    }

    /// Options that let any capture through (up to 64 facets, every energy accepted), with
    /// `sweeps` sweeps and no growth: quick.
    fn lenient(sweeps: usize) -> ModelOptions {
        ModelOptions {
            max_facets: 64,
            min_explained: 0.0,
            facets: FacetOptions {
                sweeps,
                grow: 0,
                ..FacetOptions::default()
            },
            ..ModelOptions::default()
        }
    }

    /// [`lenient`] with its facets' options changed by `edit`.
    fn lenient_with(sweeps: usize, edit: impl FnOnce(&mut FacetOptions)) -> ModelOptions {
        let mut o = lenient(sweeps);
        edit(&mut o.facets);
        o
    }

    /// A capture of noise: an image that splits into more facets than `max_facets` is given
    /// up at once, naming the count; let through (every energy accepted), its facets stay
    /// inside the image's grid widened by [`BOUNDS_MARGIN`] (without the bounds they spread
    /// over tens of square metres within a few sweeps, and a sweep takes minutes).
    #[test]
    fn noise_is_not_read_as_surfaces_and_facets_stay_in_bounds() {
        let mut cap = noise();
        let few = ModelOptions {
            max_facets: 1,
            ..ModelOptions::default()
        };
        match model_of_capture(&mut cap, &Wave::default(), &few, EXEC) {
            Ok(ModelOutcome::Unexplained {
                reason,
                model: None,
            }) => {
                assert!(
                    reason.contains("planar facets, more than 1 (not a scene"),
                    "{reason}"
                );
            }
            other => panic!("{:?}", other.map(|_| ())),
        }
        let opts = lenient(3);
        let m = match model_of_capture(&mut cap, &Wave::default(), &opts, EXEC) {
            Ok(ModelOutcome::Fitted(m)) => m,
            other => panic!("{:?}", other.map(|_| ())),
        };
        let [lo, hi] = bounds_of(&m.volume, 0.0).expect("bounds");
        let areas: Vec<f64> = m.facets.facets.iter().map(Facet::area).collect();
        eprintln!("{} facets, areas {areas:.3?} m²", areas.len());
        let moved = m.facets.facets.iter().zip(&m.initial).any(|(f, i)| f != i);
        assert!(
            moved,
            "the refinement moved no facet: the bounds were not tried"
        );
        for f in &m.facets.facets {
            for c in f.corners() {
                assert!(
                    (0..3).all(|i| c[i] >= lo[i] && c[i] <= hi[i]),
                    "corner {c:?} outside {lo:?}..{hi:?}"
                );
            }
        }
    }

    /// A refinement that has not settled within its work budget ([`FacetOptions::work`]) is
    /// given up with a reason that says so, before its sweeps run out: the noise capture let
    /// through as above, with a budget of 10⁷ surfel returns (a sweep there lays out more),
    /// against the same capture and options with the default budget, which it stays within.
    #[test]
    fn a_refinement_over_its_work_budget_is_given_up() {
        let mut cap = noise();
        let tight = lenient_with(3, |f| f.work = 1e7);
        match model_of_capture(&mut cap, &Wave::default(), &tight, EXEC) {
            Ok(ModelOutcome::Unexplained {
                reason,
                model: None,
            }) => assert!(
                reason.contains("did not settle within 1.0e7 surfel returns"),
                "{reason}"
            ),
            other => panic!("{:?}", other.map(|_| ())),
        }
        assert!(matches!(
            model_of_capture(&mut cap, &Wave::default(), &lenient(3), EXEC),
            Ok(ModelOutcome::Fitted(_))
        ));
    }

    /// Non-finite samples read as 0, as the probes read them: a capture with NaN and ±inf in
    /// some bins gives the model of the same capture with zeros there, bit for bit (the
    /// refinement's sums run in a fixed order).
    #[test]
    fn non_finite_samples_read_as_zero() {
        let opts = lenient(2);
        let (mut bad, mut zeroed) = (noise(), noise());
        for (k, i) in (0..bad.data.len()).step_by(997).enumerate() {
            bad.data[i] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][k % 3];
            zeroed.data[i] = 0.0;
        }
        let fitted = |c: &mut Capture| match model_of_capture(c, &Wave::default(), &opts, EXEC) {
            Ok(ModelOutcome::Fitted(m)) => m,
            other => panic!("{:?}", other.map(|_| ())),
        };
        let (a, b) = (fitted(&mut bad), fitted(&mut zeroed));
        assert_eq!(a.explained.to_bits(), b.explained.to_bits());
        assert_eq!(a.facets.facets.len(), b.facets.facets.len());
        for (f, g) in a.facets.facets.iter().zip(&b.facets.facets) {
            assert!(
                f.centre == g.centre && f.normal == g.normal && f.extent == g.extent,
                "{f:?} vs {g:?}"
            );
        }
    }

    /// A facet may hold at most `max_surfels` surfels: on the noise capture (let through) an
    /// initial facet over the cap is a reason naming the option, and under the default cap no
    /// refined facet exceeds it; the memory plan's share for them (`tests/leak.rs` runs a
    /// budget below it).
    #[test]
    fn facets_stay_within_their_surfels_and_the_plan_counts_them() {
        let mut cap = noise();
        let capped = lenient_with(3, |f| f.max_surfels = 10);
        match model_of_capture(&mut cap, &Wave::default(), &capped, EXEC) {
            Ok(ModelOutcome::Unexplained {
                reason,
                model: None,
            }) => assert!(
                reason.contains("surfels") && reason.contains("more than 10"),
                "{reason}"
            ),
            other => panic!("{:?}", other.map(|_| ())),
        }
        let Ok(ModelOutcome::Fitted(m)) =
            model_of_capture(&mut cap, &Wave::default(), &lenient(3), EXEC)
        else {
            panic!("the noise capture let through");
        };
        let pitch = FacetOptions::default().pitch;
        for f in &m.facets.facets {
            let most = crate::probe::synth::MAX_FACET_SURFELS;
            assert!(f.samples(pitch) <= most, "{f:?}");
        }
        assert_eq!(
            facet_legs_bytes(crate::probe::synth::MAX_FACET_SURFELS, 8, 8, 2),
            4 * 65_536 * (16 * 16 + 32)
        );
    }

    #[test]
    fn captures_the_model_cannot_explain_are_reasons_not_errors() {
        let mut cap = dark();
        let why = |cap: &mut Capture| match model_of_capture(
            cap,
            &Wave::default(),
            &ModelOptions::default(),
            EXEC,
        ) {
            Ok(ModelOutcome::Unexplained { reason, model }) => {
                assert!(model.is_none());
                assert_eq!(reason.lines().count(), 1, "{reason}");
                reason
            }
            other => panic!("{other:?}"),
        };
        // No light: the image is zero.
        let r = why(&mut cap);
        assert!(r.contains("zero"), "{r}");
        // A paired scan: refused before any pass.
        cap.geometry.confocal = true;
        let r = why(&mut cap);
        assert!(r.contains("paired or confocal"), "{r}");
        // A window that reaches no depth in front of the wall.
        cap.geometry.confocal = false;
        cap.geometry.t0 = -10.0;
        cap.geometry.dt = 0.001;
        let r = why(&mut cap);
        assert!(r.contains("time window"), "{r}");
    }
}
