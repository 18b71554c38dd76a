"""Results as the caller asked for them: a probe's values shaped like its volume, with
the amplitudes, the report or xarray labels on request (:func:`_shape_out`), and the
matrix between two voxel sets (:class:`MatrixResult`)."""

from __future__ import annotations

from typing import Any, Dict, NamedTuple

import numpy as np

from ._errors import ArgumentError, _warn


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
