//! Geometry from the capture: the surfel patches moved along their normals and scaled, one
//! patch at a time, to minimise the residual against a spread subset of the capture's
//! histograms (analysis by synthesis).
//!
//! Each patch `p` (one column of [`Surfels::from_direct`]) has a pose (an offset `δ_p` along
//! its normal and tilts about its two tangents, about its centre) and an amplitude `a_p ≥ 0`.
//! The residual `R = H − Σ_p a_p m_p(pose_p)` is kept over the subset; a sweep visits every
//! patch and tries `δ_p + {0, ±½, ±1, ±2}·step` and each tilt `± angle` (from 2°), each with
//! its optimal amplitude `a = max(0, ⟨R + a_p m_p, m⟩/‖m‖²)`, keeps the best (the current one
//! among them, so the residual never grows) and updates `R`; step and angle halve every sweep.
//! Returns are binned as the render bins them (no blur, no delay: those are fitted after).
//!
//! Cost: per patch and sweep, `11·|p|` returns per histogram of the subset (`|p|` surfels per
//! patch). Memory: the subset (`H·Nt` values, `H ≤ 4,096` histograms) and its residual.

use super::linalg::ordered_sum;
use super::render::leg;
use super::subset::PAIR_CHUNK;
use super::surfels::Surfels;
use super::vec3::{cross, rotate};
use crate::error::Result;
use crate::exec::{Exec, Pass};
use crate::io::capture::{Geometry, RowSource};
use rayon::prelude::*;
use vltm_kernel::geometry::dist64;

/// What [`refine`] found: the surfels moved and scaled, and the energy fraction explained
/// over the subset before and after.
#[derive(Clone, Debug)]
pub struct Refined {
    /// The surfels, moved along their normals and tilted; areas scaled by the patches' amplitudes
    /// relative to the first global scale; patches switched off dropped.
    pub surfels: Surfels,
    /// Fraction of the subset's energy explained with the surfels as given (one global scale).
    pub before: f64,
    /// After the sweeps.
    pub after: f64,
}

/// A patch's centre and frame: its normal (of its first surfel) and two tangents.
struct Frame {
    centre: [f64; 3],
    n: [f64; 3],
    t1: [f64; 3],
    t2: [f64; 3],
}

impl Frame {
    fn of(s: &Surfels, r: std::ops::Range<usize>) -> Self {
        let m = r.len().max(1) as f64;
        let centre: [f64; 3] =
            core::array::from_fn(|x| r.clone().map(|k| s.points[k][x]).sum::<f64>() / m);
        let n = s.normals[r.start];
        let a = if n[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let t1 = {
            let c = cross(n, a);
            let l = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
            c.map(|x| x / l)
        };
        let t2 = cross(n, t1);
        Self { centre, n, t1, t2 }
    }

    /// Surfel `k` of this patch under pose `[offset, tilt about t1, tilt about t2]`: its point
    /// and normal.
    fn place(&self, s: &Surfels, k: usize, pose: [f64; 3]) -> ([f64; 3], [f64; 3]) {
        let [d, a, b] = pose;
        let rel: [f64; 3] = core::array::from_fn(|x| s.points[k][x] - self.centre[x]);
        let (rel, n) = if a == 0.0 && b == 0.0 {
            (rel, s.normals[k])
        } else {
            let rel = rotate(rotate(rel, self.t1, a), self.t2, b);
            let n = rotate(rotate(s.normals[k], self.t1, a), self.t2, b);
            (rel, n)
        };
        let q = core::array::from_fn(|x| self.centre[x] + rel[x] + d * self.n[x]);
        (q, n)
    }
}

/// A return: `(bin, amplitude)` of surfel point `p` with normal `n` and area `a` for the pair
/// `(l, s)`; `None` outside the window or facing away.
#[inline]
fn ret(
    g: &Geometry,
    l: usize,
    s: usize,
    scale: f64,
    p: [f64; 3],
    n: [f64; 3],
    a: f64,
) -> Option<(usize, f64)> {
    let (dl, fl) = leg(g.lasers[l], g.laser_normal(l), p, n);
    let (ds, fs) = leg(g.spads[s], g.spad_normal(s), p, n);
    let w = scale * a * fl * fs;
    if w == 0.0 {
        return None;
    }
    let legs = if g.legs_in_time {
        dist64(&g.lasers[l], &g.laser_origin) + dist64(&g.spads[s], &g.sensor_origin)
    } else {
        0.0
    };
    let b = ((legs + dl + ds - g.t0) / g.dt).floor();
    (b >= 0.0 && b < g.nt as f64).then_some((b as usize, w))
}

/// Refines `surfels` (which must have patches) against the capture: one pass to read the
/// subset of at most 4,096 histograms, then `sweeps` sweeps from `step` metres.
///
/// # Errors
/// Read errors.
pub fn refine(
    src: &mut dyn RowSource,
    surfels: &Surfels,
    laser_scale: &[f64],
    sweeps: usize,
    step: f64,
    exec: Exec<'_>,
) -> Result<Refined> {
    let g = src.geometry().clone();
    let (l_n, s_n, nt) = (g.lasers.len(), g.spads.len(), g.nt);
    let stride = (l_n * s_n).div_ceil(4096).max(1);
    let pairs: Vec<(usize, usize)> = (0..l_n)
        .flat_map(|l| (0..s_n).map(move |s| (l, s)))
        .filter(|(l, s)| (l * s_n + s) % stride == 0)
        .collect();
    let mut h = vec![0.0f64; pairs.len() * nt];
    {
        let bar = Pass::start(exec, "direct-light model: geometry", l_n);
        let mut row = Vec::new();
        let mut i = 0;
        for l in 0..l_n {
            src.read_row(l, &mut row)?;
            while i < pairs.len() && pairs[i].0 == l {
                let s = pairs[i].1;
                h[i * nt..(i + 1) * nt]
                    .iter_mut()
                    .zip(&row[s * nt..(s + 1) * nt])
                    .for_each(|(o, x)| *o = if x.is_finite() { f64::from(*x) } else { 0.0 });
                i += 1;
            }
            bar.advance(1);
        }
    }
    let energy: f64 = h.iter().map(|x| x * x).sum();
    let patches = if surfels.patches.is_empty() {
        std::iter::once(0..surfels.len()).collect()
    } else {
        surfels.patches.clone()
    };
    // Per patch: its centre and an orthonormal frame (normal of its first surfel, two
    // tangents); its pose: offset along the normal and tilts about the two tangents.
    let frames: Vec<Frame> = patches
        .iter()
        .map(|r| Frame::of(surfels, r.clone()))
        .collect();
    let mut pose = vec![[0.0f64; 3]; patches.len()];
    // One global scale to start: a_p = <H, M>/<M, M>.
    let render_all = |pose: &[[f64; 3]], amp: &[f64]| -> Vec<f64> {
        let mut m = vec![0.0f64; pairs.len() * nt];
        m.par_chunks_mut(nt).zip(&pairs).for_each(|(m, &(l, s))| {
            for (p, r) in patches.iter().enumerate() {
                for k in r.clone() {
                    let (q, n) = frames[p].place(surfels, k, pose[p]);
                    if let Some((b, w)) = ret(&g, l, s, laser_scale[l], q, n, surfels.areas[k]) {
                        m[b] += amp[p] * w;
                    }
                }
            }
        });
        m
    };
    let m0 = render_all(&pose, &vec![1.0; patches.len()]);
    let hm: f64 = h.iter().zip(&m0).map(|(a, b)| a * b).sum();
    let mm: f64 = m0.iter().map(|x| x * x).sum();
    let s0 = if mm > 0.0 { (hm / mm).max(0.0) } else { 0.0 };
    let mut amp = vec![s0; patches.len()];
    let mut r: Vec<f64> = h.iter().zip(&m0).map(|(a, b)| a - s0 * b).collect();
    let explained = |r: &[f64]| 1.0 - r.iter().map(|x| x * x).sum::<f64>() / energy;
    let before = explained(&r);
    // Moves tried per patch: offsets in steps, tilts in angle steps.
    const TRY: [[f64; 3]; 11] = [
        [0.0, 0.0, 0.0],
        [-0.5, 0.0, 0.0],
        [0.5, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [-2.0, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, -1.0],
        [0.0, 0.0, 1.0],
    ];
    let mut step = step;
    let mut angle = 2f64.to_radians();
    let bar = Pass::start(exec, "direct-light model: geometry", sweeps * patches.len());
    for _ in 0..sweeps {
        for (p, range) in patches.iter().enumerate() {
            // Per histogram: the patch's old and candidate returns, <R', m_c> and ‖m_c‖².
            let cand: Vec<[f64; 3]> = TRY
                .iter()
                .map(|t| {
                    [
                        pose[p][0] + t[0] * step,
                        pose[p][1] + t[1] * angle,
                        pose[p][2] + t[2] * angle,
                    ]
                })
                .collect();
            let render = |l: usize, s: usize, d: [f64; 3], out: &mut Vec<(usize, f64)>| {
                out.clear();
                for k in range.clone() {
                    let (q, n) = frames[p].place(surfels, k, d);
                    if let Some(x) = ret(&g, l, s, laser_scale[l], q, n, surfels.areas[k]) {
                        out.push(x);
                    }
                }
            };
            // In fixed chunks of pairs ([`ordered_sum`]): the same bits on any number of
            // threads.
            let sums = ordered_sum(
                pairs.len(),
                PAIR_CHUNK,
                || (Vec::new(), Vec::new()),
                || vec![0.0f64; 2 * TRY.len()],
                |acc, (old, new), i| {
                    let (l, s) = pairs[i];
                    render(l, s, pose[p], old);
                    let rr = &r[i * nt..(i + 1) * nt];
                    // R' = R + a_p m_old on the touched bins, kept sparse.
                    let rp = |b: usize, old: &[(usize, f64)]| {
                        rr[b] + amp[p] * old.iter().filter(|x| x.0 == b).map(|x| x.1).sum::<f64>()
                    };
                    for (c, &d) in cand.iter().enumerate() {
                        render(l, s, d, new);
                        new.sort_by_key(|x| x.0);
                        let mut j = 0;
                        while j < new.len() {
                            let b = new[j].0;
                            let mut v = 0.0;
                            while j < new.len() && new[j].0 == b {
                                v += new[j].1;
                                j += 1;
                            }
                            acc[2 * c] += rp(b, old) * v;
                            acc[2 * c + 1] += v * v;
                        }
                    }
                },
                |t, p| t.iter_mut().zip(p).for_each(|(x, y)| *x += y),
            );
            let mut best = (0usize, 0.0f64, 0.0f64);
            for c in 0..TRY.len() {
                let (dot, mm) = (sums[2 * c], sums[2 * c + 1]);
                let gain = if dot > 0.0 && mm > 0.0 {
                    dot * dot / mm
                } else {
                    0.0
                };
                if c == 0 || gain > best.1 {
                    best = (c, gain, if mm > 0.0 { (dot / mm).max(0.0) } else { 0.0 });
                }
            }
            let (c, _, a_new) = best;
            // Apply: R = R + a_p m_old − a_new m_new.
            let (d_old, d_new, a_old) = (pose[p], cand[c], amp[p]);
            r.par_chunks_mut(nt)
                .zip(&pairs)
                .for_each_init(Vec::new, |buf, (rr, &(l, s))| {
                    render(l, s, d_old, buf);
                    for &(b, w) in buf.iter() {
                        rr[b] += a_old * w;
                    }
                    render(l, s, d_new, buf);
                    for &(b, w) in buf.iter() {
                        rr[b] -= a_new * w;
                    }
                });
            pose[p] = d_new;
            amp[p] = a_new;
            bar.advance(1);
        }
        step *= 0.5;
        angle *= 0.5;
    }
    drop(bar);
    let after = explained(&r);
    let (mut pts, mut nrm, mut area, mut cl, mut out_patches) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (p, range) in patches.iter().enumerate() {
        if amp[p] <= 0.0 || s0 <= 0.0 {
            continue;
        }
        let first = pts.len();
        for k in range.clone() {
            let (q, n) = frames[p].place(surfels, k, pose[p]);
            pts.push(q);
            nrm.push(n);
            area.push(surfels.areas[k] * amp[p] / s0);
            cl.push(surfels.cluster[k]);
        }
        out_patches.push(first..pts.len());
    }
    // Clusters renumbered densely (a cluster whose patches all went dark disappears).
    let mut map = vec![usize::MAX; surfels.clusters];
    let mut next = 0;
    for c in cl.iter_mut() {
        if map[*c] == usize::MAX {
            map[*c] = next;
            next += 1;
        }
        *c = map[*c];
    }
    let mut out = if pts.is_empty() {
        surfels.clone()
    } else {
        Surfels::new(pts, nrm, area, cl)?
    };
    if !out_patches.is_empty() {
        out.patches = out_patches;
    }
    Ok(Refined {
        surfels: out,
        before,
        after,
    })
}
