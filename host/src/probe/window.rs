//! One rule for a capture's time window, shared by every probe (`direct`, `column`,
//! `indirect`, `matrix`, `row`, `relight`, and any front end that streams probes).
//!
//! A probe images paths `x_l → x_a → x_b → x_s` (on the diagonal `x_a = x_b`) whose length
//! `τ = d1 + |x_l − x_a| + |x_a − x_b| + |x_b − x_s| + d4` (metres of optical path; `d1`, `d4`
//! the device legs when the capture's times include them) must fall where the capture
//! recorded light. The **window** of this rule is the recorded time axis widened by one gate
//! σ on each side, `[t0 − σ, t0 + (Nt − 1)Δt + σ]`: a path within σ of the axis still sees
//! the Gaussian gate's central lobe (weight ≥ e^{−1/2}); a path further out sees only its
//! tail, and an image made of such paths alone is numerical noise (a peak of 10⁻¹⁴ where the
//! window holds the scene).
//!
//! - When **no** path meets the window, every probe refuses the run with the same one-line
//!   error ([`window_coverage`]; [`Error::Argument`] on `volume`), before any work.
//! - When fewer than [`WARN_FRACTION`] of the paths do, the probes warn (through
//!   [`Progress::warn`](crate::Progress::warn)) and run.
//! - The higher-order gate images light arriving **after** a path's time: a path meets the
//!   window when it is no later than the window's end. The ungated (monochromatic) probes do
//!   not depend on path times: the rule does not apply to them.
//!
//! Cost: the existence test takes the span of path lengths per (focus, voxel) pair from the
//! per-point spans over lasers and SPADs, `O(F·Kl + V·Ks + F·V)` at worst, and stops at the
//! first pair that meets the window. The per-point spans are exact but prune the lasers and
//! SPADs by a k-d tree (`SpanIndex`): on a 64×64 confocal scan, a few leaves of the 4,096
//! wall points are visited per voxel. The fraction is counted exactly on a strided sample of at most 32
//! lasers × 32 SPADs × 32 foci × 1024 voxels (sorted legs, `O(n log n)` per pair).

use super::gate::ColumnGate;
use super::wave::legs;
use crate::error::{Error, Result};
use crate::exec::Exec;
use crate::io::capture::Geometry;
use rayon::prelude::*;
use vltm_kernel::geometry::dist;
use vltm_kernel::{Config, Point};

/// The probes warn when fewer than this fraction of the sampled paths lie in the window.
pub const WARN_FRACTION: f64 = 0.25;

/// How the probed paths meet a capture's window ([`window_coverage`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coverage {
    /// Fraction of the (sampled) paths whose length lies in the window, in `[0, 1]`.
    pub fraction: f64,
    /// The window `[t0 − σ, t0 + (Nt − 1)Δt + σ]` (m of path).
    pub window: (f64, f64),
    /// The span of the paths' lengths (m), over every laser, SPAD, focus and voxel.
    pub span: (f64, f64),
}

impl Coverage {
    /// The warning for a fraction under [`WARN_FRACTION`] (`None` above it).
    pub fn warning(&self) -> Option<String> {
        (self.fraction < WARN_FRACTION).then(|| {
            format!(
                "only {:.1} % of the paths through the probed points lie in the capture's time window ({:.4} to {:.4} m of path; the paths span {:.4} to {:.4} m): the rest contribute nothing",
                100.0 * self.fraction,
                self.window.0,
                self.window.1,
                self.span.0,
                self.span.1
            )
        })
    }
}

/// Most points in a leaf of a [`SpanIndex`].
const LEAF: usize = 16;

/// One node of a [`SpanIndex`]: the bounding box of its points (m), the range of their legs
/// (m), their range in the index's order, and its children (none for a leaf).
#[derive(Clone, Copy, Debug)]
struct Node {
    lo: [f64; 3],
    hi: [f64; 3],
    legs: (f64, f64),
    start: usize,
    end: usize,
    kids: Option<(u32, u32)>,
}

/// The span `(min, max)` over a point set of `|p − v| + leg_p` (`|p − v|` in `f32` as
/// [`dist`] takes it, the leg in `f64`) for any query point `v`, equal to the brute-force
/// fold over every point, at a fraction of its cost: a k-d tree (median splits along the
/// widest axis, leaves of at most [`LEAF`] points) whose nodes are bounded by their box (the
/// nearest and farthest box points, widened by a relative `1e-6` for the `f32` distances,
/// plus the node's leg range); a query descends only into nodes that can still lower the
/// minimum or raise the maximum. Cost: `O(n log n)` to build; per query a few dozen nodes
/// and leaves on a wall lattice (all `n` points at worst). Memory: ~100 bytes per leaf.
pub(crate) struct SpanIndex<'a> {
    pts: &'a [Point],
    legs: &'a [f64],
    /// Point indices, leaf by leaf.
    order: Vec<u32>,
    /// The nodes, the root first.
    nodes: Vec<Node>,
}

impl<'a> SpanIndex<'a> {
    /// Indexes `pts` with their legs (`legs[i]` belongs to `pts[i]`).
    ///
    /// # Panics
    /// If the lengths differ.
    pub(crate) fn new(pts: &'a [Point], legs: &'a [f64]) -> Self {
        assert_eq!(pts.len(), legs.len(), "one leg per point");
        let mut order: Vec<u32> = (0..pts.len() as u32).collect();
        let mut nodes: Vec<Node> = Vec::with_capacity(4 * pts.len().div_ceil(LEAF) + 1);
        // (node, start, end): the node is pushed with its box, its children filled later.
        let mut stack = vec![(0usize, 0usize, pts.len())];
        nodes.push(Self::node(pts, legs, &order, 0, pts.len()));
        while let Some((n, start, end)) = stack.pop() {
            if end - start <= LEAF {
                continue;
            }
            let (lo, hi) = (nodes[n].lo, nodes[n].hi);
            let axis = (0..3)
                .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
                .unwrap_or(0);
            let mid = start + (end - start) / 2;
            order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
                pts[a as usize][axis].total_cmp(&pts[b as usize][axis])
            });
            let k = nodes.len();
            nodes.push(Self::node(pts, legs, &order, start, mid));
            nodes.push(Self::node(pts, legs, &order, mid, end));
            nodes[n].kids = Some((k as u32, k as u32 + 1));
            stack.push((k, start, mid));
            stack.push((k + 1, mid, end));
        }
        Self {
            pts,
            legs,
            order,
            nodes,
        }
    }

    /// The node over `order[start..end]`, without children.
    fn node(pts: &[Point], legs: &[f64], order: &[u32], start: usize, end: usize) -> Node {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut lg = (f64::INFINITY, f64::NEG_INFINITY);
        for &i in &order[start..end] {
            let p = pts[i as usize];
            for c in 0..3 {
                lo[c] = lo[c].min(f64::from(p[c]));
                hi[c] = hi[c].max(f64::from(p[c]));
            }
            let l = legs[i as usize];
            lg = (lg.0.min(l), lg.1.max(l));
        }
        Node {
            lo,
            hi,
            legs: lg,
            start,
            end,
            kids: None,
        }
    }

    /// Lower bound of the minimum and upper bound of the maximum of `|p − v| + leg` over
    /// the node's points.
    #[inline]
    fn bounds(t: &Node, v: [f64; 3]) -> (f64, f64) {
        let (mut near, mut far) = (0.0, 0.0);
        // Not `clamp`: it panics on an empty box (lo = +∞, hi = −∞).
        for ((&x, &lo), &hi) in v.iter().zip(&t.lo).zip(&t.hi) {
            let n = (lo - x).max(x - hi).max(0.0);
            let f = (x - lo).abs().max((x - hi).abs());
            near += n * n;
            far += f * f;
        }
        let (near, far) = (near.sqrt(), far.sqrt());
        (
            near * (1.0 - 1e-6) - 1e-9 + t.legs.0,
            far * (1.0 + 1e-6) + 1e-9 + t.legs.1,
        )
    }

    /// The exact fold over the leaf's points, widening `span`.
    fn visit(&self, t: &Node, v: &Point, span: &mut (f64, f64)) {
        for &i in &self.order[t.start..t.end] {
            let x = f64::from(dist(&self.pts[i as usize], v)) + self.legs[i as usize];
            *span = (span.0.min(x), span.1.max(x));
        }
    }

    /// Bounds of [`SpanIndex::span`] from the root's box alone (a lower bound of the minimum,
    /// an upper bound of the maximum; `(+∞, −∞)` for no points). Cost O(1).
    pub(crate) fn root_bounds(&self, v: &Point) -> (f64, f64) {
        match self.nodes.first() {
            Some(t) if !self.pts.is_empty() => Self::bounds(t, v.map(f64::from)),
            _ => (f64::INFINITY, f64::NEG_INFINITY),
        }
    }

    /// `(min, max)` over the points of `|p − v| + leg_p`; `(+∞, −∞)` for no points.
    pub(crate) fn span(&self, v: &Point) -> (f64, f64) {
        let mut span = (f64::INFINITY, f64::NEG_INFINITY);
        if self.pts.is_empty() {
            return span;
        }
        let q = v.map(f64::from);
        // Depth-first; each entry a node and its bounds. The tree is balanced: its depth
        // is log₂(n/LEAF) + 1 < 60, and the stack holds at most one sibling per level.
        let mut stack: Vec<(u32, (f64, f64))> = Vec::with_capacity(64);
        stack.push((0, Self::bounds(&self.nodes[0], q)));
        while let Some((n, (a, b))) = stack.pop() {
            // NaN bounds are visited (the comparison fails).
            if a >= span.0 && b <= span.1 {
                continue;
            }
            let t = &self.nodes[n as usize];
            let Some((k1, k2)) = t.kids else {
                self.visit(t, v, &mut span);
                continue;
            };
            let (b1, b2) = (
                Self::bounds(&self.nodes[k1 as usize], q),
                Self::bounds(&self.nodes[k2 as usize], q),
            );
            // The child popped first: the nearer while the minimum may still fall, else
            // the one reaching farther.
            let first_is_1 = if a < span.0 {
                b1.0 <= b2.0
            } else {
                b1.1 >= b2.1
            };
            if first_is_1 {
                stack.push((k2, b2));
                stack.push((k1, b1));
            } else {
                stack.push((k1, b1));
                stack.push((k2, b2));
            }
        }
        span
    }
}

/// Sample caps of the fraction (lasers, SPADs, foci, voxels).
const SAMPLE: (usize, usize, usize, usize) = (32, 32, 32, 1024);

/// Every `len / cap`-th index (at most `cap` of them, first and spread over the range).
fn strided(len: usize, cap: usize) -> impl Iterator<Item = usize> {
    let step = len.div_ceil(cap).max(1);
    (0..len).step_by(step)
}

/// How the paths from `foci` to `voxels` (the diagonal through `voxels` for `foci = None`)
/// meet the capture's window under `gate` (see the module docs). `cfg` is the capture's
/// configuration ([`Wave::config`](super::Wave::config)): its σ widens the window and its legs
/// give `d1`, `d4`.
///
/// # Errors
/// [`Error::Argument`] on `volume` when no path meets the window: the same one line for
/// every probe, naming the window (the paths' span is in [`Coverage::span`] otherwise).
pub fn window_coverage(
    g: &Geometry,
    cfg: &Config,
    foci: Option<&[Point]>,
    voxels: &[Point],
    gate: ColumnGate,
) -> Result<Coverage> {
    coverage(g, cfg, None, foci, voxels, gate)
}

/// [`window_coverage`], with the device legs `(d1, d4)` when the caller has them
/// ([`legs`]; made here otherwise).
fn coverage(
    g: &Geometry,
    cfg: &Config,
    legs_made: Option<&(Vec<f64>, Vec<f64>)>,
    foci: Option<&[Point]>,
    voxels: &[Point],
    gate: ColumnGate,
) -> Result<Coverage> {
    let sigma = cfg.sigma();
    let window = (g.t0 - sigma, g.t0 + cfg.window() + sigma);
    let full = Coverage {
        fraction: 1.0,
        window,
        span: (f64::NAN, f64::NAN),
    };
    if voxels.is_empty() || foci.is_some_and(<[Point]>::is_empty) || gate == ColumnGate::None {
        return Ok(full);
    }
    let _t = crate::timings::section("window rule", crate::timings::Kind::Parallel);
    let after_only = gate == ColumnGate::HigherOrder;
    let (lo, hi) = window;
    let meets = |(a, b): (f64, f64)| a <= hi && (after_only || b >= lo);
    let made;
    let (d1, d4) = match legs_made {
        Some((d1, d4)) => (d1, d4),
        None => {
            made = legs(g, cfg);
            (&made.0, &made.1)
        }
    };
    let laser_spans = SpanIndex::new(&g.lasers, d1);
    let spad_spans = SpanIndex::new(&g.spads, d4);
    let join = |x: (f64, f64), y: (f64, f64)| (x.0.min(y.0), x.1.max(y.1));
    let empty = (f64::INFINITY, f64::NEG_INFINITY);
    let pair = |a: &Point, p: (f64, f64), b: &Point, c: (f64, f64)| {
        let d = f64::from(dist(a, b));
        (p.0 + d + c.0, p.1 + d + c.1)
    };
    let (found, all) = match foci {
        None => {
            // A confocal scan with equal legs: the projector spans are the camera's.
            let same = g.lasers == g.spads && d1 == d4;
            // Projector plus camera legs of a voxel, by `f` of each index.
            let both = |f: fn(&SpanIndex<'_>, &Point) -> (f64, f64), v: &Point| {
                let c = f(&spad_spans, v);
                let p = if same { c } else { f(&laser_spans, v) };
                (p.0 + c.0, p.1 + c.1)
            };
            let exact = |v: &Point| both(|t, v| t.span(v), v);
            // The span over every voxel, exactly, without a query per voxel: seeded by a
            // strided sample, then a voxel is queried only when its bounds from the trees'
            // roots could widen the running span (most voxels of a grid cannot).
            let sample: Vec<(f64, f64)> = strided(voxels.len(), 1024)
                .chain(std::iter::once(voxels.len() - 1))
                .collect::<Vec<_>>()
                .par_iter()
                .map(|&i| exact(&voxels[i]))
                .collect();
            let seed = sample.iter().fold(empty, |a, &s| join(a, s));
            let all = voxels
                .par_iter()
                .fold(
                    || seed,
                    |run, v| {
                        let (lo, hi) = both(|t, v| t.root_bounds(v), v);
                        if lo >= run.0 && hi <= run.1 {
                            run
                        } else {
                            join(run, exact(v))
                        }
                    },
                )
                .reduce(|| seed, join);
            let found = sample.iter().any(|&s| meets(s))
                || (meets(all) && voxels.par_iter().any(|v| meets(exact(v))));
            (found, all)
        }
        Some(foci) => {
            let cam: Vec<(f64, f64)> = voxels.par_iter().map(|b| spad_spans.span(b)).collect();
            let proj: Vec<(f64, f64)> = foci.par_iter().map(|a| laser_spans.span(a)).collect();
            let found = foci.par_iter().zip(&proj).any(|(a, &p)| {
                voxels
                    .iter()
                    .zip(&cam)
                    .any(|(b, &c)| meets(pair(a, p, b, c)))
            });
            let all = foci
                .par_iter()
                .zip(&proj)
                .map(|(a, &p)| {
                    voxels
                        .iter()
                        .zip(&cam)
                        .fold(empty, |acc, (b, &c)| join(acc, pair(a, p, b, c)))
                })
                .reduce(|| empty, join);
            (found, all)
        }
    };
    if !found {
        return Err(Error::arg(
            "volume",
            format!(
                "no path through the probed points lies in the capture's time window ({:.4} to {:.4} m of path: its time axis widened by σ = {:.4} m): choose points the capture saw, or check its t_start and delta_t",
                lo, hi, sigma
            ),
        ));
    }
    Ok(Coverage {
        fraction: sampled_fraction(g, (d1, d4), foci, voxels, window, after_only),
        window,
        span: all,
    })
}

/// The fraction of sampled paths in the window (module docs).
fn sampled_fraction(
    g: &Geometry,
    (d1, d4): (&[f64], &[f64]),
    foci: Option<&[Point]>,
    voxels: &[Point],
    (lo, hi): (f64, f64),
    after_only: bool,
) -> f64 {
    let (nl, ns, nf, nv) = SAMPLE;
    let lasers: Vec<usize> = strided(g.lasers.len(), nl).collect();
    let spads: Vec<usize> = strided(g.spads.len(), ns).collect();
    let vox: Vec<usize> = strided(voxels.len(), nv).collect();
    let sorted_legs = |pts: &[Point], legs: &[f64], idx: &[usize], x: &Point| {
        let mut v: Vec<f64> = idx
            .iter()
            .map(|&i| f64::from(dist(&pts[i], x)) + legs[i])
            .collect();
        v.sort_by(f64::total_cmp);
        v
    };
    // Pairs (p_i, c_j) with p_i + d + c_j in [lo, hi]: two binary searches per p_i.
    let count = |p: &[f64], d: f64, c: &[f64]| -> usize {
        p.iter()
            .map(|&x| {
                let base = x + d;
                let first = if after_only {
                    0
                } else {
                    c.partition_point(|&y| base + y < lo)
                };
                let last = c.partition_point(|&y| base + y <= hi);
                last.saturating_sub(first)
            })
            .sum()
    };
    let (inside, total) = match foci {
        None => vox
            .par_iter()
            .map(|&v| {
                let x = &voxels[v];
                let p = sorted_legs(&g.lasers, d1, &lasers, x);
                let c = sorted_legs(&g.spads, d4, &spads, x);
                (count(&p, 0.0, &c), p.len() * c.len())
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1)),
        Some(foci) => {
            let cams: Vec<Vec<f64>> = vox
                .par_iter()
                .map(|&v| sorted_legs(&g.spads, d4, &spads, &voxels[v]))
                .collect();
            strided(foci.len(), nf)
                .collect::<Vec<_>>()
                .par_iter()
                .map(|&f| {
                    let a = &foci[f];
                    let p = sorted_legs(&g.lasers, d1, &lasers, a);
                    vox.iter().zip(&cams).fold((0, 0), |acc, (&v, c)| {
                        let d = f64::from(dist(a, &voxels[v]));
                        (acc.0 + count(&p, d, c), acc.1 + p.len() * c.len())
                    })
                })
                .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
        }
    };
    if total == 0 {
        1.0
    } else {
        inside as f64 / total as f64
    }
}

/// [`window_coverage`] with the probes' warning sent to `exec`'s progress sink.
///
/// # Errors
/// As [`window_coverage`].
pub(super) fn window_rule(
    g: &Geometry,
    cfg: &Config,
    foci: Option<&[Point]>,
    voxels: &[Point],
    gate: ColumnGate,
    exec: Exec<'_>,
) -> Result<Coverage> {
    warn(window_coverage(g, cfg, foci, voxels, gate)?, exec)
}

/// [`window_rule`] with the device legs `legs` ([`legs`]) the caller has.
///
/// # Errors
/// As [`window_coverage`].
pub(super) fn window_rule_with(
    g: &Geometry,
    cfg: &Config,
    legs: &(Vec<f64>, Vec<f64>),
    foci: Option<&[Point]>,
    voxels: &[Point],
    gate: ColumnGate,
    exec: Exec<'_>,
) -> Result<Coverage> {
    warn(coverage(g, cfg, Some(legs), foci, voxels, gate)?, exec)
}

/// `c`, its warning sent to `exec`'s progress sink.
fn warn(c: Coverage, exec: Exec<'_>) -> Result<Coverage> {
    if let (Some(w), Some(p)) = (c.warning(), exec.progress) {
        p.warn(&w);
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::probe::Wave;

    fn geometry(t0: f64) -> Geometry {
        Geometry {
            lasers: vec![[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]],
            laser_shape: [2, 1],
            spads: vec![[0.0, 0.0, 0.0]],
            spad_shape: [1, 1],
            laser_origin: [0.0, 0.0, 0.5],
            sensor_origin: [0.0, 0.0, 0.5],
            legs_in_time: false,
            confocal: false,
            nt: 100,
            dt: 0.02,
            t0,
            normals: Default::default(),
        }
    }

    /// The window misses every path: one error for the diagonal, a column, and the
    /// higher-order gate only when every path is later than the window's end; a window over
    /// all paths covers them all, and one over some of them reports the fraction.
    #[test]
    fn empty_partial_and_full_windows() {
        let vox = [[0.0, 0.0, 1.0f32], [0.0, 0.0, 1.2]];
        let wave = Wave {
            wavelength: Some(0.1),
            ..Wave::default()
        };
        // Paths through (0, 0, 1): 1 + √1.25 ≈ 2.12 m; through (0, 0, 1.2): 1.2 + 1.3 = 2.5 m.
        let g = geometry(-3.0);
        let cfg = wave.config(&g).unwrap();
        for foci in [None, Some(&vox[..1])] {
            let e = window_coverage(&g, &cfg, foci, &vox, ColumnGate::TwoBounce)
                .unwrap_err()
                .to_string();
            assert!(e.contains("no path through the probed points"), "{e}");
            assert!(e.starts_with("argument `volume`"), "{e}");
        }
        // Later light: paths before the window's end exist only for a later window.
        assert!(window_coverage(&g, &cfg, None, &vox, ColumnGate::HigherOrder).is_err());
        assert!(window_coverage(&g, &cfg, None, &vox, ColumnGate::None).is_ok());
        let g = geometry(1.5);
        let cfg = wave.config(&g).unwrap();
        let c = window_coverage(&g, &cfg, None, &vox, ColumnGate::TwoBounce).unwrap();
        assert_eq!(c.fraction, 1.0);
        assert!(c.warning().is_none());
        // A window [2.3 − σ, 4.28 + σ] holds the paths of the far voxel only.
        let g = geometry(2.3);
        let cfg = wave.config(&g).unwrap();
        let c = window_coverage(&g, &cfg, None, &vox, ColumnGate::TwoBounce).unwrap();
        assert_eq!(c.fraction, 0.5, "{c:?}");
        let far = [[0.0, 0.0, 1.2f32]; 3];
        let near = [[0.0, 0.0, 1.0f32]; 9];
        let mixed: Vec<Point> = far.iter().chain(&near).copied().collect();
        let c = window_coverage(&g, &cfg, None, &mixed, ColumnGate::TwoBounce).unwrap();
        assert_eq!(c.fraction, 0.25, "{c:?}");
        let c = window_coverage(&g, &cfg, None, &mixed[2..], ColumnGate::TwoBounce).unwrap();
        assert!(c.fraction < WARN_FRACTION && c.warning().is_some(), "{c:?}");
    }

    /// The diagonal's span over a voxel grid (queried only where the roots' bounds could
    /// widen it) equals the fold over every (laser, voxel, SPAD) path, confocal and not, and
    /// the window is found met by a single voxel among thousands.
    #[test]
    fn diagonal_span_equals_the_fold_over_every_path() {
        let wall: Vec<Point> = (0..16 * 16)
            .map(|i| {
                [
                    -0.2 + (i / 16) as f32 * 0.03,
                    -0.2 + (i % 16) as f32 * 0.03,
                    0.0,
                ]
            })
            .collect();
        let vox: Vec<Point> = (0..40 * 40 * 5)
            .map(|i| {
                let (x, y, z) = (i / 200, (i / 5) % 40, i % 5);
                [
                    -0.5 + x as f32 * 0.025,
                    -0.4 + y as f32 * 0.02,
                    0.3 + z as f32 * 0.1,
                ]
            })
            .collect();
        let wave = Wave {
            wavelength: Some(0.1),
            ..Wave::default()
        };
        for confocal in [true, false] {
            let mut g = geometry(0.0);
            g.nt = 400;
            g.dt = 0.01;
            g.spads = wall.clone();
            g.spad_shape = [16, 16];
            if confocal {
                g.lasers = wall.clone();
                g.laser_shape = [16, 16];
                g.confocal = true;
            }
            let cfg = wave.config(&g).unwrap();
            let (d1, d4) = legs(&g, &cfg);
            let brute = vox
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |acc, v| {
                    let leg = |pts: &[Point], lg: &[f64]| {
                        pts.iter()
                            .zip(lg)
                            .fold((f64::INFINITY, f64::NEG_INFINITY), |a, (p, d)| {
                                let x = f64::from(dist(p, v)) + d;
                                (a.0.min(x), a.1.max(x))
                            })
                    };
                    let (p, c) = (leg(&g.lasers, &d1), leg(&g.spads, &d4));
                    (acc.0.min(p.0 + c.0), acc.1.max(p.1 + c.1))
                });
            let c = window_coverage(&g, &cfg, None, &vox, ColumnGate::TwoBounce).unwrap();
            assert_eq!(c.span, brute, "confocal {confocal}");
            // A window that only the deepest, outermost voxel's longest paths reach.
            g.t0 = brute.1 - 1e-3 + cfg.sigma();
            let cfg = wave.config(&g).unwrap();
            let c = window_coverage(&g, &cfg, None, &vox, ColumnGate::TwoBounce).unwrap();
            assert_eq!(c.span, brute);
            g.t0 = brute.1 + 1e-3 + cfg.sigma();
            let cfg = wave.config(&g).unwrap();
            assert!(window_coverage(&g, &cfg, None, &vox, ColumnGate::TwoBounce).is_err());
        }
    }

    /// The tiled spans equal the brute-force fold exactly, on a regular wall, a random
    /// cloud with random legs (leaves of mixed legs), a single point and repeated points,
    /// for queries over, beside and far from the points; and a missed tile would show.
    #[test]
    fn span_index_equals_the_brute_force_fold() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let wall: Vec<Point> = (0..64 * 64)
            .map(|i| {
                let p = 0.4 / 63.0;
                [-0.2 + (i / 64) as f32 * p, -0.2 + (i % 64) as f32 * p, 0.0]
            })
            .collect();
        let cloud: Vec<Point> = (0..777)
            .map(|_| [rnd() as f32 - 0.5, rnd() as f32 - 0.5, 0.3 * rnd() as f32])
            .collect();
        let sets: Vec<(Vec<Point>, Vec<f64>)> = vec![
            (wall.clone(), vec![0.0; wall.len()]),
            (
                wall.clone(),
                wall.iter()
                    .map(|p| f64::from(dist(p, &[0.1, -0.3, 0.9])))
                    .collect(),
            ),
            (cloud.clone(), (0..cloud.len()).map(|_| rnd()).collect()),
            (vec![[0.1, 0.2, 0.0]], vec![0.5]),
            (
                vec![[0.0; 3]; 100],
                (0..100).map(|i| i as f64 * 0.01).collect(),
            ),
        ];
        for (pts, lg) in &sets {
            let idx = SpanIndex::new(pts, lg);
            assert_eq!(idx.order.len(), pts.len());
            let mut sorted = idx.order.clone();
            sorted.sort_unstable();
            assert!(sorted.iter().enumerate().all(|(i, &k)| k as usize == i));
            for q in 0..300 {
                let far = if q % 3 == 0 { 10.0 } else { 1.0 };
                let v = [
                    (far * (rnd() - 0.5)) as f32,
                    (far * (rnd() - 0.5)) as f32,
                    (far * rnd()) as f32,
                ];
                let brute = pts.iter().zip(lg).fold(
                    (f64::INFINITY, f64::NEG_INFINITY),
                    |(a, b), (p, d)| {
                        let x = f64::from(dist(p, &v)) + d;
                        (a.min(x), b.max(x))
                    },
                );
                assert_eq!(idx.span(&v), brute, "query {v:?}");
            }
        }
        // Removing the leaves that hold the nearest and the farthest wall corner changes a
        // far query's span: the answer does come from the leaves visited.
        let lg = vec![0.0; wall.len()];
        let mut idx = SpanIndex::new(&wall, &lg);
        let v = [5.0, 5.0, 0.5];
        let full = idx.span(&v);
        let holds =
            |t: &Node, c: f64| (t.lo[0]..=t.hi[0]).contains(&c) && (t.lo[1]..=t.hi[1]).contains(&c);
        for t in &mut idx.nodes {
            if t.kids.is_none() && (holds(t, f64::from(0.2f32)) || holds(t, f64::from(-0.2f32))) {
                t.end = t.start;
            }
        }
        let cut = idx.span(&v);
        assert!(cut.0 > full.0 && cut.1 < full.1, "{cut:?} {full:?}");
    }
}
