//! The integer phase NCO: a compile-time Q1.15 cos/sin table over one turn, read with
//! linear interpolation ([`cis_q15`]), and the phase step `round(2³²·x/(NΔt))`.

use ::fixed::types::I1F15;

/// Bits of the cos/sin table index (1024 intervals over one turn).
pub(super) const CIS_BITS: u32 = 10;
pub(super) const CIS_LEN: usize = (1 << CIS_BITS) + 1;

/// `sin x` and `cos x` for |x| ≤ π/2 by Taylor series in `f64` (const; error < 1e-17).
pub(super) const fn sin_cos_quadrant(x: f64) -> (f64, f64) {
    let (mut s, mut c) = (0.0, 0.0);
    let (mut ts, mut tc) = (x, 1.0);
    let mut n = 0;
    while n < 30 {
        s += ts;
        c += tc;
        let k = (2 * n + 2) as f64;
        ts *= -x * x / (k * (k + 1.0));
        tc *= -x * x / ((k - 1.0) * k);
        n += 1;
    }
    (s, c)
}

pub(super) const fn q15(v: f64) -> I1F15 {
    let y = v * 32768.0;
    let r = if y >= 0.0 {
        (y + 0.5) as i32
    } else {
        (y - 0.5) as i32
    };
    let r = if r > 32767 {
        32767
    } else if r < -32767 {
        -32767
    } else {
        r
    };
    I1F15::from_bits(r as i16)
}

/// `[cos, sin](2π·i/1024)` in Q1.15 for i = 0..=1024, built at compile time.
pub(super) static CIS_TABLE: [[I1F15; 2]; CIS_LEN] = {
    let mut t = [[I1F15::ZERO; 2]; CIS_LEN];
    let quarter = 1usize << (CIS_BITS - 2);
    let mut i = 0;
    while i < CIS_LEN {
        let q = i / quarter;
        let r = i % quarter;
        let x = core::f64::consts::FRAC_PI_2 * r as f64 / quarter as f64;
        let (s, c) = sin_cos_quadrant(x);
        let (cs, sn) = match q % 4 {
            0 => (c, s),
            1 => (-s, c),
            2 => (-c, -s),
            _ => (s, -c),
        };
        t[i] = [q15(cs), q15(sn)];
        i += 1;
    }
    t
};

/// Bound of the error of [`cis_q15`] per component (relative to 1): `1.2·2⁻¹⁵`.
pub const CIS_ERR: f64 = 1.2 / 32768.0;

/// `2¹⁵·e^{2πi·φ/2³²}` (Q1.15 as `i32`) for a phase `φ` in turns: table and linear
/// interpolation, integers only. Error ≤ [`CIS_ERR`] = 1.2·2⁻¹⁵ per component (see the
/// module docs).
///
/// ```
/// let (c, s) = vltm_kernel::cis_q15(1 << 30); // a quarter turn
/// assert!(c.abs() <= 1 && (s - 32767).abs() <= 1);
/// ```
#[inline]
pub fn cis_q15(phase: u32) -> (i32, i32) {
    let idx = (phase >> (32 - CIS_BITS)) as usize;
    let frac = ((phase >> (17 - CIS_BITS)) & 0x7fff) as i32;
    let (Some(a), Some(b)) = (CIS_TABLE.get(idx), CIS_TABLE.get(idx + 1)) else {
        return (0, 0);
    };
    let lerp = |x: I1F15, y: I1F15| {
        let (x, y) = (i32::from(x.to_bits()), i32::from(y.to_bits()));
        x + (((y - x) * frac + (1 << 14)) >> 15)
    };
    (lerp(a[0], b[0]), lerp(a[1], b[1]))
}

/// `round(2³²·x/span) mod 2³²`: a phase step in turns (soft float on an M0, once per pair).
#[inline]
pub(super) fn phase_step(x: f64, two32_per_span: f64) -> u32 {
    let t = libm::rint(x * two32_per_span);
    // |t| < 2⁶³ for every path shorter than 2³¹·NΔt; `as i64` saturates beyond.
    (t as i64) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cis_q15_accuracy() {
        let mut worst = 0.0f64;
        let mut phase = 0u32;
        for _ in 0..1_000_003u32 {
            phase = phase.wrapping_add(4293); // odd stride: covers every table interval
            let (c, s) = cis_q15(phase);
            let a = core::f64::consts::TAU * f64::from(phase) / 4_294_967_296.0;
            let e = (f64::from(c) / 32768.0 - libm::cos(a))
                .abs()
                .max((f64::from(s) / 32768.0 - libm::sin(a)).abs());
            worst = worst.max(e);
        }
        // Bound of the module docs: 1.2·2⁻¹⁵ per component (clamp of +1 to 32767 = 2⁻¹⁵,
        // plus interpolation (2π/1024)²/8 = 4.7e-6 next to it).
        assert!(worst <= CIS_ERR, "max error {worst:e}");
        assert_eq!(cis_q15(0), (32767, 0));
        assert_eq!(cis_q15(1 << 31), (-32767, 0));
    }
}
