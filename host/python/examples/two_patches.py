"""A notebook-sized tour of vltm from Python: open a path-traced capture, image its direct light,
one column of the light transport matrix and the in-focus indirect light, plot them, then
run the same on a Dask cluster and check that the volumes agree.

Usage: python host/python/examples/two_patches.py [CAPTURE] [--png F.png] [--workers N]
(default capture: the repository's fixtures/ytal/two_patches/two_patches.hdf5; default figure:
docs/python-example.png).
"""

from __future__ import annotations

import argparse
import pathlib
import time

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import vltm  # noqa: E402

REPO = pathlib.Path(__file__).resolve().parents[3]
CAPTURE = REPO / "fixtures" / "ytal" / "two_patches" / "two_patches.hdf5"
GRID = "-0.75:0.75:24,-0.75:0.75:24,0.4:1.35:20"
FOCUS = (-0.25, 0.15, 0.7)  # on patch A


def mip(ax, a, title, focus=None):
    """Front view: the maximum over z of a DataArray over (x, y, z)."""
    m = a.max("z")
    hx, hy = float(a.x[1] - a.x[0]) / 2, float(a.y[1] - a.y[0]) / 2  # voxel centres → edges
    ext = [float(a.x[0]) - hx, float(a.x[-1]) + hx, float(a.y[0]) - hy, float(a.y[-1]) + hy]
    ax.imshow(m.values.T, origin="lower", extent=ext, cmap="inferno")
    if focus is not None:
        ax.plot(focus[0], focus[1], "c+", ms=12, mew=2)
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("capture", nargs="?", default=str(CAPTURE))
    p.add_argument("--png", default=str(REPO / "docs" / "python-example.png"))
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args()

    cap = vltm.open(a.capture)
    print(cap)
    t = time.perf_counter()
    d = vltm.direct(cap, GRID, as_xarray=True)  # x, y, z in metres; λ, σ… as attributes
    col = vltm.column(cap, GRID, FOCUS, as_xarray=True)
    ind = vltm.indirect(cap, GRID, epsilon=0.2, as_xarray=True)
    local = time.perf_counter() - t
    print(f"in process: direct, column, indirect in {local:.2f} s "
          f"(λ = {d.attrs['wavelength']:.4f} m, σ = {d.attrs['sigma']:.4f} m)")

    fig, axes = plt.subplots(1, 3, figsize=(12, 4), constrained_layout=True)
    mip(axes[0], d, "direct light I_d (max over z)")
    mip(axes[1], col, f"column T(x_a, ·), x_a = {FOCUS}", FOCUS)
    mip(axes[2], ind, "in-focus indirect light I_i (ε = 0.2)")
    fig.suptitle(f"vltm from Python: {pathlib.Path(a.capture).name}, volume {GRID}",
                 fontsize=10)
    out = pathlib.Path(a.png)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    print(f"wrote {out}")

    # The same on a Dask cluster: each task streams some laser rows from the file.
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=a.workers, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        t = time.perf_counter()
        d2 = vltm.dask.direct(a.capture, GRID, client=client)
        c2 = vltm.dask.column(a.capture, GRID, FOCUS, client=client)
        i2 = vltm.dask.indirect(a.capture, GRID, client=client, epsilon=0.2)
        print(f"on {a.workers} Dask workers: the same three in {time.perf_counter() - t:.2f} s")
    for name, one, many in (("direct", d.values, d2), ("column", col.values, c2),
                            ("indirect", ind.values, i2)):
        err = np.abs(one.astype(np.float64) - many).max() / np.abs(one).max()
        print(f"{name:9s} largest difference, in process vs Dask: {err:.1e} of the maximum")
        assert err <= 1e-6, name


if __name__ == "__main__":
    main()
