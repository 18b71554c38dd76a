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
//! 16 by default: all their pairs, so that the legs factor per laser and per SPAD), the
//! residual `R = H − Σ_f a_f m_f` is kept. A sweep
//! visits every facet, tries each of its 7 parameters `± step` (offset and edges from 2 and
//! 4 cm, tilts from 4°) with the optimal amplitude `a = max(0, ⟨R + a_f m_f, m⟩/‖m‖²)`, and
//! keeps the best (the current pose among them: the residual never grows). A facet none of
//! whose moves helps halves its steps; one whose steps are below 1/64 of their start is
//! settled and left alone while the others' sweeps go on (a round ends when all are). After the coordinate moves, one Levenberg–Marquardt
//! step on the 7 parameters and the amplitude together (central differences at half the
//! steps, damping `10⁻³…1`) is kept when it does better: it makes the coupled moves (a tilt
//! with the offset and edges it drags along) that single coordinates cannot.
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
//! Cost: per facet and sweep, about 36 renders of `K_f` surfels (`K_f` = area / pitch²) for
//! each of the `≤ subset²` pairs (17 for the coordinate moves, 15 for the Levenberg–Marquardt
//! columns, up to 4 for its dampings), each after `K_f·(L + S)` legs; per growth round 96
//! candidate strips per lit facet. A render is a scatter of one return per surfel into the
//! pair's histogram, a run of returns in one bin summed before it is stored. On panel/figure
//! (8×8 × 8×8, 300 bins; 2 facets grown to 3, 24 sweeps) the whole pipeline took 260 s per
//! capture with a subset of 64 × 64 (every histogram there), 104 s with 32 × 32 and 35–41 s
//! with 16 × 16, on 2 cores shared with other jobs; the refined geometry stayed within 0.1–1°
//! and 0.1–3 mm of `scene.json` at every size (tests/leak.rs prints it). Memory: the subset and
//! its residual (`pairs·Nt` f64 each), the Levenberg–Marquardt columns (`9·pairs·Nt` f64)
//! and the legs (`16·K_f·(L + S)` bytes).

use super::linalg::solve;
use super::render::{bin_of, leg};
use super::surfels::Surfels;
use super::vec3::{V3, cross, dot, rotate, unit};
use crate::error::{Error, Result};
use crate::exec::{Exec, Pass};
use crate::io::capture::{Geometry, RowSource};
use rayon::prelude::*;
use vltm_kernel::geometry::dist64;

/// A planar rectangle of a hidden surface (metres, the capture's frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Facet {
    /// A point of the plane; the extent is measured from it.
    pub centre: V3,
    /// Unit normal, toward the wall (the side that is lit).
    pub normal: V3,
    /// First in-plane unit axis (`v × normal`).
    pub u: V3,
    /// Second in-plane unit axis (the in-plane direction of +y, or of +x for a horizontal
    /// facet).
    pub v: V3,
    /// `[u0, u1, v0, v1]`: the rectangle spans `u ∈ [u0, u1]`, `v ∈ [v0, v1]` from `centre`.
    pub extent: [f64; 4],
    /// The cluster (object) the facet came from.
    pub cluster: usize,
}

/// The parameters a refinement moves: `[offset, tilt about u, tilt about v, Δu0, Δu1, Δv0,
/// Δv1]` (m, rad, m).
type Pose = [f64; 7];

impl Facet {
    /// A facet through `centre` with normal `normal` (turned toward `toward`), its frame as in
    /// the module docs and extent zero.
    pub(super) fn framed(centre: V3, normal: V3, toward: V3, cluster: usize) -> Self {
        let mut n = unit(normal);
        if dot(n, toward) < 0.0 {
            n = n.map(|x| -x);
        }
        let up = if n[1].abs() > 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let v = unit(core::array::from_fn(|i| up[i] - dot(up, n) * n[i]));
        let u = cross(v, n);
        Self {
            centre,
            normal: n,
            u,
            v,
            extent: [0.0; 4],
            cluster,
        }
    }

    /// This facet moved by `p` (tilts about its own centre-of-extent).
    fn moved(&self, p: &Pose) -> Self {
        let [d, a, b, e0, e1, e2, e3] = *p;
        let [u0, u1, v0, v1] = self.extent;
        // Pivot: the middle of the rectangle.
        let (mu, mv) = (0.5 * (u0 + u1), 0.5 * (v0 + v1));
        let pivot: V3 = core::array::from_fn(|i| self.centre[i] + mu * self.u[i] + mv * self.v[i]);
        let (mut n, mut u, mut v) = (self.normal, self.u, self.v);
        if a != 0.0 {
            n = rotate(n, self.u, a);
            v = rotate(v, self.u, a);
        }
        if b != 0.0 {
            n = rotate(n, self.v, b);
            u = rotate(u, self.v, b);
        }
        let centre = core::array::from_fn(|i| pivot[i] + d * self.normal[i]);
        Self {
            centre,
            normal: n,
            u,
            v,
            extent: [u0 - mu + e0, u1 - mu + e1, v0 - mv + e2, v1 - mv + e3],
            cluster: self.cluster,
        }
    }

    /// A facet of width `w` attached to edge `edge` (0: `u0`, 1: `u1`, 2: `v0`, 3: `v1`) of
    /// this one, folded about that edge by `fold` radians (0: this plane continued).
    fn attached(&self, edge: usize, fold: f64, w: f64) -> Self {
        let [u0, u1, v0, v1] = self.extent;
        let (mu, mv) = (0.5 * (u0 + u1), 0.5 * (v0 + v1));
        let (axis, out, at) = match edge {
            0 => (self.v, self.u.map(|x| -x), [u0, mv]),
            1 => (self.v, self.u, [u1, mv]),
            2 => (self.u, self.v.map(|x| -x), [mu, v0]),
            _ => (self.u, self.v, [mu, v1]),
        };
        let out = rotate(out, axis, fold);
        let normal = rotate(self.normal, axis, fold);
        let centre =
            core::array::from_fn(|i| self.centre[i] + at[0] * self.u[i] + at[1] * self.v[i]);
        let (u, v, extent) = if edge < 2 {
            (out, axis, [0.0, w, v0 - mv, v1 - mv])
        } else {
            (axis, out, [u0 - mu, u1 - mu, 0.0, w])
        };
        Self {
            centre,
            normal,
            u,
            v,
            extent,
            cluster: self.cluster,
        }
    }

    /// Area (m²; zero when an extent has collapsed).
    pub fn area(&self) -> f64 {
        let [u0, u1, v0, v1] = self.extent;
        (u1 - u0).max(0.0) * (v1 - v0).max(0.0)
    }

    /// Surfels every `pitch` metres or finer (at least one per side): `(point, area)`
    /// into `out` (cleared); none when the facet has collapsed.
    fn sample(&self, pitch: f64, out: &mut Vec<(V3, f64)>) {
        out.clear();
        let [u0, u1, v0, v1] = self.extent;
        let (wu, wv) = (u1 - u0, v1 - v0);
        if !(wu > 0.0 && wv > 0.0) {
            return;
        }
        let nu = ((wu / pitch).ceil() as usize).clamp(1, 10_000);
        let nv = ((wv / pitch).ceil() as usize).clamp(1, 10_000);
        let a = wu * wv / (nu * nv) as f64;
        for i in 0..nu {
            let x = u0 + (i as f64 + 0.5) / nu as f64 * wu;
            for j in 0..nv {
                let y = v0 + (j as f64 + 0.5) / nv as f64 * wv;
                out.push((
                    core::array::from_fn(|k| self.centre[k] + x * self.u[k] + y * self.v[k]),
                    a,
                ));
            }
        }
    }
}

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

/// The subset of the capture a refinement works on, with its legs' geometry.
struct Subset<'a> {
    g: &'a Geometry,
    lasers: Vec<usize>,
    spads: Vec<usize>,
    laser_scale: Vec<f64>,
    /// Device legs (m) per subset laser and SPAD.
    d1: Vec<f64>,
    d4: Vec<f64>,
    nt: usize,
}

/// One render's legs: per subset laser `[li·K + k]` and SPAD `[si·K + k]`, time (m, device
/// leg included, `t0` subtracted on the laser side) and weight.
#[derive(Default)]
struct Legs {
    tl: Vec<f64>,
    wl: Vec<f64>,
    ts: Vec<f64>,
    ws: Vec<f64>,
    k: usize,
}

impl Subset<'_> {
    fn pairs(&self) -> usize {
        self.lasers.len() * self.spads.len()
    }

    fn legs(&self, f: &Facet, pitch: f64, buf: &mut Vec<(V3, f64)>, out: &mut Legs) {
        f.sample(pitch, buf);
        let k_n = buf.len();
        out.k = k_n;
        let g = self.g;
        let (nl, ns) = (self.lasers.len(), self.spads.len());
        out.tl.resize(nl * k_n, 0.0);
        out.wl.resize(nl * k_n, 0.0);
        out.ts.resize(ns * k_n, 0.0);
        out.ws.resize(ns * k_n, 0.0);
        for (li, &l) in self.lasers.iter().enumerate() {
            let (nw, sc) = (g.laser_normal(l), self.laser_scale[li]);
            for (k, &(p, a)) in buf.iter().enumerate() {
                let (d, w) = leg(g.lasers[l], nw, p, f.normal);
                out.tl[li * k_n + k] = self.d1[li] + d - g.t0;
                out.wl[li * k_n + k] = sc * a * w;
            }
        }
        for (si, &s) in self.spads.iter().enumerate() {
            let nw = g.spad_normal(s);
            for (k, &(p, _)) in buf.iter().enumerate() {
                let (d, w) = leg(g.spads[s], nw, p, f.normal);
                out.ts[si * k_n + k] = self.d4[si] + d;
                out.ws[si * k_n + k] = w;
            }
        }
    }

    /// Renders pair `(li, si)` of `legs` into `m` (length `nt`, zero on entry); returns the
    /// range of bins touched.
    #[inline]
    fn render(&self, legs: &Legs, li: usize, si: usize, m: &mut [f64]) -> (usize, usize) {
        let k_n = legs.k;
        let (tl, wl) = (&legs.tl[li * k_n..][..k_n], &legs.wl[li * k_n..][..k_n]);
        let (ts, ws) = (&legs.ts[si * k_n..][..k_n], &legs.ws[si * k_n..][..k_n]);
        let inv = 1.0 / self.g.dt;
        let (mut lo, mut hi) = (usize::MAX, 0);
        // Neighbouring surfels mostly land in the same bin: a run is summed in a register
        // and stored once (a store and a reload of the same bin per surfel would chain them).
        let (mut run, mut acc) = (usize::MAX, 0.0f64);
        for k in 0..k_n {
            let w = wl[k] * ws[k];
            if w == 0.0 {
                continue;
            }
            if let Some(b) = bin_of((tl[k] + ts[k]) * inv, self.nt) {
                if b == run {
                    acc += w;
                } else {
                    if run != usize::MAX {
                        m[run] += acc;
                    }
                    (run, acc) = (b, w);
                    lo = lo.min(b);
                    hi = hi.max(b);
                }
            }
        }
        if run != usize::MAX {
            m[run] += acc;
        }
        (lo, hi)
    }

    /// `(⟨r, m⟩, ‖m‖²)` over the subset for the render of `legs`.
    fn score(&self, legs: &Legs, r: &[f64]) -> (f64, f64) {
        let (ns, nt) = (self.spads.len(), self.nt);
        (0..self.pairs())
            .into_par_iter()
            .fold(
                || (0.0, 0.0, vec![0.0f64; nt]),
                |(mut dot, mut mm, mut m), i| {
                    let (lo, hi) = self.render(legs, i / ns, i % ns, &mut m);
                    if lo <= hi {
                        let rr = &r[i * nt..(i + 1) * nt];
                        for b in lo..=hi {
                            dot += rr[b] * m[b];
                            mm += m[b] * m[b];
                            m[b] = 0.0;
                        }
                    }
                    (dot, mm, m)
                },
            )
            .map(|(d, m, _)| (d, m))
            .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
    }

    /// `r += a · m` for the render of `legs`.
    fn add(&self, legs: &Legs, a: f64, r: &mut [f64]) {
        if a == 0.0 {
            return;
        }
        let (ns, nt) = (self.spads.len(), self.nt);
        r.par_chunks_mut(nt).enumerate().for_each_init(
            || vec![0.0f64; nt],
            |m, (i, rr)| {
                let (lo, hi) = self.render(legs, i / ns, i % ns, m);
                if lo <= hi {
                    for b in lo..=hi {
                        rr[b] += a * m[b];
                        m[b] = 0.0;
                    }
                }
            },
        );
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
}

impl Default for FacetOptions {
    fn default() -> Self {
        Self {
            sweeps: 12,
            pitch: 0.01,
            grow: 6,
            grow_gain: 2e-4,
            subset: 16,
        }
    }
}

/// Folds tried at each edge (degrees; negative and positive: both ways about the edge).
const FOLDS: [f64; 8] = [-90.0, -60.0, -40.0, -20.0, 20.0, 40.0, 60.0, 90.0];
/// Widths of a grown facet before its refinement (m): a strip much narrower than the face it
/// stands for explains only its share of that face's light.
const GROW_WIDTHS: [f64; 3] = [0.04, 0.08, 0.16];
/// A grown facet's amplitude lies within this factor of its parent's (module docs).
const GROW_AMPLITUDE: f64 = 2.0;

impl Subset<'_> {
    /// The render of `legs` over the whole subset (`pairs·Nt`).
    fn dense(&self, legs: &Legs) -> Vec<f64> {
        let mut m = vec![0.0f64; self.pairs() * self.nt];
        self.add(legs, 1.0, &mut m);
        m
    }

    /// One Levenberg–Marquardt step of facet `f` (amplitude `a`, gain `gain` against `r`) on
    /// its 7 parameters and its amplitude together, from central differences at half the
    /// current steps (`scale · base`): the first damping of `10⁻³…1` whose pose raises the
    /// gain, as `(facet, gain, amplitude, true)`; `None` when none does.
    #[allow(clippy::too_many_arguments)]
    fn levenberg_marquardt(
        &self,
        f: &Facet,
        a: f64,
        gain: f64,
        r: &[f64],
        pitch: f64,
        scale: f64,
        base: &[f64; 7],
    ) -> Option<(Facet, f64, f64, bool)> {
        let (mut legs, mut buf) = (Legs::default(), Vec::new());
        self.legs(f, pitch, &mut buf, &mut legs);
        let m0 = self.dense(&legs);
        let mut cols: Vec<Vec<f64>> = Vec::with_capacity(8);
        for p in 0..7 {
            let h = 0.5 * base[p] * scale.max(1.0 / 32.0);
            let mut pose = [0.0; 7];
            pose[p] = h;
            self.legs(&f.moved(&pose), pitch, &mut buf, &mut legs);
            let mut d = self.dense(&legs);
            pose[p] = -h;
            self.legs(&f.moved(&pose), pitch, &mut buf, &mut legs);
            self.add(&legs, -1.0, &mut d);
            let k = a / (2.0 * h);
            d.iter_mut().for_each(|x| *x *= k);
            cols.push(d);
        }
        let e: Vec<f64> = r.iter().zip(&m0).map(|(r, m)| r - a * m).collect();
        cols.push(m0);
        const N: usize = 8;
        let dotv = |x: &[f64], y: &[f64]| -> f64 { x.par_iter().zip(y).map(|(a, b)| a * b).sum() };
        let mut gm = vec![0.0f64; N * N];
        let mut b = vec![0.0f64; N];
        for i in 0..N {
            b[i] = dotv(&cols[i], &e);
            for j in i..N {
                let v = dotv(&cols[i], &cols[j]);
                gm[i * N + j] = v;
                gm[j * N + i] = v;
            }
        }
        for mu in [1e-3, 1e-2, 1e-1, 1.0] {
            let mut g2 = gm.clone();
            (0..N).for_each(|i| g2[i * N + i] *= 1.0 + mu);
            let mut d = vec![0.0f64; N];
            if !solve(&g2, &b, &mut d) {
                continue;
            }
            let cand = f.moved(&core::array::from_fn(|i| d[i]));
            let [u0, u1, v0, v1] = cand.extent;
            if u1 - u0 < pitch || v1 - v0 < pitch {
                continue;
            }
            self.legs(&cand, pitch, &mut buf, &mut legs);
            let (dd, mm) = self.score(&legs, r);
            if dd > 0.0 && mm > 0.0 && dd * dd / mm > gain * (1.0 + 1e-9) {
                return Some((cand, dd * dd / mm, dd / mm, true));
            }
        }
        None
    }
}

/// At most `n` of `0..len`, spread evenly.
fn spread(len: usize, n: usize) -> Vec<usize> {
    if len <= n {
        return (0..len).collect();
    }
    (0..n).map(|i| (i * len + len / 2) / n).collect()
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
    } = *opts;
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
    let g = src.geometry().clone();
    if laser_scale.len() != g.lasers.len() {
        return Err(Error::arg(
            "laser_scale",
            format!("{} values for {} lasers", laser_scale.len(), g.lasers.len()),
        ));
    }
    let nt = g.nt;
    let lasers = spread(g.lasers.len(), subset);
    let spads = spread(g.spads.len(), subset);
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
                    .for_each(|(o, x)| *o = f64::from(*x));
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
    let bar = Pass::start(exec, "direct-light model: facets", (grow + 1) * sweeps);
    let mut ran = 0;
    let mut grown = 0;
    for round in 0..=grow {
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
                if scale[fi] < 1.0 / 64.0 {
                    // Settled: its steps are below the round's end (the others' go on).
                    continue;
                }
                // R' = R + a_f m_f.
                sub.legs(&facets[fi], pitch, &mut buf, &mut legs);
                sub.add(&legs, amp[fi], &mut r);
                let mut best = (facets[fi], 0.0f64, 0.0f64, false);
                let (d, m) = sub.score(&legs, &r);
                if d > 0.0 && m > 0.0 {
                    best = (facets[fi], d * d / m, d / m, false);
                }
                for p in 0..7 {
                    for sign in [-1.0, 1.0] {
                        let mut pose = [0.0; 7];
                        pose[p] = sign * base[p] * scale[fi];
                        let cand = facets[fi].moved(&pose);
                        let [u0, u1, v0, v1] = cand.extent;
                        if u1 - u0 < pitch || v1 - v0 < pitch {
                            continue;
                        }
                        sub.legs(&cand, pitch, &mut buf, &mut legs);
                        let (d, m) = sub.score(&legs, &r);
                        if d > 0.0 && m > 0.0 && d * d / m > best.1 * (1.0 + 1e-9) {
                            best = (cand, d * d / m, d / m, true);
                        }
                    }
                }
                if best.2 > 0.0
                    && let Some(lm) = sub
                        .levenberg_marquardt(&best.0, best.2, best.1, &r, pitch, scale[fi], &base)
                {
                    best = lm;
                }
                let (f, _, a, moved) = best;
                if !moved {
                    scale[fi] *= 0.5;
                }
                facets[fi] = f;
                amp[fi] = a.max(0.0);
                sub.legs(&facets[fi], pitch, &mut buf, &mut legs);
                sub.add(&legs, -amp[fi], &mut r);
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
