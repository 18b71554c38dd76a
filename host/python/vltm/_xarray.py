"""Labelled results: probe volumes as ``xarray.DataArray`` with their voxel coordinates
(``x``, ``y``, ``z`` in metres) and parameters as attributes (netCDF-safe: numbers,
strings and number arrays only). ``xarray`` is optional: ``pip install vltm[xarray]``."""

from __future__ import annotations

from typing import Any, Dict, Optional, Sequence

import numpy as np

from ._errors import ArgumentError


def xr() -> Any:
    try:
        import xarray
    except ImportError:
        raise ArgumentError(
            "argument `as_xarray`: labelled results need xarray: pip install 'vltm[xarray]'"
        ) from None
    return xarray


def clean_attrs(attrs: Dict[str, Any]) -> Dict[str, Any]:
    """Attributes netCDF can store: None dropped, booleans as 0/1, sequences as arrays."""
    out: Dict[str, Any] = {}
    for k, v in attrs.items():
        if v is None:
            continue
        if isinstance(v, (bool, np.bool_)):
            out[k] = int(v)
        elif isinstance(v, (int, float, str, np.integer, np.floating)):
            out[k] = v
        elif isinstance(v, (list, tuple, np.ndarray)):
            a = np.asarray(v)
            if a.dtype.kind in "biuf" and a.ndim == 1:
                out[k] = a.astype(np.float64)
    return out


def volume_array(values: np.ndarray, points: np.ndarray, grid: bool, attrs: Dict[str, Any],
                 lead: Optional[Sequence[Any]] = None, lead_dim: str = "shell",
                 name: str = "intensity") -> Any:
    """``values`` of shape ``[len(lead)] + vol_shape`` over voxel centres ``points``
    (``vol_shape + (3,)``): a grid gets dimensions ``x, y, z`` with 1-D coordinates; points
    get dimensions ``voxel`` (or ``i0, i1…``) with ``x, y, z`` coordinates along them."""
    xarray = xr()
    shape = points.shape[:-1]
    coords: Dict[str, Any] = {}
    if grid and len(shape) == 3:
        dims = ["x", "y", "z"]
        coords = {"x": points[:, 0, 0, 0].astype(np.float64),
                  "y": points[0, :, 0, 1].astype(np.float64),
                  "z": points[0, 0, :, 2].astype(np.float64)}
    else:
        dims = ["voxel"] if len(shape) == 1 else [f"i{k}" for k in range(len(shape))]
        for k, c in enumerate("xyz"):
            coords[c] = (tuple(dims), points[..., k].astype(np.float64))
    if lead is not None:
        dims = [lead_dim] + dims
        coords[lead_dim] = list(lead)
    a = xarray.DataArray(values, dims=dims, coords=coords, name=name,
                         attrs=clean_attrs(attrs))
    for c in "xyz":
        a[c].attrs["units"] = "m"
    return a
