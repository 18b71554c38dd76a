"""Captures: :class:`Capture` (a file opened with :func:`open`, arrays with
:meth:`Capture.from_arrays`, a scene rendered by :func:`simulate`), its summed transient, and
the ``capture`` argument of every probe (a path or a :class:`Capture`)."""

from __future__ import annotations

import os
from typing import Any, Dict, Optional, Sequence, Tuple, Union

import numpy as np

from . import _check, _native, _options
from ._errors import ArgumentError, _warn

PathLike = Union[str, os.PathLike[str]]


def _normals(name: str, x: Any, n: int) -> Optional[np.ndarray]:
    """Normals at `n` spots as a contiguous (n, 3) float32 array (None: +z), checked: `n` of
    them, finite, of non-zero length (one-line :class:`ArgumentError` naming `name`)."""
    if x is None:
        return None
    a = _check.array(name, x, dtype=np.float64, finite=False)
    if a.ndim not in (2, 3) or a.shape[-1] != 3 or a.size != 3 * n:
        raise _check.fail(name, f"expected one normal per spot ({n} x 3 values, the points' "
                          f"shape), found shape {list(a.shape)}")
    a = a.reshape(n, 3)
    bad = ~(np.isfinite(a).all(axis=1) & ((a * a).sum(axis=1) > 0))
    if bad.any():
        i = int(np.argmax(bad))
        raise _check.fail(name, f"expected finite normals of non-zero length, found "
                          f"{a[i].tolist()} at index {i}")
    return np.ascontiguousarray(a, dtype=np.float32)


class Capture:
    """A transient NLOS capture: ``H[l][s][t]`` for laser spot l, SPAD spot s, time bin t at
    path length ``t_start + t * delta_t``. Open a file with :func:`open` (its rows are
    streamed from the file by every probe: never shipped, never read whole unless the format
    needs it) or build one from arrays with :meth:`Capture.from_arrays`."""

    def __init__(self, native: Any, path: Optional[str] = None,
                 open_options: Optional[Dict[str, Any]] = None) -> None:
        self._native = native
        self.path = path
        self._open_options = dict(open_options or {})

    @classmethod
    def from_arrays(
        cls,
        H: np.ndarray,
        laser_grid_xyz: Optional[np.ndarray] = None,
        sensor_grid_xyz: Optional[np.ndarray] = None,
        delta_t: Optional[float] = None,
        t_start: float = 0.0,
        laser_xyz: Any = (-0.5, 0.0, 0.25),
        sensor_xyz: Any = (-0.5, 0.0, 0.25),
        t_accounts_first_and_last_bounces: bool = False,
        scan_type: str = "exhaustive",
        laser_origin: Optional[Sequence[float]] = None,
        sensor_origin: Optional[Sequence[float]] = None,
        laser_normals: Optional[np.ndarray] = None,
        sensor_normals: Optional[np.ndarray] = None,
    ) -> "Capture":
        """A capture from y-tal's fields (metres, time first), or a paired scan per histogram.

        ``scan_type="exhaustive"``: ``H`` of shape ``(nt, Lx, Ly, Sx, Sy)`` with grids
        ``(Lx, Ly, 3)`` and ``(Sx, Sy, 3)``, or ``(nt, L, S)`` with point lists ``(L, 3)``,
        ``(S, 3)``. ``scan_type="confocal"``: ``H`` of shape ``(nt, Sx, Sy)`` (or ``(nt, S)``)
        and ``laser_grid_xyz`` = ``sensor_grid_xyz``. ``scan_type="paired"`` (y-tal's paired
        ``T_Si``/``T_Sx_Sy``): as confocal, with a laser grid of the sensor grid's shape, pair
        ``k`` lit at ``laser_grid_xyz[k]``. ``laser_xyz``/``sensor_xyz``: the device
        positions (y-tal's defaults). ``H`` must be real and finite (counts).

        **Paired scans** (a galvo-scanned non-confocal or arbitrary scan; the ``.npz`` reader's
        per-histogram form, same names): no grids, ``H`` of shape ``(K, nt)`` (time last),
        ``laser_xyz`` and ``sensor_xyz`` of shape ``(K, 3)``: histogram ``k`` lit at
        ``laser_xyz[k]`` and seen at ``sensor_xyz[k]`` (equal points make a confocal capture).
        ``laser_origin``/``sensor_origin``: the device positions (default the origin; both
        needed with ``t_accounts_first_and_last_bounces``).

        ``laser_normals``/``sensor_normals`` (optional, any scan): the relay surface's normals
        at the spots, one per laser / SPAD spot (the points' shape: ``(K, 3)`` for a paired
        scan, the grid's ``(X, Y, 3)`` or ``(N, 3)``); default +z. Used by
        ``compensate_laser`` (the laser's falloff ``|cos θ|/d²`` to each spot) and
        ``weights="cos"`` (the wall's cosine per leg, ``direct`` on paired and confocal
        scans); finite and of non-zero length, else an :class:`ArgumentError` naming them."""
        if laser_grid_xyz is None and sensor_grid_xyz is None and np.ndim(laser_xyz) == 2:
            return cls._from_pairs(H, laser_xyz, sensor_xyz, delta_t, t_start,
                                   t_accounts_first_and_last_bounces, laser_origin,
                                   sensor_origin, laser_normals, sensor_normals)
        for name, v in (("laser_grid_xyz", laser_grid_xyz), ("sensor_grid_xyz", sensor_grid_xyz),
                        ("delta_t", delta_t)):
            if v is None:
                raise _check.fail(name, "missing (a paired scan gives `laser_xyz` and "
                                  "`sensor_xyz` of shape (K, 3) instead of the grids)"
                                  if name != "delta_t" else "missing: the bin width in metres")
        for name, v in (("laser_origin", laser_origin), ("sensor_origin", sensor_origin)):
            if v is not None:
                raise _check.fail(name, "only for paired scans (`laser_xyz`, `sensor_xyz` "
                                  "of shape (K, 3)); grid scans take the device positions "
                                  "as `laser_xyz`, `sensor_xyz`")
        lg = _check.array("laser_grid_xyz", laser_grid_xyz, last=3, ndim=(2, 3))
        sg = _check.array("sensor_grid_xyz", sensor_grid_xyz, last=3, ndim=(2, 3))
        # What this call holds at once besides the caller's H, checked against the memory
        # budget before any of it is made: H as float32 (a copy unless it is one already),
        # its rows with time last, and the library's capture.
        raw = np.asarray(H)
        n = int(raw.size)
        conv = 4 * n if not (raw.dtype == np.float32 and raw.flags.c_contiguous) else 0
        _native.check_memory(f"a capture from arrays of {n} samples", [
            ("H as float32", conv), ("the finiteness mask of H", n),
            ("H's rows with time last (float32)", 4 * n), ("the library's capture (float32)", 4 * n)])
        H = _check.array("H", raw, ndim=(2, 3, 4, 5))
        dt = _check.real("delta_t", delta_t)
        if dt <= 0:  # type: ignore[operator]
            raise _check.fail("delta_t", f"expected a bin width > 0 in metres, found {dt}")
        t0 = _check.real("t_start", t_start)
        lx = _check.point("laser_xyz", laser_xyz)
        sx = _check.point("sensor_xyz", sensor_xyz)
        legs = _check.flag("t_accounts_first_and_last_bounces", t_accounts_first_and_last_bounces)
        _check.text("scan_type", scan_type)

        def grid_shape(g: np.ndarray) -> Tuple[int, int]:
            return (g.shape[0], g.shape[1]) if g.ndim == 3 else (g.shape[0], 1)

        ls, ss = grid_shape(lg), grid_shape(sg)
        nl, ns = ls[0] * ls[1], ss[0] * ss[1]
        confocal = scan_type in ("confocal", "paired")
        if scan_type not in ("exhaustive", "confocal", "paired"):
            raise ArgumentError(
                f"argument `scan_type`: expected exhaustive, confocal or paired, found `{scan_type}`"
            )
        if scan_type == "paired" and lg.shape != sg.shape:
            raise _check.fail("sensor_grid_xyz", f"expected one SPAD point per laser point "
                              f"(laser_grid_xyz has shape {lg.shape}), found shape {sg.shape}")
        nt = H.shape[0]
        per = ns if not confocal else 1
        rows = nl if not confocal else ns
        if H.size != nt * rows * per:
            raise ArgumentError(
                f"argument `H`: expected {nt} x {rows} x {per} values for these grids, found shape {H.shape}"
            )
        h = np.ascontiguousarray(np.moveaxis(H.reshape(nt, rows, per), 0, -1), dtype=np.float32)
        if scan_type == "confocal":
            lg, ls = sg, ss
            if laser_normals is None:
                laser_normals = sensor_normals
        ln = _normals("laser_normals", laser_normals, len(lg.reshape(-1, 3)))
        sn = _normals("sensor_normals", sensor_normals, len(sg.reshape(-1, 3)))
        native = _native.capture_from_arrays(
            h, np.ascontiguousarray(lg.reshape(-1, 3)), ls,
            np.ascontiguousarray(sg.reshape(-1, 3)), ss, dt, t0,
            list(lx), list(sx), legs, confocal, ln, sn,
        )
        return cls(native)

    @classmethod
    def _from_pairs(cls, H: Any, laser_xyz: Any, sensor_xyz: Any, delta_t: Any, t_start: Any,
                    legs: Any, laser_origin: Any, sensor_origin: Any,
                    laser_normals: Any = None, sensor_normals: Any = None) -> "Capture":
        """A paired scan per histogram (:meth:`from_arrays`); the ``.npz`` reader's checks
        and wording."""
        if delta_t is None:
            raise _check.fail("delta_t", "missing: the bin width in metres")

        def pts(name: str, x: Any) -> np.ndarray:
            a = _check.array(name, x, dtype=np.float64, finite=False)
            if a.ndim != 2 or a.shape[1] != 3:
                raise _check.fail(name, f"expected shape (K, 3): one point per histogram, "
                                  f"found {list(a.shape)}")
            bad = ~np.isfinite(a).all(axis=1)
            if bad.any():
                i = int(np.argmax(bad))
                p = ", ".join("NaN" if c != c else repr(float(c)) for c in a[i])
                raise _check.fail(name, f"expected finite coordinates, found [{p}] at index {i}")
            return a

        lp = pts("laser_xyz", laser_xyz)
        sp = pts("sensor_xyz", sensor_xyz)
        if len(sp) != len(lp):
            raise _check.fail("sensor_xyz", f"expected one SPAD point per laser point "
                              f"(laser_xyz has {len(lp)}), found {len(sp)} points")
        raw = np.asarray(H)
        n = int(raw.size)
        _native.check_memory(f"a capture from arrays of {n} samples", [
            ("H as float32", 4 * n), ("the finiteness mask of H", n),
            ("the library's capture (float32)", 4 * n)])
        h = _check.array("H", raw)
        if h.ndim != 2 or h.shape[0] != len(lp):
            raise _check.fail("H", f"expected shape ({len(lp)}, Nt): one histogram per pair, "
                              f"found {list(h.shape)}")
        dt = _check.real("delta_t", delta_t)
        if dt <= 0:  # type: ignore[operator]
            raise _check.fail("delta_t", f"expected a bin width > 0 in metres, found {dt}")
        t0 = _check.real("t_start", t_start)
        legs = _check.flag("t_accounts_first_and_last_bounces", legs)
        if legs and (laser_origin is None or sensor_origin is None):
            raise _check.fail("t_accounts_first_and_last_bounces",
                              "expected laser_origin and sensor_origin (the device legs need "
                              "the device positions), found True without them")
        lo = (0.0, 0.0, 0.0) if laser_origin is None else _check.point("laser_origin", laser_origin)
        so = (0.0, 0.0, 0.0) if sensor_origin is None else _check.point("sensor_origin", sensor_origin)
        k = len(lp)
        ln = _normals("laser_normals", laser_normals, k)
        sn = _normals("sensor_normals", sensor_normals, k)
        native = _native.capture_from_arrays(
            h.reshape(k, 1, -1), lp.astype(np.float32), (k, 1), sp.astype(np.float32), (k, 1),
            dt, t0, list(lo), list(so), legs, True, ln, sn)
        return cls(native)

    def info(self) -> dict:
        """Dimensions, geometry and time axis: ``lasers``, ``spads``, ``nt``, ``delta_t``,
        ``t_start``, shapes, device positions, ``default_wavelength``… ``scan`` names the
        scan as ``vltm info`` does: ``"confocal"`` (laser and SPAD at the same wall point),
        ``"paired"`` (one laser and one SPAD spot per histogram, apart) or
        ``"non-confocal"`` (a laser grid × a SPAD grid); ``confocal`` is true for the first
        only, ``paired`` (one histogram per row) for the first two. ``normals`` is ``"+z"``
        (none given, or all +z) or ``"per point"``; ``relay`` is ``"planar"`` or says why
        not (a z span, tilted normals)."""
        return self._native.info()

    @_options.documented(_options.PREP)
    def transient(self, *, t_min: Any = None, t_max: Any = None, rebin: int = 1,
                  background: Any = None, report: bool = False,
                  as_xarray: bool = False) -> Any:
        """The summed transient (``vltm info --png``'s curve): every histogram summed bin by
        bin (non-finite samples skipped), float64 ``(nt,)``, after the preprocessing
        (below; ``background="auto"`` uses the last tenth of the window, as ``vltm info``).
        ``report=True`` also returns a dict with the path axis ``t`` (m), ``t_start``,
        ``delta_t`` and the preprocessing summary; ``as_xarray=True`` a ``DataArray`` over
        ``t``."""
        report = _check.flag("report", report)
        as_xarray = _check.flag("as_xarray", as_xarray)
        counts, t0, dt, summary, warning = self._native.transient(
            **_options.checked(locals(), _options.PREP))
        _warn(warning)
        t = t0 + dt * np.arange(len(counts))
        rep = {"t": t, "t_start": t0, "delta_t": dt, "preprocessing": summary}
        if as_xarray:
            from . import _xarray

            a = _xarray.xr().DataArray(counts, dims=["t"], coords={"t": t}, name="counts",
                                       attrs=_xarray.clean_attrs({
                                           "t_start": t0, "delta_t": dt,
                                           "preprocessing": summary, "capture": self.path}))
            a["t"].attrs["units"] = "m"
            return a
        return (counts, rep) if report else counts

    def save(self, path: PathLike, *, uncompressed: bool = False,
             ptu: Optional[PathLike] = None) -> None:
        """Writes the capture as a vltm ``.npz`` (compressed unless ``uncompressed``), and
        with ``ptu`` also as a synthetic PicoQuant T3 stream with its ``.json`` sidecar (as
        ``vltm simulate --out F.npz --ptu F.ptu``); all files or none."""
        self._native.save(os.fspath(path), _check.flag("uncompressed", uncompressed),
                          None if ptu is None else os.fspath(ptu))

    @property
    def laser_points(self) -> np.ndarray:
        """Laser spots on the wall, float32 ``(lasers, 3)``."""
        return self._native.laser_points().reshape(-1, 3)

    @property
    def spad_points(self) -> np.ndarray:
        """SPAD spots on the wall, float32 ``(spads, 3)``."""
        return self._native.spad_points().reshape(-1, 3)

    def __repr__(self) -> str:
        i = self.info()
        return f"vltm.Capture({i['path']!r}: {i['lasers']} lasers x {i['spads_per_row']} SPADs x {i['nt']} bins)"


def open(path: PathLike, *, delta_t: Optional[float] = None,  # noqa: A001 - `io::open`
         t_start: Optional[float] = None, grid_width: Optional[float] = None) -> Capture:
    """Opens a capture file: vltm ``.npz``, y-tal ``HDF5_TAL`` / Z-NLOS (``.hdf5``/``.h5``),
    PicoQuant ``.ptu`` (with its ``.json`` sidecar), MATLAB ``.mat``… Reads the geometry only
    (a ``.mat`` file is read into memory once). ``delta_t`` (bin width, m), ``t_start``
    (path of bin 0, m) and ``grid_width`` (half-width of a confocal grid, m) override a
    ``.mat`` file's conventions, as ``--delta-t``, ``--t-start``, ``--grid-width``."""
    if isinstance(path, Capture):
        return path
    if not isinstance(path, (str, os.PathLike)):
        raise _check.fail("capture", f"expected a path or a vltm.Capture, found {type(path).__name__}")
    p = os.fspath(path)
    kw = {"delta_t": _check.real("delta_t", delta_t, none=True),
          "t_start": _check.real("t_start", t_start, none=True),
          "grid_width": _check.real("grid_width", grid_width, none=True)}
    return Capture(_native.open_capture(p, **kw), p, {k: v for k, v in kw.items() if v is not None})


def simulate(scene: PathLike, out: Optional[PathLike] = None, *,
             ptu: Optional[PathLike] = None, uncompressed: bool = False) -> Capture:
    """Renders a synthetic capture from a scene file (JSON, as ``vltm simulate``), in
    memory; with ``out`` also writes it (``.npz``, and ``ptu``: a PicoQuant T3 stream, see
    :meth:`Capture.save`)."""
    c = Capture(_native.simulate(os.fspath(scene)))
    if out is not None:
        c.save(out, uncompressed=uncompressed, ptu=ptu)
    elif ptu is not None:
        raise _check.fail("ptu", "the PTU stream is written beside the capture: give out= too")
    return c


def _capture(capture: Any) -> Capture:
    if isinstance(capture, Capture):
        return capture
    return open(capture)
