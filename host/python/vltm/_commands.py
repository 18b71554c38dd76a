"""What the command line does besides probing: ``vltm info`` and ``vltm demo`` as text
(:class:`Text`), and the process settings ``--threads`` and ``--max-memory``."""

from __future__ import annotations

import os
from typing import Any, Dict, Optional, Union

from . import _check, _native, _options
from ._captures import Capture, PathLike
from ._errors import _warn
from ._volumes import Volume


class Text(str):
    """Text the command line prints (:func:`info`, :func:`demo`): a ``str`` that a REPL or
    notebook shows as its lines rather than as a quoted string."""

    def __repr__(self) -> str:
        return str(self)


@_options.documented(_options.PREP)
def info(capture: Union[Capture, PathLike], *, delta_t: Optional[float] = None,
         t_start: Optional[float] = None, grid_width: Optional[float] = None,
         t_min: Any = None, t_max: Any = None, rebin: int = 1, background: Any = None,
         png: Optional[PathLike] = None, volume: Any = None) -> Text:
    """The layout text of ``vltm info CAPTURE``, line for line: format, scan, laser and SPAD
    spots, device positions, time axis, counts, default λ, the memory budget and where it
    comes from, and the summed transient (after the preprocessing, below). ``delta_t``, ``t_start``, ``grid_width``
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
        p, **opts, **_options.checked(locals(), _options.PREP),
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
