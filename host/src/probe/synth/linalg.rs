//! Small dense solvers of the fits: `G a = b` by Gaussian elimination, and non-negative least
//! squares from the normal equations. `c × c` systems, `c` the clusters or the parameters of
//! one facet (≤ 8 in practice). And [`ordered_sum`], the fits' parallel sums in a fixed order.

use rayon::prelude::*;

/// `Σ_{i < n}` of what `fold(acc, scratch, i)` adds, on the thread pool, with the same bits on
/// any number of threads: the indices in fixed chunks of `chunk`, each folded in index order
/// into its own accumulator (`zero()`), the chunks' accumulators added in chunk order by
/// `add(total, part)`. (A rayon `fold`/`reduce` splits where work is stolen, so its rounding
/// follows the threads.) `scratch()` makes a worker's scratch, whose contents must not
/// change the sums. Memory: one accumulator per chunk.
pub(super) fn ordered_sum<A, S>(
    n: usize,
    chunk: usize,
    scratch: impl Fn() -> S + Sync + Send,
    zero: impl Fn() -> A + Sync + Send,
    fold: impl Fn(&mut A, &mut S, usize) + Sync + Send,
    add: impl Fn(&mut A, &A),
) -> A
where
    A: Send,
{
    let chunk = chunk.max(1);
    let parts: Vec<A> = (0..n.div_ceil(chunk))
        .into_par_iter()
        .map_init(scratch, |s, c| {
            let mut a = zero();
            for i in c * chunk..((c + 1) * chunk).min(n) {
                fold(&mut a, s, i);
            }
            a
        })
        .collect();
    let mut total = zero();
    for p in &parts {
        add(&mut total, p);
    }
    total
}

/// Non-negative least squares `min ‖y − Σ a_c m_c‖²` from the normal equations `G a = b`
/// (`G` row-major `c × c`): the exact solution when it is non-negative, otherwise projected
/// Gauss–Seidel from it clamped.
pub(super) fn nnls(g: &[f64], b: &[f64], a: &mut [f64]) {
    let c = b.len();
    if solve(g, b, a) && a.iter().all(|x| *x >= 0.0) {
        return;
    }
    a.iter_mut()
        .for_each(|x| *x = if x.is_finite() { x.max(0.0) } else { 0.0 });
    for _ in 0..500 {
        let mut moved = 0.0f64;
        for i in 0..c {
            let gii = g[i * c + i];
            if gii <= 0.0 {
                a[i] = 0.0;
                continue;
            }
            let r = b[i]
                - (0..c)
                    .filter(|&j| j != i)
                    .map(|j| g[i * c + j] * a[j])
                    .sum::<f64>();
            let new = (r / gii).max(0.0);
            moved = moved.max((new - a[i]).abs() * gii.sqrt());
            a[i] = new;
        }
        if moved <= 1e-14 * b.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300) {
            break;
        }
    }
}

/// `G a = b` by Gaussian elimination with partial pivoting; false when singular.
pub(super) fn solve(g: &[f64], b: &[f64], a: &mut [f64]) -> bool {
    let c = b.len();
    let mut m: Vec<f64> = g.to_vec();
    a.copy_from_slice(b);
    let scale = (0..c).map(|i| g[i * c + i].abs()).fold(0.0f64, f64::max);
    for k in 0..c {
        let p = (k..c)
            .max_by(|&i, &j| m[i * c + k].abs().total_cmp(&m[j * c + k].abs()))
            .unwrap_or(k);
        let pivot = m[p * c + k].abs();
        if pivot.is_nan() || pivot <= 1e-13 * scale {
            return false;
        }
        if p != k {
            for j in 0..c {
                m.swap(p * c + j, k * c + j);
            }
            a.swap(p, k);
        }
        for i in k + 1..c {
            let f = m[i * c + k] / m[k * c + k];
            for j in k..c {
                m[i * c + j] -= f * m[k * c + j];
            }
            a[i] -= f * a[k];
        }
    }
    for k in (0..c).rev() {
        let s: f64 = (k + 1..c).map(|j| m[k * c + j] * a[j]).sum();
        a[k] = (a[k] - s) / m[k * c + k];
    }
    a.iter().all(|x| x.is_finite())
}
