"""Argument checks of the public API: every bad argument raises one
:class:`~vltm.ArgumentError` naming it (``argument `name`: ...``), before any work starts."""

from __future__ import annotations

import numbers
from typing import Any, Optional, Sequence, Tuple

import numpy as np

from . import _native
from ._errors import ArgumentError


def fail(name: str, msg: str) -> ArgumentError:
    return ArgumentError(f"argument `{name}`: {msg}")


def real(name: str, x: Any, *, none: bool = False, finite: bool = True) -> Optional[float]:
    """A real number (not a bool, not NaN; finite unless ``finite=False``)."""
    if x is None and none:
        return None
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Real):
        raise fail(name, f"expected a number, found {type(x).__name__} {x!r}")
    v = float(x)
    if v != v or (finite and not np.isfinite(v)):
        raise fail(name, f"expected a finite number, found {v}")
    return v


def integer(name: str, x: Any, lo: int = 0) -> int:
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Integral):
        raise fail(name, f"expected an integer, found {type(x).__name__} {x!r}")
    if int(x) < lo:
        raise fail(name, f"expected an integer >= {lo}, found {int(x)}")
    return int(x)


def flag(name: str, x: Any) -> bool:
    if not isinstance(x, (bool, np.bool_)):
        raise fail(name, f"expected True or False, found {type(x).__name__} {x!r}")
    return bool(x)


def leak(name: str, x: Any) -> Tuple[bool, bool, bool]:
    """A probe's ``leak_correct``: ``True`` or ``"gate"`` (the time windows, the default),
    ``"model"`` (the surface model, the windows its fallback), ``"auto"`` (the windows, or
    the model where the energy they leave lies next to them) or ``False``; as (corrected,
    model, auto)."""
    if isinstance(x, str):
        if x in ("gate", "model", "auto"):
            return True, x == "model", x == "auto"
        raise fail(name, f"expected True, False, 'gate', 'model' or 'auto', found {x!r}")
    if not isinstance(x, (bool, np.bool_)):
        raise fail(name, f"expected True, False, 'gate', 'model' or 'auto', found {type(x).__name__} {x!r}")
    return bool(x), False, False


def text(name: str, x: Any) -> str:
    if not isinstance(x, str):
        raise fail(name, f"expected a string, found {type(x).__name__} {x!r}")
    return x


def point(name: str, x: Any) -> Tuple[float, float, float]:
    """``(x, y, z)`` in metres: three finite numbers."""
    if isinstance(x, (str, bytes)) or not hasattr(x, "__len__"):
        raise fail(name, f"expected (x, y, z) in metres, found {x!r}")
    a = np.asarray(x)
    if a.shape != (3,):
        raise fail(name, f"expected (x, y, z) in metres, found {x!r}")
    return tuple(real(name, v) for v in a.tolist())  # type: ignore[return-value]


def pair(name: str, x: Any, *, inf: bool = True) -> Tuple[float, float]:
    """``(r0, r1)`` in metres (``r1`` may be ``inf`` where ``inf`` allows)."""
    if isinstance(x, (str, bytes)) or not hasattr(x, "__len__") or len(x) != 2:
        raise fail(name, f"expected (r0, r1) in metres, found {x!r}")
    a = real(name, x[0])
    b = real(name, x[1], finite=not inf)
    return (a, b)  # type: ignore[return-value]


def array(name: str, x: Any, *, dtype: Any = np.float32, last: Optional[int] = None,
          ndim: Optional[Sequence[int]] = None, finite: bool = True,
          empty: bool = False) -> np.ndarray:
    """A real-valued array converted to ``dtype`` (C order): not object, string or complex,
    not empty, finite; ``last``: the size of the last axis, ``ndim``: allowed ranks."""
    try:
        a = np.asarray(x)
    except Exception as e:  # ragged lists and the like
        raise fail(name, f"expected an array, found {type(x).__name__} ({e})") from None
    if a.dtype.kind not in "biuf":
        raise fail(name, f"expected a real-valued array, found dtype {a.dtype}")
    if ndim is not None and a.ndim not in ndim:
        raise fail(name, f"expected {' or '.join(map(str, ndim))} dimensions, found shape {a.shape}")
    if last is not None and (a.ndim == 0 or a.shape[-1] != last):
        raise fail(name, f"expected shape (..., {last}), found {a.shape}")
    if a.size == 0 and not empty:
        raise fail(name, f"expected a non-empty array, found shape {a.shape}")
    # The copy in ``dtype`` and the finiteness mask count against vltm's memory budget.
    copy = a.size * np.dtype(dtype).itemsize if (a.dtype != dtype or not a.flags.c_contiguous) else 0
    _native.check_memory(f"argument `{name}`: an array of {a.size} values", [
        (f"`{name}` as {np.dtype(dtype).name}", copy),
        (f"the finiteness mask of `{name}`", a.size if finite else 0)])
    a = np.ascontiguousarray(a, dtype=dtype)
    if finite and a.size and not np.all(np.isfinite(a)):
        n = int(np.size(a) - np.count_nonzero(np.isfinite(a)))
        raise fail(name, f"{n} values are NaN or infinite")
    return a


def time_bound(name: str, x: Any) -> Optional[str]:
    """A window end as the command line reads it: metres (a number, ``"0.72m"``) or bins
    (``"600b"``)."""
    if x is None:
        return None
    if isinstance(x, str):
        return x
    return repr(real(name, x))


def background(x: Any) -> Optional[str]:
    """``None``/``"none"``, ``"auto"``, or counts per bin (a number >= 0)."""
    if x is None or isinstance(x, str):
        return x
    return repr(real("background", x))
