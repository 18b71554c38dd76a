//! Partial accumulators (`vltm::probe::partial`): a scan split by laser rows, each part's
//! state serialised and read back, merged and finished, equals one pass over all rows —
//! bit-identical where the summation order is the same (one part holding every row, the
//! same number of threads), else within 1e-6 relative — for every probe and evaluation path, on a committed
//! fixture and on the path-traced y-tal capture (`fixtures/ytal`). Parts of other captures or parameters,
//! overlapping or missing rows, and damaged states are refused with one-line errors.

mod support;

use std::path::{Path, PathBuf};
use vltm::exec::{EvalPath, Exec};
use vltm::io::{self, RowSource};
use vltm::probe::{
    self, ColumnGate, IndirectOptions, LeakOptions, Partial, Shell, Task, Wave, partial,
};
use vltm::volume::Volume;

fn fixture() -> PathBuf {
    support::fixture("two_patches.npz")
}

/// A grid whose pitch (1/14 m) divides the fixture's SPAD pitch (1/7 m): planar applies.
const GRID: &str = "-0.5:0.5:15,-0.5:0.5:15,0.4:1.2:9";
const FOCUS: [f32; 3] = [-0.25, 0.15, 0.7];

fn exec(path: EvalPath) -> Exec<'static> {
    Exec {
        path,
        ..Exec::default()
    }
}

fn source(p: &Path) -> Box<dyn RowSource> {
    io::open_source(p).expect("open")
}

/// The task's state over the rows `rows` of the capture `p` (default wave; size 1, name `x`).
fn accumulate(
    p: &Path,
    volume: &Volume,
    task: &Task,
    path: EvalPath,
    rows: std::ops::Range<usize>,
) -> Partial {
    let mut src = source(p);
    partial::accumulate(
        &mut *src,
        1,
        "x",
        volume,
        task,
        &Wave::default(),
        exec(path),
        rows,
    )
    .expect("part")
}

/// The task's state over each row range, through bytes, merged in reverse order, finished.
fn split(p: &Path, volume: &Volume, task: &Task, path: EvalPath, cuts: &[usize]) -> Vec<f32> {
    let parts: Vec<Partial> = cuts
        .windows(2)
        .rev()
        .map(|w| {
            let part = accumulate(p, volume, task, path, w[0]..w[1]);
            let bytes = part.to_bytes();
            assert_eq!(bytes.len(), part.byte_len());
            Partial::from_bytes(&bytes, Path::new("part")).expect("read back")
        })
        .collect();
    let names: Vec<String> = (0..parts.len()).map(|i| format!("p{i}")).collect();
    let merged = Partial::merge(parts, &names).expect("merge");
    assert!(merged.is_complete());
    merged.finish().expect("finish").output.values
}

/// The one-pass result of a task.
fn one_pass(p: &Path, volume: &Volume, task: &Task, path: EvalPath) -> Vec<f32> {
    let mut src = source(p);
    let w = Wave::default();
    match task {
        Task::Direct => {
            probe::direct(&mut *src, volume, &w, exec(path))
                .expect("direct")
                .values
        }
        Task::Column { focus, gate, shell } => {
            probe::column(&mut *src, *focus, volume, *gate, *shell, &w, exec(path))
                .expect("column")
                .values
        }
        Task::Indirect { gamma, shell, leak } => {
            let opts = IndirectOptions {
                shell: *shell,
                leak: leak.then(LeakOptions::default),
                ..IndirectOptions::default()
            };
            probe::indirect_over(&mut *src, volume, gamma, &opts, &w, exec(path))
                .expect("indirect")
                .values
        }
        Task::Matrix { from } => probe::matrix(&mut *src, from, &volume.points, &w, exec(path))
            .expect("matrix")
            .intensities(),
    }
}

fn assert_close(what: &str, a: &[f32], b: &[f32], rel: f32) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    let max = a.iter().copied().fold(0.0f32, f32::max);
    assert!(max > 0.0, "{what}: an empty volume proves nothing");
    let worst = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    assert!(
        worst <= rel * max,
        "{what}: split/merge differs from one pass by {worst:e} (max {max:e})"
    );
}

fn tasks(volume: &Volume, p: &Path) -> Vec<(String, Task, EvalPath)> {
    let col = |gate| Task::Column {
        focus: FOCUS,
        gate,
        shell: Shell::ALL,
    };
    let mut src = source(p);
    let d = probe::direct(&mut *src, volume, &Wave::default(), Exec::default()).expect("direct");
    let gamma = probe::gamma_mask(&d.values, 0.1);
    assert!(gamma.iter().filter(|&&g| g).count() > 10);
    vec![
        ("direct band".into(), Task::Direct, EvalPath::Band),
        ("direct lookup".into(), Task::Direct, EvalPath::Lookup),
        ("direct phasor".into(), Task::Direct, EvalPath::Phasor),
        ("direct planar".into(), Task::Direct, EvalPath::Planar),
        (
            "column two-bounce planar".into(),
            col(ColumnGate::TwoBounce),
            EvalPath::Planar,
        ),
        (
            "column two-bounce band".into(),
            col(ColumnGate::TwoBounce),
            EvalPath::Band,
        ),
        (
            "column higher-order".into(),
            col(ColumnGate::HigherOrder),
            EvalPath::Auto,
        ),
        ("column none".into(), col(ColumnGate::None), EvalPath::Auto),
        (
            "indirect".into(),
            Task::Indirect {
                gamma: gamma.clone(),
                shell: Some(Shell {
                    r0: 0.2,
                    r1: f32::INFINITY,
                }),
                leak: false,
            },
            EvalPath::Auto,
        ),
        (
            "indirect leak-corrected".into(),
            Task::Indirect {
                gamma,
                shell: None,
                leak: true,
            },
            EvalPath::Auto,
        ),
        (
            "matrix".into(),
            Task::Matrix {
                from: vec![FOCUS, [0.1, -0.2, 0.9], [0.3, 0.3, 0.6]],
            },
            EvalPath::Auto,
        ),
    ]
}

/// Every probe and path: three parts merged equal one pass to 1e-6 relative.
#[test]
fn split_and_merge_equals_one_pass() {
    let p = fixture();
    let volume = Volume::parse(GRID).expect("grid");
    for (name, task, path) in tasks(&volume, &p) {
        let one = one_pass(&p, &volume, &task, path);
        let three = split(&p, &volume, &task, path, &[0, 17, 40, 64]);
        assert_close(&name, &one, &three, 1e-6);
    }
}

/// One part holding every row sums the rows in the order of one pass: on one thread and on
/// three, the finished state is bit-identical. Which worker's partial sum holds which row
/// depends on the row's index only, never on the thread that ran it: every probe's state is
/// the same bytes run to run.
#[test]
fn one_part_is_bit_identical_to_one_pass() {
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let p = fixture();
            let volume = Volume::parse(GRID).expect("grid");
            for (name, task, path) in tasks(&volume, &p) {
                let one = one_pass(&p, &volume, &task, path);
                let all = split(&p, &volume, &task, path, &[0, 64]);
                assert!(
                    one == all,
                    "{name}: not bit-identical on {threads} thread(s)"
                );
                let state = || accumulate(&p, &volume, &task, path, 0..64).to_bytes();
                let first = state();
                for run in 1..4 {
                    assert!(
                        state() == first,
                        "{name}: on {threads} thread(s), run {run}'s state differs from run 0's"
                    );
                }
            }
        });
    }
}

/// The path-traced y-tal capture of `fixtures/ytal` (streamed from HDF5), direct light on the default path and a
/// column: four parts equal one pass.
#[test]
fn shared_capture_split_four_ways() {
    let p = support::fixture("ytal/two_patches/two_patches.hdf5");
    let volume = Volume::parse("-0.75:0.75:16,-0.75:0.75:16,0.4:1.35:20").expect("grid");
    for task in [
        Task::Direct,
        Task::Column {
            focus: FOCUS,
            gate: ColumnGate::TwoBounce,
            shell: Shell::ALL,
        },
    ] {
        let one = one_pass(&p, &volume, &task, EvalPath::Auto);
        let four = split(&p, &volume, &task, EvalPath::Auto, &[0, 16, 32, 48, 64]);
        assert_close(&format!("shared {task:?}"), &one, &four, 1e-6);
    }
}

fn part(p: &Path, volume: &Volume, wave: &Wave, rows: std::ops::Range<usize>) -> Partial {
    let mut src = source(p);
    let bytes = std::fs::metadata(p).expect("size").len();
    partial::accumulate(
        &mut *src,
        bytes,
        "c",
        volume,
        &Task::Direct,
        wave,
        Exec::default(),
        rows,
    )
    .expect("part")
}

fn merge_err(parts: Vec<Partial>) -> String {
    let names = vec!["A".to_string(), "B".to_string()];
    match Partial::merge(parts, &names).and_then(|m| m.finish()) {
        Ok(_) => panic!("merged and finished parts that must be refused"),
        Err(e) => e.to_string(),
    }
}

/// Parts of different captures or parameters, overlapping and missing rows are refused,
/// and so are damaged states; each error is one line naming the parts or the field.
#[test]
fn mismatched_parts_are_refused() {
    let p = fixture();
    let other = support::fixture("two_patches_direct.npz");
    let volume = Volume::parse("-0.5:0.5:6,-0.5:0.5:6,0.5:1.0:3").expect("grid");
    let w = Wave::default();
    let a = part(&p, &volume, &w, 0..32);
    let e = merge_err(vec![a.clone(), part(&other, &volume, &w, 32..64)]);
    assert!(e.contains("different captures"), "{e}");
    let lam = Wave {
        wavelength: Some(0.3),
        ..w
    };
    let e = merge_err(vec![a.clone(), part(&p, &volume, &lam, 32..64)]);
    assert!(e.contains("different probes or parameters"), "{e}");
    let finer = Volume::parse("-0.5:0.5:6,-0.5:0.5:6,0.5:1.0:4").expect("grid");
    let e = merge_err(vec![a.clone(), part(&p, &finer, &w, 32..64)]);
    assert!(e.contains("different probes or parameters"), "{e}");
    let e = merge_err(vec![a.clone(), part(&p, &volume, &w, 30..64)]);
    assert!(e.contains("overlap") && e.contains("30:64"), "{e}");
    let e = merge_err(vec![a.clone(), part(&p, &volume, &w, 40..64)]);
    assert!(e.contains("rows 32:40") && e.contains("missing"), "{e}");
    assert!(!e.contains('\n'));
    // Rows outside the scan.
    let mut src = source(&p);
    let e = partial::accumulate(
        &mut *src,
        0,
        "c",
        &volume,
        &Task::Direct,
        &w,
        Exec::default(),
        60..65,
    )
    .expect_err("rows beyond the scan");
    assert!(
        e.to_string().contains("argument `rows`") && e.is_usage(),
        "{e}"
    );
    // Damaged bytes: a flipped accumulator byte fails the CRC, a cut file the size check,
    // another file the magic.
    let mut bytes = a.to_bytes();
    let n = bytes.len();
    bytes[n - 3] ^= 0x40;
    let e = Partial::from_bytes(&bytes, Path::new("a.part")).expect_err("crc");
    assert!(e.to_string().contains("a.part: field `crc32`"), "{e}");
    let e = Partial::from_bytes(&a.to_bytes()[..n - 8], Path::new("a.part")).expect_err("cut");
    assert!(e.to_string().contains("field `body`"), "{e}");
    let e = Partial::from_bytes(b"PK\x03\x04 not a state at all", Path::new("x.npz"))
        .expect_err("magic");
    assert!(e.to_string().contains("field `magic`"), "{e}");
    // A part alone does not finish; the two halves do, whatever the order given.
    let b = part(&p, &volume, &w, 32..64);
    assert!(
        Partial::merge(vec![a.clone()], &[])
            .unwrap()
            .finish()
            .is_err()
    );
    let ab = Partial::merge(vec![b.clone(), a.clone()], &[]).expect("merge");
    assert_eq!(ab.rows(), vec![0..64]);
    let v = ab.finish().expect("finish").output.values;
    let mut src = source(&p);
    let one = probe::direct(&mut *src, &volume, &w, Exec::default()).expect("direct");
    assert_close("halves", &one.values, &v, 1e-6);
}

/// A tree of merges (pairs of parts, then pairs of pairs) equals a flat merge and a state
/// written to a file and read back is the same state.
#[test]
fn tree_merge_and_files() {
    let p = fixture();
    let volume = Volume::parse("-0.5:0.5:8,-0.5:0.5:8,0.5:1.0:4").expect("grid");
    let w = Wave::default();
    let parts: Vec<Partial> = (0..4)
        .map(|i| part(&p, &volume, &w, 16 * i..16 * (i + 1)))
        .collect();
    let flat = Partial::merge(parts.clone(), &[]).expect("flat");
    let left = Partial::merge(parts[..2].to_vec(), &[]).expect("left");
    let right = Partial::merge(parts[2..].to_vec(), &[]).expect("right");
    assert_eq!(left.rows(), vec![0..32]);
    assert!(!left.is_complete());
    let tree = Partial::merge(vec![right, left], &[]).expect("tree");
    let (a, b) = (flat.finish().unwrap(), tree.finish().unwrap());
    assert_close("tree", &a.output.values, &b.output.values, 1e-6);
    let amps = a.amplitudes.expect("direct light has amplitudes");
    let i = a
        .output
        .values
        .iter()
        .enumerate()
        .max_by(|x, y| x.1.total_cmp(y.1))
        .map(|(i, _)| i)
        .unwrap();
    assert!((amps[i].norm_sqr() as f32 - a.output.values[i]).abs() <= 1e-6 * a.output.values[i]);
    let dir = std::env::temp_dir().join(format!("vltm-partial-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let f = dir.join("flat.part");
    flat.write(&f).expect("write");
    let back = Partial::read(&f).expect("read");
    assert_eq!(back.to_bytes(), flat.to_bytes());
    std::fs::remove_dir_all(&dir).ok();
}

/// A two-bounce column's complex amplitudes (`finish_with(true)`) square to its intensities
/// on both imaging paths, are 0 outside the shell, and the un-gated column has none; a
/// leak-corrected indirect state split in parts measures the removed energy as one pass.
#[test]
fn column_amplitudes_and_leak_energy() {
    let p = fixture();
    let volume = Volume::parse(GRID).expect("grid");
    let shell = Shell { r0: 0.2, r1: 0.6 };
    for path in [EvalPath::Band, EvalPath::Planar] {
        let task = Task::Column {
            focus: FOCUS,
            gate: ColumnGate::TwoBounce,
            shell,
        };
        let part = accumulate(&p, &volume, &task, path, 0..64);
        let f = part.finish_with(true).expect("finish");
        let a = f.amplitudes.expect("amplitudes of a two-bounce column");
        let sq: Vec<f32> = a.iter().map(|z| z.norm_sqr() as f32).collect();
        assert_close(&format!("|A|² {path:?}"), &f.output.values, &sq, 1e-5);
        let outside = volume
            .points
            .iter()
            .zip(&a)
            .filter(|(q, _)| {
                let d = (0..3)
                    .map(|i| (q[i] - FOCUS[i]).powi(2))
                    .sum::<f32>()
                    .sqrt();
                !shell.contains(d)
            })
            .collect::<Vec<_>>();
        assert!(!outside.is_empty() && outside.iter().all(|(_, z)| z.norm() == 0.0));
        assert!(part.finish().expect("finish").amplitudes.is_none());
    }
    let none = Task::Column {
        focus: FOCUS,
        gate: ColumnGate::None,
        shell: Shell::ALL,
    };
    let part = accumulate(&p, &volume, &none, EvalPath::Auto, 0..64);
    assert!(part.finish_with(true).expect("finish").amplitudes.is_none());

    let mut src = source(&p);
    let d = probe::direct(&mut *src, &volume, &Wave::default(), Exec::default()).expect("direct");
    let gamma = probe::gamma_mask(&d.values, 0.1);
    let opts = IndirectOptions {
        leak: Some(LeakOptions::default()),
        ..IndirectOptions::default()
    };
    let one = probe::indirect_over(
        &mut *src,
        &volume,
        &gamma,
        &opts,
        &Wave::default(),
        Exec::default(),
    )
    .expect("indirect");
    let task = Task::Indirect {
        gamma,
        shell: None,
        leak: true,
    };
    let parts: Vec<Partial> = [0..20, 20..64]
        .into_iter()
        .map(|r| {
            let mut src = source(&p);
            let w = Wave::default();
            partial::accumulate(&mut *src, 1, "x", &volume, &task, &w, Exec::default(), r)
                .expect("part")
        })
        .collect();
    let merged = Partial::merge(parts, &["a".into(), "b".into()]).expect("merge");
    let f = merged.finish().expect("finish");
    let (e1, e2) = (
        one.explained.expect("one pass"),
        f.explained.expect("parts"),
    );
    assert!(e1 > 0.0 && (e1 - e2).abs() <= 1e-9 * e1, "{e1} vs {e2}");
    assert_close("leak-corrected", &one.values, &f.output.values, 1e-6);
}
