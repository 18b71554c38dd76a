"""The keywords the wrappers share, checked by one helper and documented once.

Every probe (:func:`vltm.direct`, :func:`vltm.column`, :func:`vltm.indirect`,
:func:`vltm.relight`, :func:`vltm.row`, :func:`vltm.matrix`) takes the wave options and,
but for ``matrix``, the capture options; :meth:`vltm.Capture.transient` and
:func:`vltm.info` take the preprocessing. Their signatures keep every keyword explicit (so
``help``, ``inspect.signature`` and unknown-keyword errors stay as they are); what the
keywords mean and how they are checked lives here:

- :func:`checked` turns a wrapper's arguments into the checked keyword arguments of the
  library call, always in the order of :data:`WAVE` then :data:`INPUT`, so that of several
  bad arguments the same one is named first everywhere;
- :func:`documented` appends the section *Common keywords* (from :data:`DOCS`) to a
  wrapper's docstring, with the keywords its signature has.
"""

from __future__ import annotations

import inspect
import textwrap
from typing import Any, Callable, Dict, Mapping, Sequence, Tuple, TypeVar

from . import _check

#: The wave options, as ``vltm direct --wavelength … --path`` reads them.
WAVE: Tuple[str, ...] = ("wavelength", "sigma", "weights", "band", "compensate_laser", "crop",
                         "path")
#: The preprocessing of raw counts, in the order it is applied.
PREP: Tuple[str, ...] = ("t_min", "t_max", "rebin", "background")
#: The capture options: the role swap and the preprocessing.
INPUT: Tuple[str, ...] = ("swap_roles",) + PREP
#: What a probe returns besides its volume (checked by the probe itself).
OUTPUT: Tuple[str, ...] = ("rows", "amplitudes", "report", "as_xarray")

_CHECKS: Dict[str, Callable[[str, Any], Any]] = {
    "wavelength": lambda k, v: _check.real(k, v, none=True),
    "sigma": lambda k, v: _check.real(k, v, none=True),
    "weights": _check.text,
    "band": _check.real,
    "compensate_laser": _check.flag,
    "crop": _check.flag,
    "path": _check.text,
    "swap_roles": _check.flag,
    "t_min": _check.time_bound,
    "t_max": _check.time_bound,
    "rebin": _check.integer,
    "background": lambda k, v: _check.background(v),
}


def checked(given: Mapping[str, Any], names: Sequence[str] = WAVE + INPUT,
            **fixed: Any) -> Dict[str, Any]:
    """The shared keywords ``names`` of a wrapper, checked (the ranges are the library's
    checks), as keyword arguments for the library: ``given`` is the wrapper's ``locals()``
    (its arguments by name), ``fixed`` values the wrapper does not take from its caller
    (``path="auto"`` for the matrix). A bad value raises the one-line
    :class:`~vltm.ArgumentError` naming it."""
    values = {**given, **fixed}
    return {k: _CHECKS[k](k, values[k]) for k in names}


#: One entry per shared keyword: what it means, its default and its command-line flag.
DOCS: Dict[str, str] = {
    "wavelength": "λ, the virtual illumination's wavelength (m; default twice the aperture "
                  "pitch; ``--wavelength``).",
    "sigma": "the time gate's standard deviation (m; default 2λ/3; ``--sigma``).",
    "weights": "``\"inv\"`` (the paper's 1/d, default), ``\"one\"`` (y-tal) or ``\"cos\"`` "
               "(the wall's cosine per leg, from the relay's normals: :func:`direct` on paired "
               "and confocal scans).",
    "band": "the band half-width in 1/σ (default 5.0).",
    "compensate_laser": "``True`` divides each row by the laser's falloff cos θ/d² "
                        "(``--compensate-laser``).",
    "crop": "``False`` keeps the whole time axis; by default it is cropped to the bins the "
            "probed voxels can reach, with the gate's support, before the band transform "
            "(``--no-crop``).",
    "path": "the evaluation path, ``\"auto\"`` (default), ``\"band\"``, ``\"planar\"`` or "
            "``\"lookup\"``.",
    "swap_roles": "``True`` uses the SPADs as the projector and the lasers as the camera "
                  "(reciprocity; reads the capture into memory).",
    "t_min": "start of the time window: metres of path as a number or ``\"0.72m\"``, bins as "
             "``\"600b\"``; the histograms are cropped to it.",
    "t_max": "end of the time window, as ``t_min``.",
    "rebin": "``K`` bins summed into one (default 1).",
    "background": "``\"auto\"`` (each histogram's floor, from the bins no return from the "
                  "volume reaches), ``\"none\"`` or counts per source bin; by default nothing "
                  "is subtracted.",
    "rows": "``slice(a, b)`` returns a :class:`Partial` over those laser rows (accumulator "
            "state: merge with :func:`merge`, then ``.finish()``) instead of the result.",
    "amplitudes": "``True`` also returns the complex amplitudes ``A`` (complex128, "
                  "``T = |A|²``).",
    "report": "``True`` also returns the counters and configuration as a dict "
              "(``wavelength``, ``sigma``, ``bins``, ``rows``, ``seconds``, ``path``, "
              "``crop``, ``warnings``…).",
    "as_xarray": "``True`` returns an ``xarray.DataArray`` with the voxel coordinates ``x``, "
                 "``y``, ``z`` (m) and the parameters as attributes (needs ``xarray``).",
}

_GROUPS: Tuple[Tuple[str, Tuple[str, ...]], ...] = (
    ("Wave options", WAVE),
    ("Capture options (the preprocessing is applied per histogram in this order)", INPUT),
    ("Results (with several, a tuple: the volume, then the amplitudes, then the report)",
     OUTPUT),
)

F = TypeVar("F", bound=Callable[..., Any])


def _fill(text: str) -> str:
    """One bullet, wrapped without breaking inside a ````literal````."""
    parts = text.split("``")
    text = "``".join(p.replace(" ", "\u00a0") if i % 2 else p for i, p in enumerate(parts))
    out = textwrap.fill(text, width=88, initial_indent="- ", subsequent_indent="  ")
    return out.replace("\u00a0", " ")


def section(params: Sequence[str], groups: Sequence[Tuple[str, ...]], indent: str = "    ") -> str:
    """The *Common keywords* section for a signature with ``params``: the keywords of
    ``groups`` it takes, group by group, each line prefixed with ``indent``."""
    out = ["Common keywords (the same in every wrapper that takes them):"]
    for title, names in _GROUPS:
        have = [k for k in names if k in params and any(k in g for g in groups)]
        if not have:
            continue
        out.append("")
        out.append(f"{title}:")
        out.extend(_fill(f"``{k}``: {DOCS[k]}") for k in have)
    return textwrap.indent("\n".join(out), indent, lambda line: bool(line.strip()))


def documented(*groups: Tuple[str, ...]) -> Callable[[F], F]:
    """Appends the section *Common keywords* (the keywords of ``groups`` in the wrapper's
    signature, from :data:`DOCS`) to the wrapper's docstring, indented as its body, so
    that ``help`` shows them while their text is written once, here."""

    def apply(fn: F) -> F:
        params = list(inspect.signature(fn).parameters)
        doc = (fn.__doc__ or "").rstrip()
        body = [line for line in doc.expandtabs().split("\n")[1:] if line.strip()]
        indent = min((line[:len(line) - len(line.lstrip())] for line in body), key=len,
                     default="    ")
        fn.__doc__ = doc + "\n\n" + section(params, groups, indent) + "\n" + indent
        return fn

    return apply
