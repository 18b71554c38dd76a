"""The probes over a volume: direct light (:func:`direct`), columns (:func:`column`) and the
in-focus indirect light (:func:`indirect`), with Γ (:func:`gamma_mask`); and what every probe
does around the library call (:func:`_probe`: the capture opened, the volume and the row
range checked, the result shaped or kept as a :class:`Partial`)."""

from __future__ import annotations

from typing import Any, Dict, Optional, Sequence, Tuple, Union

import numpy as np

from . import _check, _native, _options
from ._captures import Capture, PathLike, _capture
from ._errors import ArgumentError
from ._options import INPUT, OUTPUT, WAVE
from ._partial import Partial
from ._results import _shape_out
from ._volumes import Volume, _volume


def gamma_mask(direct: np.ndarray, epsilon: float = 0.1) -> np.ndarray:
    """Γ = {v : I_d(v) > ε·max I_d} (Eq. 15), as vltm computes it; boolean, shaped like
    ``direct``."""
    d = _check.array("direct", direct)
    e = _check.real("epsilon", epsilon)
    return np.asarray(_native.gamma_mask(d.ravel(), e), dtype=bool).reshape(d.shape)


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


@_options.documented(WAVE, INPUT, OUTPUT)
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

    ``capture``: a :class:`Capture` or a file path (opened as :func:`open` does);
    ``volume``: a SPEC string, a :class:`Volume` or an ``(..., 3)`` array of points (m).
    ``gate``: ``"gaussian"`` (direct light), ``"none"`` (monochromatic, no gate: paper
    Fig. 6) or ``"higher-order"`` (light arriving after the 3-vertex time: Eq. 18 on the
    diagonal)."""
    return _probe("direct", capture, volume, rows, amplitudes, report, as_xarray,
                  {"gate": gate}, gate=_check.text("gate", gate), **_options.checked(locals()))


@_options.documented(WAVE, INPUT, OUTPUT)
def column(
    capture: Union[Capture, PathLike],
    volume: Union[str, np.ndarray, Volume],
    focus: Sequence[float],
    *,
    gate: str = "two-bounce",
    shell: Optional[Tuple[float, float]] = None,
    shells: Optional[Tuple[float, float]] = None,
    mask_epsilon: Optional[float] = None,
    leak_correct: Union[bool, str] = True,
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
    """A column ``T(x_a, ·)`` of the LTM for the focus ``x_a`` = ``focus`` (m, z > 0), float32
    shaped like the volume — the same numbers as ``vltm column``.

    ``gate``: ``"two-bounce"`` (Eq. 14), ``"higher-order"`` (Eq. 18) or ``"none"``; ``shell``
    ``(r0, r1)`` keeps ``r0 <= |x_a - x_b| < r1``. ``shells=(r1, r2)``: the near
    ``[0, r1)``, middle ``[r1, r2)`` and far ``[r2, inf)`` light of one run, stacked as
    ``(3,) + shape`` (``vltm column --shells``; a ``shell`` dimension with ``as_xarray``).
    ``mask_epsilon`` zeroes every voxel whose direct light is not above ε·max (an extra
    diagonal pass). ``leak_correct=True`` (the default, as ``vltm column``; also
    ``"gate"``) removes the capture's direct light first (the 3-vertex windows of Γ = direct
    light above ``leak_epsilon``·max; ``report["explained"]`` the energy removed);
    ``leak_correct="model"`` subtracts a surface model fitted to the capture instead
    (``--leak-correct model``; ``report["explained"]`` the energy it explains), falling back
    to the windows with a ``RuntimeWarning`` that says why when it explains less than 99 %
    or cannot be fitted; ``report["leak_correct"]`` says which ran. ``leak_correct="auto"``
    (``--leak-correct auto``): the windows' pass first, then the model only where the energy
    the windows leave lies mostly next to them (``report["adjacency"]``, the share it chose
    by; at least ``0.4``). ``leak_correct=False``
    is the column of the capture as it is (``--no-leak-correct``), needed for partial
    states (``rows=``). ``amplitudes=True`` also returns the complex
    amplitudes ``A(x_a, ·)`` (complex128, ``T = |A|²``, 0 outside ``shell``) of two-bounce
    and higher-order columns; the un-gated column has none. ``capture`` and ``volume`` as
    :func:`direct`."""
    f = _check.point("focus", focus)
    me = _check.real("mask_epsilon", mask_epsilon, none=True)
    le = _check.real("leak_epsilon", leak_epsilon)
    sh = None if shell is None else _check.pair("shell", shell)
    cut = _shells(shells)
    lc, lm, la = _check.leak("leak_correct", leak_correct)
    attrs = {"gate": gate, "focus": list(f), "mask_epsilon": me, "shell": sh,
             "shells": None if shells is None else list(_check.pair("shells", shells)),
             "leak_correct": leak_correct, "leak_epsilon": le if lc else None}
    return _probe("column", capture, volume, rows, amplitudes, report, as_xarray, attrs,
                  _SHELLS if cut else None, focus=list(f), gate=_check.text("gate", gate),
                  shell=sh, shells=cut, mask_epsilon=me,
                  leak_correct=lc, leak_model=lm, leak_auto=la, leak_epsilon=le,
                  **_options.checked(locals()))


@_options.documented(WAVE, INPUT, OUTPUT)
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
    leak_correct: Union[bool, str] = True,
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
    """In-focus indirect light (Eqs. 15–17), float32 shaped like the volume — the same
    numbers as ``vltm indirect``: Γ = voxels whose direct light exceeds
    ``epsilon``·max, then ``Σ T(x_a, x_b)`` over pairs of Γ at least ``min_separation``
    apart (default 1.5σ) or within ``shell``; ``shells=(r1, r2)``: the near, middle and far
    pair sums of one run, stacked as ``(3,) + shape``. ``gate``: of the summed columns,
    ``"two-bounce"`` (first-order indirect light), ``"higher-order"`` (the paper's ">= 3rd
    bounce") or ``"none"``. ``direct``: the direct light over the same volume (e.g. from
    :func:`direct` or a merged Dask run) instead of pass 1 — required with ``rows=``.
    ``report=True`` also returns Γ (``report["gamma"]``, boolean) and the direct light
    (``report["direct"]``), as ``vltm indirect`` writes them beside ``I_i``. ``capture`` and
    ``volume`` as :func:`direct`.

    ``leak_correct=True`` (the default, as ``vltm indirect``): the capture's direct light is
    removed first — per laser/SPAD pair the bins where a 3-vertex return of a Γ voxel can
    arrive are zeroed; one more pass over the capture measures the removed energy
    (``report["explained"]``). It uses the return times only, so each row is corrected on
    its own and partial states (``rows=``) take it too (also ``"gate"``).
    ``leak_correct="model"`` (``--leak-correct model``): a surface model fitted to the whole
    capture is subtracted instead, keeping the indirect light inside the windows
    (``report["explained"]`` the energy it explains); when it explains less than 99 % or
    cannot be fitted, a ``RuntimeWarning`` says why and the windows are used
    (``report["leak_correct"]`` says which ran); not with ``rows=``. ``leak_correct="auto"``
    (``--leak-correct auto``): the windows' pass over Γ first, then the model only where the
    energy they leave lies mostly next to them (``report["adjacency"]``); not with ``rows=``.
    ``leak_correct=False``:
    the paper's Eq. 17 on the capture as it is (``vltm indirect --no-leak-correct``)."""
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
    lc, lm, la = _check.leak("leak_correct", leak_correct)
    attrs = {"gate": gate, "epsilon": eps, "shell": sh, "leak_correct": leak_correct,
             "shells": None if shells is None else list(_check.pair("shells", shells))}
    return _probe("indirect", capture, volume, rows, False, report, as_xarray, attrs,
                  _SHELLS if cut else None, epsilon=eps, shell=sh, shells=cut, direct=d,
                  gate=_check.text("gate", gate), leak_correct=lc, leak_model=lm, leak_auto=la,
                  **_options.checked(locals()))
