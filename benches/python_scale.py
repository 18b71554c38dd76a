"""Python call overhead and Dask scale-out of vltm (docs/python.md, docs/performance.md).

  target/release/vltm simulate benches/scenes/exh16.json --uncompressed --out /tmp/exh16.npz
  python benches/python_scale.py [--vltm target/release/vltm] [--exh16 /tmp/exh16.npz]

Needs the package installed (`pip install ./host/python dask distributed`). Prints:
1. the CLI's `vltm direct` vs `vltm.open` + `vltm.direct` on the path-traced two_patches capture (`fixtures/ytal`)
   (median of 7 wall times each; the CLI writes only its .npy);
2. on exh16 (256 rows), direct light over 32x32x24 voxels and a two-bounce column, one
   process vs a LocalCluster of 2 worker processes (one rayon thread each) through
   `vltm.dask` (median of 3; the cluster is started before timing), with the partial-state
   sizes and the merge time of two states.
"""

import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]


def median_time(fn, n):
    ts = []
    for _ in range(n):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts), ts


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--vltm", default=str(REPO / "target/release/vltm"))
    ap.add_argument("--exh16", default="/tmp/exh16.npz")
    ap.add_argument("--capture", default=str(REPO / "fixtures/ytal/two_patches/two_patches.hdf5"))
    a = ap.parse_args()
    import vltm

    tp = a.capture
    grid = "-0.75:0.75:16,-0.75:0.75:16,0.4:1.35:20"
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "d.npy")
        cmd = [a.vltm, "direct", tp, "--volume", grid, "--out", out]
        subprocess.run(cmd, check=True, capture_output=True)
        vltm.direct(vltm.open(tp), grid)  # warm the page cache and the pool
        cli, cli_all = median_time(lambda: subprocess.run(cmd, check=True, capture_output=True), 7)
        py, py_all = median_time(lambda: vltm.direct(vltm.open(tp), grid), 7)
        same = np.abs(np.load(out) - vltm.direct(tp, grid)).max()
    print(f"two_patches direct {grid}: CLI {cli * 1e3:.1f} ms, Python {py * 1e3:.1f} ms "
          f"(Python/CLI {py / cli:.3f}); max |diff| {same:.2e}")
    print(f"  CLI runs {[round(x * 1e3, 1) for x in cli_all]} ms; Python runs {[round(x * 1e3, 1) for x in py_all]} ms")

    import distributed
    import vltm.dask

    cap = vltm.open(a.exh16)
    s = cap.spad_points
    x0, x1 = float(s[:, 0].min()), float(s[:, 0].max())
    y0, y1 = float(s[:, 1].min()), float(s[:, 1].max())
    p = (x1 - x0) / 15
    vol = f"{x0}:{x1 + p / 2}:32,{y0}:{y1 + p / 2}:32,0.4:1.6:24"
    focus = (0.0, 0.0, 0.8)
    print(f"exh16: {cap.info()['lasers']} rows, volume {vol}")
    single = {
        "direct": lambda: vltm.direct(cap, vol),
        # The plain column (a leak-corrected one runs as one task: its Γ needs every row).
        "column": lambda: vltm.column(cap, vol, focus, leak_correct=False),
    }
    ref = {k: f() for k, f in single.items()}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None,
                                  env={"RAYON_NUM_THREADS": "1"}) as cluster, \
            distributed.Client(cluster) as client:
        dist = {
            "direct": lambda: vltm.dask.direct(a.exh16, vol, client=client),
            "column": lambda: vltm.dask.column(a.exh16, vol, focus, client=client,
                                               leak_correct=False),
        }
        for k in single:
            dist[k]()  # warm up the workers (imports, page cache)
            t1, _ = median_time(single[k], 3)
            t2, _ = median_time(dist[k], 3)
            got = dist[k]()
            rel = np.abs(got.astype(np.float64) - ref[k]).max() / ref[k].max()
            print(f"  {k}: one process {t1:.2f} s, LocalCluster 2 workers {t2:.2f} s "
                  f"(ratio {t2 / t1:.2f}); rel diff {rel:.1e}")
    for k, kw in {"direct": {}, "column": {"focus": focus, "leak_correct": False}}.items():
        fn = vltm.direct if k == "direct" else vltm.column
        args = (cap, vol) if k == "direct" else (cap, vol, focus)
        parts = [fn(*args, rows=slice(0, 128)), fn(*args, rows=slice(128, 256))]
        t, _ = median_time(lambda: vltm.merge(parts), 5)
        tb, _ = median_time(lambda: [vltm.Partial.from_bytes(q.to_bytes()) for q in parts], 5)
        print(f"  {k} partial state {parts[0].nbytes} bytes; merge of 2: {t * 1e3:.2f} ms; "
              f"to/from bytes of 2: {tb * 1e3:.2f} ms")
    vol_tp = "-0.6:0.6:10,-0.6:0.6:10,0.5:1.2:8"
    d = vltm.direct(tp, vol_tp)
    ip = vltm.indirect(tp, vol_tp, direct=d, rows=slice(0, 32))
    n_gamma = int(vltm.gamma_mask(d, 0.1).sum())
    print(f"  indirect partial state (two_patches, |Γ| = {n_gamma}): {ip.nbytes} bytes")


if __name__ == "__main__":
    sys.exit(main())
