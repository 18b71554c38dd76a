//! Leak-corrected in-focus indirect light on the path-traced scenes of `fixtures/pathtraced`,
//! against the direct-only control and the indirect-only truth (docs/indirect-light.md).
//!
//! `cargo bench --bench pathtraced` prints, for every object of every scene, as means over the
//! object's voxels: the corrected `I_i` vs its control (ratio), `kept` (the fraction of the
//! truth's `I_i` that survives) and the Pearson correlation with the truth's `I_i` (over the
//! object's Γ voxels and over Γ). `cargo bench --bench pathtraced -- diagnose` adds the
//! measurements of the leak's candidate causes (`vltm::probe::leak`'s module doc); `-- pearson`
//! only the breakdown of where the Pearson correlation with the truth is lost.
//! A second table gives the ceilings of a window-based correction (the truth put through the
//! same windows: kept and Pearson with the truth) and the oracle subtraction
//! `H_all − H_control` with no windows, which validates the measuring chain. With
//! a seed-1 render of a scene's full capture (the committed `fixtures/pathtraced/seed1`, or
//! `PATHTRACED_SEED1=<dir>`, a folder holding `<scene>_all/<scene>_all.hdf5` rendered with
//! another seed: `SEED=1 fixtures/pathtraced/render.sh`), a third table gives the figures of
//! that render and the `I_i` of the noise-only capture `(H_seed0 − H_seed1)/√2`.
//! `PATHTRACED_DIR=<dir>` measures another set of the same scenes' captures instead (for
//! example all three rendered with seed 1, or at 16 × 16 lasers × 16 × 16 SPADs: `GRID=16`
//! in `fixtures/pathtraced/render.sh`), in both tables and in `-- synth`.
//! `cargo bench --bench pathtraced -- synth` prints instead the analysis by synthesis
//! (`vltm::probe::synth`): Stage 1 with the oracle geometry of `scene.json`, Stage 2 with
//! surfels from each capture's own direct light (`-- synth capture` for Stage 2 only;
//! `SURFEL_EPSILON`, `SURFEL_VOLUME` and `SURFEL_SUB` change where its surfels come from);
//! Stage 2 prints seed 0 and, where `fixtures/pathtraced/seed1` holds the scene, seed 1 and
//! the noise share; `-- synth capture robust` measures the captures blurred by an unknown
//! response and delayed (docs/indirect-light.md, Stage 2); `PATHTRACED_LAMBDA=<m>` sets the
//! probes' wavelength of `-- synth` (default twice the wall's pitch).
//! Not a timing benchmark: it measures fidelity. Takes about a minute per setup and scene.

#[path = "../tests/support/pathtraced.rs"]
mod pathtraced;

use pathtraced::*;
use vltm::probe::{LeakOptions, Wave};

fn main() {
    if std::env::args().any(|a| a == "synth") {
        synth();
        return;
    }
    let diagnose = std::env::args().any(|a| a == "diagnose");
    let breakdown = diagnose || std::env::args().any(|a| a == "pearson");
    println!(
        "| scene | setup | object | Γ | corrected I_i vs control | kept | Pearson with the truth |"
    );
    println!("|---|---|---|---|---|---|---|");
    let named: Vec<String> = std::env::args()
        .filter(|a| SCENES.contains(&a.as_str()))
        .collect();
    let mut ceilings = Vec::new();
    let mut seed1 = Vec::new();
    for scene in SCENES {
        if !named.is_empty() && !named.iter().any(|n| n == scene) {
            continue;
        }
        let mut c = match std::env::var_os("PATHTRACED_DIR") {
            Some(d) => load_from(std::path::Path::new(&d), scene),
            None => load(scene),
        };
        let r = measure(&mut c, &defaults());
        print(scene, "defaults", &r);
        ceilings.push((scene, r.clone()));
        // The seed-1 render of `PATHTRACED_SEED1`, or the committed one where there is one
        // (`fixtures/pathtraced/seed1`: panel/figure).
        let given = std::env::var_os("PATHTRACED_SEED1");
        let p = match &given {
            Some(dir) => std::path::Path::new(dir)
                .join(format!("{scene}_all"))
                .join(format!("{scene}_all.hdf5")),
            None => seed1_path(scene),
        };
        if given.is_some() || p.is_file() {
            match vltm::io::open(&p) {
                Ok(other) => {
                    let (r1, n, avg) = seed_one(&mut c, other);
                    seed1.push((scene, r.clone(), r1, n, avg, c.objects.clone()));
                }
                Err(e) => eprintln!("{}: {e} (no seed-1 figures for {scene})", p.display()),
            }
        }
        if breakdown {
            pearson_breakdown(&c, &r);
        }
        if !diagnose {
            continue;
        }
        let d = defaults();
        let setups: Vec<(&str, Setup)> = vec![
            ("Eq. 17 (no correction)", Setup { leak: None, ..d }),
            (
                "no --compensate-laser",
                Setup {
                    wave: Wave {
                        compensate_laser: false,
                        ..d.wave
                    },
                    ..d
                },
            ),
            (
                "windows 2 r_cell",
                Setup {
                    leak: Some(LeakOptions {
                        cells: 2.0,
                        ..LeakOptions::default()
                    }),
                    ..d
                },
            ),
            (
                "windows 4 r_cell",
                Setup {
                    leak: Some(LeakOptions {
                        cells: 4.0,
                        ..LeakOptions::default()
                    }),
                    ..d
                },
            ),
            ("ε = 0.03", Setup { epsilon: 0.03, ..d }),
            ("r0 = 0.6 m", Setup { r0: Some(0.6), ..d }),
        ];
        for (label, s) in setups {
            let r = measure(&mut c, &s);
            print(scene, label, &r);
        }
        // Pairs on one object only: Γ restricted to each object in turn; its share of the
        // object's I_i under the defaults.
        for (name, idx) in c.objects.clone() {
            let only = same_object(&mut c, &d, &idx);
            let o = r.rows.iter().find(|o| o.name == name).unwrap();
            println!(
                "same-object pairs only, {scene}/{name}: full {:.4e} ({:.2} of all pairs'), control {:.4e} ({:.2}), truth {:.4e} ({:.2})",
                only[0],
                only[0] / o.full,
                only[1],
                only[1] / o.control,
                only[2],
                only[2] / o.truth
            );
        }
    }
    println!();
    println!("Ceilings of a window-based correction and the oracle subtraction (defaults):");
    println!();
    println!(
        "| scene | object | kept ceiling | Pearson ceiling: object (Γ) | Pearson of the corrected I_i with the windowed truth | oracle kept | oracle Pearson: object (Γ) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (scene, r) in &ceilings {
        print_ceilings(scene, r);
    }
    if seed1.is_empty() {
        return;
    }
    println!();
    println!(
        "Second seed (the same scene rendered with seed 1; control and truth of seed 0) and the noise-only capture (H_seed0 − H_seed1)/√2:"
    );
    println!();
    println!(
        "| scene | object | seed 0: vs control / kept / Pearson | seed 1: vs control / kept / Pearson | mean of both seeds (60 000 samples): vs control / kept / Pearson | Pearson seed 0 vs seed 1 | noise I_i corrected: vs full / vs control / vs truth | noise I_i, Eq. 17: vs truth |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (scene, r0, r1, noise, avg, objects) in &seed1 {
        for (((a, b), n), m) in r0.rows.iter().zip(&r1.rows).zip(noise).zip(&avg.rows) {
            let idx = &objects.iter().find(|o| o.0 == a.name).unwrap().1;
            let ig: Vec<usize> = idx
                .iter()
                .copied()
                .filter(|&i| r0.mask[i] && r1.mask[i])
                .collect();
            println!(
                "| {scene} | {} | {:.2}× / {:.3} / {:.3} | {:.2}× / {:.3} / {:.3} | {:.2}× / {:.3} / {:.3} | {:.3} | {:.3} / {:.3} / {:.4} | {:.4} |",
                a.name,
                a.ratio(),
                a.kept(),
                a.pearson,
                b.ratio(),
                b.kept(),
                b.pearson,
                m.ratio(),
                m.kept(),
                m.pearson,
                pearson(&r0.maps[0], &r1.maps[0], &ig),
                n.corrected / a.full,
                n.corrected / a.control,
                n.corrected / a.truth,
                n.plain / a.truth
            );
        }
        println!(
            "| {scene} | all of Γ: Pearson | {:.3} | {:.3} | {:.3} | | | |",
            r0.pearson, r1.pearson, avg.pearson
        );
    }
}

/// Where the Pearson correlation with the truth is lost, per object over its Γ voxels: the
/// corrected I_i against the windowed truth (what the windows let through), the corrected I_i
/// minus the corrected control (the residual direct light taken out) against the truth, and
/// the Γ voxels nearer and farther from the other object: their share of the truth, kept
/// ceiling, Pearson and Pearson ceiling (split at the median distance), and where Γ lies.
fn pearson_breakdown(c: &Captures, r: &SceneResult) {
    let [f, k, t, tg, _] = &r.maps;
    let fk: Vec<f32> = f.iter().zip(k).map(|(a, b)| a - b).collect();
    for (j, (name, idx)) in c.objects.iter().enumerate() {
        let ig: Vec<usize> = idx.iter().copied().filter(|&i| r.mask[i]).collect();
        let d = distance_to_others(c, j, &ig);
        let da = distance_to_others(c, j, idx);
        let z = |s: &[usize]| {
            s.iter()
                .map(|&i| c.vol.points[i][2])
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), z| {
                    (a.min(z), b.max(z))
                })
        };
        let mut sorted = d.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
        let sum = |v: &[f32], s: &[usize]| s.iter().map(|&i| f64::from(v[i])).sum::<f64>();
        let (zg, za) = (z(&ig), z(idx));
        println!(
            "Pearson breakdown, {}/{name} ({} Γ voxels, z {:.2}–{:.2} m of the object's {:.2}–{:.2} m; {:.2}–{:.2} m from the other object, the object's voxels {:.2}–{:.2} m): corrected vs windowed truth {:.3}; corrected − control vs truth {:.3}; windowed truth vs truth {:.3}",
            c.scene,
            ig.len(),
            zg.0,
            zg.1,
            za.0,
            za.1,
            sorted.first().copied().unwrap_or(f64::NAN),
            sorted.last().copied().unwrap_or(f64::NAN),
            da.iter().copied().fold(f64::INFINITY, f64::min),
            da.iter().copied().fold(0.0, f64::max),
            pearson(f, tg, &ig),
            pearson(&fk, t, &ig),
            pearson(tg, t, &ig)
        );
        for (label, near) in [
            ("Γ voxels nearer the other object than the median", true),
            ("the farther half", false),
        ] {
            let s: Vec<usize> = ig
                .iter()
                .zip(&d)
                .filter(|&(_, &x)| (x < median) == near)
                .map(|(&i, _)| i)
                .collect();
            println!(
                "  {label}: {} voxels, {:.2} of the truth, kept ceiling {:.3}, kept {:.3}, Pearson {:.3}, Pearson ceiling {:.3}",
                s.len(),
                sum(t, &s) / sum(t, &ig),
                sum(tg, &s) / sum(t, &s),
                sum(f, &s) / sum(t, &s),
                pearson(f, t, &s),
                pearson(tg, t, &s)
            );
        }
    }
}

/// The figures with `other` (the same scene rendered with another seed) as the full capture,
/// and the noise-only capture's I_i.
fn seed_one(
    c: &mut Captures,
    other: vltm::io::Capture,
) -> (SceneResult, Vec<NoiseRow>, SceneResult) {
    let n = noise(c, &other, &defaults());
    let mean = {
        let mut m = subtract(&c.all, &other, 0.5);
        for (x, (a, b)) in m.data.iter_mut().zip(c.all.data.iter().zip(&other.data)) {
            *x = 0.5 * (a + b);
        }
        m
    };
    let seed0 = std::mem::replace(&mut c.all, other);
    let r = measure(c, &defaults());
    c.all = mean;
    let avg = measure(c, &defaults());
    c.all = seed0;
    (r, n, avg)
}

/// Means over `idx` of I_i of the full capture, the control and the truth, summed over the
/// pairs with both x_a and x_b on that object only (Γ restricted to `idx` for the pairs; the
/// full capture and the control corrected with the windows of the whole Γ, as the defaults).
fn same_object(c: &mut Captures, s: &Setup, idx: &[usize]) -> [f64; 3] {
    use vltm::probe::{self, DirectModel, Exec, LeakCorrected};
    let exec = Exec {
        progress: None,
        path: probe::EvalPath::Auto,
    };
    let d = probe::direct(&mut c.all, &c.vol, &s.wave, exec).unwrap();
    let full = probe::gamma_mask(&d.values, s.epsilon);
    let pts: Vec<_> = (0..full.len())
        .filter(|&i| full[i])
        .map(|i| c.vol.points[i])
        .collect();
    let lo = s.leak.unwrap_or_default();
    let model = DirectModel::gate(
        &c.all.geometry,
        &pts,
        probe::cell_radius(&c.vol),
        &s.wave,
        &lo,
    )
    .unwrap();
    let mut mask = vec![false; full.len()];
    for &i in idx {
        mask[i] = full[i];
    }
    let opts = s.uncorrected();
    let f = {
        let mut src = LeakCorrected::new(&mut c.all, &model);
        probe::indirect_over(&mut src, &c.vol, &mask, &opts, &s.wave, exec).unwrap()
    };
    let k = {
        let mut src = LeakCorrected::new(&mut c.direct, &model);
        probe::indirect_over(&mut src, &c.vol, &mask, &opts, &s.wave, exec).unwrap()
    };
    let t = probe::indirect_over(&mut c.indirect, &c.vol, &mask, &opts, &s.wave, exec).unwrap();
    let m = |v: &[f32]| idx.iter().map(|&i| f64::from(v[i])).sum::<f64>() / idx.len() as f64;
    [m(&f.values), m(&k.values), m(&t.values)]
}

/// Stage 1 (oracle geometry) and Stage 2 (geometry from the capture) of the analysis by
/// synthesis (`vltm::probe::synth`), both scenes, the same settings. Stage 2 adds, where
/// `fixtures/pathtraced/seed1/<scene>_all` exists, the rows of that seed-1 re-render as the
/// full capture (control, its model and truth of seed 0) and the noise share. With `robust`,
/// every capture is first convolved with a 40 ps FWHM Gaussian response and delayed by 6 ps
/// (`pathtraced::blurred`; the model is told neither).
fn synth() {
    use vltm::probe::synth::{SynthModel, SynthOptions};
    let local = std::env::args().any(|a| a == "global");
    let robust = std::env::args().any(|a| a == "robust");
    let opts = SynthOptions {
        per_histogram: !local,
        ..SynthOptions::default()
    };
    let mut s = defaults();
    // `PATHTRACED_LAMBDA=<m>`: the probes' wavelength instead of twice the wall's pitch (the
    // model's own image keeps its wavelength).
    if let Some(l) = std::env::var("PATHTRACED_LAMBDA")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        s.wave.wavelength = Some(l);
    }
    println!(
        "| stage | scene | object | Γ | corrected I_i vs control | kept | Pearson with the truth | explained: full / control | fit s |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let only2 = std::env::args().any(|a| a == "capture");
    let mut shares = Vec::new();
    let row = |stage: &str, scene: &str, r: &SceneResult, ma: &SynthModel, mk: &SynthModel| {
        for o in &r.rows {
            println!(
                "| {stage} | {scene} | {} | {}/{} | {:.1}× | {:.3} | {:.3} | {:.4} / {:.4} | {:.1} |",
                o.name,
                o.in_gamma,
                o.voxels,
                o.ratio(),
                o.kept(),
                o.pearson,
                ma.explained,
                mk.explained,
                ma.seconds
            );
        }
        println!(
            "| {stage} | {scene} | all of Γ | {} | | | {:.3} | | |",
            r.gamma, r.pearson
        );
    };
    for (stage, surf) in [("1 oracle", Surf::Oracle), ("2 capture", Surf::Capture)] {
        if only2 && surf == Surf::Oracle {
            continue;
        }
        for scene in SCENES {
            if std::env::var("PATHTRACED_SCENE").is_ok_and(|s| s != scene) {
                continue;
            }
            let mut c = match std::env::var_os("PATHTRACED_DIR") {
                Some(d) => load_from(std::path::Path::new(&d), scene),
                None => load(scene),
            };
            let stage = if robust {
                blur_all(&mut c, 40.0, 6.0);
                format!("{stage}, blurred 40 ps + 6 ps")
            } else {
                stage.to_string()
            };
            let boxes = c.boxes.clone();
            let models = surface_models(vec![&mut c.all, &mut c.direct], &boxes, &s, surf, &opts);
            let [ma, mk]: [_; 2] = models.try_into().unwrap_or_else(|_| unreachable!());
            let r = measure_models(&mut c, &s, &ma, &mk);
            if robust {
                eprintln!(
                    "{scene}: fitted response width {:.3} / {:.3} bin, delay {:.3} / {:.3} bin (full / control)",
                    ma.width, mk.width, ma.shift, mk.shift
                );
            }
            row(&format!("{stage}, seed 0"), scene, &r, &ma, &mk);
            // The seed-1 render: `PATHTRACED_SEED1`'s, else the committed one unless another
            // set of captures is measured.
            let p = match std::env::var_os("PATHTRACED_SEED1") {
                Some(dir) => std::path::Path::new(&dir)
                    .join(format!("{scene}_all"))
                    .join(format!("{scene}_all.hdf5")),
                None if std::env::var_os("PATHTRACED_DIR").is_some() => continue,
                None => seed1_path(scene),
            };
            if surf == Surf::Oracle || robust || !p.is_file() {
                continue;
            }
            let mut other = vltm::io::open(&p).expect("seed-1 capture");
            let m1 = surface_model(&mut other, &boxes, &s, surf, &opts);
            let (r1, noise) = synth_seed_one(&mut c, &s, other, &ma, &m1, &mk);
            row(&format!("{stage}, seed 1"), scene, &r1, &m1, &mk);
            shares.push((scene, r, noise));
        }
    }
    if shares.is_empty() {
        return;
    }
    println!();
    println!(
        "Noise share of Stage 2: the I_i of the noise-only capture ((H_seed0 − M_seed0) − (H_seed1 − M_seed1))/√2 (each render minus its own model) over the seed-0 corrected I_i; and of (H_seed0 − H_seed1)/√2 with no model:"
    );
    println!();
    println!("| scene | object | noise share, model-corrected | noise share, no model |");
    println!("|---|---|---|---|");
    for (scene, r, noise) in &shares {
        for (o, n) in r.rows.iter().zip(noise) {
            println!(
                "| {scene} | {} | {:.4} | {:.4} |",
                o.name,
                n.corrected / o.full,
                n.plain / o.full
            );
        }
    }
}
