//! The firmware-to-host firmware: folds the laser rows [`STATE_ROWS`] of the fixture scan into
//! the Gaussian diagonal and the column `T(P1, ·)`, as the MCU next to the TCSPC does while the
//! scan runs, then writes both accumulator states in vltm's partial-state format through
//! semihosting (`fw_direct.vltmpart`, `fw_column.vltmpart` in QEMU's working folder; on a
//! board the same bytes go over a debug probe or a UART). The host merges them with its own
//! parts of the other rows (`vltm merge`) or continues from them (`vltm live --resume`).
//! Exit status: 0 = written; 2 = a kernel call or the fixture was rejected; 8 = a state could
//! not be written (its error is printed); 7 = a static buffer was handed out twice.
#![no_std]
#![no_main]

use cortex_m::singleton;
use cortex_m_rt::entry;
use panic_semihosting as _;
use semihosting::{fs, println, process};
use vltm_firmware::fixture::{
    COLUMN_LEN, DIAG_LEN, FOCUS, LASERS, N_LASERS, NT, ROW, ROWBUF_LEN, SPADS, STATE_ROWS,
    TABLES_LEN, VOXELS, params,
};
use vltm_firmware::state::{StateParts, write_state};
use vltm_kernel::{ArgumentError, Config, Gate, Probe, RowBuffer, Scan, Target};

/// The host's header templates for this fixture (`gen state-template`).
const DIRECT_HEAD: &str = include_str!("../../fixture/state_direct.json");
const COLUMN_HEAD: &str = include_str!("../../fixture/state_column.json");

fn save(name: &core::ffi::CStr, parts: &StateParts<'_>) -> Result<(), ()> {
    use semihosting::io::Write as _;
    let mut file = fs::File::create(name).map_err(|_| ())?;
    write_state(parts, |b| file.write_all(b).map_err(|_| ())).map_err(|e| {
        println!("ERROR state {e:?}");
    })
}

/// Folds the rows [`STATE_ROWS`] into a diagonal (state in `diag`) and a column (`column`).
fn fold<'m>(
    cfg: &Config,
    data: &[u16],
    (tables, row, diag, column): (&mut [f32], &mut [f32], &'m mut [f64], &'m mut [f64]),
) -> Result<(Probe<'m>, Probe<'m>), ArgumentError> {
    let scan = Scan::new(cfg, &SPADS, tables)?;
    let mut rows = RowBuffer::new(&scan, row)?;
    let mut d = Probe::new(&scan, Target::Diagonal, Gate::Gaussian, &VOXELS, diag)?;
    let mut c = Probe::new(
        &scan,
        Target::Column(FOCUS),
        Gate::Gaussian,
        &VOXELS,
        column,
    )?;
    let expected = N_LASERS * ROW;
    if data.len() != expected {
        return Err(ArgumentError::Length {
            what: "scan data",
            expected,
            found: data.len(),
        });
    }
    for (hists, &laser) in data
        .chunks_exact(ROW)
        .zip(&LASERS)
        .skip(STATE_ROWS.start)
        .take(STATE_ROWS.len())
    {
        let r = rows.load(&scan, laser, hists)?;
        d.push_row(&scan, &r)?;
        c.push_row(&scan, &r)?;
    }
    Ok((d, c))
}

#[entry]
fn main() -> ! {
    let (Some(tables), Some(row), Some(diag), Some(column)) = (
        singleton!(: [f32; TABLES_LEN] = [0.0; TABLES_LEN]),
        singleton!(: [f32; ROWBUF_LEN] = [0.0; ROWBUF_LEN]),
        singleton!(: [f64; DIAG_LEN] = [0.0; DIAG_LEN]),
        singleton!(: [f64; COLUMN_LEN] = [0.0; COLUMN_LEN]),
    ) else {
        process::exit(7)
    };
    let Some(data) = vltm_firmware::scan_data() else {
        process::exit(2)
    };
    let Ok(cfg) = Config::try_new(&params()) else {
        process::exit(2)
    };
    let bufs: (&mut [f32], &mut [f32], &mut [f64], &mut [f64]) = (tables, row, diag, column);
    let (d, c) = match fold(&cfg, data, bufs) {
        Ok(p) => p,
        Err(e) => {
            println!("ERROR {e:?}");
            process::exit(2)
        }
    };
    let rows = [STATE_ROWS.start, STATE_ROWS.end];
    let direct = StateParts {
        template: DIRECT_HEAD,
        rows,
        report: d.report(),
        legs: None,
        spads: &[],
        points: &VOXELS,
        acc: d.accumulators(),
    };
    let col = StateParts {
        template: COLUMN_HEAD,
        rows,
        report: c.report(),
        legs: Some(c.leg_range()),
        spads: &SPADS,
        points: &VOXELS,
        acc: c.accumulators(),
    };
    for (name, parts) in [
        (c"fw_direct.vltmpart", &direct),
        (c"fw_column.vltmpart", &col),
    ] {
        if save(name, parts).is_err() {
            println!("ERROR writing {name:?}");
            process::exit(8)
        }
        println!(
            "STATE {name:?} rows={}..{} bins={NT} accumulators={}",
            rows[0],
            rows[1],
            parts.acc.len()
        );
    }
    process::exit(0)
}
