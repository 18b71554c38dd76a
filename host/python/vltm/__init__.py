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
>>> R = vltm.relight(cap, vol, pattern="-0.25,0.15,0.7,1;0.25,0,0.9,0.5")
>>> Rb = vltm.row(cap, vol, focus=(0.25, 0.0, 0.9))     # T(., x_b)
>>> part = vltm.direct(cap, vol, rows=slice(0, 32))     # a Partial (accumulator state)
>>> rest = vltm.direct(cap, vol, rows=slice(32, 64))
>>> vltm.merge([part, rest]).finish()                   # == vltm.direct(cap, vol)
>>> vltm.direct(cap, vol, as_xarray=True)               # xarray.DataArray over x, y, z (m)

Every probe releases the GIL while it runs. Errors are :class:`VltmError` subclasses
(:class:`ArgumentError` is a ``ValueError``, :class:`DataError` an ``OSError``) carrying the
command line's one-line messages, naming keyword arguments (``t_min``) where the command
line names flags (``--t-min``). Scale-out over a Dask cluster: :mod:`vltm.dask` (imported
on first use; needs ``dask`` and ``distributed``).

The keywords the probes share (the wave options ``wavelength`` … ``path``, the capture
options ``swap_roles``, ``t_min``, ``t_max``, ``rebin``, ``background`` and the result
options ``rows``, ``amplitudes``, ``report``, ``as_xarray``) mean the same everywhere: each
function's ``help`` lists the ones it takes under *Common keywords* (written once, in
``vltm._options``).
"""

from __future__ import annotations

import importlib
from typing import Any

# Each name is defined in one module of the package (README.md's table lists them).
from . import _native
from ._captures import Capture, open, simulate
from ._commands import demo, info, max_memory, set_max_memory, set_threads
from ._errors import ArgumentError, DataError, VltmError
from ._ltm import matrix, relight, row
from ._partial import Partial, merge
from ._probes import column, direct, gamma_mask, indirect
from ._results import MatrixResult
from ._volumes import Volume, volume

# Reachable from `vltm` as before the split, though not in `__all__`: the path type and
# `info`'s return type, and the private helpers (`vltm.dask` uses `_check`, `_volume` and
# `_voxel_set`; pickled Partials name `vltm._partial_from_state`).
from . import _check  # noqa: F401
from ._captures import PathLike, _capture, _normals  # noqa: F401
from ._commands import Text  # noqa: F401
from ._errors import _warn  # noqa: F401
from ._ltm import _voxel_set  # noqa: F401
from ._partial import _out_shape, _partial_from_state, _Voxels  # noqa: F401
from ._probes import _SHELLS, _probe, _rows, _shells  # noqa: F401
from ._results import _matrix_result, _shape_out  # noqa: F401
from ._volumes import _volume  # noqa: F401

__version__: str = _native.__version__

__all__ = [
    "ArgumentError",
    "Capture",
    "DataError",
    "MatrixResult",
    "Partial",
    "VltmError",
    "Volume",
    "column",
    "demo",
    "direct",
    "gamma_mask",
    "indirect",
    "info",
    "matrix",
    "max_memory",
    "merge",
    "open",
    "relight",
    "row",
    "set_max_memory",
    "set_threads",
    "simulate",
    "volume",
]


def __getattr__(name: str) -> Any:
    """``vltm.dask`` on first use (Dask stays optional)."""
    if name == "dask":
        return importlib.import_module(".dask", __name__)
    raise AttributeError(f"module 'vltm' has no attribute {name!r}")
