"""The light transport matrix beyond the diagonal and its columns, as ``vltm``'s ``ltm``
commands: relighting (:func:`relight`), rows (:func:`row`) and the matrix between two voxel
sets (:func:`matrix`)."""

from __future__ import annotations

import os
from typing import Any, Optional, Sequence, Union

import numpy as np

from . import _check, _native, _options, _probes
from ._captures import Capture, PathLike, _capture
from ._errors import ArgumentError, DataError
from ._options import INPUT, OUTPUT, WAVE
from ._partial import Partial
from ._probes import _probe, _rows, gamma_mask
from ._results import MatrixResult
from ._volumes import Volume, _volume


@_options.documented(WAVE, INPUT, OUTPUT)
def relight(
    capture: Union[Capture, PathLike],
    volume: Union[str, np.ndarray, Volume],
    pattern: Union[str, np.ndarray],
    *,
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
    amplitudes: bool = False,
    report: bool = False,
    as_xarray: bool = False,
) -> Any:
    """Relighting (``vltm relight``): the virtual camera's image ``i = T·p`` over
    ``volume`` (float32 shaped like the volume) under an illumination that weights several projector foci, in one factorised
    pass (amplitudes add: ``A_p(b) = Σ_a p_a A(a, b)``, intensities ``|A_p|²``).

    ``pattern``: weighted foci ``"x,y,z,w;x,y,z,w"`` (metres; w = 1 if left out), an
    ``(n, 3)`` or ``(n, 4)`` array of foci (and weights), a voxel image of the volume's
    shape (its voxels are the foci, its values the weights), or the path of a float32
    ``.npy`` image. ``amplitudes=True`` also returns ``A_p`` (complex128);
    ``report["passes"]`` the passes over the capture. ``leak_correct`` (``True``/``"gate"``,
    ``"model"`` or ``False``), ``leak_epsilon`` as :func:`column` (on by default). ``capture`` and ``volume`` as :func:`direct`."""
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
    lc, lm, la = _check.leak("leak_correct", leak_correct)
    return _probe("relight", capture, vol, None, amplitudes, report, as_xarray,
                  {"pattern": spec, "leak_correct": leak_correct}, pattern=pts, pattern_spec=spec,
                  leak_correct=lc, leak_model=lm, leak_auto=la,
                  leak_epsilon=_check.real("leak_epsilon", leak_epsilon),
                  **_options.checked(locals()))


@_options.documented(WAVE, INPUT, OUTPUT)
def row(
    capture: Union[Capture, PathLike],
    volume: Union[str, np.ndarray, Volume],
    focus: Sequence[float],
    *,
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
    report: bool = False,
    as_xarray: bool = False,
) -> Any:
    """A row ``T(·, x_b)`` of the LTM (``vltm row``), float32 shaped like the volume: the
    virtual camera focused at ``x_b`` = ``focus`` (m, z > 0), the projector over ``volume``
    (two-bounce gate), streamed by laser rows without transposing the capture.
    ``swap_roles`` is refused (a row is the transposed column already). ``leak_correct``
    (``True``/``"gate"``, ``"model"``, ``"auto"`` or ``False``), ``leak_epsilon`` as :func:`column` (on by
    default). ``capture`` and ``volume`` as
    :func:`direct`."""
    f = _check.point("focus", focus)
    lc, lm, la = _check.leak("leak_correct", leak_correct)
    return _probe("row", capture, volume, None, False, report, as_xarray,
                  {"gate": "two-bounce", "focus": list(f), "leak_correct": leak_correct},
                  focus=list(f), leak_correct=lc, leak_model=lm, leak_auto=la,
                  leak_epsilon=_check.real("leak_epsilon", leak_epsilon),
                  **_options.checked(locals()))


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


@_options.documented(WAVE, OUTPUT)
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
    factorised column per focus; ``gamma`` then needs ``direct``). The matrix is imaged on
    the band path (there is no ``path`` keyword)."""
    cap = _capture(capture)
    wave = _options.checked(locals(), WAVE, path="auto")
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
            d = _probes.direct(cap, vol, wavelength=wavelength, sigma=sigma, weights=weights,
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
