"""Voxel sets: :class:`Volume` (a grid SPEC, a point list or an array of points) and the
check of every wrapper's ``volume`` argument."""

from __future__ import annotations

from typing import Any, Optional, Tuple, Union

import numpy as np

from . import _check, _native


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
