//! Small 3-vector helpers of the geometry (metres, unit vectors where named so).

/// A point or a direction.
pub(super) type V3 = [f64; 3];

pub(super) fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(super) fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(super) fn unit(a: V3) -> V3 {
    let l = dot(a, a).sqrt();
    if l > 0.0 { a.map(|x| x / l) } else { a }
}

/// `v` rotated by `angle` about the unit axis `k` (Rodrigues).
pub(super) fn rotate(v: V3, k: V3, angle: f64) -> V3 {
    let (s, c) = angle.sin_cos();
    let x = cross(k, v);
    let d = dot(k, v);
    core::array::from_fn(|i| v[i] * c + x[i] * s + k[i] * d * (1.0 - c))
}
