"""Scale-out over a Dask cluster: a scan split by laser rows into tasks.

Each task opens the capture file itself (workers read it from shared storage: the capture is
never shipped through the scheduler), streams its rows through the probe and returns the
partial state as bytes; the states are reduced by addition in a tree (``split_every`` parts
per merge) and the root is finished on the client. The volumes are the same, bit for bit,
as one process computes.

>>> from distributed import Client, LocalCluster
>>> import vltm
>>> with LocalCluster(n_workers=2, threads_per_worker=1) as cluster, Client(cluster) as client:
...     I = vltm.dask.direct("scan.npz", "-0.75:0.75:32,-0.75:0.75:32,0.4:1.4:24", client=client)

Every keyword of the in-process function (:func:`vltm.direct`, :func:`vltm.column`,
:func:`vltm.indirect`, :func:`vltm.relight`, :func:`vltm.row`, :func:`vltm.matrix`) passes
through unchanged and is checked on the client before any task starts. Options a row split
cannot carry — the preprocessing (``t_min``, ``t_max``, ``rebin``, ``background``), the
un-gated and higher-order diagonals, ``shells``, ``mask_epsilon``, a column's leak
correction (on by default, as ``vltm column``: its Γ needs the whole capture; pass
``leak_correct=False`` to split a column), ``leak_correct="model"`` and ``"auto"`` (the
surface model is fitted to the whole capture, and auto decides on the whole capture), a
non-two-bounce indirect gate, and
``relight``/``row`` (no partial states) — run as **one task** on a worker over the whole
capture.

Cost per task: its rows' share of the one-pass time plus opening the file; per merge: one
addition per f64 of state (see ``Partial.nbytes``) plus (de)serialisation.
"""

from __future__ import annotations

import inspect
import math
import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

import vltm

__all__ = ["column", "direct", "indirect", "matrix", "relight", "row", "row_ranges"]

CaptureArg = Union[str, "os.PathLike[str]", "vltm.Capture"]


def row_ranges(n_rows: int, rows_per_task: int) -> List[Tuple[int, int]]:
    """The tasks' row ranges ``[a, b)`` covering ``0..n_rows``."""
    k = max(1, int(rows_per_task))
    return [(a, min(a + k, n_rows)) for a in range(0, n_rows, k)]


def _volume_arg(volume: Any) -> Union[str, np.ndarray]:
    """What a task gets for the volume: its SPEC (a few bytes) or its points."""
    v = vltm._volume(volume)
    return v.spec if v.spec is not None else v.points


def _source(capture: Any) -> Tuple[str, Dict[str, Any]]:
    """The file a task opens and the options it opens it with."""
    if isinstance(capture, vltm.Capture):
        if capture.path is None:
            raise vltm.ArgumentError(
                "argument `capture`: vltm.dask needs a capture file the workers can open (a path), not arrays"
            )
        return capture.path, dict(capture._open_options)
    if not isinstance(capture, (str, os.PathLike)):
        raise vltm.ArgumentError(
            f"argument `capture`: expected a path or a vltm.Capture opened from a file, found {type(capture).__name__}"
        )
    return os.fspath(capture), {}


def _open(src: Tuple[str, Dict[str, Any]]) -> "vltm.Capture":
    return vltm.open(src[0], **src[1])


def _part(src: Tuple[str, Dict[str, Any]], volume: Any, kind: str, a: int, b: int,
          kw: dict) -> bytes:
    """One task: opens the file, streams rows a..b, returns the state as bytes."""
    cap = _open(src)
    if kind == "matrix":
        return vltm.matrix(cap, kw["from_"], volume, rows=slice(a, b),
                           **{k: v for k, v in kw.items() if k != "from_"}).to_bytes()
    fn = {"direct": vltm.direct, "column": vltm.column, "indirect": vltm.indirect}[kind]
    return fn(cap, volume, rows=slice(a, b), **kw).to_bytes()


def _whole(src: Tuple[str, Dict[str, Any]], kind: str, args: tuple, kw: dict) -> Any:
    """One task over the whole capture (options a row split cannot carry)."""
    fn = {"direct": vltm.direct, "column": vltm.column, "indirect": vltm.indirect,
          "relight": vltm.relight, "row": vltm.row}[kind]
    return fn(_open(src), *args, **kw)


def _merge(parts: Sequence[bytes]) -> bytes:
    """One reduction step: the sum of some states, as bytes."""
    return vltm._native.merge_bytes([bytes(p) for p in parts])


def _client(client: Any) -> Any:
    if client is not None:
        return client
    from distributed import get_client

    return get_client()


def _check(fn: Any, args: tuple, kw: dict) -> None:
    """The in-process function's own check of the keywords (unknown ones name themselves)."""
    if "rows" in kw:
        raise vltm.ArgumentError("argument `rows`: vltm.dask splits the rows itself (rows_per_task)")
    try:
        inspect.signature(fn).bind(None, *args, **kw)
    except TypeError as e:
        raise vltm.ArgumentError(f"argument `{_unknown(e)}`: {e}") from None


def _unknown(e: TypeError) -> str:
    msg = str(e)
    if "'" in msg:
        return msg.split("'")[1]
    return "options"


def _run(kind: str, src: Tuple[str, Dict[str, Any]], volume: Any, client: Any,
         rows_per_task: Optional[int], split_every: int, kw: dict) -> "vltm.Partial":
    import dask

    client = _client(client)
    info = _open(src).info()
    n = info["spads" if kw.get("swap_roles") else "lasers"]
    if rows_per_task is None:
        workers = max(1, len(client.scheduler_info().get("workers", {})))
        rows_per_task = math.ceil(n / (2 * workers))
    vol = volume if kind == "matrix" else _volume_arg(volume)
    part = dask.delayed(_part, pure=True)
    merge = dask.delayed(_merge, pure=True)
    token = dask.base.tokenize(src, vol, kw)
    layer = [part(src, vol, kind, a, b, kw, dask_key_name=f"vltm-{kind}-rows-{a}-{b}-{token}")
             for a, b in row_ranges(n, rows_per_task)]
    k = max(2, int(split_every))
    while len(layer) > 1:
        layer = [merge(layer[i:i + k]) for i in range(0, len(layer), k)]
    state = client.compute(layer[0]).result()
    p = vltm.Partial.from_bytes(state)
    if kind != "matrix":
        v = vltm._volume(volume)
        p._shape, p._volume = v.shape, v
    return p


def _one_task(kind: str, src: Tuple[str, Dict[str, Any]], args: tuple, client: Any,
              kw: dict) -> Any:
    return _client(client).submit(_whole, src, kind, args, kw, pure=False).result()


_PREP = ("t_min", "t_max", "background")


def _splits(kw: dict, extra: Sequence[str] = ()) -> bool:
    """Whether a run with these options can be split into row ranges."""
    if any(kw.get(k) is not None for k in _PREP + tuple(extra)):
        return False
    return kw.get("rebin", 1) == 1


def _finish(p: "vltm.Partial", kw: dict, attrs: Dict[str, Any]) -> Any:
    p._attrs = attrs
    return p.finish(amplitudes=kw.get("amplitudes", False), report=kw.get("report", False),
                    as_xarray=kw.get("as_xarray", False))


def _split_kw(kw: dict) -> dict:
    return {k: v for k, v in kw.items() if k not in ("amplitudes", "report", "as_xarray")}


def direct(capture: CaptureArg, volume: Any, *, client: Any = None,
           rows_per_task: Optional[int] = None, split_every: int = 8, **options: Any) -> Any:
    """:func:`vltm.direct` over a Dask cluster: ``rows_per_task`` laser rows per task
    (default: two tasks per worker), states reduced ``split_every`` at a time. ``client``: a
    ``distributed.Client`` (default: the current one). ``capture``: a path the workers can
    open, or a :class:`vltm.Capture` opened from one. ``options``: those of
    :func:`vltm.direct`, unchanged (``gate``, ``wavelength``, ``path``, ``as_xarray``…)."""
    _check(vltm.direct, (volume,), options)
    src = _source(capture)
    if not _splits(options) or options.get("gate", "gaussian") != "gaussian":
        return _one_task("direct", src, (volume,), client, options)
    p = _run("direct", src, volume, client, rows_per_task, split_every, _split_kw(options))
    return _finish(p, options, {"gate": options.get("gate", "gaussian"), "capture": src[0]})


def column(capture: CaptureArg, volume: Any, focus: Sequence[float], *, client: Any = None,
           rows_per_task: Optional[int] = None, split_every: int = 8, **options: Any) -> Any:
    """:func:`vltm.column` over a Dask cluster (arguments as :func:`direct`)."""
    _check(vltm.column, (volume, focus), options)
    src = _source(capture)
    if not _splits(options, ("shells", "mask_epsilon")) or options.get("leak_correct", True):
        return _one_task("column", src, (volume, focus), client, options)
    f = list(vltm._check.point("focus", focus))
    kw = dict(_split_kw(options), focus=f)
    p = _run("column", src, volume, client, rows_per_task, split_every, kw)
    return _finish(p, options, {"gate": options.get("gate", "two-bounce"), "capture": src[0],
                                "shell": options.get("shell")})


def indirect(capture: CaptureArg, volume: Any, *, client: Any = None,
             rows_per_task: Optional[int] = None, split_every: int = 8,
             **options: Any) -> Any:
    """:func:`vltm.indirect` over a Dask cluster: round 1 the direct light (unless
    ``direct`` is given) to find Γ, round 2 the Γ columns; two passes over the rows, each
    split into tasks. ``leak_correct`` (default True, as :func:`vltm.indirect`): every task
    zeroes the direct-return windows of Γ in its own rows (the gate needs only Γ and the
    geometry), and the removed energy adds up over the tasks; ``leak_correct="model"`` and
    ``"auto"`` run as one task (the surface model is fitted to, and auto decides on, the
    whole capture)."""
    _check(vltm.indirect, (volume,), options)
    src = _source(capture)
    if (not _splits(options, ("shells",)) or options.get("gate", "two-bounce") != "two-bounce"
            or options.get("leak_correct") in ("model", "auto")):
        # The surface model is fitted to (and auto decides on) the whole capture: one task.
        return _one_task("indirect", src, (volume,), client, options)
    wave_keys = ("wavelength", "sigma", "weights", "band", "compensate_laser", "crop", "path",
                 "swap_roles")
    direct_ = options.get("direct")
    if direct_ is None:
        wave = {k: v for k, v in options.items() if k in wave_keys}
        direct_ = _run("direct", src, volume, client, rows_per_task, split_every, wave).finish()
    eps = vltm._check.real("epsilon", options.get("epsilon", 0.1))
    d = vltm._check.array("direct", direct_)
    if options.get("report"):
        # Γ and I_d beside I_i, as the in-process report has them.
        g = vltm.gamma_mask(d, eps)
    kw = dict(_split_kw(options), epsilon=eps, direct=d)
    p = _run("indirect", src, volume, client, rows_per_task, split_every, kw)
    out = _finish(p, options, {"gate": "two-bounce", "epsilon": eps, "capture": src[0],
                               "leak_correct": options.get("leak_correct", True)})
    if options.get("report"):
        out[-1]["gamma"] = g.reshape(vltm._volume(volume).shape)
        out[-1]["direct"] = d.reshape(vltm._volume(volume).shape)
    return out


def relight(capture: CaptureArg, volume: Any, pattern: Any, *, client: Any = None,
            **options: Any) -> Any:
    """:func:`vltm.relight` on a Dask worker (one task: relighting has no partial
    states)."""
    _check(vltm.relight, (volume, pattern), options)
    return _one_task("relight", _source(capture), (volume, pattern), client, options)


def row(capture: CaptureArg, volume: Any, focus: Sequence[float], *, client: Any = None,
        **options: Any) -> Any:
    """:func:`vltm.row` on a Dask worker (one task: a row has no partial states)."""
    _check(vltm.row, (volume, focus), options)
    return _one_task("row", _source(capture), (volume, focus), client, options)


def matrix(capture: CaptureArg, from_: Any, to: Any, *, client: Any = None,
           rows_per_task: Optional[int] = None, split_every: int = 8,
           **options: Any) -> "vltm.MatrixResult":
    """:func:`vltm.matrix` over a Dask cluster: each task accumulates one factorised column
    per focus of ``from_`` over its rows (state ``16·J·(Ks+1)`` bytes per focus); the
    states add up and the client images the matrix. ``"gamma"`` in ``from_``/``to``: Γ of
    ``volume`` from ``direct`` or else a first round of direct light over the cluster.
    ``options``: those of :func:`vltm.matrix`, unchanged."""
    _check(vltm.matrix, (from_, to), options)
    src = _source(capture)
    volume = options.pop("volume", None)
    epsilon = options.pop("epsilon", 0.1)
    direct_ = options.pop("direct", None)
    sets = [from_, to]
    if any(isinstance(x, str) and x.strip() == "gamma" for x in sets):
        if volume is None:
            raise vltm.ArgumentError("argument `volume`: `gamma` in from_/to needs the volume of Γ")
        vol = vltm._volume(volume)
        if direct_ is None:
            wave_keys = ("wavelength", "sigma", "weights", "band", "compensate_laser", "crop")
            wave = {k: v for k, v in options.items() if k in wave_keys}
            direct_ = _run("direct", src, vol, client, rows_per_task, split_every, wave).finish()
        g = vltm.gamma_mask(np.asarray(direct_, dtype=np.float32).reshape(vol.shape), epsilon)
        pts = np.ascontiguousarray(vol.points[g].reshape(-1, 3), dtype=np.float32)
        if len(pts) == 0:
            raise vltm.ArgumentError(
                "argument `epsilon`: Γ is empty: no voxel of volume has direct light above ε·max (all zero)"
            )
        sets = [pts if isinstance(x, str) and x.strip() == "gamma" else x for x in sets]
    frm, dst = (vltm._voxel_set(x, w, None) for x, w in zip(sets, ("from_", "to")))
    kw = dict(options, from_=frm)
    return _run("matrix", src, dst, client, rows_per_task, split_every, kw).finish()
