#![no_std]
#![no_main]

use cortex_m::singleton;
use cortex_m_rt::entry;
use panic_halt as _;
use vltm_kernel::{Config, Gate, Params, Point, Probe, RowBuffer, Scan, Target};

// Static buffers need constant sizes: compute them once on the host (Scan::tables_len,
// RowBuffer::len, Probe::state_len, or `gen budget`) and check them at start-up.
const NT: usize = 128; // bins per histogram
const KS: usize = 4; // SPADs
const J: usize = 48; // Config::bins() for these Params
const N: usize = 195; // Config::n_fft()
const KV: usize = 16; // voxels
static SPADS: [Point; KS] = [
    [-0.15, 0.0, 0.0],
    [-0.05, 0.0, 0.0],
    [0.05, 0.0, 0.0],
    [0.15, 0.0, 0.0],
];
static VOXELS: [Point; KV] = [[0.0, 0.0, 0.5]; KV];

#[entry]
fn main() -> ! {
    let code = run().unwrap_or(2);
    semihosting::process::exit(code)
}

fn run() -> Option<i32> {
    let params = Params {
        t0: 0.5,
        ..Params::new(0.1, NT, 0.01)
    };
    let cfg = Config::try_new(&params).ok()?;
    if cfg.bins() != J || cfg.n_fft() != N {
        return None;
    }
    // All state: zero-initialised statics (.bss), each handed out once as &'static mut.
    let tables = singleton!(: [f32; 2 * N + J + KS] = [0.0; 2 * N + J + KS])?; // Scan::tables_len
    let rowbuf = singleton!(: [f32; KS * (2 * J + 3)] = [0.0; KS * (2 * J + 3)])?; // RowBuffer::len
    let state = singleton!(: [f64; 2 * KV] = [0.0; 2 * KV])?; // Probe::state_len (diagonal)
    let hist = singleton!(: [u16; KS * NT] = [0; KS * NT])?; // your TCSPC histograms
    let image = singleton!(: [f64; KV] = [0.0; KV])?;

    let scan = Scan::new(&cfg, &SPADS, tables).ok()?;
    let mut rows = RowBuffer::new(&scan, rowbuf).ok()?;
    let mut diag = Probe::new(&scan, Target::Diagonal, Gate::Gaussian, &VOXELS, state).ok()?;

    // Per laser position: fill `hist` (SPAD-major, hist[s * NT + n]), then fold it in.
    // (Or rows.begin_photons(); rows.push_photon(&scan, spad, bin) per event;
    //  rows.end_photons(&scan, laser) — no histogram memory at all.)
    hist[100] = 7;
    let row = rows.load(&scan, [0.0, 0.0, 0.0], &hist[..]).ok()?;
    diag.push_row(&scan, &row).ok()?;

    let report = diag.finish(&scan, image).ok()?; // image[v] = T(v, v) = |A|²
    Some(if report.rows == 1 && image.iter().all(|v| v.is_finite()) {
        0
    } else {
        1
    })
}
