//! A planar rectangle of a hidden surface ([`Facet`]): its frame, the moves a refinement
//! makes of it ([`super::refine_facets`]), the facets grown from its edges and its surfels.

use super::vec3::{V3, cross, dot, rotate, unit};

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
pub(super) type Pose = [f64; 7];

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
    pub(super) fn moved(&self, p: &Pose) -> Self {
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
    pub(super) fn attached(&self, edge: usize, fold: f64, w: f64) -> Self {
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

    /// The rectangle's four corners.
    pub fn corners(&self) -> [V3; 4] {
        let [u0, u1, v0, v1] = self.extent;
        [(u0, v0), (u1, v0), (u1, v1), (u0, v1)]
            .map(|(a, b)| core::array::from_fn(|k| self.centre[k] + a * self.u[k] + b * self.v[k]))
    }

    /// Area (m²; zero when an extent has collapsed).
    pub fn area(&self) -> f64 {
        let [u0, u1, v0, v1] = self.extent;
        (u1 - u0).max(0.0) * (v1 - v0).max(0.0)
    }

    /// The sampling grid of [`Facet::sample`]: cells along `u` and `v` (each at most 10,000)
    /// and the facet's sides; `None` for a facet of no area.
    fn grid(&self, pitch: f64) -> Option<(usize, usize, f64, f64)> {
        let [u0, u1, v0, v1] = self.extent;
        let (wu, wv) = (u1 - u0, v1 - v0);
        if !(wu > 0.0 && wv > 0.0) {
            return None;
        }
        let nu = ((wu / pitch).ceil() as usize).clamp(1, 10_000);
        let nv = ((wv / pitch).ceil() as usize).clamp(1, 10_000);
        Some((nu, nv, wu, wv))
    }

    /// How many surfels the facet is sampled into at `pitch` (one per cell of a grid no coarser
    /// than `pitch`, at most 10,000 per side; 0 for a facet of no area).
    pub fn samples(&self, pitch: f64) -> usize {
        self.grid(pitch).map_or(0, |(nu, nv, ..)| nu * nv)
    }

    /// Surfels every `pitch` metres or finer (at least one per side): `(point, area)`
    /// into `out` (cleared); none when the facet has collapsed.
    pub(super) fn sample(&self, pitch: f64, out: &mut Vec<(V3, f64)>) {
        out.clear();
        let [u0, _, v0, _] = self.extent;
        let Some((nu, nv, wu, wv)) = self.grid(pitch) else {
            return;
        };
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
