//! Bad input: every `ConfigError`, every `ArgumentError` at every call boundary, and non-finite
//! histogram samples (read as 0, counted, never a panic).

mod support;

use support::{Data, all_probes, all_rows, run};
use vltm_kernel::{
    ArgumentError, Config, ConfigError, Gate, Legs, Params, Point, Probe, RowBuffer, Scan, Target,
};

fn base() -> Params {
    Params::new(0.1, 200, 0.01)
}

fn err(p: Params) -> ConfigError {
    Config::try_new(&p).expect_err("must be rejected")
}

const NON_FINITE: [f64; 3] = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY];

#[test]
fn config_not_finite() {
    assert!(Config::try_new(&base()).is_ok());
    for x in NON_FINITE {
        let cases: [(Params, &str); 8] = [
            (
                Params {
                    wavelength: x,
                    ..base()
                },
                "wavelength",
            ),
            (
                Params {
                    sigma: Some(x),
                    ..base()
                },
                "sigma",
            ),
            (
                Params {
                    band_half_width: x,
                    ..base()
                },
                "band_half_width",
            ),
            (
                Params {
                    gate_support: x,
                    ..base()
                },
                "gate_support",
            ),
            (Params { dt: x, ..base() }, "dt"),
            (Params { d_min: x, ..base() }, "d_min"),
            (Params { t0: x, ..base() }, "t0"),
            (
                Params {
                    margin: x,
                    ..base()
                },
                "margin",
            ),
        ];
        for (p, name) in cases {
            // +∞ is "not finite", not "positive".
            assert_eq!(err(p), ConfigError::NotFinite(name), "{name} = {x}");
        }
        let mut origin = [0.0, 0.0, 0.5];
        for i in 0..3 {
            origin[i] = x;
            let legs = Legs::FirstAndLast {
                laser_origin: origin,
                sensor_origin: [0.0; 3],
            };
            assert_eq!(
                err(Params { legs, ..base() }),
                ConfigError::NotFinite("laser_origin")
            );
            let legs = Legs::FirstAndLast {
                laser_origin: [0.0; 3],
                sensor_origin: origin,
            };
            assert_eq!(
                err(Params { legs, ..base() }),
                ConfigError::NotFinite("sensor_origin")
            );
            origin[i] = 0.0;
        }
    }
}

#[test]
fn config_not_positive() {
    for x in [0.0, -0.0, -1e-9, -3.0, f64::MIN] {
        let cases: [(Params, &str); 6] = [
            (
                Params {
                    wavelength: x,
                    ..base()
                },
                "wavelength",
            ),
            (
                Params {
                    sigma: Some(x),
                    ..base()
                },
                "sigma",
            ),
            (
                Params {
                    band_half_width: x,
                    ..base()
                },
                "band_half_width",
            ),
            (
                Params {
                    gate_support: x,
                    ..base()
                },
                "gate_support",
            ),
            (Params { dt: x, ..base() }, "dt"),
            (Params { d_min: x, ..base() }, "d_min"),
        ];
        for (p, name) in cases {
            assert_eq!(err(p), ConfigError::NotPositive(name), "{name} = {x}");
        }
    }
    // margin may be 0 but not negative; t0 may be anything finite.
    assert!(
        Config::try_new(&Params {
            margin: 0.0,
            t0: -5.0,
            ..base()
        })
        .is_ok()
    );
    // A negative margin shrinks the guard, down to −c_g·σ (σ = 2λ/3 here); below it, refused.
    let cg_sigma = base().gate_support * base().sigma_or_default();
    assert!(
        Config::try_new(&Params {
            margin: -cg_sigma,
            ..base()
        })
        .is_ok()
    );
    assert_eq!(
        err(Params {
            margin: -cg_sigma - 0.01,
            ..base()
        }),
        ConfigError::BelowMinimum("margin")
    );
    // A positive d_min too small for the f32 weights (1/d_min = ∞) is out of range.
    for d_min in [1e-39, 1e-45, 1e-300] {
        assert_eq!(
            err(Params { d_min, ..base() }),
            ConfigError::OutOfRange("d_min"),
            "d_min = {d_min:e}"
        );
    }
    assert!(
        Config::try_new(&Params {
            d_min: 1e-30,
            ..base()
        })
        .is_ok()
    );
    // With σ defaulted from λ, a bad λ is reported as λ.
    assert_eq!(
        err(Params {
            wavelength: -0.1,
            ..base()
        }),
        ConfigError::NotPositive("wavelength")
    );
}

#[test]
fn config_empty_time_axis() {
    assert_eq!(err(Params { nt: 0, ..base() }), ConfigError::EmptyTimeAxis);
    assert!(Config::try_new(&Params { nt: 1, ..base() }).is_ok());
}

#[test]
fn config_band_crosses_nyquist() {
    // Need Δt·(1/λ + m/(2πσ)) < 1/2; σ = 2λ/3, m = 5 → λ > 4.39 Δt.
    for lam_over_dt in [1.0, 2.0, 3.0, 4.0, 4.3] {
        let p = Params {
            wavelength: lam_over_dt * 0.01,
            ..base()
        };
        assert_eq!(
            err(p),
            ConfigError::BandCrossesNyquist,
            "λ = {lam_over_dt} Δt"
        );
    }
    assert!(
        Config::try_new(&Params {
            wavelength: 0.05,
            ..base()
        })
        .is_ok()
    );
    // A wider band (larger m or narrower σ) crosses earlier.
    assert_eq!(
        err(Params {
            wavelength: 0.05,
            band_half_width: 8.0,
            ..base()
        }),
        ConfigError::BandCrossesNyquist
    );
    assert_eq!(
        err(Params {
            wavelength: 0.05,
            sigma: Some(0.02),
            ..base()
        }),
        ConfigError::BandCrossesNyquist
    );
}

#[test]
fn config_size_overflow() {
    let n = ConfigError::SizeOverflow("n_fft");
    assert_eq!(
        err(Params {
            sigma: Some(1e7),
            ..base()
        }),
        n
    ); // 2·c_g·σ/Δt = 1e10 bins
    assert_eq!(
        err(Params {
            gate_support: 1e9,
            ..base()
        }),
        n
    );
    assert_eq!(
        err(Params {
            margin: 1e12,
            ..base()
        }),
        n
    );
    assert_eq!(
        err(Params {
            nt: usize::MAX,
            ..base()
        }),
        n
    );
    assert_eq!(
        err(Params {
            nt: 1 << 30,
            ..base()
        }),
        n
    );
    assert_eq!(
        err(Params {
            dt: 1e-12,
            wavelength: 1e-10,
            sigma: Some(1e-3),
            ..base()
        }),
        n
    );
}

#[test]
fn config_errors_display_their_parameter() {
    for (e, needle) in [
        (ConfigError::NotFinite("t0"), "t0"),
        (ConfigError::NotPositive("dt"), "dt"),
        (ConfigError::EmptyTimeAxis, "nt"),
        (ConfigError::BandCrossesNyquist, "dt"),
        (ConfigError::SizeOverflow("n_fft"), "n_fft"),
        (ConfigError::BelowMinimum("margin"), "margin"),
    ] {
        assert!(e.to_string().contains(needle), "{e}");
    }
}

/// A working scan used by the buffer tests.
struct Setup {
    cfg: Config,
    spads: Vec<Point>,
    voxels: Vec<Point>,
    hists: Vec<f32>,
}

fn setup() -> Setup {
    let cfg = Config::try_new(&base()).unwrap();
    let spads = vec![[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.2, 0.0]];
    let voxels = vec![[0.0, 0.0, 0.5], [0.1, 0.1, 0.6]];
    let hists = (0..spads.len() * cfg.nt())
        .map(|i| ((i * 7919) % 13) as f32 - 6.0)
        .collect();
    Setup {
        cfg,
        spads,
        voxels,
        hists,
    }
}

fn len_err(what: &'static str, expected: usize, found: usize) -> ArgumentError {
    ArgumentError::Length {
        what,
        expected,
        found,
    }
}

#[test]
fn length_of_tables_and_row_buffer() {
    let s = setup();
    let ks = s.spads.len();
    let need = Scan::tables_len(&s.cfg, ks);
    for found in [0, need - 1, need + 1, 2 * need] {
        let mut tables = vec![0.0f32; found];
        assert_eq!(
            Scan::new(&s.cfg, &s.spads, &mut tables).unwrap_err(),
            len_err("tables", need, found)
        );
    }
    let mut tables = vec![0.0f32; need];
    let scan = Scan::new(&s.cfg, &s.spads, &mut tables).unwrap();
    let need = RowBuffer::len(&s.cfg, ks);
    for found in [0, need - 1, need + 1] {
        let mut buf = vec![0.0f32; found];
        assert_eq!(
            RowBuffer::new(&scan, &mut buf).unwrap_err(),
            len_err("row buffer", need, found)
        );
    }
}

#[test]
fn length_of_histograms_state_and_out() {
    let s = setup();
    let (ks, nt) = (s.spads.len(), s.cfg.nt());
    let mut tables = vec![0.0f32; Scan::tables_len(&s.cfg, ks)];
    let scan = Scan::new(&s.cfg, &s.spads, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(&s.cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    for found in [0, ks * nt - 1, ks * nt + 1, (ks - 1) * nt] {
        let h = vec![1u16; found];
        assert_eq!(
            rows.load(&scan, [0.0; 3], &h).unwrap_err(),
            len_err("histograms", ks * nt, found)
        );
    }
    for (t, g) in all_probes([0.0, 0.1, 0.7]) {
        let need = Probe::state_len(&s.cfg, t, g, s.voxels.len(), ks);
        for found in [0, need - 1, need + 1] {
            let mut state = vec![0.0; found];
            let e = Probe::new(&scan, t, g, &s.voxels, &mut state).unwrap_err();
            assert_eq!(e, len_err("state", need, found), "{t:?}/{g:?}");
        }
        let mut state = vec![0.0; need];
        let probe = Probe::new(&scan, t, g, &s.voxels, &mut state).unwrap();
        for found in [0, 1, 3] {
            let mut out = vec![0.0; found];
            assert_eq!(
                probe.finish(&scan, &mut out).unwrap_err(),
                len_err("out", 2, found),
                "{t:?}/{g:?}"
            );
            if probe.is_factorised() {
                let e = probe.image(&scan, &s.voxels, &mut out).unwrap_err();
                assert_eq!(e, len_err("out", 2, found), "{t:?}/{g:?}");
            }
        }
    }
}

/// A row buffer or a row made for a scan of another size is rejected, and the probe is left
/// unchanged.
#[test]
fn length_of_rows_from_another_scan() {
    let s = setup();
    let (ks, nt) = (s.spads.len(), s.cfg.nt());
    let mut tables = vec![0.0f32; Scan::tables_len(&s.cfg, ks)];
    let scan = Scan::new(&s.cfg, &s.spads, &mut tables).unwrap();
    let spads2 = &s.spads[..2];
    let mut tables2 = vec![0.0f32; Scan::tables_len(&s.cfg, 2)];
    let scan2 = Scan::new(&s.cfg, spads2, &mut tables2).unwrap();
    let j = s.cfg.bins();

    // Row buffer of scan2 (2 SPADs) used with scan (3 SPADs).
    let mut buf2 = vec![0.0f32; RowBuffer::len(&s.cfg, 2)];
    let mut rows2 = RowBuffer::new(&scan2, &mut buf2).unwrap();
    assert_eq!(
        rows2.load(&scan, [0.0; 3], &s.hists).unwrap_err(),
        len_err("row buffer", ks * j, 2 * j)
    );

    // A row of scan2 pushed into a probe of scan.
    let row2 = rows2.load(&scan2, [0.0; 3], &s.hists[..2 * nt]).unwrap();
    for (t, g) in all_probes([0.0, 0.1, 0.7]) {
        let mut state = vec![0.0; Probe::state_len(&s.cfg, t, g, s.voxels.len(), ks)];
        let mut probe = Probe::new(&scan, t, g, &s.voxels, &mut state).unwrap();
        assert_eq!(
            probe.push_row(&scan, &row2).unwrap_err(),
            len_err("row spectra", ks * j, 2 * j)
        );
        assert_eq!(probe.report().rows, 0, "nothing changed");
        let mut out = vec![1.0; 2];
        probe.finish(&scan, &mut out).unwrap();
        assert_eq!(out, [0.0, 0.0]);
    }

    // Same band size J but another Nt: the histograms check catches it.
    let nt3 = (nt + 1..nt + 100)
        .find(|&n| Config::try_new(&Params { nt: n, ..base() }).unwrap().bins() == j)
        .expect("a neighbouring Nt with the same band size");
    let cfg3 = Config::try_new(&Params { nt: nt3, ..base() }).unwrap();
    let mut tables3 = vec![0.0f32; Scan::tables_len(&cfg3, ks)];
    let scan3 = Scan::new(&cfg3, &s.spads, &mut tables3).unwrap();
    let mut buf3 = vec![0.0f32; RowBuffer::len(&cfg3, ks)];
    let mut rows3 = RowBuffer::new(&scan3, &mut buf3).unwrap();
    let h3 = vec![1.0f32; ks * nt3];
    let row3 = rows3.load(&scan3, [0.0; 3], &h3).unwrap();
    let mut state = vec![0.0; Probe::state_len(&s.cfg, Target::Diagonal, Gate::Gaussian, 2, ks)];
    let mut probe = Probe::new(
        &scan,
        Target::Diagonal,
        Gate::Gaussian,
        &s.voxels,
        &mut state,
    )
    .unwrap();
    assert_eq!(
        probe.push_row(&scan, &row3).unwrap_err(),
        len_err("row histograms", ks * nt, ks * nt3)
    );
}

#[test]
fn non_finite_positions() {
    let s = setup();
    let ks = s.spads.len();
    for x in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        for i in 0..3 {
            // SPADs.
            let mut spads = s.spads.clone();
            spads[1][i] = x;
            let mut tables = vec![0.0f32; Scan::tables_len(&s.cfg, ks)];
            let e = Scan::new(&s.cfg, &spads, &mut tables).unwrap_err();
            assert_eq!(
                e,
                ArgumentError::NonFinite {
                    what: "spads",
                    index: 1
                }
            );

            let mut tables = vec![0.0f32; Scan::tables_len(&s.cfg, ks)];
            let scan = Scan::new(&s.cfg, &s.spads, &mut tables).unwrap();
            // Laser.
            let mut buf = vec![0.0f32; RowBuffer::len(&s.cfg, ks)];
            let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
            let mut laser = [0.1f32, 0.0, 0.0];
            laser[i] = x;
            let e = rows.load(&scan, laser, &s.hists).unwrap_err();
            assert_eq!(
                e,
                ArgumentError::NonFinite {
                    what: "laser",
                    index: 0
                }
            );
            // Voxels and focus, every probe kind.
            let mut voxels = s.voxels.clone();
            voxels[1][i] = x;
            let mut focus = [0.0f32, 0.1, 0.7];
            for (t, g) in all_probes(focus) {
                let mut state = vec![0.0; Probe::state_len(&s.cfg, t, g, 2, ks)];
                let e = Probe::new(&scan, t, g, &voxels, &mut state).unwrap_err();
                assert_eq!(
                    e,
                    ArgumentError::NonFinite {
                        what: "voxels",
                        index: 1
                    },
                    "{t:?}/{g:?}"
                );
            }
            // `image` of a factorised column on a non-finite voxel.
            for g in [Gate::Gaussian, Gate::None] {
                let t = Target::Column(focus);
                let mut state = vec![0.0; Probe::state_len(&s.cfg, t, g, 2, ks)];
                let probe = Probe::new(&scan, t, g, &s.voxels, &mut state).unwrap();
                let mut out = vec![0.0; 2];
                let e = probe.image(&scan, &voxels, &mut out).unwrap_err();
                assert_eq!(
                    e,
                    ArgumentError::NonFinite {
                        what: "voxels",
                        index: 1
                    },
                    "{g:?}"
                );
            }
            focus[i] = x;
            for g in [Gate::Gaussian, Gate::HigherOrder, Gate::None] {
                let t = Target::Column(focus);
                let mut state = vec![0.0; Probe::state_len(&s.cfg, t, g, 2, ks)];
                let e = Probe::new(&scan, t, g, &s.voxels, &mut state).unwrap_err();
                assert_eq!(
                    e,
                    ArgumentError::NonFinite {
                        what: "focus",
                        index: 0
                    },
                    "{g:?}"
                );
            }
        }
    }
}

#[test]
fn merging_different_probes_is_incompatible() {
    let s = setup();
    let ks = s.spads.len();
    let mut tables = vec![0.0f32; Scan::tables_len(&s.cfg, ks)];
    let scan = Scan::new(&s.cfg, &s.spads, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(&s.cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let row = rows.load(&scan, [0.1, 0.0, 0.0], &s.hists).unwrap();
    let other_voxels = vec![[0.0, 0.0, 0.5], [0.1, 0.1, 0.7]];
    let three_voxels = vec![[0.0, 0.0, 0.5], [0.1, 0.1, 0.6], [0.2, 0.0, 0.9]];
    let (fa, fb) = ([0.0f32, 0.1, 0.7], [0.0f32, 0.1, 0.8]);
    let kinds: Vec<(Target, Gate)> = all_probes(fa)
        .into_iter()
        .chain([(Target::Column(fb), Gate::Gaussian)])
        .collect();

    for (i, &(t1, g1)) in kinds.iter().enumerate() {
        let mut st1 = vec![0.0; Probe::state_len(&s.cfg, t1, g1, 2, ks)];
        let mut p1 = Probe::new(&scan, t1, g1, &s.voxels, &mut st1).unwrap();
        p1.push_row(&scan, &row).unwrap();
        let mut before = vec![0.0; 2];
        p1.finish(&scan, &mut before).unwrap();
        let mut check_rejected = |p2: &Probe<'_>, why: &str| {
            assert!(
                matches!(p1.merge(p2), Err(ArgumentError::Incompatible(_))),
                "{t1:?}/{g1:?} vs {why}"
            );
            let mut after = vec![0.0; 2];
            assert_eq!(
                p1.finish(&scan, &mut after).unwrap().rows,
                1,
                "nothing changed"
            );
            assert_eq!(after, before, "nothing changed");
        };
        // Another target, gate or focus.
        for (j, &(t2, g2)) in kinds.iter().enumerate().filter(|&(j, _)| j != i) {
            let mut st2 = vec![0.0; Probe::state_len(&s.cfg, t2, g2, 2, ks)];
            let mut p2 = Probe::new(&scan, t2, g2, &s.voxels, &mut st2).unwrap();
            p2.push_row(&scan, &row).unwrap();
            check_rejected(&p2, &format!("kind {j}"));
        }
        // Other voxels (same count) and another voxel count.
        for voxels in [&other_voxels, &three_voxels] {
            let mut st2 = vec![0.0; Probe::state_len(&s.cfg, t1, g1, voxels.len(), ks)];
            let p2 = Probe::new(&scan, t1, g1, voxels, &mut st2).unwrap();
            check_rejected(&p2, "other voxels");
        }
        // Same kind and voxels under another configuration (another wavelength).
        let cfg2 = Config::try_new(&Params {
            wavelength: 0.12,
            ..base()
        })
        .unwrap();
        let mut tables2 = vec![0.0f32; Scan::tables_len(&cfg2, ks)];
        let scan2 = Scan::new(&cfg2, &s.spads, &mut tables2).unwrap();
        let mut st2 = vec![0.0; Probe::state_len(&cfg2, t1, g1, 2, ks)];
        let p2 = Probe::new(&scan2, t1, g1, &s.voxels, &mut st2).unwrap();
        check_rejected(&p2, "another configuration");
        // Control: a compatible probe merges.
        let mut st2 = vec![0.0; Probe::state_len(&s.cfg, t1, g1, 2, ks)];
        let p2 = Probe::new(&scan, t1, g1, &s.voxels, &mut st2).unwrap();
        p1.merge(&p2).unwrap();
    }
}

/// NaN and ±∞ samples in `f32` histograms: no panic, counted in `Report::non_finite`, and the
/// result is bit-for-bit the one with those samples set to 0 — for every probe.
#[test]
fn non_finite_samples_read_as_zero() {
    let p = Params { t0: 0.3, ..base() };
    let cfg = Config::try_new(&p).unwrap();
    let nt = cfg.nt();
    let lasers: Vec<Point> = vec![[-0.3, 0.0, 0.0], [0.0, 0.3, 0.0], [0.3, -0.2, 0.0]];
    let spads: Vec<Point> = vec![[0.0, 0.0, 0.0], [0.2, 0.1, 0.0]];
    let voxels: Vec<Point> = vec![[0.0, 0.0, 0.5], [0.1, 0.1, 0.6], [-0.1, 0.0, 0.7]];
    let mut clean: Vec<f32> = (0..lasers.len() * spads.len() * nt)
        .map(|i| ((i * 37) % 11) as f32 * 0.1)
        .collect();
    // Put a strong return where the voxels' path times are, so the corrupt bins matter.
    for (i, x) in clean.iter_mut().enumerate() {
        if i % nt == 70 || i % nt == 95 {
            *x = 25.0;
        }
    }
    let bad_at = [
        3,
        70,
        71,
        95,
        nt + 70,
        2 * nt + 95,
        3 * nt - 1,
        5 * nt + 70,
        clean.len() - 1,
    ];
    let mut dirty = clean.clone();
    for (k, &i) in bad_at.iter().enumerate() {
        dirty[i] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -f32::NAN][k % 4];
        clean[i] = 0.0;
    }
    for (t, g) in all_probes([0.0, 0.1, 0.6]) {
        let run_on = |h: &[f32]| {
            let data = Data {
                lasers: &lasers,
                spads: &spads,
                hists: h,
            };
            run(&cfg, data, t, g, &voxels, &all_rows(lasers.len()))
        };
        let (t_dirty, r_dirty) = run_on(&dirty);
        let (t_clean, r_clean) = run_on(&clean);
        assert!(
            t_dirty.iter().all(|x| x.is_finite()),
            "{t:?}/{g:?}: {t_dirty:?}"
        );
        assert!(t_clean.iter().any(|&x| x > 0.0));
        assert_eq!(t_dirty, t_clean, "{t:?}/{g:?}");
        assert_eq!(r_dirty.non_finite, bad_at.len() as u64, "{t:?}/{g:?}");
        assert_eq!(r_clean.non_finite, 0);
        assert_eq!(r_dirty.rows, r_clean.rows);
    }
}

/// Degenerate but valid sizes — no SPADs, no voxels, no rows, a single bin — never panic and
/// give zeros.
#[test]
fn empty_lists_do_not_panic() {
    for nt in [1, 200] {
        let cfg = Config::try_new(&Params { nt, ..base() }).unwrap();
        for n_spads in [0, 2] {
            let spads: Vec<Point> = vec![[0.1, 0.0, 0.0]; n_spads];
            for voxels in [vec![], vec![[0.0f32, 0.0, 0.5]]] {
                for (t, g) in all_probes([0.0, 0.0, 0.6]) {
                    let hists = vec![1.0f32; n_spads * nt * 3];
                    let data = Data {
                        lasers: &[[0.0, 0.0, 0.0]; 3],
                        spads: &spads,
                        hists: &hists,
                    };
                    for rows in [vec![], all_rows(3)] {
                        let (out, rep) = run(&cfg, data, t, g, &voxels, &rows);
                        assert_eq!(out.len(), voxels.len());
                        assert_eq!(rep.rows, rows.len() as u64);
                        if n_spads == 0 || rows.is_empty() {
                            assert!(out.iter().all(|&x| x == 0.0), "{t:?}/{g:?}: {out:?}");
                        }
                        assert!(out.iter().all(|x| x.is_finite()));
                    }
                }
            }
        }
    }
}
