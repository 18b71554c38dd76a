//! Geometry from the capture as planar facets: rectangles (from [`super::facets_from_surfels`])
//! whose poses and edges are refined against the capture, and faces the direct-light image
//! missed grown from their neighbours' edges (analysis by synthesis).
//!
//! # Why rectangles
//!
//! The phasor-field image resolves depth to a fraction of its envelope but blurs the lateral
//! extent by about λ/2, rounds a convex edge and cannot hold two depths in one column (a
//! concave apex). Surfels per column therefore miss the edges by centimetres, and the
//! two-bounce light is 0.1–3 % of a capture's energy: the direct residual must be far below
//! that. A rectangle per plane has 7 numbers (an offset along its normal, two tilts, four
//! edges) that the capture's direct returns pin down to millimetres: the arrival of the first
//! and the last return of every histogram moves with the edges.
//!
//! # Refinement ([`refine_facets`])
//!
//! Over a spread subset of at most [`FacetOptions::subset`] laser rows × as many SPADs (16 ×
//! 16 by default: all their pairs, so that the legs factor per laser and per SPAD; each
//! spread over both axes of its grid, 8 rows × 2 columns), the
//! residual `R = H − Σ_f a_f m_f` is kept. A sweep
//! visits every facet, tries each of its 7 parameters `± step` (offset and edges from 2 and
//! 4 cm, tilts from 4°) with the optimal amplitude `a = max(0, ⟨R + a_f m_f, m⟩/‖m‖²)`, and
//! keeps the best (the current pose among them: the residual never grows). A facet none of
//! whose moves helps halves its steps; one whose steps are below 1/64 of their start is
//! settled and left alone while the others' sweeps go on (a round ends when all are). Then
//! one Levenberg–Marquardt step from the facet's pose on the 7 parameters and the amplitude
//! together (damping `10⁻³…1`) is kept when it does better still: it makes the coupled moves
//! (a tilt with the offset and edges it drags along) that single coordinates cannot. Its
//! Jacobian is the coordinate moves' own renders as central differences (`(m₊ − m₋)/2h` at
//! the current steps; one-sided against the facet's render where a move collapsed it), so it
//! costs no render but its trials.
//!
//! **Growth**: after the sweeps, facets 4, 8 and 16 cm wide attached to each edge of each lit
//! facet and folded by ±20…90° are scored against the residual; the best joins when it
//! explains at least [`FacetOptions::grow_gain`] of the subset's energy with an amplitude
//! within a factor 2 of its parent's, and the sweeps run again (at most
//! [`FacetOptions::grow`] times). A box's second face is as bright as its first; a strip
//! that only fits the diffuse light beside an edge (the blur, the indirect light) needs a far
//! smaller amplitude, and a strip much narrower than the face it stands for explains only its
//! share: on panel/figure a 4 cm strip of the figure's second face explained 2·10⁻⁴ of the
//! energy, below the former threshold of 10⁻³, while the panel's edge strips that won had a
//! third of the panel's amplitude. Facets are sampled every `pitch` metres (1 cm: a
//! return per bin and row, as the renderer bins them). Returns are binned without blur and
//! delay: [`super::SynthModel::fit`] fits those after.
//!
//! Cost: per facet and sweep, 15 renders of `K_f` surfels (`K_f` = area / pitch²) for each
//! of the `≤ subset²` pairs (the facet's and its 14 coordinate moves', kept; the moves
//! rendered and scored in parallel, a task each) and 1–4 for the
//! Levenberg–Marquardt trials, each after `K_f·(L + S)` legs; per growth round 96 candidate
//! strips per lit facet. A render ([`super::subset`]) computes every surfel's bin in vectors,
//! then scatters the returns into 4 interleaved copies of the pair's histogram (neighbouring
//! surfels mostly share a bin: one copy would chain their stores). On panel/figure (8×8 ×
//! 8×8, 300 bins; 2 facets grown to 3, 24 sweeps) the refinement takes about 1.2 s on 2 idle
//! cores (the whole pipeline took 260 s per capture with a subset of 64 × 64, every histogram
//! there, before the renders were made faster; the refined geometry stayed within 0.1–1° and
//! 0.1–3 mm of `scene.json` at subsets of 64, 32 and 16: tests/leak.rs prints it). Memory:
//! the subset's residual, the facet's render and its 14 moves' (`16·pairs·Nt` f64) and the
//! legs (`16·K_f·(L + S)` bytes per worker rendering a move).

use super::facet::Facet;
use super::subset::{Column, Legs, Src, Subset, dots};
use super::surfels::Surfels;
use crate::error::{Error, Result};
use crate::exec::{Exec, Pass};
use crate::io::capture::RowSource;
use rayon::prelude::*;
use vltm_kernel::geometry::dist64;

/// What [`refine_facets`] found.
#[derive(Clone, Debug)]
pub struct FacetFit {
    /// The facets, moved; a facet switched off (amplitude 0) or collapsed keeps its place here
    /// and gets no surfel in [`FacetFit::surfels`].
    pub facets: Vec<Facet>,
    /// Amplitude per facet, relative to the first global scale (1: the global fit's
    /// reflectance).
    pub amplitudes: Vec<f64>,
    /// Fraction of the subset's energy explained with the facets as given (one global scale).
    pub before: f64,
    /// After the sweeps.
    pub after: f64,
    /// Sweeps run.
    pub sweeps: usize,
    /// Facets grown from the edges of others (the last ones of `facets`).
    pub grown: usize,
}

impl FacetFit {
    /// The facets as surfels every `pitch` metres, areas scaled by their amplitudes; one
    /// cluster per facet (`per_facet`) or per source cluster.
    ///
    /// # Errors
    /// No facet left lit (`surfels`), `pitch` not positive.
    pub fn surfels(&self, pitch: f64, per_facet: bool) -> Result<Surfels> {
        if !(pitch.is_finite() && pitch > 0.0) {
            return Err(Error::arg("pitch", "must be positive and finite (m)"));
        }
        let (mut pts, mut nrm, mut area, mut cl) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut buf = Vec::new();
        for (i, (f, &a)) in self.facets.iter().zip(&self.amplitudes).enumerate() {
            if a <= 0.0 {
                continue;
            }
            f.sample(pitch, &mut buf);
            for &(p, s) in &buf {
                pts.push(p);
                nrm.push(f.normal);
                area.push(s * a);
                cl.push(if per_facet { i } else { f.cluster });
            }
        }
        // Clusters renumbered densely.
        let mut map = std::collections::BTreeMap::new();
        for c in cl.iter_mut() {
            let next = map.len();
            *c = *map.entry(*c).or_insert(next);
        }
        Surfels::new(pts, nrm, area, cl)
    }
}

/// How [`refine_facets`] works.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FacetOptions {
    /// Sweeps at most per round (default 12; a round ends early when every facet's steps are
    /// below 1/64 of their start).
    pub sweeps: usize,
    /// Surfel spacing of the facets' renders (m, default 0.01: about a bin of 1 cm).
    pub pitch: f64,
    /// Facets grown at most, one per round: the best facet attached to an edge of a lit one
    /// (default 6).
    pub grow: usize,
    /// The fraction of the subset's energy a grown facet must explain (default 2·10⁻⁴).
    pub grow_gain: f64,
    /// Laser rows and SPADs of the subset, each at most (default 16: 256 histograms).
    pub subset: usize,
    /// A box `[min, max]` (m) every facet's corners stay inside: a move, a
    /// Levenberg–Marquardt step or a grown facet that leaves it is refused (`None`: no bound).
    /// Without one, a capture of noise lets facets spread over tens of square metres.
    pub bounds: Option<[[f64; 3]; 2]>,
    /// Surfel returns (surfels rendered × the subset's histograms) the refinement may lay
    /// out before it gives up (default [`REFINE_WORK`]); a refinement that has not settled by
    /// then is an error naming `work`.
    pub work: f64,
    /// Surfels a facet may hold at `pitch` (default [`MAX_FACET_SURFELS`]): a move, a
    /// Levenberg–Marquardt step or a grown facet larger than this is refused before it is
    /// rendered, and an initial facet larger than this is an error naming `max_surfels`. It
    /// bounds the refinement's memory, which [`facet_legs_bytes`] states.
    pub max_surfels: usize,
}

/// The default of [`FacetOptions::max_surfels`]: 65,536 surfels, 6.5 m² at the default pitch
/// of 1 cm (the path-traced panel/figure's largest facet holds 3,000; the box the facets
/// must stay in, a quarter wider than the image on every side, allows 14 m² on the 8 × 8
/// fixtures).
pub const MAX_FACET_SURFELS: usize = 1 << 16;

/// Bytes the refinement's surfel legs take at most when `threads` render moves at once over a
/// subset of `lasers × spads`: one set of legs per thread and two more (the facet's own and
/// a Levenberg–Marquardt step's), each `16·(lasers + spads)` bytes per surfel for the legs
/// and 32 for the surfel itself, at [`FacetOptions::max_surfels`] surfels.
pub fn facet_legs_bytes(max_surfels: usize, lasers: usize, spads: usize, threads: usize) -> u128 {
    let per_surfel = 16 * (lasers as u128 + spads as u128) + 32;
    (threads as u128 + 2) * max_surfels as u128 * per_surfel
}

/// The default of [`FacetOptions::work`]: 6·10⁹ surfel returns, about 10 s on 2 cores. The
/// path-traced captures need 0.8·10⁹ (panel/figure, 8 × 8 × 8 × 8 and 16 × 16 × 16 × 16
/// alike: the subset is the same size), 3.7·10⁹ (the corner), the 8 × 8 fixtures 0.005–0.03·10⁹;
/// captures of noise ran 14–38·10⁹ (24–58 s) before they fell back.
pub const REFINE_WORK: f64 = 6e9;

impl Default for FacetOptions {
    fn default() -> Self {
        Self {
            sweeps: 12,
            pitch: 0.01,
            grow: 6,
            grow_gain: 2e-4,
            subset: 16,
            bounds: None,
            work: REFINE_WORK,
            max_surfels: MAX_FACET_SURFELS,
        }
    }
}

impl FacetOptions {
    /// Checks [`FacetOptions::bounds`].
    ///
    /// # Errors
    /// [`Error::Argument`] naming `bounds` when it is not a box of finite corners, min below
    /// max on every axis.
    pub(crate) fn check_bounds(&self) -> Result<()> {
        match self.bounds {
            Some([lo, hi])
                if !(0..3).all(|i| lo[i].is_finite() && hi[i].is_finite() && lo[i] < hi[i]) =>
            {
                Err(Error::arg(
                    "bounds",
                    "must be a box of finite corners, min below max on every axis (m)",
                ))
            }
            _ => Ok(()),
        }
    }

    /// Checks [`FacetOptions::work`].
    ///
    /// # Errors
    /// [`Error::Argument`] naming `work` when it is not positive and finite.
    pub(crate) fn check_work(&self) -> Result<()> {
        if !(self.work.is_finite() && self.work > 0.0) {
            return Err(Error::arg(
                "work",
                "must be positive and finite (surfel returns)",
            ));
        }
        if !(1..=MAX_FACET_SURFELS * 16).contains(&self.max_surfels) {
            return Err(Error::arg(
                "max_surfels",
                format!("must lie in 1..={}", MAX_FACET_SURFELS * 16),
            ));
        }
        Ok(())
    }
}

/// Folds tried at each edge (degrees; negative and positive: both ways about the edge).
const FOLDS: [f64; 8] = [-90.0, -60.0, -40.0, -20.0, 20.0, 40.0, 60.0, 90.0];
/// Widths of a grown facet before its refinement (m): a strip much narrower than the face it
/// stands for explains only its share of that face's light.
const GROW_WIDTHS: [f64; 3] = [0.04, 0.08, 0.16];
/// A grown facet's amplitude lies within this factor of its parent's (module docs).
const GROW_AMPLITUDE: f64 = 2.0;

/// `r += a·m`.
fn axpy(a: f64, m: &[f64], r: &mut [f64]) {
    r.par_iter_mut().zip(m).for_each(|(x, m)| *x += a * m);
}

/// At most `n` of `0..len`, spread evenly.
fn spread(len: usize, n: usize) -> Vec<usize> {
    if len <= n {
        return (0..len).collect();
    }
    (0..n).map(|i| (i * len + len / 2) / n).collect()
}

/// At most `n` of the `len` spots of a C-order grid of `shape` (`[nx, ny]`, spot `i·ny + j`),
/// spread over both axes: `n/2` rows (all of them up to that) × the columns that leave (two
/// for `n` = 16). Of an 8 × 8 grid these are the spots a spread over the flat index takes
/// (rows 0–7 × columns 2 and 6); of a 16 × 16 grid a flat spread would take one column, with
/// no parallax across it: on the 16 × 16 × 16 × 16 panel/figure render its facets ended 7–11°
/// off and explained 92–94 % of the capture, and a 4 × 4 lattice left them 1–2° off (3.5× /
/// 2.9× the control), against 0.2–0.4° (28.5× / 14.8×) with 8 rows × 2 columns
/// (docs/indirect-light.md). A list that is not the grid's is spread as a list.
fn spread_grid(shape: [usize; 2], len: usize, n: usize) -> Vec<usize> {
    let [nx, ny] = shape;
    if len <= n || nx.saturating_mul(ny) != len || n == 0 {
        return spread(len, n);
    }
    let kx = (n / 2).clamp(1, nx);
    let ky = (n / kx).clamp(1, ny);
    let kx = (n / ky).clamp(1, nx);
    let cols = spread(ny, ky);
    spread(nx, kx)
        .into_iter()
        .flat_map(|i| cols.iter().map(move |j| i * ny + j))
        .collect()
}

/// Refines `facets` against the capture (module docs) with `opts`; `laser_scale` per laser
/// row (the physical laser's falloff, or 1).
///
/// # Errors
/// No facet, `pitch`, `grow_gain` or `laser_scale` wrong (named), a capture with no energy in
/// the subset (`leak_correct`), read errors.
pub fn refine_facets(
    src: &mut dyn RowSource,
    facets: &[Facet],
    laser_scale: &[f64],
    opts: &FacetOptions,
    exec: Exec<'_>,
) -> Result<FacetFit> {
    if facets.is_empty() {
        return Err(Error::arg("surfels", "no facet to refine"));
    }
    let FacetOptions {
        sweeps,
        pitch,
        grow,
        grow_gain,
        subset,
        bounds,
        work,
        max_surfels,
    } = *opts;
    opts.check_bounds()?;
    // Whether a facet stays inside the bounds and within its surfels.
    let inside = |f: &Facet| {
        f.samples(pitch) <= max_surfels
            && bounds.is_none_or(|[lo, hi]| {
                f.corners()
                    .iter()
                    .all(|c| (0..3).all(|i| c[i] >= lo[i] && c[i] <= hi[i]))
            })
    };
    if !(1..=256).contains(&subset) {
        return Err(Error::arg(
            "subset",
            "must lie in 1..=256 laser rows and SPADs",
        ));
    }
    if !(pitch.is_finite() && pitch > 0.0) {
        return Err(Error::arg("pitch", "must be positive and finite (m)"));
    }
    if !(grow_gain.is_finite() && grow_gain > 0.0 && grow_gain < 1.0) {
        return Err(Error::arg("grow_gain", "must lie in (0, 1)"));
    }
    opts.check_work()?;
    if let Some(f) = facets.iter().find(|f| f.samples(pitch) > max_surfels) {
        return Err(Error::arg(
            "max_surfels",
            format!(
                "a facet of {:.2} m² holds {} surfels at a pitch of {pitch} m, more than {max_surfels}",
                f.area(),
                f.samples(pitch)
            ),
        ));
    }
    let g = src.geometry().clone();
    if laser_scale.len() != g.lasers.len() {
        return Err(Error::arg(
            "laser_scale",
            format!("{} values for {} lasers", laser_scale.len(), g.lasers.len()),
        ));
    }
    let nt = g.nt;
    let lasers = spread_grid(g.laser_shape, g.lasers.len(), subset);
    let spads = spread_grid(g.spad_shape, g.spads.len(), subset);
    let leg_len = |x: &[f32; 3], o: [f64; 3]| if g.legs_in_time { dist64(x, &o) } else { 0.0 };
    let sub = Subset {
        g: &g,
        d1: lasers
            .iter()
            .map(|&l| leg_len(&g.lasers[l], g.laser_origin))
            .collect(),
        d4: spads
            .iter()
            .map(|&s| leg_len(&g.spads[s], g.sensor_origin))
            .collect(),
        laser_scale: lasers.iter().map(|&l| laser_scale[l]).collect(),
        lasers,
        spads,
        nt,
        work: 0.into(),
    };
    let ns = sub.spads.len();
    let mut r = vec![0.0f64; sub.pairs() * nt];
    {
        let bar = Pass::start(exec, "direct-light model: facets", sub.lasers.len());
        let mut row = Vec::new();
        for (li, &l) in sub.lasers.iter().enumerate() {
            src.read_row(l, &mut row)?;
            for (si, &s) in sub.spads.iter().enumerate() {
                r[(li * ns + si) * nt..][..nt]
                    .iter_mut()
                    .zip(&row[s * nt..(s + 1) * nt])
                    // Non-finite samples read as 0, as the probes read them.
                    .for_each(|(o, x)| *o = if x.is_finite() { f64::from(*x) } else { 0.0 });
            }
            bar.advance(1);
        }
    }
    let energy: f64 = r.iter().map(|x| x * x).sum();
    if !(energy.is_finite() && energy > 0.0) {
        return Err(Error::arg(
            "leak_correct",
            "the capture has no finite energy where the facets are fitted",
        ));
    }
    let explained = |r: &[f64]| 1.0 - r.iter().map(|x| x * x).sum::<f64>() / energy;
    let mut facets = facets.to_vec();
    let (mut legs, mut buf) = (Legs::default(), Vec::new());
    // One global scale to start: s0 = ⟨H, M⟩/⟨M, M⟩.
    let mut m_all = vec![0.0f64; r.len()];
    for f in &facets {
        sub.legs(f, pitch, &mut buf, &mut legs);
        sub.add(&legs, 1.0, &mut m_all);
    }
    let hm: f64 = r.iter().zip(&m_all).map(|(a, b)| a * b).sum();
    let mm: f64 = m_all.iter().map(|x| x * x).sum();
    let s0 = if mm > 0.0 { (hm / mm).max(0.0) } else { 0.0 };
    r.iter_mut().zip(&m_all).for_each(|(x, m)| *x -= s0 * m);
    drop(m_all);
    let before = explained(&r);
    let mut amp = vec![s0; facets.len()];
    // Step scale per facet: offset, tilts, edges.
    let base = [
        0.02,
        4f64.to_radians(),
        4f64.to_radians(),
        0.04,
        0.04,
        0.04,
        0.04,
    ];
    let mut scale = vec![1.0f64; facets.len()];
    // The facet's render and its 14 coordinate moves' (also the Jacobian's differences).
    let mut m0 = vec![0.0f64; r.len()];
    let mut moves = vec![vec![0.0f64; r.len()]; 14];
    let bar = Pass::start(exec, "direct-light model: facets", (grow + 1) * sweeps);
    let mut ran = 0;
    let mut grown = 0;
    // The work so far against the budget, checked between a facet's steps.
    let spent = |ran: usize| {
        let w = sub.work.load(std::sync::atomic::Ordering::Relaxed) as f64;
        if w > work {
            return Err(Error::arg(
                "work",
                format!(
                    "the facets' refinement did not settle within {work:.1e} surfel returns (after {ran} sweeps; not a scene of a few planar surfaces)"
                ),
            ));
        }
        Ok(())
    };
    for round in 0..=grow {
        spent(ran)?;
        if round > 0 {
            // Grow: the best facet attached to an edge of a lit one, if it explains enough.
            let mut best: Option<(Facet, f64, f64)> = None;
            for fi in 0..facets.len() {
                if amp[fi] <= 0.0 {
                    continue;
                }
                for (edge, fold, w) in (0..4).flat_map(|e| {
                    FOLDS
                        .into_iter()
                        .flat_map(move |f| GROW_WIDTHS.into_iter().map(move |w| (e, f, w)))
                }) {
                    let cand = facets[fi].attached(edge, fold.to_radians(), w);
                    if !inside(&cand) {
                        continue;
                    }
                    sub.legs(&cand, pitch, &mut buf, &mut legs);
                    let (d, m) = sub.score(&legs, &r);
                    // The same object's reflectance: within a factor GROW_AMPLITUDE of the
                    // parent's (a strip that fits diffuse light needs a far smaller one).
                    let a = if m > 0.0 { d / m } else { 0.0 };
                    let plausible = a >= amp[fi] / GROW_AMPLITUDE && a <= amp[fi] * GROW_AMPLITUDE;
                    if d > 0.0 && plausible && best.is_none_or(|b| d * d / m > b.1) {
                        best = Some((cand, d * d / m, a));
                    }
                }
            }
            let Some((f, _, a)) = best.filter(|b| b.1 >= grow_gain * energy) else {
                break;
            };
            sub.legs(&f, pitch, &mut buf, &mut legs);
            sub.add(&legs, -a, &mut r);
            facets.push(f);
            amp.push(a);
            scale.iter_mut().for_each(|s| *s = s.max(0.25));
            scale.push(0.5);
            grown += 1;
        }
        for _ in 0..sweeps {
            bar.advance(1);
            if scale.iter().all(|s| *s < 1.0 / 64.0) {
                break;
            }
            ran += 1;
            for fi in 0..facets.len() {
                spent(ran)?;
                if scale[fi] < 1.0 / 64.0 {
                    // Settled: its steps are below the round's end (the others' go on).
                    continue;
                }
                // R' = R + a_f m_f.
                sub.legs(&facets[fi], pitch, &mut buf, &mut legs);
                sub.dense_into(&legs, &mut m0);
                let a_f = amp[fi];
                axpy(a_f, &m0, &mut r);
                // (facet, gain, amplitude, the render it came from: None for LM's).
                let mut best = (facets[fi], 0.0f64, 0.0f64, Some(Src::M0));
                let (d, m) = dots(&r, &m0);
                if d > 0.0 && m > 0.0 {
                    best.1 = d * d / m;
                    best.2 = d / m;
                }
                let a0 = best.2;
                let mut cols = [Column {
                    plus: Src::M0,
                    minus: Src::M0,
                    k: 0.0,
                }; 7];
                // The 14 coordinate moves (`2p` the minus side of parameter `p`, by `step[p]`),
                // rendered and scored in parallel: `None` where the move collapses the facet.
                let step: [f64; 7] = std::array::from_fn(|p| base[p] * scale[fi]);
                let cands: [Option<Facet>; 14] = std::array::from_fn(|j| {
                    let (p, sign) = (j / 2, if j % 2 == 0 { -1.0 } else { 1.0 });
                    let mut pose = [0.0; 7];
                    pose[p] = sign * step[p];
                    let cand = facets[fi].moved(&pose);
                    let [u0, u1, v0, v1] = cand.extent;
                    (u1 - u0 >= pitch && v1 - v0 >= pitch && cand.samples(pitch) <= max_surfels)
                        .then_some(cand)
                });
                let scores: Vec<Option<(f64, f64)>> = moves
                    .par_iter_mut()
                    .zip(&cands)
                    .map_init(
                        || (Vec::new(), Legs::default()),
                        |(buf, legs), (mv, cand)| {
                            let cand = cand.as_ref()?;
                            sub.legs(cand, pitch, buf, legs);
                            sub.dense_into(legs, mv);
                            Some(dots(&r, mv))
                        },
                    )
                    .collect();
                for (p, col) in cols.iter_mut().enumerate() {
                    let h = step[p];
                    let mut have = [false; 2];
                    for (side, had) in have.iter_mut().enumerate() {
                        let j = 2 * p + side;
                        let (Some(cand), Some((d, m))) = (cands[j], scores[j]) else {
                            continue;
                        };
                        *had = true;
                        // Outside the bounds: a column of the Jacobian, never a pose.
                        if inside(&cand) && d > 0.0 && m > 0.0 && d * d / m > best.1 * (1.0 + 1e-9)
                        {
                            best = (cand, d * d / m, d / m, Some(Src::Move(j)));
                        }
                    }
                    // The column of the Jacobian of a0·m at the facet's pose.
                    *col = match have {
                        [true, true] => Column {
                            plus: Src::Move(2 * p + 1),
                            minus: Src::Move(2 * p),
                            k: a0 / (2.0 * h),
                        },
                        [false, true] => Column {
                            plus: Src::Move(2 * p + 1),
                            minus: Src::M0,
                            k: a0 / h,
                        },
                        [true, false] => Column {
                            plus: Src::M0,
                            minus: Src::Move(2 * p),
                            k: a0 / h,
                        },
                        [false, false] => *col,
                    };
                }
                if a0 > 0.0
                    && let Some((f, g, a)) = sub.levenberg_marquardt(
                        &facets[fi],
                        a0,
                        best.1,
                        &r,
                        &m0,
                        &moves,
                        &cols,
                        pitch,
                        max_surfels,
                    )
                    && inside(&f)
                {
                    best = (f, g, a, None);
                }
                let (f, _, a, from) = best;
                if matches!(from, Some(Src::M0)) {
                    scale[fi] *= 0.5;
                }
                facets[fi] = f;
                amp[fi] = a.max(0.0);
                // R = R' − a_f m_f, from the kept render where the pose came from one.
                match from {
                    Some(Src::M0) => axpy(-amp[fi], &m0, &mut r),
                    Some(Src::Move(j)) => axpy(-amp[fi], &moves[j], &mut r),
                    None => {
                        sub.legs(&facets[fi], pitch, &mut buf, &mut legs);
                        sub.add(&legs, -amp[fi], &mut r);
                    }
                }
            }
        }
    }
    drop(bar);
    let after = explained(&r);
    let amplitudes = amp
        .iter()
        .map(|a| if s0 > 0.0 { a / s0 } else { 0.0 })
        .collect();
    Ok(FacetFit {
        facets,
        amplitudes,
        before,
        after,
        sweeps: ran,
        grown,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The subset's spots cover both axes of a grid: 16 of 16 × 16 are 8 rows × 2 columns,
    /// 16 of 8 × 8 the same spots as a spread over the flat index (8 rows × columns 2 and 6);
    /// a line or a list is spread along itself; never more than asked, never a spot twice.
    #[test]
    fn the_subset_spreads_over_both_axes_of_a_grid() {
        let g = spread_grid([16, 16], 256, 16);
        assert_eq!(g.len(), 16);
        let rows: std::collections::BTreeSet<_> = g.iter().map(|i| i / 16).collect();
        let cols: std::collections::BTreeSet<_> = g.iter().map(|i| i % 16).collect();
        assert_eq!((rows.len(), cols.len()), (8, 2), "{g:?}");
        assert_eq!(cols.iter().copied().collect::<Vec<_>>(), vec![4, 12]);
        assert_eq!(spread_grid([8, 8], 64, 16), spread(64, 16));
        // A line of spots, a list (not the grid's size), fewer spots than asked.
        assert_eq!(spread_grid([1, 64], 64, 16).len(), 16);
        assert_eq!(spread_grid([64, 1], 64, 16), spread(64, 16));
        assert_eq!(spread_grid([4, 4], 10, 4), spread(10, 4));
        assert_eq!(spread_grid([3, 3], 9, 16), (0..9).collect::<Vec<_>>());
        // Non-square requests: at most n, distinct.
        for (shape, n) in [([16, 4], 10), ([5, 7], 12), ([2, 50], 9)] {
            let g = spread_grid(shape, shape[0] * shape[1], n);
            let set: std::collections::BTreeSet<_> = g.iter().collect();
            assert!(
                g.len() <= n && g.len() >= n / 2 && set.len() == g.len(),
                "{shape:?} {n}: {g:?}"
            );
        }
    }
}
