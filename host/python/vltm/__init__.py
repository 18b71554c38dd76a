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
>>> part = vltm.direct(cap, vol, rows=slice(0, 32))     # a Partial (accumulator state)
>>> rest = vltm.direct(cap, vol, rows=slice(32, 64))
>>> vltm.merge([part, rest]).finish()                   # == vltm.direct(cap, vol)

Every probe releases the GIL while it runs. Errors are :class:`VltmError` subclasses
(:class:`ArgumentError` is a ``ValueError``, :class:`DataError` an ``OSError``) carrying the
command line's one-line messages. Scale-out over a Dask cluster: :mod:`vltm.dask`.
"""

from __future__ import annotations

import builtins
import os
from typing import Any, Iterable, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._errors import ArgumentError, DataError, VltmError

__version__: str = _native.__version__

__all__ = [
    "ArgumentError",
    "Capture",
    "MatrixResult",
    "DataError",
    "Partial",
    "Volume",
    "VltmError",
    "column",
    "direct",
    "gamma_mask",
    "indirect",
    "matrix",
    "merge",
    "open",
    "set_threads",
    "volume",
]

PathLike = Union[str, "os.PathLike[str]"]


class Volume:
    """A set of voxels: a grid from a SPEC ``"x0:x1:nx,y0:y1:ny,z0:z1:nz"`` (metres,
    inclusive end points), a point list ``"x,y,z;x,y,z"``, or an ``(..., 3)`` array of points.
    Results come back shaped like the volume: ``(nx, ny, nz)`` for a grid, the array's
    leading shape for points."""

    def __init__(self, spec: Union[str, np.ndarray, "Volume"]) -> None:
        if isinstance(spec, Volume):
            self._native, self.shape = spec._native, spec.shape
            return
        if isinstance(spec, str):
            self._native = _native.volume_from_spec(spec)
            self.shape: Tuple[int, ...] = (
                tuple(self._native.shape) if self._native.is_grid else (len(self._native),)
            )
            return
        pts = np.asarray(spec, dtype=np.float32)
        if pts.ndim < 1 or pts.shape[-1] != 3:
            raise ArgumentError(
                f"argument `volume`: expected a SPEC string or an (..., 3) array of points, found shape {pts.shape}"
            )
        self._native = _native.volume_from_points(np.ascontiguousarray(pts.reshape(-1, 3)))
        self.shape = tuple(pts.shape[:-1])

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


class Capture:
    """A transient NLOS capture: ``H[l][s][t]`` for laser spot l, SPAD spot s, time bin t at
    path length ``t_start + t * delta_t``. Open a file with :func:`open` (its rows are
    streamed from the file by every probe: never shipped, never read whole unless the format
    needs it) or build one from arrays with :meth:`Capture.from_arrays`."""

    def __init__(self, native: Any, path: Optional[str] = None) -> None:
        self._native = native
        self.path = path

    @classmethod
    def from_arrays(
        cls,
        H: np.ndarray,
        laser_grid_xyz: np.ndarray,
        sensor_grid_xyz: np.ndarray,
        delta_t: float,
        t_start: float = 0.0,
        laser_xyz: Sequence[float] = (-0.5, 0.0, 0.25),
        sensor_xyz: Sequence[float] = (-0.5, 0.0, 0.25),
        t_accounts_first_and_last_bounces: bool = False,
        scan_type: str = "exhaustive",
    ) -> "Capture":
        """A capture from y-tal's fields (metres, time first).

        ``scan_type="exhaustive"``: ``H`` of shape ``(nt, Lx, Ly, Sx, Sy)`` with grids
        ``(Lx, Ly, 3)`` and ``(Sx, Sy, 3)``, or ``(nt, L, S)`` with point lists ``(L, 3)``,
        ``(S, 3)``. ``scan_type="confocal"``: ``H`` of shape ``(nt, Sx, Sy)`` (or ``(nt, S)``)
        and ``laser_grid_xyz`` = ``sensor_grid_xyz``. ``laser_xyz``/``sensor_xyz``: the device
        positions (y-tal's defaults)."""
        H = np.asarray(H)
        lg = np.asarray(laser_grid_xyz, dtype=np.float32)
        sg = np.asarray(sensor_grid_xyz, dtype=np.float32)

        def grid_shape(g: np.ndarray, what: str) -> Tuple[int, int]:
            if g.ndim == 3 and g.shape[2] == 3:
                return (g.shape[0], g.shape[1])
            if g.ndim == 2 and g.shape[1] == 3:
                return (g.shape[0], 1)
            raise ArgumentError(
                f"argument `{what}`: expected (nx, ny, 3) or (n, 3), found shape {g.shape}"
            )

        ls, ss = grid_shape(lg, "laser_grid_xyz"), grid_shape(sg, "sensor_grid_xyz")
        nl, ns = ls[0] * ls[1], ss[0] * ss[1]
        confocal = scan_type == "confocal"
        if scan_type not in ("exhaustive", "confocal"):
            raise ArgumentError(
                f"argument `scan_type`: expected exhaustive or confocal, found `{scan_type}`"
            )
        if H.ndim < 2:
            raise ArgumentError(f"argument `H`: expected time first, found shape {H.shape}")
        nt = H.shape[0]
        per = ns if not confocal else 1
        rows = nl if not confocal else ns
        if H.size != nt * rows * per:
            raise ArgumentError(
                f"argument `H`: expected {nt} x {rows} x {per} values for these grids, found shape {H.shape}"
            )
        h = np.ascontiguousarray(
            np.moveaxis(H.reshape(nt, rows, per), 0, -1), dtype=np.float32
        )
        if confocal:
            lg, ls = sg, ss
        native = _native.capture_from_arrays(
            h,
            np.ascontiguousarray(lg.reshape(-1, 3)),
            ls,
            np.ascontiguousarray(sg.reshape(-1, 3)),
            ss,
            float(delta_t),
            float(t_start),
            [float(x) for x in laser_xyz],
            [float(x) for x in sensor_xyz],
            bool(t_accounts_first_and_last_bounces),
            confocal,
        )
        return cls(native)

    def info(self) -> dict:
        """Dimensions, geometry and time axis: ``lasers``, ``spads``, ``nt``, ``delta_t``,
        ``t_start``, ``confocal``, shapes, device positions, ``default_wavelength``…"""
        return self._native.info()

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


def open(path: PathLike) -> Capture:  # noqa: A001 - mirrors the library's `io::open`
    """Opens a capture file: vltm ``.npz``, y-tal ``HDF5_TAL`` (``.hdf5``/``.h5``),
    PicoQuant ``.ptu`` (with its ``.json`` sidecar)… Reads the geometry only."""
    p = os.fspath(path)
    return Capture(_native.open_capture(p), p)


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

    def finish(self, amplitudes: bool = False, report: bool = False) -> Any:
        """The probe's volume (float32, shaped like the volume). With ``amplitudes=True``
        also the complex amplitudes ``A`` (``T = |A|²``; direct light, two-bounce and
        higher-order columns), with ``report=True`` also the counters dict. A ``matrix``
        state finishes into a :class:`MatrixResult` (``amplitudes``/``report`` ignored)."""
        if self.kind == "matrix":
            return _matrix_result(*self._native.finish())
        values, amps, shape, rep = self._native.finish(amplitudes=bool(amplitudes))
        return _shape_out(values, amps, rep, _out_shape(shape, self._shape), amplitudes, report)

    _shape: Optional[Tuple[int, ...]] = None

    def __reduce__(self) -> Any:
        return (_partial_from_state, (self.to_bytes(), self._shape))

    def __repr__(self) -> str:
        rows = ", ".join(f"{r.start}:{r.stop}" for r in self.rows)
        return f"vltm.Partial({self.kind}, rows [{rows}] of {self.total_rows}, {self.nbytes} bytes)"


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
        raise ArgumentError("argument `merge`: no partial states to merge")
    m = Partial(_native.merge([p._native for p in ps]))
    m._shape = ps[0]._shape
    return m


def gamma_mask(direct: np.ndarray, epsilon: float = 0.1) -> np.ndarray:
    """Γ = {v : I_d(v) > ε·max I_d} (Eq. 15), as vltm computes it; boolean, shaped like
    ``direct``."""
    d = np.asarray(direct, dtype=np.float32)
    return np.asarray(_native.gamma_mask(d.ravel().tolist(), float(epsilon)), dtype=bool).reshape(d.shape)


def set_threads(n: int) -> None:
    """Worker threads of this process (once, before the first probe; default: all cores,
    or ``RAYON_NUM_THREADS``)."""
    _native.set_threads(int(n))


def _shape_out(values, amps, rep, shape, amplitudes, report):
    out = [values.reshape(shape)]
    if amplitudes:
        if amps is None:
            raise ArgumentError(
                "argument `amplitudes`: complex amplitudes exist for direct light, two-bounce and higher-order columns only (the un-gated column and indirect light are imaged as intensities)"
            )
        out.append(amps.reshape(shape))
    if report:
        out.append(rep)
    return out[0] if len(out) == 1 else tuple(out)


def _rows(rows: Optional[slice], capture: Capture) -> Optional[Tuple[int, int]]:
    if rows is None:
        return None
    if isinstance(rows, range):
        rows = slice(rows.start, rows.stop, rows.step)
    if not isinstance(rows, slice) or rows.step not in (None, 1):
        raise ArgumentError(f"argument `rows`: expected slice(a, b) with step 1, found {rows!r}")
    n = capture.info()["lasers"]
    a = 0 if rows.start is None else int(rows.start)
    b = n if rows.stop is None else int(rows.stop)
    if not (0 <= a <= b <= n):
        raise ArgumentError(
            f"argument `--rows`: expected A:B with 0 <= A <= B <= {n} (laser rows, B exclusive), found `{a}:{b}`"
        )
    return (a, b)


def _probe(kind: str, capture: Union[Capture, PathLike], volume: Union[str, np.ndarray, Volume],
           rows: Optional[slice], amplitudes: bool, report: bool, **kw: Any) -> Any:
    cap = capture if isinstance(capture, Capture) else open(capture)
    vol = Volume(volume)
    r = _rows(rows, cap)
    res = _native.run(cap._native, vol._native, kind, rows=r, amplitudes=amplitudes, **kw)
    if r is not None:
        p = Partial(res)
        p._shape = vol.shape
        return p
    values, amps, rep = res
    return _shape_out(values, amps, rep, vol.shape, amplitudes, report)


def _wave(wavelength, sigma, weights, band, compensate_laser, path) -> dict:
    return dict(wavelength=None if wavelength is None else float(wavelength),
                sigma=None if sigma is None else float(sigma), weights=weights,
                band=float(band), compensate_laser=bool(compensate_laser), path=path)


def direct(
    capture: Union[Capture, PathLike],
    volume: Union[str, np.ndarray, Volume],
    *,
    wavelength: Optional[float] = None,
    sigma: Optional[float] = None,
    weights: str = "inv",
    band: float = 5.0,
    compensate_laser: bool = False,
    path: str = "auto",
    rows: Optional[slice] = None,
    amplitudes: bool = False,
    report: bool = False,
) -> Any:
    """Direct light: the LTM diagonal ``T(x_v, x_v)`` over ``volume`` (Eqs. 11–12), float32
    shaped like the volume — the same numbers as ``vltm direct``.

    ``wavelength`` λ (m, default twice the aperture pitch), ``sigma`` the gate std (m,
    default 2λ/3), ``weights`` ``"inv"`` (the paper's 1/d) or ``"one"`` (y-tal), ``band`` the
    band half-width in 1/σ, ``compensate_laser`` divides each row by the laser's cos θ/d²,
    ``path`` ``auto|band|planar|lookup``. ``rows=slice(a, b)`` returns a :class:`Partial`
    over those laser rows instead; ``amplitudes=True`` also returns the complex amplitudes;
    ``report=True`` also the counters."""
    return _probe("direct", capture, volume, rows, amplitudes, report,
                  **_wave(wavelength, sigma, weights, band, compensate_laser, path))


def column(
    capture: Union[Capture, PathLike],
    volume: Union[str, np.ndarray, Volume],
    focus: Sequence[float],
    *,
    gate: str = "two-bounce",
    shell: Optional[Tuple[float, float]] = None,
    wavelength: Optional[float] = None,
    sigma: Optional[float] = None,
    weights: str = "inv",
    band: float = 5.0,
    compensate_laser: bool = False,
    path: str = "auto",
    rows: Optional[slice] = None,
    amplitudes: bool = False,
    report: bool = False,
) -> Any:
    """A column ``T(x_a, ·)`` of the LTM for the focus ``x_a`` = ``focus`` (m, z > 0):
    ``gate`` ``"two-bounce"`` (Eq. 14), ``"higher-order"`` (Eq. 18) or ``"none"``; ``shell``
    ``(r0, r1)`` keeps ``r0 <= |x_a - x_b| < r1``. ``amplitudes=True`` also returns the
    complex amplitudes ``A(x_a, ·)`` (complex128, ``T = |A|²``, 0 outside ``shell``) of
    two-bounce (imaged beside the intensities: about twice the imaging time) and
    higher-order columns; the un-gated column has none. Other arguments as
    :func:`direct`."""
    f = [float(x) for x in focus]
    if len(f) != 3:
        raise ArgumentError(f"argument `focus`: expected (x, y, z), found {focus!r}")
    return _probe("column", capture, volume, rows, amplitudes, report, focus=f, gate=gate,
                  shell=None if shell is None else (float(shell[0]), float(shell[1])),
                  **_wave(wavelength, sigma, weights, band, compensate_laser, path))


def indirect(
    capture: Union[Capture, PathLike],
    volume: Union[str, np.ndarray, Volume],
    *,
    epsilon: float = 0.1,
    min_separation: Optional[float] = None,
    shell: Optional[Tuple[float, float]] = None,
    direct: Optional[np.ndarray] = None,
    wavelength: Optional[float] = None,
    sigma: Optional[float] = None,
    weights: str = "inv",
    band: float = 5.0,
    compensate_laser: bool = False,
    path: str = "auto",
    leak_correct: bool = True,
    rows: Optional[slice] = None,
    report: bool = False,
) -> Any:
    """In-focus indirect light (Eqs. 15–17): Γ = voxels whose direct light exceeds
    ``epsilon``·max, then ``Σ T(x_a, x_b)`` over pairs of Γ at least ``min_separation``
    apart (default 1.5σ) or within ``shell``. ``direct``: the direct light over the same
    volume (e.g. from :func:`direct` or a merged Dask run) instead of pass 1 — required with
    ``rows=``. Other arguments as :func:`direct`.

    ``leak_correct=True`` (the default, as ``vltm indirect``): the capture's direct light is
    removed first — per laser/SPAD pair the bins where a 3-vertex return of a Γ voxel can
    arrive are zeroed (docs/indirect-light.md); one more pass over the
    capture measures the removed energy (``report["explained"]``). It uses the return
    times only, so each row is corrected on its own and partial states (``rows=``) take it
    too. ``leak_correct=False``: the paper's Eq. 17 on the capture as it is
    (``vltm indirect --no-leak-correct``)."""
    if shell is None and min_separation is not None:
        if min_separation < 0:
            raise ArgumentError(f"argument `--min-separation`: expected R >= 0, found {min_separation}")
        shell = (float(min_separation), float("inf"))
    d = None if direct is None else np.asarray(direct, dtype=np.float32).ravel().tolist()
    return _probe("indirect", capture, volume, rows, False, report, epsilon=float(epsilon),
                  shell=None if shell is None else (float(shell[0]), float(shell[1])), direct=d,
                  leak_correct=bool(leak_correct),
                  **_wave(wavelength, sigma, weights, band, compensate_laser, path))


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
        v = Volume(spec)
    except ArgumentError as e:
        msg = str(e)
        for old in ("argument `--volume`: ", "argument `volume`: "):
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
    rows: Optional[slice] = None,
) -> Any:
    """The two-bounce LTM (Eq. 14) between two voxel sets as a matrix — the same numbers as
    ``vltm matrix``: a :class:`MatrixResult` with the complex amplitudes (complex64) and
    intensities (float32) of shape ``(n_from, n_to)`` and the voxel coordinates.

    ``from_`` (the projector foci, the rows) and ``to`` (the imaged voxels, the columns): a
    SPEC, a :class:`Volume`, an ``(..., 3)`` array of points (m, z > 0), or ``"gamma"``: Γ of
    ``volume`` = the voxels whose direct light exceeds ``epsilon``·max, from ``direct`` (the
    direct light over ``volume``) or else a direct pass first. One pass over the capture
    (more if the accumulators of all foci exceed the memory budget); cost per laser row
    ``n_from·Ks·8J`` flops, at the end ``n_from·n_to·Ks·14J``; memory ``16·J·(Ks+1)`` bytes
    per focus and 44 bytes per element. ``rows=slice(a, b)`` returns a :class:`Partial` (one
    factorised column per focus; ``gamma`` then needs ``direct``). Wave options as
    :func:`direct`; the matrix is imaged on the band path."""
    cap = capture if isinstance(capture, Capture) else open(capture)
    wave = _wave(wavelength, sigma, weights, band, compensate_laser, "auto")
    gamma = None
    if any(isinstance(x, str) and x.strip() == "gamma" for x in (from_, to)):
        if volume is None:
            raise ArgumentError("argument `--volume`: `gamma` in --from/--to needs the volume of Γ")
        if not (0.0 <= float(epsilon) < 1.0):
            raise ArgumentError(f"argument `--epsilon`: expected 0 <= E < 1, found {epsilon}")
        vol = Volume(volume)
        if direct is None:
            if rows is not None:
                raise ArgumentError(
                    "argument `rows`: `gamma` over a part of the rows needs Γ: pass direct=, the finished direct light over volume"
                )
            d = globals()["direct"](cap, vol, wavelength=wavelength, sigma=sigma, weights=weights,
                                    band=band, compensate_laser=compensate_laser)
        else:
            d = np.asarray(direct, dtype=np.float32)
            if d.size != len(vol):
                raise ArgumentError(
                    f"argument `direct`: expected {len(vol)} values (the volume's voxels), found {d.size}"
                )
        g = gamma_mask(d, float(epsilon)).ravel()
        gamma = np.ascontiguousarray(vol.points.reshape(-1, 3)[g], dtype=np.float32)
        if len(gamma) == 0:
            raise ArgumentError(
                "argument `--epsilon`: Γ is empty: no voxel of --volume has direct light above ε·max (all zero)"
            )
    frm = _voxel_set(from_, "--from", gamma)
    dst = _voxel_set(to, "--to", gamma)
    if len(frm) == 0 or len(dst) == 0:
        raise ArgumentError(
            f"argument `{'--from' if len(frm) == 0 else '--to'}`: the voxel set is empty"
        )
    r = _rows(rows, cap)
    res = _native.run(cap._native, _native.volume_from_points(dst), "matrix", rows=r,
                      from_points=frm, **wave)
    if r is not None:
        return Partial(res)
    values, amps, rep = res
    n = (len(frm), len(dst))
    return MatrixResult(amps.reshape(n), values.reshape(n), frm, dst, rep)
