//! Leak-corrected in-focus indirect light on the path-traced scenes of `fixtures/pathtraced`,
//! against the direct-only control and the indirect-only truth (docs/indirect-light.md).
//!
//! `cargo bench --bench pathtraced` prints, for every object of every scene, as means over the
//! object's voxels: the corrected `I_i` vs its control (ratio), `kept` (the fraction of the
//! truth's `I_i` that survives) and the Pearson correlation with the truth's `I_i` (over the
//! object's Γ voxels and over Γ). `cargo bench --bench pathtraced -- diagnose` adds the
//! measurements of the leak's candidate causes (`vltm::probe::leak`'s module doc).
//! Not a timing benchmark: it measures fidelity. Takes about a minute per setup and scene.

#[path = "../tests/support/pathtraced.rs"]
mod pathtraced;

use pathtraced::*;
use vltm::probe::{LeakOptions, Wave};

fn main() {
    let diagnose = std::env::args().any(|a| a == "diagnose");
    println!(
        "| scene | setup | object | Γ | corrected I_i vs control | kept | Pearson with the truth |"
    );
    println!("|---|---|---|---|---|---|---|");
    let named: Vec<String> = std::env::args()
        .filter(|a| SCENES.contains(&a.as_str()))
        .collect();
    for scene in SCENES {
        if !named.is_empty() && !named.iter().any(|n| n == scene) {
            continue;
        }
        let mut c = load(scene);
        let r = measure(&mut c, &defaults());
        print(scene, "defaults", &r);
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
}

/// Means over `idx` of I_i of the full capture, the control and the truth, summed over the
/// pairs with both x_a and x_b on that object only (Γ restricted to `idx` for the pairs; the
/// full capture and the control corrected with the windows of the whole Γ, as the defaults).
fn same_object(c: &mut Captures, s: &Setup, idx: &[usize]) -> [f64; 3] {
    use vltm::probe::{self, DirectModel, Exec, IndirectOptions, LeakCorrected, Shell};
    let exec = Exec {
        progress: None,
        path: probe::Path::Auto,
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
    let opts = IndirectOptions {
        epsilon: s.epsilon,
        shell: s.r0.map(|r0| Shell {
            r0,
            r1: f32::INFINITY,
        }),
        leak: None,
        ..IndirectOptions::default()
    };
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
