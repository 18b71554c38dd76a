"""Type stubs of the extension module `vltm._native` (the Rust side; use the `vltm` API)."""

from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

__version__: str

class NativeCapture:
    def info(self) -> Dict[str, Any]: ...
    def laser_points(self) -> np.ndarray: ...
    def spad_points(self) -> np.ndarray: ...
    def transient(
        self,
        t_min: Optional[str] = ...,
        t_max: Optional[str] = ...,
        rebin: int = ...,
        background: Optional[str] = ...,
    ) -> Tuple[np.ndarray, float, float, Optional[str], Optional[str]]:
        """(summed counts float64, t0, dt, preprocessing summary, warning)."""
        ...
    def save(self, path: str, uncompressed: bool = ..., ptu: Optional[str] = ...) -> None: ...

class Volume:
    @property
    def shape(self) -> Tuple[int, int, int]: ...
    @property
    def is_grid(self) -> bool: ...
    @property
    def spec(self) -> Optional[str]: ...
    def flat_points(self) -> np.ndarray: ...
    def __len__(self) -> int: ...

class NativePartial:
    def to_bytes(self) -> bytes: ...
    def rows(self) -> List[Tuple[int, int]]: ...
    def total_rows(self) -> int: ...
    def kind(self) -> str: ...
    def is_complete(self) -> bool: ...
    def nbytes(self) -> int: ...
    def focus(self) -> Optional[Tuple[float, float, float]]: ...
    def finish(self, amplitudes: bool = ...) -> Tuple[Any, ...]:
        """(intensities, amplitudes or None, shape, report, voxel points, is_grid); a matrix state:
        (intensities, amplitudes complex64, (n_from, n_to), report, from points, to points)."""
        ...

def open_capture(
    path: str,
    delta_t: Optional[float] = ...,
    t_start: Optional[float] = ...,
    grid_width: Optional[float] = ...,
) -> NativeCapture: ...
def capture_from_arrays(
    h: np.ndarray,
    lasers: np.ndarray,
    laser_shape: Tuple[int, int],
    spads: np.ndarray,
    spad_shape: Tuple[int, int],
    delta_t: float,
    t_start: float,
    laser_xyz: Sequence[float],
    sensor_xyz: Sequence[float],
    legs_in_time: bool,
    confocal: bool,
) -> NativeCapture: ...
def volume_from_spec(spec: str) -> Volume: ...
def volume_from_points(points: np.ndarray) -> Volume: ...
def partial_from_bytes(data: bytes) -> NativePartial: ...
def merge(parts: List[NativePartial]) -> NativePartial: ...
def merge_bytes(parts: List[bytes]) -> bytes: ...
def gamma_mask(direct: np.ndarray, epsilon: float) -> List[bool]: ...
def check_memory(what: str, buffers: List[Tuple[str, int]]) -> None:
    """Checks buffers about to be made against the memory budget (one-line DataError)."""
    ...
def info_text(
    path: str,
    delta_t: Optional[float] = ...,
    t_start: Optional[float] = ...,
    grid_width: Optional[float] = ...,
    t_min: Optional[str] = ...,
    t_max: Optional[str] = ...,
    rebin: int = ...,
    background: Optional[str] = ...,
    png: Optional[str] = ...,
) -> Tuple[List[str], List[str], np.ndarray, float, float]:
    """`vltm info`'s lines, its warnings, the summed transient, t0 and dt."""
    ...
def demo(out: str) -> str:
    """`vltm demo` into `out`; returns the table."""
    ...
def simulate(scene: str) -> NativeCapture: ...
def run(
    capture: NativeCapture,
    volume: Volume,
    kind: str,
    *,
    focus: Optional[Sequence[float]] = ...,
    gate: str = ...,
    shell: Optional[Tuple[float, float]] = ...,
    shells: Optional[str] = ...,
    epsilon: float = ...,
    direct: Optional[np.ndarray] = ...,
    mask_epsilon: Optional[float] = ...,
    leak_correct: bool = ...,
    leak_model: bool = ...,
    leak_auto: bool = ...,
    leak_epsilon: float = ...,
    wavelength: Optional[float] = ...,
    sigma: Optional[float] = ...,
    weights: str = ...,
    band: float = ...,
    compensate_laser: bool = ...,
    crop: bool = ...,
    path: str = ...,
    swap_roles: bool = ...,
    t_min: Optional[str] = ...,
    t_max: Optional[str] = ...,
    rebin: int = ...,
    background: Optional[str] = ...,
    rows: Optional[Tuple[int, int]] = ...,
    amplitudes: bool = ...,
    from_points: Optional[np.ndarray] = ...,
    pattern: Optional[np.ndarray] = ...,
    pattern_spec: Optional[str] = ...,
) -> Any:
    """A probe (direct, column, indirect, matrix, relight, row): (values, amplitudes,
    report) — values flat, three volumes concatenated with ``shells`` — a matrix's
    (intensities, amplitudes, report), or a NativePartial with ``rows``."""
    ...
def set_threads(n: int) -> None: ...
def set_max_memory(size: str) -> int: ...
def max_memory() -> int: ...
