"""vltm: virtual light transport matrices of hidden scenes from NLOS captures
(Marco et al., ICCV 2021), with NumPy in and out.

The relay wall is the plane z = 0, the hidden scene is at z > 0, all lengths are metres of
optical path.

>>> import vltm
>>> cap = vltm.open("two_patches.hdf5")                 # any format vltm reads
>>> vol = vltm.volume("-0.75:0.75:16,-0.75:0.75:16,0.4:1.35:20")
>>> I = vltm.direct(cap, vol)                           # float32 (16, 16, 20)
>>> C = vltm.column(cap, vol, focus=(-0.25, 0.15, 0.7))
>>> Ii = vltm.indirect(cap, vol)                         # leak-corrected, as `vltm indirect`
>>> M = vltm.matrix(cap, from_="gamma", to="gamma", volume=vol)  # M.amplitudes: (n_from, n_to)
>>> R = vltm.relight(cap, vol, pattern="-0.25,0.15,0.7,1;0.25,0,0.9,0.5")
>>> Rb = vltm.row(cap, vol, focus=(0.25, 0.0, 0.9))     # T(., x_b)
>>> part = vltm.direct(cap, vol, rows=slice(0, 32))     # a Partial (accumulator state)
>>> rest = vltm.direct(cap, vol, rows=slice(32, 64))
>>> vltm.merge([part, rest]).finish()                   # == vltm.direct(cap, vol)
>>> vltm.direct(cap, vol, as_xarray=True)               # xarray.DataArray over x, y, z (m)

Every probe releases the GIL while it runs. Errors are :class:`VltmError` subclasses
(:class:`ArgumentError` is a ``ValueError``, :class:`DataError` an ``OSError``) carrying the
command line's one-line messages, naming keyword arguments (``t_min``) where the command
line names flags (``--t-min``). Scale-out over a Dask cluster: :mod:`vltm.dask` (imported
on first use; needs ``dask`` and ``distributed``).
"""

from __future__ import annotations

import builtins
import importlib
import os
from typing import Any, Dict, Iterable, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from . import _check, _native
from ._errors import ArgumentError, DataError, VltmError

__version__: str = _native.__version__

__all__ = [
    "ArgumentError",
    "Capture",
    "DataError",
    "MatrixResult",
    "Partial",
    "VltmError",
    "Volume",
    "column",
    "demo",
    "direct",
    "gamma_mask",
    "indirect",
    "info",
    "matrix",
    "max_memory",
    "merge",
    "open",
    "relight",
    "row",
    "set_max_memory",
    "set_threads",
    "simulate",
    "volume",
]

PathLike = Union[str, "os.PathLike[str]"]


def __getattr__(name: str) -> Any:
    """``vltm.dask`` on first use (Dask stays optional)."""
    if name == "dask":
        return importlib.import_module(".dask", __name__)
    raise AttributeError(f"module 'vltm' has no attribute {name!r}")


class Volume:
    """A set of voxels: a grid from a SPEC ``"x0:x1:nx,y0:y1:ny,z0:z1:nz"`` (metres,
    inclusive end points), a point list ``"x,y,z;x,y,z"``, or an ``(..., 3)`` array of points.
    Results come back shaped like the volume: ``(nx, ny, nz)`` for a grid, the array's
    leading shape for points."""

    def __init__(self, spec: Union[str, np.ndarray, "Volume"], name: str = "volume") -> None:
        if isinstance(spec, Volume):
            self._native, self.shape, self.is_grid = spec._native, spec.shape, spec.is_grid
            return
        if isinstance(spec, str):
            self._native = _native.volume_from_spec(spec)
            self.is_grid: bool = bool(self._native.is_grid)
            self.shape: Tuple[int, ...] = (
                tuple(self._native.shape) if self._native.is_grid else (len(self._native),)
            )
            return
        pts = _check.array(name, spec, last=3)
        self._native = _native.volume_from_points(np.ascontiguousarray(pts.reshape(-1, 3)))
        self.shape = tuple(pts.shape[:-1])
        self.is_grid = False

    @property
    def spec(self) -> Optional[str]:
        """The SPEC the volume was parsed from (None for an array of points)."""
        return self._native.spec

    @property
    def points(self) -> np.ndarray:
        """Voxel centres, float32 of shape ``self.shape + (3,)``."""
        return self._native.flat_points().reshape(self.shape + (3,))

    def __len__(self) -> int:
        return len(self._native)

    def __repr__(self) -> str:
        return f"vltm.Volume({self.spec!r})" if self.spec else f"vltm.Volume(<{len(self)} points>)"

    def __reduce__(self) -> Any:
        return (Volume, (self.spec if self.spec is not None else self.points,))


def volume(spec: Union[str, np.ndarray, Volume]) -> Volume:
    """A :class:`Volume` from a SPEC string or an ``(..., 3)`` array of points (metres)."""
    return Volume(spec)


def _volume(v: Any, name: str = "volume") -> Volume:
    if not isinstance(v, (str, Volume, np.ndarray, list, tuple)):
        raise _check.fail(name, f"expected a SPEC string, a vltm.Volume or an (..., 3) array of points, found {type(v).__name__}")
    return Volume(v, name)


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

    def transient(self, *, t_min: Any = None, t_max: Any = None, rebin: int = 1,
                  background: Any = None, report: bool = False,
                  as_xarray: bool = False) -> Any:
        """The summed transient (``vltm info --png``'s curve): every histogram summed bin by
        bin (non-finite samples skipped), float64 ``(nt,)``, after the preprocessing
        (``t_min``, ``t_max``, ``rebin``, ``background`` as :func:`direct`; ``auto`` uses
        the last tenth of the window, as ``vltm info``). ``report=True`` also returns a dict
        with the path axis ``t`` (m), ``t_start``, ``delta_t`` and the preprocessing summary;
        ``as_xarray=True`` a ``DataArray`` over ``t``."""
        report = _check.flag("report", report)
        as_xarray = _check.flag("as_xarray", as_xarray)
        counts, t0, dt, summary, warning = self._native.transient(
            t_min=_check.time_bound("t_min", t_min), t_max=_check.time_bound("t_max", t_max),
            rebin=_check.integer("rebin", rebin), background=_check.background(background))
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


class Text(str):
    """Text the command line prints (:func:`info`, :func:`demo`): a ``str`` that a REPL or
    notebook shows as its lines rather than as a quoted string."""

    def __repr__(self) -> str:
        return str(self)


def info(capture: Union[Capture, PathLike], *, delta_t: Optional[float] = None,
         t_start: Optional[float] = None, grid_width: Optional[float] = None,
         t_min: Any = None, t_max: Any = None, rebin: int = 1, background: Any = None,
         png: Optional[PathLike] = None, volume: Any = None) -> Text:
    """The layout text of ``vltm info CAPTURE``, line for line: format, scan, laser and SPAD
    spots, device positions, time axis, counts, default λ, the memory budget and where it
    comes from, and the summed transient (after the preprocessing ``t_min``, ``t_max``,
    ``rebin``, ``background``, as :func:`direct`). ``delta_t``, ``t_start``, ``grid_width``
    override a ``.mat`` file's conventions (as :func:`open`); ``png`` also draws the summed
    transient there (``--png``); ``volume`` (a SPEC string or a grid :class:`Volume`, as
    ``--volume``) is named in the ``fast paths`` line: the path it takes, or the aligned grid
    that is fast. Warnings (the background emptied most histograms) come as
    ``RuntimeWarning`` (the command line writes them to stderr).

    ``capture``: a file path, or a :class:`Capture` opened from one (its ``.mat`` options
    are used). Returns a :class:`Text` (a ``str``) of newline-separated lines; for the same
    facts as a dict see :meth:`Capture.info`."""
    opts: Dict[str, Any] = {}
    if isinstance(capture, Capture):
        if capture.path is None:
            raise _check.fail("capture", "info describes a capture file: this one was made from arrays (use Capture.info())")
        p, opts = capture.path, dict(capture._open_options)
    elif isinstance(capture, (str, os.PathLike)):
        p = os.fspath(capture)
    else:
        raise _check.fail("capture", f"expected a path or a vltm.Capture, found {type(capture).__name__}")
    for k, v in (("delta_t", delta_t), ("t_start", t_start), ("grid_width", grid_width)):
        if v is not None:
            opts[k] = _check.real(k, v)
    if isinstance(volume, Volume):
        if volume.spec is None:
            raise _check.fail("volume", "info names the path of a grid: give its SPEC, not points")
        volume = volume.spec
    elif volume is not None and not isinstance(volume, str):
        raise _check.fail("volume", f"expected a SPEC string or a vltm.Volume, found {type(volume).__name__}")
    lines, warnings, _counts, _t0, _dt = _native.info_text(
        p, **opts, t_min=_check.time_bound("t_min", t_min),
        t_max=_check.time_bound("t_max", t_max), rebin=_check.integer("rebin", rebin),
        background=_check.background(background),
        png=None if png is None else os.fspath(png), volume=volume)
    for w in warnings:
        _warn(w)
    return Text("\n".join(lines) + "\n")


def demo(out: PathLike = "vltm-demo") -> Text:
    """The built-in demo (``vltm demo``), no input files: a scene like the paper's Fig. 5 (a
    panel lighting a figure beside it, a box as distractor) is rendered with all light paths
    and with direct light only, every probe runs on both, and ``out`` (created if needed)
    receives each result's figure (``<result>.png``), volume (``<result>.npy``) and
    ``summary.txt``. Returns the summary table (a :class:`Text`), the lines ``vltm demo``
    prints. About a minute on two cores."""
    if not isinstance(out, (str, os.PathLike)):
        raise _check.fail("out", f"expected a directory path, found {type(out).__name__}")
    return Text(_native.demo(os.fspath(out)))


class Partial:
    """The accumulator state of a probe over some laser rows (``rows=slice(a, b)``).
    Pickles (as vltm's binary partial format, the bytes ``--partial`` writes), merges by
    addition (:func:`merge`) and finishes into the probe's volume once its rows cover the
    scan."""

    def __init__(self, native: Any) -> None:
        self._native = native

    @classmethod
    def from_bytes(cls, data: bytes) -> "Partial":
        """Reads a state from bytes (:meth:`to_bytes`, or a ``--partial`` file's content)."""
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise _check.fail("data", f"expected bytes, found {type(data).__name__}")
        return cls(_native.partial_from_bytes(bytes(data)))

    @classmethod
    def read(cls, path: PathLike) -> "Partial":
        """Reads a ``--partial`` file."""
        with builtins.open(os.fspath(path), "rb") as f:
            return cls.from_bytes(f.read())

    def to_bytes(self) -> bytes:
        """The state in vltm's binary partial format."""
        return self._native.to_bytes()

    def write(self, path: PathLike) -> None:
        """Writes the state to a file (readable by ``vltm merge``)."""
        tmp = os.fspath(path) + ".tmp"
        with builtins.open(tmp, "wb") as f:
            f.write(self.to_bytes())
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, os.fspath(path))

    @property
    def rows(self) -> list:
        """Row ranges held, as ``range`` objects."""
        return [range(a, b) for a, b in self._native.rows()]

    @property
    def total_rows(self) -> int:
        """Laser rows of the whole scan."""
        return self._native.total_rows()

    @property
    def kind(self) -> str:
        """``direct``, ``column``, ``indirect`` or ``matrix``."""
        return self._native.kind()

    @property
    def complete(self) -> bool:
        """Whether the rows cover the scan (the state can be finished)."""
        return self._native.is_complete()

    @property
    def nbytes(self) -> int:
        """Size of the serialised state (bytes)."""
        return self._native.nbytes()

    def merge(self, *others: "Partial") -> "Partial":
        """This state plus others (see :func:`merge`)."""
        return merge([self, *others])

    def finish(self, amplitudes: bool = False, report: bool = False,
               as_xarray: bool = False) -> Any:
        """The probe's volume (float32, shaped like the volume). With ``amplitudes=True``
        also the complex amplitudes ``A`` (``T = |A|²``; direct light, two-bounce and
        higher-order columns), with ``report=True`` also the counters dict, with
        ``as_xarray=True`` an ``xarray.DataArray`` (see :func:`direct`). A ``matrix`` state
        finishes into a :class:`MatrixResult` (``amplitudes``/``report`` ignored)."""
        amplitudes = _check.flag("amplitudes", amplitudes)
        if self.kind == "matrix":
            return _matrix_result(*self._native.finish())
        values, amps, shape, rep, pts, grid = self._native.finish(amplitudes=amplitudes)
        shape = _out_shape(shape, self._shape)
        labels = None
        if as_xarray:
            vol = self._volume if self._volume is not None else _Voxels(
                pts.reshape(tuple(shape) + (3,)), grid)
            attrs = dict(self._attrs or {}, probe=self.kind)
            f = self._native.focus()
            if f is not None:
                attrs["focus"] = list(f)
            labels = (vol, attrs)
        return _shape_out(values, amps, rep, shape, amplitudes, report, labels)

    _shape: Optional[Tuple[int, ...]] = None
    _volume: Optional[Volume] = None
    _attrs: Optional[Dict[str, Any]] = None

    def __reduce__(self) -> Any:
        return (_partial_from_state, (self.to_bytes(), self._shape))

    def __repr__(self) -> str:
        rows = ", ".join(f"{r.start}:{r.stop}" for r in self.rows)
        return f"vltm.Partial({self.kind}, rows [{rows}] of {self.total_rows}, {self.nbytes} bytes)"


class _Voxels(NamedTuple):
    """Voxel centres of a finished state whose volume was not given from Python."""

    points: np.ndarray
    is_grid: bool


def _partial_from_state(data: bytes, shape: Optional[Tuple[int, ...]]) -> Partial:
    p = Partial.from_bytes(data)
    p._shape = shape
    return p


def _out_shape(native_shape: Tuple[int, int, int], shape: Optional[Tuple[int, ...]]) -> Tuple[int, ...]:
    if shape is not None:
        return shape
    return tuple(native_shape)


def merge(parts: Iterable[Union[Partial, bytes]]) -> Partial:
    """Adds partial states (of one probe over one capture, disjoint rows) into one.
    Raises :class:`ArgumentError` for parts of different captures or parameters and for
    overlapping rows."""
    ps = [p if isinstance(p, Partial) else Partial.from_bytes(p) for p in parts]
    if not ps:
        raise ArgumentError("argument `parts`: no partial states to merge")
    m = Partial(_native.merge([p._native for p in ps]))
    m._shape, m._volume, m._attrs = ps[0]._shape, ps[0]._volume, ps[0]._attrs
    return m


def gamma_mask(direct: np.ndarray, epsilon: float = 0.1) -> np.ndarray:
    """Γ = {v : I_d(v) > ε·max I_d} (Eq. 15), as vltm computes it; boolean, shaped like
    ``direct``."""
    d = _check.array("direct", direct)
    e = _check.real("epsilon", epsilon)
    return np.asarray(_native.gamma_mask(d.ravel(), e), dtype=bool).reshape(d.shape)


def set_threads(n: int) -> None:
    """Worker threads of this process, as ``--threads`` (1 to 4 per core; once, before the
    first probe; default: all cores, or ``RAYON_NUM_THREADS``)."""
    _native.set_threads(_check.integer("threads", n, lo=-(2**62)))


def set_max_memory(size: Union[str, int]) -> int:
    """The memory budget, as ``--max-memory``: ``"12G"``, ``"500M"`` or bytes (default:
    half of the physical memory). Every buffer sized from a file, a scene or an argument is
    checked against it before it is made. Returns the budget in bytes."""
    if not isinstance(size, str):
        size = str(_check.integer("size", size, lo=1))
    return _native.set_max_memory(size)


def max_memory() -> int:
    """The memory budget in bytes (see :func:`set_max_memory`)."""
    return _native.max_memory()


def _warn(msg: Optional[str]) -> None:
    if msg:
        import warnings

        warnings.warn(f"vltm: {msg}", RuntimeWarning, stacklevel=3)


def _shape_out(values, amps, rep, shape, amplitudes, report, labels=None, lead=None):
    """The caller's return value: values shaped like the volume (``lead`` parts first), then
    the amplitudes and the report on request; ``labels`` = (volume, attrs): a DataArray."""
    full = shape if lead is None else (len(lead),) + tuple(shape)
    out = [values.reshape(full)]
    for k in ("gamma", "direct"):
        if k in rep:
            rep[k] = rep[k].reshape(shape)
    for w in rep.get("warnings", []):
        _warn(w)
    if labels is not None:
        from . import _xarray

        vol, attrs = labels
        attrs = dict(attrs, wavelength=rep.get("wavelength"), sigma=rep.get("sigma"),
                     path=rep.get("path"), bins=rep.get("bins"), rows=rep.get("rows"),
                     explained=rep.get("explained"), preprocessing=rep.get("preprocessing"),
                     units="relative intensity (T = |A|^2)", length_units="m")
        out[0] = _xarray.volume_array(out[0], vol.points, vol.is_grid, attrs, lead=lead)
    if amplitudes:
        if amps is None:
            raise ArgumentError(
                "argument `amplitudes`: complex amplitudes exist for direct light, two-bounce and higher-order columns and relighting only (the un-gated column and indirect light are imaged as intensities)"
            )
        out.append(amps.reshape(shape))
    if report:
        out.append(rep)
    return out[0] if len(out) == 1 else tuple(out)


def _rows(rows: Any, capture: Capture, swap_roles: bool = False) -> Optional[Tuple[int, int]]:
    if rows is None:
        return None
    if isinstance(rows, range):
        rows = slice(rows.start, rows.stop, rows.step)
    if not isinstance(rows, slice) or rows.step not in (None, 1):
        raise ArgumentError(f"argument `rows`: expected slice(a, b) with step 1, found {rows!r}")
    n = capture.info()["spads" if swap_roles else "lasers"]
    a = 0 if rows.start is None else _check.integer("rows", rows.start)
    b = n if rows.stop is None else _check.integer("rows", rows.stop)
    if not (0 <= a <= b <= n):
        raise ArgumentError(
            f"argument `rows`: expected A:B with 0 <= A <= B <= {n} (laser rows, B exclusive), found `{a}:{b}`"
        )
    return (a, b)


def _capture(capture: Any) -> Capture:
    if isinstance(capture, Capture):
        return capture
    return open(capture)


def _wave(wavelength, sigma, weights, band, compensate_laser, crop, path) -> dict:
    """The wave options, checked (ranges are the library's checks)."""
    return dict(wavelength=_check.real("wavelength", wavelength, none=True),
                sigma=_check.real("sigma", sigma, none=True),
                weights=_check.text("weights", weights),
                band=_check.real("band", band),
                compensate_laser=_check.flag("compensate_laser", compensate_laser),
                crop=_check.flag("crop", crop),
                path=_check.text("path", path))


def _input(swap_roles, t_min, t_max, rebin, background) -> dict:
    """The capture options: role swap and preprocessing of the counts, checked."""
    return dict(swap_roles=_check.flag("swap_roles", swap_roles),
                t_min=_check.time_bound("t_min", t_min), t_max=_check.time_bound("t_max", t_max),
                rebin=_check.integer("rebin", rebin),
                background=_check.background(background))


def _probe(kind: str, capture: Any, volume: Any, rows: Any, amplitudes: Any, report: Any,
           as_xarray: Any, attrs: Dict[str, Any], lead: Optional[Sequence[str]] = None,
           **kw: Any) -> Any:
    cap = _capture(capture)
    vol = _volume(volume)
    amplitudes = _check.flag("amplitudes", amplitudes)
    report = _check.flag("report", report)
    as_xarray = _check.flag("as_xarray", as_xarray)
    if as_xarray:
        from . import _xarray

        _xarray.xr()
    r = _rows(rows, cap, kw.get("swap_roles", False))
    res = _native.run(cap._native, vol._native, kind, rows=r, amplitudes=amplitudes, **kw)
    attrs = dict(attrs, probe=kind, capture=cap.path or "<arrays>")
    if r is not None:
        p = Partial(res)
        p._shape, p._volume, p._attrs = vol.shape, vol, attrs
        return p
    values, amps, rep = res
    labels = (vol, attrs) if as_xarray else None
    return _shape_out(values, amps, rep, vol.shape, amplitudes, report, labels, lead)


_SHELLS = ("near", "middle", "far")


def _shells(shells: Any) -> Optional[str]:
    if shells is None:
        return None
    r1, r2 = _check.pair("shells", shells, inf=False)
    return f"{r1!r},{r2!r}"


def direct(
    capture: Union[Capture, PathLike],
    volume: Union[str, np.ndarray, Volume],
    *,
    gate: str = "gaussian",
    wavelength: Optional[float] = None,
    sigma: Optional[float] = None,
    weights: str = "inv",
    band: float = 5.0,
    compensate_laser: bool = False,
    crop: bool = True,
    path: str = "auto",
    swap_roles: bool = False,
    t_min: Any = None,
    t_max: Any = None,
    rebin: int = 1,
    background: Any = None,
    rows: Optional[slice] = None,
    amplitudes: bool = False,
    report: bool = False,
    as_xarray: bool = False,
) -> Any:
    """Direct light: the LTM diagonal ``T(x_v, x_v)`` over ``volume`` (Eqs. 11–12), float32
    shaped like the volume — the same numbers as ``vltm direct``.

    ``gate``: ``"gaussian"`` (direct light), ``"none"`` (monochromatic, no gate: paper
    Fig. 6) or ``"higher-order"`` (light arriving after the 3-vertex time: Eq. 18 on the
    diagonal). ``wavelength`` λ (m, default twice the aperture pitch), ``sigma`` the gate
    std (m, default 2λ/3), ``weights`` ``"inv"`` (the paper's 1/d) or ``"one"`` (y-tal),
    ``band`` the band half-width in 1/σ, ``compensate_laser`` divides each row by the
    laser's cos θ/d², ``crop=False`` keeps the whole time axis (by default it is cropped to
    the bins the probed voxels can reach, with the gate's support, before the band
    transform: the command line's ``--no-crop``), ``path`` ``auto|band|planar|lookup``,
    ``swap_roles`` uses the SPADs
    as the projector and the lasers as the camera (reciprocity; reads the capture into
    memory).

    Preprocessing of raw counts, per histogram in this order: the window ``t_min`` ..
    ``t_max`` (metres of path as numbers or ``"0.72m"``, bins as ``"600b"``; cropped),
    ``rebin`` K bins summed, ``background`` ``"auto"`` (each histogram's floor from the bins
    no return from the volume reaches), ``"none"`` or counts per source bin.

    ``rows=slice(a, b)`` returns a :class:`Partial` over those laser rows instead;
    ``amplitudes=True`` also returns the complex amplitudes; ``report=True`` also the
    counters; ``as_xarray=True`` returns an ``xarray.DataArray`` with coordinates ``x``,
    ``y``, ``z`` (m) and the parameters as attributes."""
    return _probe("direct", capture, volume, rows, amplitudes, report, as_xarray,
                  {"gate": gate}, gate=_check.text("gate", gate),
                  **_wave(wavelength, sigma, weights, band, compensate_laser, crop, path),
                  **_input(swap_roles, t_min, t_max, rebin, background))


def column(
    capture: Union[Capture, PathLike],
    volume: Union[str, np.ndarray, Volume],
    focus: Sequence[float],
    *,
    gate: str = "two-bounce",
    shell: Optional[Tuple[float, float]] = None,
    shells: Optional[Tuple[float, float]] = None,
    mask_epsilon: Optional[float] = None,
    leak_correct: bool = True,
    leak_epsilon: float = 0.1,
    wavelength: Optional[float] = None,
    sigma: Optional[float] = None,
    weights: str = "inv",
    band: float = 5.0,
    compensate_laser: bool = False,
    crop: bool = True,
    path: str = "auto",
    swap_roles: bool = False,
    t_min: Any = None,
    t_max: Any = None,
    rebin: int = 1,
    background: Any = None,
    rows: Optional[slice] = None,
    amplitudes: bool = False,
    report: bool = False,
    as_xarray: bool = False,
) -> Any:
    """A column ``T(x_a, ·)`` of the LTM for the focus ``x_a`` = ``focus`` (m, z > 0):
    ``gate`` ``"two-bounce"`` (Eq. 14), ``"higher-order"`` (Eq. 18) or ``"none"``; ``shell``
    ``(r0, r1)`` keeps ``r0 <= |x_a - x_b| < r1``. ``shells=(r1, r2)``: the near
    ``[0, r1)``, middle ``[r1, r2)`` and far ``[r2, inf)`` light of one run, stacked as
    ``(3,) + shape`` (``vltm column --shells``; a ``shell`` dimension with ``as_xarray``).
    ``mask_epsilon`` zeroes every voxel whose direct light is not above ε·max (an extra
    diagonal pass). ``leak_correct=True`` (the default, as ``vltm column``) removes the
    capture's direct light first (the 3-vertex windows of Γ = direct light above
    ``leak_epsilon``·max; ``report["explained"]`` the energy removed);
    ``leak_correct=False`` is the column of the capture as it is (``--no-leak-correct``),
    needed for partial states (``rows=``). ``amplitudes=True`` also returns the complex
    amplitudes ``A(x_a, ·)`` (complex128, ``T = |A|²``, 0 outside ``shell``) of two-bounce
    and higher-order columns; the un-gated column has none. Other arguments as
    :func:`direct`."""
    f = _check.point("focus", focus)
    me = _check.real("mask_epsilon", mask_epsilon, none=True)
    le = _check.real("leak_epsilon", leak_epsilon)
    sh = None if shell is None else _check.pair("shell", shell)
    cut = _shells(shells)
    attrs = {"gate": gate, "focus": list(f), "mask_epsilon": me, "shell": sh,
             "shells": None if shells is None else list(_check.pair("shells", shells)),
             "leak_correct": leak_correct, "leak_epsilon": le if leak_correct else None}
    return _probe("column", capture, volume, rows, amplitudes, report, as_xarray, attrs,
                  _SHELLS if cut else None, focus=list(f), gate=_check.text("gate", gate),
                  shell=sh, shells=cut, mask_epsilon=me,
                  leak_correct=_check.flag("leak_correct", leak_correct), leak_epsilon=le,
                  **_wave(wavelength, sigma, weights, band, compensate_laser, crop, path),
                  **_input(swap_roles, t_min, t_max, rebin, background))


def indirect(
    capture: Union[Capture, PathLike],
    volume: Union[str, np.ndarray, Volume],
    *,
    epsilon: float = 0.1,
    min_separation: Optional[float] = None,
    shell: Optional[Tuple[float, float]] = None,
    shells: Optional[Tuple[float, float]] = None,
    gate: str = "two-bounce",
    direct: Optional[np.ndarray] = None,
    leak_correct: bool = True,
    wavelength: Optional[float] = None,
    sigma: Optional[float] = None,
    weights: str = "inv",
    band: float = 5.0,
    compensate_laser: bool = False,
    crop: bool = True,
    path: str = "auto",
    swap_roles: bool = False,
    t_min: Any = None,
    t_max: Any = None,
    rebin: int = 1,
    background: Any = None,
    rows: Optional[slice] = None,
    report: bool = False,
    as_xarray: bool = False,
) -> Any:
    """In-focus indirect light (Eqs. 15–17): Γ = voxels whose direct light exceeds
    ``epsilon``·max, then ``Σ T(x_a, x_b)`` over pairs of Γ at least ``min_separation``
    apart (default 1.5σ) or within ``shell``; ``shells=(r1, r2)``: the near, middle and far
    pair sums of one run, stacked as ``(3,) + shape``. ``gate``: of the summed columns,
    ``"two-bounce"`` (first-order indirect light), ``"higher-order"`` (the paper's ">= 3rd
    bounce") or ``"none"``. ``direct``: the direct light over the same volume (e.g. from
    :func:`direct` or a merged Dask run) instead of pass 1 — required with ``rows=``.
    ``report=True`` also returns Γ (``report["gamma"]``, boolean) and the direct light
    (``report["direct"]``), as ``vltm indirect`` writes them beside ``I_i``. Other
    arguments as :func:`direct`.

    ``leak_correct=True`` (the default, as ``vltm indirect``): the capture's direct light is
    removed first — per laser/SPAD pair the bins where a 3-vertex return of a Γ voxel can
    arrive are zeroed; one more pass over the capture measures the removed energy
    (``report["explained"]``). It uses the return times only, so each row is corrected on
    its own and partial states (``rows=``) take it too. ``leak_correct=False``: the paper's
    Eq. 17 on the capture as it is (``vltm indirect --no-leak-correct``)."""
    eps = _check.real("epsilon", epsilon)
    ms = _check.real("min_separation", min_separation, none=True)
    sh = None if shell is None else _check.pair("shell", shell)
    if sh is None and ms is not None:
        if ms < 0:
            raise ArgumentError(f"argument `min_separation`: expected R >= 0, found {ms}")
        sh = (ms, float("inf"))
    if shells is not None and (shell is not None or min_separation is not None):
        raise ArgumentError("argument `shells`: cannot be used with shell or min_separation")
    d = None
    if direct is not None:
        d = _check.array("direct", direct).ravel()
    cut = _shells(shells)
    attrs = {"gate": gate, "epsilon": eps, "shell": sh, "leak_correct": leak_correct,
             "shells": None if shells is None else list(_check.pair("shells", shells))}
    return _probe("indirect", capture, volume, rows, False, report, as_xarray, attrs,
                  _SHELLS if cut else None, epsilon=eps, shell=sh, shells=cut, direct=d,
                  gate=_check.text("gate", gate),
                  leak_correct=_check.flag("leak_correct", leak_correct),
                  **_wave(wavelength, sigma, weights, band, compensate_laser, crop, path),
                  **_input(swap_roles, t_min, t_max, rebin, background))


def relight(
    capture: Union[Capture, PathLike],
    volume: Union[str, np.ndarray, Volume],
    pattern: Union[str, np.ndarray],
    *,
    leak_correct: bool = True,
    leak_epsilon: float = 0.1,
    wavelength: Optional[float] = None,
    sigma: Optional[float] = None,
    weights: str = "inv",
    band: float = 5.0,
    compensate_laser: bool = False,
    crop: bool = True,
    path: str = "auto",
    swap_roles: bool = False,
    t_min: Any = None,
    t_max: Any = None,
    rebin: int = 1,
    background: Any = None,
    amplitudes: bool = False,
    report: bool = False,
    as_xarray: bool = False,
) -> Any:
    """Relighting (``vltm relight``): the virtual camera's image ``i = T·p`` over
    ``volume`` under an illumination that weights several projector foci, in one factorised
    pass (amplitudes add: ``A_p(b) = Σ_a p_a A(a, b)``, intensities ``|A_p|²``).

    ``pattern``: weighted foci ``"x,y,z,w;x,y,z,w"`` (metres; w = 1 if left out), an
    ``(n, 3)`` or ``(n, 4)`` array of foci (and weights), a voxel image of the volume's
    shape (its voxels are the foci, its values the weights), or the path of a float32
    ``.npy`` image. ``amplitudes=True`` also returns ``A_p`` (complex128);
    ``report["passes"]`` the passes over the capture. ``leak_correct``, ``leak_epsilon`` as
    :func:`column` (on by default). Other arguments as :func:`direct`."""
    vol = _volume(volume)
    spec, pts = None, None
    if isinstance(pattern, (str, os.PathLike)) and os.fspath(pattern).strip().endswith(".npy"):
        p = os.fspath(pattern).strip()
        try:
            img = np.load(p)
        except OSError as e:
            raise DataError(f"{p}: {e.strerror or e}") from None
        if img.ndim != len(vol.shape) or img.size != len(vol):
            raise ArgumentError(
                f"argument `pattern`: {p}: shape {list(img.shape)}, expected the volume's {list(vol.shape)}")
        pattern = img
    if isinstance(pattern, str):
        spec = pattern
    else:
        a = _check.array("pattern", pattern, dtype=np.float64)
        if a.shape == tuple(vol.shape):
            pts = np.concatenate([vol.points.reshape(-1, 3).astype(np.float64),
                                  a.reshape(-1, 1)], axis=1)
        elif a.ndim == 2 and a.shape[1] in (3, 4):
            pts = a if a.shape[1] == 4 else np.concatenate([a, np.ones((len(a), 1))], axis=1)
        else:
            raise ArgumentError(
                f"argument `pattern`: expected x,y,z,w;... foci, an (n, 3) or (n, 4) array, or an image of the volume's shape {list(vol.shape)}, found shape {list(a.shape)}")
        pts = np.ascontiguousarray(pts, dtype=np.float64)
    return _probe("relight", capture, vol, None, amplitudes, report, as_xarray,
                  {"pattern": spec, "leak_correct": leak_correct}, pattern=pts, pattern_spec=spec,
                  leak_correct=_check.flag("leak_correct", leak_correct),
                  leak_epsilon=_check.real("leak_epsilon", leak_epsilon),
                  **_wave(wavelength, sigma, weights, band, compensate_laser, crop, path),
                  **_input(swap_roles, t_min, t_max, rebin, background))


def row(
    capture: Union[Capture, PathLike],
    volume: Union[str, np.ndarray, Volume],
    focus: Sequence[float],
    *,
    leak_correct: bool = True,
    leak_epsilon: float = 0.1,
    wavelength: Optional[float] = None,
    sigma: Optional[float] = None,
    weights: str = "inv",
    band: float = 5.0,
    compensate_laser: bool = False,
    crop: bool = True,
    path: str = "auto",
    swap_roles: bool = False,
    t_min: Any = None,
    t_max: Any = None,
    rebin: int = 1,
    background: Any = None,
    report: bool = False,
    as_xarray: bool = False,
) -> Any:
    """A row ``T(·, x_b)`` of the LTM (``vltm row``): the virtual camera focused at
    ``x_b`` = ``focus`` (m, z > 0), the projector over ``volume`` (two-bounce gate),
    streamed by laser rows without transposing the capture. ``swap_roles`` is refused (a
    row is the transposed column already). ``leak_correct``, ``leak_epsilon`` as
    :func:`column` (on by default). Other arguments as :func:`direct`."""
    f = _check.point("focus", focus)
    return _probe("row", capture, volume, None, False, report, as_xarray,
                  {"gate": "two-bounce", "focus": list(f), "leak_correct": leak_correct},
                  focus=list(f), leak_correct=_check.flag("leak_correct", leak_correct),
                  leak_epsilon=_check.real("leak_epsilon", leak_epsilon),
                  **_wave(wavelength, sigma, weights, band, compensate_laser, crop, path),
                  **_input(swap_roles, t_min, t_max, rebin, background))


class MatrixResult(NamedTuple):
    """The two-bounce LTM between two voxel sets (:func:`matrix`): element ``[i, k]`` is
    ``T(from_xyz[i], to_xyz[k])``, as ``vltm matrix`` writes it (datasets ``re``, ``im``,
    ``intensity``, ``from_xyz``, ``to_xyz``)."""

    #: Complex amplitudes ``A``, complex64 ``(n_from, n_to)``.
    amplitudes: np.ndarray
    #: Intensities ``T = |A|²``, float32 ``(n_from, n_to)``.
    intensities: np.ndarray
    #: Projector foci ``x_a`` (the rows), float32 ``(n_from, 3)``, metres.
    from_xyz: np.ndarray
    #: Imaged voxels ``x_b`` (the columns), float32 ``(n_to, 3)``, metres.
    to_xyz: np.ndarray
    #: Counters and configuration: ``rows``, ``aliased``, ``wavelength``, ``sigma``, ``bins``…
    report: dict

    def to_xarray(self) -> Any:
        """The intensities as an ``xarray.DataArray`` over dimensions ``from`` and ``to``
        with coordinates ``from_x/from_y/from_z`` and ``to_x/to_y/to_z`` (m); the
        amplitudes' real and imaginary parts as ``re``/``im`` coordinates would double
        the size, so they stay in :attr:`amplitudes`."""
        from . import _xarray

        xr = _xarray.xr()
        coords: Dict[str, Any] = {}
        for side, pts in (("from", self.from_xyz), ("to", self.to_xyz)):
            for k, c in enumerate("xyz"):
                coords[f"{side}_{c}"] = ((side,), pts[:, k].astype(np.float64))
        attrs = _xarray.clean_attrs({
            "probe": "matrix", "gate": "two-bounce", "wavelength": self.report.get("wavelength"),
            "sigma": self.report.get("sigma"), "path": self.report.get("path", "band"),
            "bins": self.report.get("bins"), "rows": self.report.get("rows"),
            "units": "relative intensity (T = |A|^2)", "length_units": "m"})
        a = xr.DataArray(self.intensities, dims=["from", "to"], coords=coords,
                         name="intensity", attrs=attrs)
        for c in coords:
            a[c].attrs["units"] = "m"
        return a


def _matrix_result(values, amps, shape, rep, frm, to) -> MatrixResult:
    return MatrixResult(amps.reshape(shape), values.reshape(shape), frm.reshape(-1, 3),
                        to.reshape(-1, 3), rep)


def _voxel_set(spec: Any, what: str, gamma: Optional[np.ndarray]) -> np.ndarray:
    """A voxel set as float32 ``(n, 3)``: a SPEC, a :class:`Volume`, an ``(..., 3)`` array or
    ``"gamma"`` (Γ's points, given)."""
    if isinstance(spec, str) and spec.strip() == "gamma":
        assert gamma is not None
        return gamma
    try:
        v = _volume(spec, what)
    except ArgumentError as e:
        msg = str(e)
        for old in ("argument `volume`: ", f"argument `{what}`: "):
            if msg.startswith(old):
                msg = msg[len(old):]
        raise ArgumentError(f"argument `{what}`: {msg}") from None
    return np.ascontiguousarray(v.points.reshape(-1, 3), dtype=np.float32)


def matrix(
    capture: Union[Capture, PathLike],
    from_: Union[str, np.ndarray, Volume],
    to: Union[str, np.ndarray, Volume],
    *,
    volume: Optional[Union[str, np.ndarray, Volume]] = None,
    epsilon: float = 0.1,
    direct: Optional[np.ndarray] = None,
    wavelength: Optional[float] = None,
    sigma: Optional[float] = None,
    weights: str = "inv",
    band: float = 5.0,
    compensate_laser: bool = False,
    crop: bool = True,
    rows: Optional[slice] = None,
) -> Any:
    """The two-bounce LTM (Eq. 14) between two voxel sets as a matrix — the same numbers as
    ``vltm matrix``: a :class:`MatrixResult` with the complex amplitudes (complex64) and
    intensities (float32) of shape ``(n_from, n_to)`` and the voxel coordinates
    (``.to_xarray()`` labels them).

    ``from_`` (the projector foci, the rows) and ``to`` (the imaged voxels, the columns): a
    SPEC, a :class:`Volume`, an ``(..., 3)`` array of points (m, z > 0), or ``"gamma"``: Γ of
    ``volume`` = the voxels whose direct light exceeds ``epsilon``·max, from ``direct`` (the
    direct light over ``volume``) or else a direct pass first. One pass over the capture
    (more if the accumulators of all foci exceed the memory budget); cost per laser row
    ``n_from·Ks·8J`` flops, at the end ``n_from·n_to·Ks·14J``; memory ``16·J·(Ks+1)`` bytes
    per focus and 44 bytes per element. ``rows=slice(a, b)`` returns a :class:`Partial` (one
    factorised column per focus; ``gamma`` then needs ``direct``). Wave options as
    :func:`direct`; the matrix is imaged on the band path."""
    cap = _capture(capture)
    wave = _wave(wavelength, sigma, weights, band, compensate_laser, crop, "auto")
    eps = _check.real("epsilon", epsilon)
    gamma = None
    if any(isinstance(x, str) and x.strip() == "gamma" for x in (from_, to)):
        if volume is None:
            raise ArgumentError("argument `volume`: `gamma` in from_/to needs the volume of Γ")
        if not (0.0 <= eps < 1.0):
            raise ArgumentError(f"argument `epsilon`: expected 0 <= E < 1, found {eps}")
        vol = _volume(volume)
        if direct is None:
            if rows is not None:
                raise ArgumentError(
                    "argument `rows`: `gamma` over a part of the rows needs Γ: pass direct=, the finished direct light over volume"
                )
            d = globals()["direct"](cap, vol, wavelength=wavelength, sigma=sigma, weights=weights,
                                    band=band, compensate_laser=compensate_laser, crop=crop)
        else:
            d = _check.array("direct", direct)
            if d.size != len(vol):
                raise ArgumentError(
                    f"argument `direct`: expected {len(vol)} values (the volume's voxels), found {d.size}"
                )
        g = gamma_mask(d, eps).ravel()
        gamma = np.ascontiguousarray(vol.points.reshape(-1, 3)[g], dtype=np.float32)
        if len(gamma) == 0:
            raise ArgumentError(
                "argument `epsilon`: Γ is empty: no voxel of volume has direct light above ε·max (all zero)"
            )
    frm = _voxel_set(from_, "from_", gamma)
    dst = _voxel_set(to, "to", gamma)
    r = _rows(rows, cap)
    res = _native.run(cap._native, _native.volume_from_points(dst), "matrix", rows=r,
                      from_points=frm, **wave)
    if r is not None:
        return Partial(res)
    values, amps, rep = res
    n = (len(frm), len(dst))
    return MatrixResult(amps.reshape(n), values.reshape(n), frm, dst, rep)
