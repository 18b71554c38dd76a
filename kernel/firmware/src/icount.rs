//! Instruction counting under QEMU `-icount shift=0` (feature `cycles`): the virtual clock
//! advances 1 ns per executed guest instruction and SysTick (core clock) runs on it, so
//! SysTick ticks × instructions per tick (calibrated with a loop of known length) = executed
//! instructions. Works on ARMv6-M and ARMv7E-M (no atomic read-modify-write needed).
//!
//! The bin defines the SysTick handler and calls [`on_systick`] from it:
//! `#[exception] fn SysTick() { vltm_firmware::icount::on_systick() }`.

use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::{SYST, syst::SystClkSource};

static WRAPS: AtomicU32 = AtomicU32::new(0);

/// Counts one SysTick wrap (2²⁴ ticks). The exception is the only writer.
pub fn on_systick() {
    WRAPS.store(
        WRAPS.load(Ordering::Relaxed).wrapping_add(1),
        Ordering::Relaxed,
    );
}

/// SysTick ticks since start (24-bit counter + wraps counted by the exception).
pub fn ticks() -> u64 {
    loop {
        let w = WRAPS.load(Ordering::Relaxed);
        let v = SYST::get_current();
        if WRAPS.load(Ordering::Relaxed) == w {
            return u64::from(w) * (1 << 24) + u64::from(0xFF_FFFF - v);
        }
    }
}

/// Ticks taken by `f`, and its result.
pub fn measure<R>(f: impl FnOnce() -> R) -> (u64, R) {
    let t0 = ticks();
    let r = f();
    (ticks() - t0, r)
}

/// Starts SysTick on the core clock with its interrupt, and calibrates: returns the
/// instructions per tick, measured with a loop of exactly 2 instructions per iteration
/// (`subs` + `bne`), and the calibration's (instructions, ticks).
pub fn start(mut syst: SYST) -> (f64, u32, u64) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0xFF_FFFF);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
    // VAL reads 0 until the first tick reloads it.
    while SYST::get_current() == 0 {}
    let n_loop = 5_000_000u32;
    let (t_cal, ()) = measure(|| unsafe {
        core::arch::asm!("2:", "subs {0}, #1", "bne 2b", inout(reg) n_loop => _, options(nomem, nostack));
    });
    (2.0 * f64::from(n_loop) / t_cal as f64, 2 * n_loop, t_cal)
}
