//! What the kernel's property tests share (`fixed_point.rs`, `proptest_kernel.rs`,
//! `proptest_fast.rs`): the fixed-seed runner configuration, wall and hidden-point
//! strategies, and the generator of histogram contents.

use proptest::prelude::*;
use proptest::test_runner::{Config, FileFailurePersistence, RngAlgorithm, RngSeed};
use vltm_kernel::Point;

/// `cases` cases from the fixed seed `seed` (ChaCha), failures persisted beside the test file
/// (`proptest-regressions/`). The `proptest!` macro sets the source file; a hand-run
/// `TestRunner` sets it itself.
pub fn config(seed: u64, cases: u32) -> Config {
    Config {
        cases,
        rng_algorithm: RngAlgorithm::ChaCha,
        rng_seed: RngSeed::Fixed(seed),
        failure_persistence: Some(Box::new(FileFailurePersistence::WithSource(
            "proptest-regressions",
        ))),
        ..Config::default()
    }
}

/// A point of the wall `z = 0` within `[-1, 1]²`.
pub fn wall() -> impl Strategy<Value = Point> {
    (-1.0f32..=1.0, -1.0f32..=1.0).prop_map(|(x, y)| [x, y, 0.0])
}

/// A hidden point in `[-1, 1]² × [0.3, 1.5]`: every leg from the wall is longer than 0.25.
pub fn hidden() -> impl Strategy<Value = Point> {
    (-1.0f32..=1.0, -1.0f32..=1.0, 0.3f32..=1.5).prop_map(|(x, y, z)| [x, y, z])
}

/// SplitMix64: histogram contents drawn from a case's seed (no need to shrink 10⁴ samples).
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn f(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `0..n` (`n > 0`).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// A runner for a hand-run sweep (statistics over many drawn cases, no shrinking): the
/// default configuration with a ChaCha generator seeded from `seed` (its bytes, four times).
pub fn sweep_runner(seed: u64) -> proptest::test_runner::TestRunner {
    let rng = proptest::test_runner::TestRng::from_seed(
        RngAlgorithm::ChaCha,
        &[seed.to_le_bytes(); 4].concat(),
    );
    proptest::test_runner::TestRunner::new_with_rng(Config::default(), rng)
}

/// `p` with its margin widened until the path times `lo..=hi` lie in `Config::alias_free`
/// (where the factorised column is exact), plus two bins; `p` itself when they already do.
pub fn widen_margin(p: vltm_kernel::Params, (lo, hi): (f64, f64)) -> vltm_kernel::Params {
    let (af_lo, af_hi) = vltm_kernel::Config::try_new(&p)
        .expect("valid parameters")
        .alias_free();
    let need = (af_lo - (lo - p.t0)).max((hi - p.t0) - af_hi);
    if need > 0.0 {
        vltm_kernel::Params {
            margin: p.margin + need + 2.0 * p.dt,
            ..p
        }
    } else {
        p
    }
}

/// `p` (margin 0) with the most negative margin whose `Config::guard` still holds the path
/// times `lo..=hi` with `1e-4·σ` to spare (what `vltm`'s `direct` does with the crop on), and
/// `extra` metres more (> 0: a guard too tight by that much); `p` itself when the guard
/// cannot shrink.
pub fn tighten_margin(
    p: vltm_kernel::Params,
    (lo, hi): (f64, f64),
    extra: f64,
) -> vltm_kernel::Params {
    let cfg = vltm_kernel::Config::try_new(&p).expect("valid parameters");
    let a = p.gate_support * cfg.sigma();
    let slack = 1e-4 * cfg.sigma();
    let (lo, hi) = (lo - p.t0 - slack + extra, hi - p.t0 + slack - extra);
    let m = (-a).max(-(lo + a) / 2.0).max((hi - cfg.window() - a) / 2.0);
    if m < 0.0 {
        vltm_kernel::Params { margin: m, ..p }
    } else {
        p
    }
}

/// The kernel's legs for a case's optional device positions `(laser, sensor)`: wall to wall
/// without them.
pub fn legs(devices: Option<([f64; 3], [f64; 3])>) -> vltm_kernel::Legs {
    match devices {
        None => vltm_kernel::Legs::WallToWall,
        Some((laser_origin, sensor_origin)) => vltm_kernel::Legs::FirstAndLast {
            laser_origin,
            sensor_origin,
        },
    }
}
