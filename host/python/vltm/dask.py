"""Scale-out over a Dask cluster: a scan split by laser rows into tasks.

Each task opens the capture file itself (workers read it from shared storage: the capture is
never shipped through the scheduler), streams its rows through the probe and returns the
partial state as bytes; the states are reduced by addition in a tree (``split_every`` parts
per merge) and the root is finished on the client.

>>> from distributed import Client, LocalCluster
>>> import vltm.dask
>>> with LocalCluster(n_workers=2, threads_per_worker=1) as cluster, Client(cluster) as client:
...     I = vltm.dask.direct("scan.npz", "-0.75:0.75:32,-0.75:0.75:32,0.4:1.4:24", client=client)

Cost per task: its rows' share of the one-pass time plus opening the file; per merge: one
addition per f64 of state (see ``Partial.nbytes``) plus (de)serialisation.
"""

from __future__ import annotations

import math
import os
from typing import Any, List, Optional, Sequence, Tuple, Union

import numpy as np

import vltm

__all__ = ["column", "direct", "indirect", "matrix", "row_ranges"]


def row_ranges(n_rows: int, rows_per_task: int) -> List[Tuple[int, int]]:
    """The tasks' row ranges ``[a, b)`` covering ``0..n_rows``."""
    k = max(1, int(rows_per_task))
    return [(a, min(a + k, n_rows)) for a in range(0, n_rows, k)]


def _volume_arg(volume: Union[str, np.ndarray, "vltm.Volume"]) -> Union[str, np.ndarray]:
    """What a task gets for the volume: its SPEC (a few bytes) or its points."""
    v = vltm.Volume(volume)
    return v.spec if v.spec is not None else v.points


def _part(path: str, volume: Any, kind: str, a: int, b: int, kw: dict) -> bytes:
    """One task: opens the file, streams rows a..b, returns the state as bytes."""
    if kind == "matrix":
        return vltm.matrix(path, kw["from_"], volume, rows=slice(a, b),
                           **{k: v for k, v in kw.items() if k != "from_"}).to_bytes()
    fn = {"direct": vltm.direct, "column": vltm.column, "indirect": vltm.indirect}[kind]
    return fn(path, volume, rows=slice(a, b), **kw).to_bytes()


def _merge(parts: Sequence[bytes]) -> bytes:
    """One reduction step: the sum of some states, as bytes."""
    return vltm._native.merge_bytes([bytes(p) for p in parts])


def _client(client: Any) -> Any:
    if client is not None:
        return client
    from distributed import get_client

    return get_client()


def _run(kind: str, path: Union[str, "os.PathLike[str]"], volume: Any, client: Any,
         rows_per_task: Optional[int], split_every: int, kw: dict) -> vltm.Partial:
    import dask

    path = os.fspath(path)
    client = _client(client)
    n = vltm.open(path).info()["lasers"]
    if rows_per_task is None:
        workers = max(1, len(client.scheduler_info().get("workers", {})))
        rows_per_task = math.ceil(n / (2 * workers))
    vol = volume if kind == "matrix" else _volume_arg(volume)
    part = dask.delayed(_part, pure=True)
    merge = dask.delayed(_merge, pure=True)
    layer = [part(path, vol, kind, a, b, kw, dask_key_name=f"vltm-{kind}-rows-{a}-{b}-{dask.base.tokenize(path, vol, kw)}")
             for a, b in row_ranges(n, rows_per_task)]
    k = max(2, int(split_every))
    while len(layer) > 1:
        layer = [merge(layer[i:i + k]) for i in range(0, len(layer), k)]
    state = client.compute(layer[0]).result()
    p = vltm.Partial.from_bytes(state)
    if kind != "matrix":
        p._shape = vltm.Volume(volume).shape
    return p


def direct(path: Union[str, "os.PathLike[str]"], volume: Any, *, client: Any = None,
           rows_per_task: Optional[int] = None, split_every: int = 8, **options: Any) -> np.ndarray:
    """:func:`vltm.direct` over a Dask cluster: ``rows_per_task`` laser rows per task
    (default: two tasks per worker), states reduced ``split_every`` at a time. ``client``: a
    ``distributed.Client`` (default: the current one). ``options``: those of
    :func:`vltm.direct` (``wavelength``, ``sigma``, ``weights``, ``band``, ``path``...)."""
    return _run("direct", path, volume, client, rows_per_task, split_every, options).finish()


def column(path: Union[str, "os.PathLike[str]"], volume: Any, focus: Sequence[float], *,
           client: Any = None, rows_per_task: Optional[int] = None, split_every: int = 8,
           **options: Any) -> np.ndarray:
    """:func:`vltm.column` over a Dask cluster (arguments as :func:`direct`)."""
    kw = dict(options, focus=[float(x) for x in focus])
    return _run("column", path, volume, client, rows_per_task, split_every, kw).finish()


def indirect(path: Union[str, "os.PathLike[str]"], volume: Any, *, client: Any = None,
             rows_per_task: Optional[int] = None, split_every: int = 8, epsilon: float = 0.1,
             direct: Optional[np.ndarray] = None, **options: Any) -> np.ndarray:
    """:func:`vltm.indirect` over a Dask cluster: round 1 the direct light (unless
    ``direct`` is given) to find Γ, round 2 the Γ columns; two passes over the rows, each
    split into tasks. ``leak_correct`` (default True, as :func:`vltm.indirect`): every task
    zeroes the direct-return windows of Γ in its own rows (the gate needs only Γ and the
    geometry), and the removed energy adds up over the tasks."""
    wave_keys = ("wavelength", "sigma", "weights", "band", "compensate_laser", "path")
    if direct is None:
        wave = {k: v for k, v in options.items() if k in wave_keys}
        direct = _run("direct", path, volume, client, rows_per_task, split_every, wave).finish()
    d = np.asarray(direct, dtype=np.float32)
    kw = dict(options, epsilon=float(epsilon), direct=d)
    return _run("indirect", path, volume, client, rows_per_task, split_every, kw).finish()


def matrix(path: Union[str, "os.PathLike[str]"], from_: Any, to: Any, *, client: Any = None,
           rows_per_task: Optional[int] = None, split_every: int = 8, volume: Any = None,
           epsilon: float = 0.1, direct: Optional[np.ndarray] = None,
           **options: Any) -> "vltm.MatrixResult":
    """:func:`vltm.matrix` over a Dask cluster: each task accumulates one factorised column
    per focus of ``from_`` over its rows (state ``16·J·(Ks+1)`` bytes per focus); the
    states add up and the client images the matrix. ``"gamma"`` in ``from_``/``to``: Γ of
    ``volume`` from ``direct`` or else a first round of direct light over the cluster.
    ``options``: the wave options of :func:`vltm.matrix`."""
    sets = [from_, to]
    if any(isinstance(x, str) and x.strip() == "gamma" for x in sets):
        if volume is None:
            raise vltm.ArgumentError("argument `--volume`: `gamma` in --from/--to needs the volume of Γ")
        vol = vltm.Volume(volume)
        if direct is None:
            wave_keys = ("wavelength", "sigma", "weights", "band", "compensate_laser")
            wave = {k: v for k, v in options.items() if k in wave_keys}
            direct = _run("direct", path, vol, client, rows_per_task, split_every, wave).finish()
        g = vltm.gamma_mask(np.asarray(direct, dtype=np.float32).reshape(vol.shape), epsilon)
        pts = np.ascontiguousarray(vol.points[g].reshape(-1, 3), dtype=np.float32)
        if len(pts) == 0:
            raise vltm.ArgumentError(
                "argument `--epsilon`: Γ is empty: no voxel of --volume has direct light above ε·max (all zero)"
            )
        sets = [pts if isinstance(x, str) and x.strip() == "gamma" else x for x in sets]
    frm, dst = (vltm._voxel_set(x, w, None) for x, w in zip(sets, ("--from", "--to")))
    kw = dict(options, from_=frm)
    return _run("matrix", path, dst, client, rows_per_task, split_every, kw).finish()
