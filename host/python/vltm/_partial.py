"""Partial states: a probe over some laser rows (``rows=slice(a, b)``) kept as its
accumulators (:class:`Partial`), pickled as vltm's binary partial format, added up by
:func:`merge` and finished into the one-pass result."""

from __future__ import annotations

import builtins
import os
from typing import Any, Dict, Iterable, NamedTuple, Optional, Tuple, Union

import numpy as np

from . import _check, _native
from ._captures import PathLike
from ._errors import ArgumentError
from ._results import _matrix_result, _shape_out
from ._volumes import Volume


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


# Pickles of a Partial name this function: it keeps the name they have always used,
# ``vltm._partial_from_state``, so that states pickled by any version of the package load.
_partial_from_state.__module__ = "vltm"


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
