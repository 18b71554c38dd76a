//! The subset of a capture a facet refinement ([`super::refine_facets`]) works on: its
//! legs' geometry, the renders of a facet into its histograms (a scatter of one return per
//! surfel, the bins computed in vectors behind `pulp`'s runtime dispatch), their scores
//! against the residual and the Levenberg–Marquardt step of one facet.

use super::facet::Facet;
use super::linalg::{ordered_sum, solve};
use super::render::leg;
use super::vec3::V3;
use crate::io::capture::Geometry;
use rayon::prelude::*;

/// The subset of the capture a refinement works on, with its legs' geometry.
pub(super) struct Subset<'a> {
    pub(super) g: &'a Geometry,
    pub(super) lasers: Vec<usize>,
    pub(super) spads: Vec<usize>,
    pub(super) laser_scale: Vec<f64>,
    /// Device legs (m) per subset laser and SPAD.
    pub(super) d1: Vec<f64>,
    pub(super) d4: Vec<f64>,
    pub(super) nt: usize,
    /// Surfel returns laid out so far: every [`Subset::legs`] adds its surfels × the subset's
    /// pairs (the refinement's work budget, [`super::facets::REFINE_WORK`]).
    pub(super) work: std::sync::atomic::AtomicU64,
}

/// Interleaved copies of a histogram a render scatters into ([`Subset::render`]).
const LANES: usize = 4;

/// Pairs per chunk of [`Subset::score`]'s sums (a render each) and of the refinement's move
/// scores: fixed, so that the sums' order, hence their bits, do not follow the threads.
pub(super) const PAIR_CHUNK: usize = 16;

/// Bins per chunk of the sums over the whole subset's residual ([`dots`], the normal
/// equations of a facet's step).
const BIN_CHUNK: usize = 4096;

/// The first loop of [`Subset::render`]: every surfel's index into the interleaved copies
/// and its weight, and the range of bins, compiled for the CPU's vector extensions behind
/// `pulp`'s runtime dispatch (the same arithmetic on every CPU).
struct Bins<'a> {
    t: (&'a [f64], &'a [f64]),
    w: (&'a [f64], &'a [f64]),
    idx: &'a mut [u32],
    out: &'a mut [f64],
    nt: usize,
}

impl pulp::WithSimd for Bins<'_> {
    type Output = (u32, u32);

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> (u32, u32) {
        let nt = self.nt;
        let n = nt as f64;
        let (mut lo, mut hi) = (nt as u32, 0u32);
        for (k, (((i, o), (a, b)), (c, d))) in self
            .idx
            .iter_mut()
            .zip(self.out.iter_mut())
            .zip(self.t.0.iter().zip(self.t.1))
            .zip(self.w.0.iter().zip(self.w.1))
            .enumerate()
        {
            let x = a + b;
            // NaN fails both comparisons.
            let ok = x >= 0.0 && x < n;
            let bin = if ok { x as u32 } else { nt as u32 };
            lo = lo.min(bin);
            hi = hi.max(if ok { bin } else { 0 });
            *i = bin * LANES as u32 + (k % LANES) as u32;
            *o = c * d;
        }
        (lo, hi)
    }
}

/// A thread's buffers of [`Subset::render`].
struct Work {
    /// The histogram (`nt`).
    m: Vec<f64>,
    /// Its interleaved copies and the dump bin (`LANES·(nt + 1)`).
    lanes: Vec<f64>,
    /// Per surfel: its index into `lanes` and its weight.
    idx: Vec<u32>,
    w: Vec<f64>,
}

impl Work {
    fn new(nt: usize) -> Self {
        Self {
            m: vec![0.0; nt],
            lanes: vec![0.0; LANES * (nt + 1)],
            idx: Vec::new(),
            w: Vec::new(),
        }
    }
}

/// One render's legs: per subset laser `[li·K + k]` and SPAD `[si·K + k]`, time (bins, device
/// leg included, `t0` subtracted on the laser side) and weight.
#[derive(Default)]
pub(super) struct Legs {
    tl: Vec<f64>,
    wl: Vec<f64>,
    ts: Vec<f64>,
    ws: Vec<f64>,
    k: usize,
}

impl Subset<'_> {
    pub(super) fn pairs(&self) -> usize {
        self.lasers.len() * self.spads.len()
    }

    pub(super) fn legs(&self, f: &Facet, pitch: f64, buf: &mut Vec<(V3, f64)>, out: &mut Legs) {
        f.sample(pitch, buf);
        let k_n = buf.len();
        out.k = k_n;
        self.work.fetch_add(
            (k_n as u64).saturating_mul(self.pairs() as u64),
            std::sync::atomic::Ordering::Relaxed,
        );
        let g = self.g;
        let (nl, ns) = (self.lasers.len(), self.spads.len());
        out.tl.resize(nl * k_n, 0.0);
        out.wl.resize(nl * k_n, 0.0);
        out.ts.resize(ns * k_n, 0.0);
        out.ws.resize(ns * k_n, 0.0);
        if k_n == 0 {
            return;
        }
        // Times in bins, so that a render only adds and truncates.
        let inv = 1.0 / g.dt;
        let buf = &buf[..];
        out.tl
            .par_chunks_mut(k_n)
            .zip(out.wl.par_chunks_mut(k_n))
            .enumerate()
            .for_each(|(li, (tl, wl))| {
                let l = self.lasers[li];
                let (nw, sc) = (g.laser_normal(l), self.laser_scale[li]);
                for ((t, w), &(p, a)) in tl.iter_mut().zip(wl.iter_mut()).zip(buf) {
                    let (d, f) = leg(g.lasers[l], nw, p, f.normal);
                    *t = (self.d1[li] + d - g.t0) * inv;
                    *w = sc * a * f;
                }
            });
        out.ts
            .par_chunks_mut(k_n)
            .zip(out.ws.par_chunks_mut(k_n))
            .enumerate()
            .for_each(|(si, (ts, ws))| {
                let s = self.spads[si];
                let nw = g.spad_normal(s);
                for ((t, w), &(p, _)) in ts.iter_mut().zip(ws.iter_mut()).zip(buf) {
                    let (d, f) = leg(g.spads[s], nw, p, f.normal);
                    *t = (self.d4[si] + d) * inv;
                    *w = f;
                }
            });
    }

    /// Renders pair `(li, si)` of `legs` into `w.m` (length `nt`, zero on entry); returns
    /// the range of bins touched (`lo > hi`: none).
    ///
    /// Two loops: the first computes every surfel's bin and weight without a branch (it
    /// vectorises); the second adds each weight to one of [`LANES`] interleaved copies of its
    /// bin (surfel `k` to copy `k mod LANES`, an out-of-window return to a dump bin `nt`), so
    /// that neighbouring surfels, which mostly share a bin, do not chain their stores. The
    /// copies are summed in a fixed order: the result does not depend on the thread.
    #[inline]
    fn render(&self, legs: &Legs, li: usize, si: usize, w: &mut Work) -> (usize, usize) {
        let (k_n, nt) = (legs.k, self.nt);
        let (tl, wl) = (&legs.tl[li * k_n..][..k_n], &legs.wl[li * k_n..][..k_n]);
        let (ts, ws) = (&legs.ts[si * k_n..][..k_n], &legs.ws[si * k_n..][..k_n]);
        w.idx.resize(k_n, 0);
        w.w.resize(k_n, 0.0);
        w.lanes.resize(LANES * (nt + 1), 0.0);
        let bins = Bins {
            t: (tl, ts),
            w: (wl, ws),
            idx: &mut w.idx,
            out: &mut w.w,
            nt,
        };
        // AVX2 also on AVX-512 CPUs, as before `pulp`'s `x86-v4` feature (on for
        // `fast::sgemm`): the 512-bit build of this loop is not measured.
        #[cfg(target_arch = "x86_64")]
        let (lo, hi) = match pulp::x86::V3::try_new() {
            Some(v3) => pulp::Simd::vectorize(v3, bins),
            None => pulp::Arch::new().dispatch(bins),
        };
        #[cfg(not(target_arch = "x86_64"))]
        let (lo, hi) = pulp::Arch::new().dispatch(bins);
        let lanes = &mut w.lanes[..LANES * (nt + 1)];
        for (&i, &x) in w.idx.iter().zip(&w.w) {
            lanes[i as usize] += x;
        }
        let (lo, hi) = (lo as usize, hi as usize);
        if lo <= hi {
            for (o, c) in w.m[lo..=hi]
                .iter_mut()
                .zip(lanes[lo * LANES..(hi + 1) * LANES].chunks_exact_mut(LANES))
            {
                *o += (c[0] + c[1]) + (c[2] + c[3]);
                c.fill(0.0);
            }
        }
        lanes[nt * LANES..].fill(0.0);
        (lo, hi)
    }

    /// `(⟨r, m⟩, ‖m‖²)` over the subset for the render of `legs` ([`ordered_sum`]: the same
    /// bits on any number of threads).
    pub(super) fn score(&self, legs: &Legs, r: &[f64]) -> (f64, f64) {
        let (ns, nt) = (self.spads.len(), self.nt);
        ordered_sum(
            self.pairs(),
            PAIR_CHUNK,
            || Work::new(nt),
            || (0.0, 0.0),
            |(dot, mm), w, i| {
                let (lo, hi) = self.render(legs, i / ns, i % ns, w);
                let m = &mut w.m;
                if lo <= hi {
                    let rr = &r[i * nt..(i + 1) * nt];
                    for b in lo..=hi {
                        *dot += rr[b] * m[b];
                        *mm += m[b] * m[b];
                        m[b] = 0.0;
                    }
                }
            },
            |t, p| {
                t.0 += p.0;
                t.1 += p.1;
            },
        )
    }

    /// `r += a · m` for the render of `legs`.
    pub(super) fn add(&self, legs: &Legs, a: f64, r: &mut [f64]) {
        if a == 0.0 {
            return;
        }
        let (ns, nt) = (self.spads.len(), self.nt);
        r.par_chunks_mut(nt).enumerate().for_each_init(
            || Work::new(nt),
            |w, (i, rr)| {
                let (lo, hi) = self.render(legs, i / ns, i % ns, w);
                let m = &mut w.m;
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

impl Subset<'_> {
    /// The render of `legs` over the whole subset into `m` (`pairs·Nt`, overwritten).
    pub(super) fn dense_into(&self, legs: &Legs, m: &mut [f64]) {
        m.fill(0.0);
        self.add(legs, 1.0, m);
    }

    /// One Levenberg–Marquardt step of facet `f` (amplitude `a`) on its 7 parameters and its
    /// amplitude together, against `r` (the residual with the facet's light put back) and
    /// the best gain so far `gain`. The Jacobian's columns are central differences of the
    /// coordinate moves' renders, `a·(m₊ − m₋)/(2h)` (one-sided against `m0` where a move
    /// collapsed the facet; [`Column`]), then `m0` itself for the amplitude. Returns the
    /// first damping of `10⁻³…1` whose pose raises the gain, as `(facet, gain, amplitude)`;
    /// `None` when none does or a column is missing.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn levenberg_marquardt(
        &self,
        f: &Facet,
        a: f64,
        gain: f64,
        r: &[f64],
        m0: &[f64],
        moves: &[Vec<f64>],
        cols: &[Column; 7],
        pitch: f64,
        max_surfels: usize,
    ) -> Option<(Facet, f64, f64)> {
        if cols.iter().any(|c| c.k == 0.0) {
            return None;
        }
        const N: usize = 8;
        let at = |src: Src, i: usize| match src {
            Src::M0 => m0[i],
            Src::Move(j) => moves[j][i],
        };
        // The normal equations G = JᵀJ, b = Jᵀe (e = r − a·m0) in one pass over the subset.
        let sums = ordered_sum(
            r.len(),
            BIN_CHUNK,
            || (),
            || [0.0f64; N * N + N],
            |acc, _, i| {
                let mut c = [0.0f64; N];
                for (x, col) in c.iter_mut().zip(cols) {
                    *x = col.k * (at(col.plus, i) - at(col.minus, i));
                }
                c[7] = m0[i];
                let e = r[i] - a * m0[i];
                for p in 0..N {
                    acc[N * N + p] += c[p] * e;
                    for q in p..N {
                        acc[p * N + q] += c[p] * c[q];
                    }
                }
            },
            |t, p| t.iter_mut().zip(p).for_each(|(x, y)| *x += y),
        );
        let mut gm = [0.0f64; N * N];
        for p in 0..N {
            for q in p..N {
                gm[p * N + q] = sums[p * N + q];
                gm[q * N + p] = sums[p * N + q];
            }
        }
        let bv = &sums[N * N..];
        let (mut legs, mut buf) = (Legs::default(), Vec::new());
        for mu in [1e-3, 1e-2, 1e-1, 1.0] {
            let mut g2 = gm;
            (0..N).for_each(|i| g2[i * N + i] *= 1.0 + mu);
            let mut d = [0.0f64; N];
            if !solve(&g2, bv, &mut d) {
                continue;
            }
            let cand = f.moved(&core::array::from_fn(|i| d[i]));
            let [u0, u1, v0, v1] = cand.extent;
            if u1 - u0 < pitch || v1 - v0 < pitch || cand.samples(pitch) > max_surfels {
                continue;
            }
            self.legs(&cand, pitch, &mut buf, &mut legs);
            let (dd, mm) = self.score(&legs, r);
            if dd > 0.0 && mm > 0.0 && dd * dd / mm > gain * (1.0 + 1e-9) {
                return Some((cand, dd * dd / mm, dd / mm));
            }
        }
        None
    }
}

/// Where a Jacobian column's render comes from: the facet's own (`m0`) or a coordinate move's.
#[derive(Clone, Copy, Debug)]
pub(super) enum Src {
    /// The facet's own render.
    M0,
    /// Coordinate move `j` (`2·parameter + side`, side 0: −, 1: +).
    Move(usize),
}

/// A Jacobian column of [`Subset::levenberg_marquardt`]: `k·(plus − minus)` (`k = 0`: none).
#[derive(Clone, Copy, Debug)]
pub(super) struct Column {
    pub(super) plus: Src,
    pub(super) minus: Src,
    pub(super) k: f64,
}

/// `(⟨r, m⟩, ‖m‖²)` ([`ordered_sum`]: the same bits on any number of threads).
pub(super) fn dots(r: &[f64], m: &[f64]) -> (f64, f64) {
    ordered_sum(
        r.len().min(m.len()),
        BIN_CHUNK,
        || (),
        || (0.0, 0.0),
        |(d, q), _, i| {
            *d += r[i] * m[i];
            *q += m[i] * m[i];
        },
        |t, p| {
            t.0 += p.0;
            t.1 += p.1;
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{Aperture, Scene, Setup};

    /// The render (bins in vectors, 4 interleaved copies, a dump bin) against a plain loop
    /// that adds each return to its bin: the same bins, the same sums to rounding, returns
    /// outside the window (negative, past the end, NaN) dropped, the copies left clear.
    #[test]
    fn render_matches_a_plain_scatter() {
        let g = Scene::new(Setup::new(
            Aperture::grid([2, 2], [1.0, 1.0], [0.0, 0.0]),
            Aperture::grid([2, 2], [1.0, 1.0], [0.0, 0.0]),
            50,
            0.01,
        ))
        .geometry();
        let nt = 50;
        let sub = Subset {
            g: &g,
            lasers: vec![0, 1],
            spads: vec![0, 1, 2],
            laser_scale: vec![1.0; 2],
            d1: vec![0.0; 2],
            d4: vec![0.0; 3],
            nt,
            work: 0.into(),
        };
        let k = 103;
        // Times in bins running through and past the window, a few returns per bin.
        let t = |i: usize, j: usize| -5.0 + 0.6 * i as f64 + 0.11 * j as f64;
        let mut legs = Legs {
            tl: (0..2 * k).map(|i| t(i % k, i / k)).collect(),
            wl: (0..2 * k).map(|i| 1.0 + (i % 7) as f64).collect(),
            ts: (0..3 * k).map(|i| 0.5 * (i / k) as f64).collect(),
            ws: (0..3 * k).map(|i| 0.5 + (i % 5) as f64).collect(),
            k,
        };
        legs.ts[2 * k + 7] = f64::NAN;
        let mut w = Work::new(nt);
        for li in 0..2 {
            for si in 0..3 {
                let mut plain = vec![0.0f64; nt];
                for i in 0..k {
                    let x = legs.tl[li * k + i] + legs.ts[si * k + i];
                    if x >= 0.0 && x < nt as f64 {
                        plain[x as usize] += legs.wl[li * k + i] * legs.ws[si * k + i];
                    }
                }
                let (lo, hi) = sub.render(&legs, li, si, &mut w);
                assert!(lo <= hi && hi < nt);
                let scale = plain.iter().fold(0.0f64, |m, x| m.max(x.abs()));
                for (b, (x, y)) in w.m.iter().zip(&plain).enumerate() {
                    assert!((x - y).abs() <= 1e-14 * scale, "bin {b}: {x} vs {y}");
                    assert!(
                        *y == 0.0 || (lo..=hi).contains(&b),
                        "bin {b} outside {lo}..={hi}"
                    );
                }
                assert!(plain.iter().filter(|x| **x > 0.0).count() > nt - 3);
                assert!(w.lanes.iter().all(|x| *x == 0.0), "copies left behind");
                w.m.fill(0.0);
            }
        }
    }
}
