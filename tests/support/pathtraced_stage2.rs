//! Stage 2 of the analysis by synthesis beyond the seed-0 captures (part of
//! `support/pathtraced.rs`): the full capture replaced by its seed-1 re-render (whose Monte
//! Carlo noise the truth does not share) with the noise share of the corrected `I_i`, and the
//! robustness case, every capture blurred by an unknown response and shifted in time.

use super::{
    Captures, EXEC, NoiseRow, SceneResult, Setup, Surf, dir, mean, measure_models, subtract,
    surface_model,
};
use std::path::{Path, PathBuf};
use vltm::io::Capture;
use vltm::probe::{self, synth::SynthModel};

/// `fixtures/pathtraced/seed1/<scene>_all/<scene>_all.hdf5`: the full capture rendered with
/// seed 1 (fixtures/pathtraced/README.md).
pub fn seed1_path(scene: &str) -> PathBuf {
    dir()
        .join("seed1")
        .join(format!("{scene}_all"))
        .join(format!("{scene}_all.hdf5"))
}

/// [`surface_model`] of each capture, fitted in threads of their own (the geometry step runs
/// mostly on one core, so two captures take about the time of one on two cores).
pub fn surface_models(
    caps: Vec<&mut Capture>,
    boxes: &[serde_json::Value],
    s: &Setup,
    surf: Surf,
    opts: &probe::synth::SynthOptions,
) -> Vec<SynthModel> {
    std::thread::scope(|sc| {
        let fits: Vec<_> = caps
            .into_iter()
            .map(|cap| sc.spawn(move || surface_model(cap, boxes, s, surf, opts)))
            .collect();
        fits.into_iter().map(|f| f.join().expect("fit")).collect()
    })
}

/// `cap` minus `m`'s direct light, bin by bin (what [`probe::synth::Synthesized`] streams).
pub fn model_subtracted(cap: &Capture, m: &SynthModel) -> Capture {
    let g = &cap.geometry;
    let mut data = cap.data.clone();
    for (l, row) in data.chunks_mut(g.spads_per_row() * g.nt).enumerate() {
        m.subtract_row(l, row);
    }
    Capture::new(g.clone(), data, Path::new("model-subtracted")).unwrap()
}

/// Stage 2 with the full capture replaced by `other` (the same scene rendered with another
/// seed; `m1` its own model), the control `c.direct` with its model `mk` and the truth as
/// they are (seed 0): the figures, Γ from `other`'s diagonal. Also the noise-only capture's
/// `I_i` per object over the Γ of `c.all` (seed 0, whose model is `m0`): `corrected` is that
/// of `((H0 − M0) − (H1 − M1))/√2`, each render minus its own fitted model (the Monte Carlo
/// noise as the corrected `I_i` sees it, the fits' response to the noise included), `plain`
/// that of `(H0 − H1)/√2` (no model).
pub fn synth_seed_one(
    c: &mut Captures,
    s: &Setup,
    other: Capture,
    m0: &SynthModel,
    m1: &SynthModel,
    mk: &SynthModel,
) -> (SceneResult, Vec<NoiseRow>) {
    let d = probe::direct(&mut c.all, &c.vol, &s.wave, EXEC).expect("direct");
    let mask = probe::gamma_mask(&d.values, s.epsilon);
    let opts = s.uncorrected();
    let half = core::f32::consts::FRAC_1_SQRT_2;
    let mut n = subtract(
        &model_subtracted(&c.all, m0),
        &model_subtracted(&other, m1),
        half,
    );
    let f = probe::indirect_over(&mut n, &c.vol, &mask, &opts, &s.wave, EXEC).expect("noise");
    let mut n = subtract(&c.all, &other, half);
    let p = probe::indirect_over(&mut n, &c.vol, &mask, &opts, &s.wave, EXEC).expect("noise");
    let noise = c
        .objects
        .iter()
        .map(|(name, idx)| NoiseRow {
            name: name.clone(),
            corrected: mean(&f.values, idx),
            plain: mean(&p.values, idx),
        })
        .collect();
    let seed0 = std::mem::replace(&mut c.all, other);
    let r = measure_models(c, s, m1, mk);
    c.all = seed0;
    (r, noise)
}

/// Speed of light (m/ps).
const C_M_PER_PS: f64 = 299_792_458.0e-12;

/// The kernel of [`blurred`]: a Gaussian of `fwhm_ps` centred at `shift_ps`, integrated over
/// each bin of `dt` m (bin offset `d` covers `[d − ½, d + ½]` bins) and normalised to 1;
/// returns the first offset and the weights.
pub fn blur_kernel(dt: f64, fwhm_ps: f64, shift_ps: f64) -> (isize, Vec<f64>) {
    let sigma = fwhm_ps * C_M_PER_PS / (8.0 * 2f64.ln()).sqrt() / dt;
    let mu = shift_ps * C_M_PER_PS / dt;
    let reach = (mu.abs() + 8.0 * sigma).ceil() as isize;
    let sub = 2000;
    let w: Vec<f64> = (-reach..=reach)
        .map(|d| {
            (0..sub)
                .map(|k| {
                    let t = d as f64 - 0.5 + (k as f64 + 0.5) / sub as f64;
                    (-0.5 * ((t - mu) / sigma).powi(2)).exp()
                })
                .sum::<f64>()
        })
        .collect();
    let total: f64 = w.iter().sum();
    (-reach, w.into_iter().map(|x| x / total).collect())
}

/// `cap` with every histogram convolved with [`blur_kernel`] (light arriving `shift_ps`
/// later, spread by a Gaussian response of `fwhm_ps`; zero beyond the time axis).
pub fn blurred(cap: &Capture, fwhm_ps: f64, shift_ps: f64) -> Capture {
    let g = &cap.geometry;
    let (first, w) = blur_kernel(g.dt, fwhm_ps, shift_ps);
    let nt = g.nt;
    let mut data = vec![0.0f32; cap.data.len()];
    for (o, h) in data.chunks_mut(nt).zip(cap.data.chunks(nt)) {
        for (n, y) in o.iter_mut().enumerate() {
            let mut acc = 0.0f64;
            for (j, wj) in w.iter().enumerate() {
                let m = n as isize - (first + j as isize);
                if (0..nt as isize).contains(&m) {
                    acc += wj * f64::from(h[m as usize]);
                }
            }
            *y = acc as f32;
        }
    }
    Capture::new(g.clone(), data, Path::new("blurred")).unwrap()
}

/// All three captures of `c` [`blurred`] alike.
pub fn blur_all(c: &mut Captures, fwhm_ps: f64, shift_ps: f64) {
    for cap in [&mut c.all, &mut c.direct, &mut c.indirect] {
        *cap = blurred(cap, fwhm_ps, shift_ps);
    }
}
